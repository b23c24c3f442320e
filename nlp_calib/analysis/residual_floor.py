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
#: Rows of windows handled at a time.
STEP = 1 << 16


class ScoreRows:
    """Each window's score ``ρ'_w·J_wᵀΩe_w`` (free parameters' coordinates), filled chunk by chunk
    and kept as running sums (one array of the windows' size: the prefix sums)."""

    def __init__(self, starts: np.ndarray, stops: np.ndarray, n_free: int):
        self.starts, self.stops = starts, stops
        self.prefix = np.zeros((starts.size + 1, n_free))

    def add(self, w: slice, J: np.ndarray, weighted_e: np.ndarray, Omega: np.ndarray) -> None:
        """Windows ``w``: their Jacobians ``J`` (., rows, n) and residuals times ρ' (rows, .)."""
        self.prefix[w.start + 1 : w.stop + 1] = np.einsum("wrn,r,rw->wn", J, Omega, weighted_e)

    def variances(self, to_cov: Callable[[np.ndarray], np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
        """Each parameter's variance from the residuals' own meat and the margin its sampling noise
        leaves (Student's t at :data:`LEVEL` times its σ; None: too few windows to split into
        batches). ``to_cov`` maps a meat to the covariance it gives (linear)."""
        a, b = self.starts, self.stops
        if a.size and not np.all(np.diff(a) >= 0):
            return None
        # Windows u < v (by first record) share a record where v starts at or before u's end.
        hi = np.searchsorted(a, b, side="right")
        span = int(np.max(hi - np.arange(a.size))) if a.size else 0
        batches = min(BATCHES, a.size // max(BATCH_SPAN * span, 1))
        if batches < 5:
            return None
        np.cumsum(self.prefix, axis=0, out=self.prefix)
        P = self.prefix
        edges = np.linspace(0, a.size, batches + 1).astype(int)
        meats = np.zeros((batches, P.shape[1], P.shape[1]))
        for k in range(batches):
            for lo in range(edges[k], edges[k + 1], STEP):
                up = min(lo + STEP, edges[k + 1])
                g = P[lo + 1 : up + 1] - P[lo:up]
                later = P[hi[lo:up]] - P[lo + 1 : up + 1]
                meats[k] += g.T @ g + g.T @ later + later.T @ g
        per = np.array([np.diag(to_cov(m)) for m in meats])
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
