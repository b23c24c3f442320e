"""Whether contiguous blocks of one drive agree on each parameter within their own σ.

The σ to believe takes in errors that vary along the drive through the block jackknife: the fit
without each block. Where blocks carry very unequal information (a car whose few bends hold all
that a mount's lateral offset is known from), leaving one out moves the fit little although the
blocks, each fitted alone, disagree far beyond their σ: the jackknife cannot see it.

So the blocks of windows the residuals' own σ is estimated from (:mod:`residual_floor`'s
batches) are each fitted alone: one Gauss-Newton step from the fit on the block's own score and
information, ``θ_k = θ − H_k⁻¹g_k`` (its own marginal estimate: holding the other parameters at the
fit would move a parameter with how each block weighs the others' errors, which white noise alone
makes disagree). Its σ is the larger of the block's own residuals' meat's and the noise model's:
its share of the whole fit's meat plus what the block keeps at its two borders of a pose's noise
that cancels along the chain. The χ² of the blocks' estimates about their weighted mean has
``K − 1`` degrees of freedom when they scatter as their σ allow. Beyond its upper :data:`LEVEL`
point the blocks disagree: the parameter's σ (the larger of the white-noise σ and the residuals'
own) is scaled by the Birge ratio ``√(χ²/(K − 1))``, a spread the σ to believe takes in. A block
that leaves a parameter free, or holds a negligible share of its weight, is left out of its χ².
"""

from __future__ import annotations

import math

import numpy as np

#: Upper-tail probability of χ²(K − 1) beyond which a parameter's blocks disagree: strict, so
#: white noise almost never widens a σ (measured on simulated white-noise runs, see the tests).
LEVEL = 1e-3
#: A block counts in a parameter's χ² where its weight (1/σ²) is at least this fraction of an
#: equal share: a σ ten times an average block's says the block barely determines it.
MIN_SHARE = 0.01
#: A direction of a block's information below this fraction of its largest (in units where every
#: parameter's diagonal is 1) is one the block leaves free.
SINGULAR = 1e-9
#: Fewer blocks that determine a parameter than this judge nothing.
MIN_BLOCKS = 4


def chi2_tail(x: float, dof: int) -> float:
    """``P(χ² > x)`` for ``dof`` (a whole number ≥ 1) degrees of freedom, in closed form."""
    if x <= 0.0:
        return 1.0
    half = 0.5 * x
    if dof % 2 == 0:
        term = total = 1.0
        for i in range(1, dof // 2):
            term *= half / i
            total += term
        return math.exp(-half) * total
    tail = math.erfc(math.sqrt(half))
    term = math.sqrt(2.0 * x / math.pi) * math.exp(-half)
    for i in range(1, (dof + 1) // 2):
        tail += term
        term *= x / (2 * i + 1)
    return tail


def block_estimates(rows: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Each block's own estimate as a step from the fit, ``−H_k⁻¹g_k`` (blocks, n), and its σ;
    NaN for a parameter the block does not determine (in a direction its information leaves
    free). ``rows``: each block's score, information, meat and border meat (``ScoreRows.blocks``)
    and the noise model's meat of the whole fit. The σ is the larger of the block's own meat's and
    the noise's: its share of the noise model's meat (by information) plus its borders'. The own
    meat of a block is a sum of cancelling terms where a pose's noise cancels along the chain, so
    it can come out near 0, while the block keeps the noise of the poses at its two ends."""
    scores, information, meats, border, white = rows
    step, std = np.full(scores.shape, np.nan), np.full(scores.shape, np.nan)
    total = np.clip(np.diagonal(information, axis1=1, axis2=2).sum(axis=0), 0.0, None)
    for k, (g, H) in enumerate(zip(scores, information)):
        d = np.sqrt(np.clip(np.diag(H), 0.0, None))
        if not np.all(np.isfinite(H)) or not np.any(d > 0):
            continue
        unit = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 0.0)
        lam, V = np.linalg.eigh(H * np.outer(unit, unit))
        keep = lam > SINGULAR * lam.max()
        inv = (V[:, keep] / lam[keep]) @ V[:, keep].T * np.outer(unit, unit)
        free = ((V[:, ~keep] ** 2).sum(axis=1) > 1e-3) | (d == 0)
        share = np.sqrt(np.where(total > 0, d * d / np.where(total > 0, total, 1.0), 0.0))
        noise = white * np.outer(share, share) + border[k]
        var = np.fmax(np.diag(inv @ meats[k] @ inv), np.diag(inv @ noise @ inv))
        step[k] = np.where(free, np.nan, -inv @ g)
        std[k] = np.where(free, np.nan, np.sqrt(np.clip(var, 0.0, None)))
    return step, std


def chi2_about_mean(step: np.ndarray, std: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per parameter, the χ² of the blocks that determine it (each with at least :data:`MIN_SHARE`
    of an equal share of the weight) about their weighted mean, the block that adds most to it
    left out, and its degrees of freedom (0 where fewer than :data:`MIN_BLOCKS` remain)."""
    ok = np.isfinite(step) & np.isfinite(std) & (std > 0)
    w = np.where(ok, 1.0 / np.where(ok, std, 1.0) ** 2, 0.0)
    counts = ok & (w * step.shape[0] >= MIN_SHARE * w.sum(axis=0))
    chi2, terms = _about_mean(step, np.where(counts, w, 0.0))
    # One block's σ can come out too small (its own meat is a sum of cancelling terms, its floor
    # an apportioned share): one block alone never makes the blocks disagree.
    worst = np.argmax(terms, axis=0)
    counts[worst, np.arange(step.shape[1])] = False
    chi2, _ = _about_mean(step, np.where(counts, w, 0.0))
    dof = counts.sum(axis=0) - 1
    return chi2, np.where(dof + 1 >= MIN_BLOCKS, dof, 0)


def _about_mean(step: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The χ² of ``step`` (blocks, n) about its mean weighted by ``w`` (0: left out), and each
    block's term of it."""
    v = np.where(w > 0, step, 0.0)
    total = w.sum(axis=0)
    mean = (w * v).sum(axis=0) / np.where(total > 0, total, 1.0)
    terms = w * (v - mean) ** 2
    return terms.sum(axis=0), terms


def birge_spread(chi2: np.ndarray, dof: np.ndarray, std: np.ndarray) -> np.ndarray:
    """``std`` scaled by the Birge ratio where the χ² lies beyond its :data:`LEVEL` point; NaN
    elsewhere."""
    out = np.full(std.shape, np.nan)
    for i, (c, d) in enumerate(zip(chi2, dof)):
        if d >= 1 and np.isfinite(std[i]) and chi2_tail(float(c), int(d)) < LEVEL:
            out[i] = std[i] * math.sqrt(c / d)
    return out


def block_scatter(rows: tuple[np.ndarray, ...], std: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per free parameter: the spread (``std`` times the Birge ratio where the blocks disagree,
    NaN elsewhere), the blocks' χ² and its degrees of freedom (0: not judged). ``rows``: see
    :func:`block_estimates`."""
    if rows[0].shape[0] < MIN_BLOCKS:
        n = std.size
        return np.full(n, np.nan), np.full(n, np.nan), np.zeros(n, dtype=int)
    step, sd = block_estimates(rows)
    chi2, dof = chi2_about_mean(step, sd)
    return birge_spread(chi2, dof, std), np.where(dof > 0, chi2, np.nan), dof
