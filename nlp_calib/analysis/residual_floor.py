"""The covariance the fit's own residuals give its score, beside the one the noise model gives.

The sandwich's meat is propagated from white noise sources (tracker poses, encoder inputs) whose
variances the residuals set. A pose's noise enters the two windows that meet at it with opposite
signs, so along a chain of windows it cancels: an error that is each window's own (a motion the
model misses, slip, a device that shakes) but is read as pose noise cancels with it, and the σ
comes out as small as a chain of poses allows. Nothing in the noise model can tell the two apart;
the residuals can: a pose's noise makes the scores of the windows that share it anti-correlated,
an error of each window's own does not.

So the score's covariance is also taken from the residuals themselves: every window's score
``g_w = ρ'_w·J_wᵀΩe_w`` times every score that shares a record with it (a pose or an interval:
white sources reach no other window), ``S = Σ_{u,v share a record} g_u g_vᵀ`` (a
heteroskedasticity-and-autocorrelation-consistent meat truncated where white sources stop). Under
the noise model its expectation is the propagated meat, whatever the noise's size; where the
residuals hold more than the model's cancelling noise it is larger. It is noisy (a sum of
cancelling terms), so each parameter's variance from it is compared with the propagated one in
units of its own sampling noise, from contiguous batches of windows, and only a variance beyond
it beyond that noise (Student's t, 95 %) is taken: a spread the σ to believe takes in, as the
block jackknife's, beside the noise model's σ (which stays the white-noise σ).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from nlp_calib.analysis.drift import t_quantile

#: Contiguous batches of windows the residuals' variance is split into to estimate its noise.
BATCHES = 20
#: A batch spans at least this many times the windows a window shares records with.
BATCH_SPAN = 4
#: One-sided level at which the residuals' variance exceeds the propagated one beyond its noise.
LEVEL = 0.95


class ScoreRows:
    """The residuals' own meat of each batch of windows, from each window's score ``ρ'_w·J_wᵀΩe_w``
    (free parameters' coordinates) as the blocks of windows arrive in order: a window's part is
    counted once every window it shares a record with has arrived, so only those few are kept (an
    array of every window's scores was 64 MB at 10^6 windows, beside the uncertainty's peak)."""

    def __init__(self, starts: np.ndarray, stops: np.ndarray, n_free: int):
        n = starts.size
        ordered = n == 0 or bool(np.all(np.diff(starts) >= 0))
        # Windows u < v (by first record) share a record where v starts at or before u's end.
        self.hi = np.searchsorted(starts, stops, side="right") if ordered else np.zeros(n, dtype=int)
        span = int(np.max(self.hi - np.arange(n))) if n and ordered else 0
        batches = min(BATCHES, n // max(BATCH_SPAN * span, 1)) if ordered else 0
        self.edges = np.linspace(0, n, max(batches, 0) + 1).astype(int)
        # The windows whose every neighbour has arrived once the first ``k`` have.
        self.reach = np.maximum.accumulate(self.hi) if n else self.hi
        self.meats = np.zeros((batches, n_free, n_free))
        # Each batch's score and information: a block's own estimate (:mod:`block_scatter`) ...
        self.scores = np.zeros((batches, n_free))
        self.information = np.zeros((batches, n_free, n_free))
        # ... and the sum of its windows' scores' squares, each alone.
        self.alone = np.zeros((batches, n_free, n_free))
        #: How many later windows a window shares a record with, on average.
        self.span = float(np.mean(self.hi - np.arange(n))) - 1.0 if n and ordered else 0.0
        self.kept = np.zeros((0, n_free))
        self.done = 0

    def add(
        self, w: slice, J: np.ndarray, weighted_e: np.ndarray, Omega: np.ndarray, weight: np.ndarray
    ) -> None:
        """Windows ``w`` (the next after those added): their Jacobians ``J`` (., rows, n),
        residuals times ρ' (rows, .) and ρ' (.)."""
        if self.meats.shape[0] < 5:
            return
        if w.start != self.done + self.kept.shape[0]:
            raise ValueError(f"windows {w.start}-{w.stop} added out of order")
        self._add_information(w, J, Omega, weight)
        g = np.concatenate([self.kept, np.einsum("wrn,r,rw->wn", J, Omega, weighted_e)])
        base = self.done
        ready = int(np.searchsorted(self.reach[base : w.stop], w.stop, side="right"))
        prefix = np.concatenate([np.zeros((1, g.shape[1])), np.cumsum(g, axis=0)])
        for k in range(self.meats.shape[0]):
            lo, up = max(self.edges[k], base), min(self.edges[k + 1], base + ready)
            if lo >= up:
                continue
            own = g[lo - base : up - base]
            later = prefix[self.hi[lo:up] - base] - prefix[lo - base + 1 : up - base + 1]
            self.meats[k] += own.T @ own + own.T @ later + later.T @ own
            self.scores[k] += own.sum(axis=0)
            self.alone[k] += own.T @ own
        self.kept, self.done = g[ready:], base + ready

    def _add_information(self, w: slice, J: np.ndarray, Omega: np.ndarray, weight: np.ndarray) -> None:
        """Each batch's ``Σ ρ'·JᵀΩJ`` over the windows ``w``, batch by batch and row by row: the
        temporaries are (windows, n), never J's whole size."""
        cut = np.clip(self.edges, w.start, w.stop) - w.start
        for b in np.flatnonzero(cut[1:] > cut[:-1]):
            first, last = int(cut[b]), int(cut[b + 1])
            for r in range(J.shape[1]):
                A = J[first:last, r, :]
                self.information[b] += (A * (Omega[r] * weight[first:last])[:, None]).T @ A

    def blocks(self) -> tuple[np.ndarray, ...]:
        """Each batch's score, information and residuals' meat, and the meat its borders keep of a
        noise that cancels along the chain (one window's mean squared score times the windows it
        shares records with: :mod:`block_scatter`)."""
        windows = np.diff(self.edges)[:, None, None]
        border = self.alone / np.where(windows > 0, windows, 1) * max(self.span, 1.0)
        return self.scores, self.information, self.meats, border

    def variances(self, to_cov: Callable[[np.ndarray], np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
        """Each parameter's variance from the residuals' own meat and the margin its sampling noise
        leaves (Student's t at :data:`LEVEL` times its σ; None: too few windows to split into
        batches, or not every window added). ``to_cov`` maps a meat to the covariance it gives
        (linear)."""
        batches = self.meats.shape[0]
        if batches < 5 or self.done != self.hi.size:
            return None
        per = np.array([np.diag(to_cov(m)) for m in self.meats])
        t = t_quantile(2.0 * (1.0 - LEVEL), batches - 1)
        return per.sum(axis=0), t * np.sqrt(batches * per.var(axis=0, ddof=1))


def beyond(cov: np.ndarray, found: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """Each parameter's σ from the residuals' own scores (``found``: its variance and the margin of
    its noise) where it exceeds the σ of ``cov`` (the noise model's) beyond that margin; NaN
    elsewhere."""
    n = cov.shape[0]
    if found is None:
        return np.full(n, np.nan)
    var, margin = found
    base = np.diag(cov)
    with np.errstate(invalid="ignore"):
        raised = np.isfinite(base) & (var - base > margin)
    return np.where(raised, np.sqrt(np.where(raised, var, 0.0)), np.nan)
