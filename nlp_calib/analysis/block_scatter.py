"""Whether contiguous blocks of one drive agree on each parameter within their own σ.

The σ to believe takes in errors that vary along the drive through the block jackknife: the fit
without each block. Where blocks carry very unequal information (a car whose few bends hold all
that a mount's lateral offset is known from), leaving one out moves the fit little although the
blocks, each fitted alone, disagree far beyond their σ: the jackknife cannot see it.

So each parameter is also estimated on each block of windows alone, the others held at the fit:
one Gauss-Newton step from the fit on the block's own score ``g_k`` and information ``H_k``
(the parameter's diagonal entry), ``θ_k = θ − g_k / H_k``, with the σ of the block's own
residuals' meat (:mod:`residual_floor`: each window's score times those sharing a record with it),
never below the white noise's share of the block (the noise model's meat apportioned by the
block's information). The χ² of the blocks' estimates about their weighted mean has ``K − 1``
degrees of freedom when the blocks scatter as their σ allow. Beyond its upper :data:`LEVEL`
point, the blocks disagree: the parameter's σ (the larger of the white-noise σ and the residuals'
own) is scaled by the Birge ratio ``√(χ²/(K − 1))``, a spread the σ to believe takes in. Blocks
where the parameter is not determined (no information, or a negligible share of it) are left out.
"""

from __future__ import annotations

import math

import numpy as np

#: Upper-tail probability of χ²(K − 1) beyond which a parameter's blocks disagree: strict, so
#: white noise almost never widens a σ (measured on simulated white-noise runs, see the tests).
LEVEL = 1e-3
#: A block counts in a parameter's χ² where it holds at least this share of its information.
MIN_SHARE = 1e-3
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


def block_estimates(
    scores: np.ndarray, information: np.ndarray, meats: np.ndarray, white_meat: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each block's step from the fit for each parameter alone, ``−g_k/H_k`` (blocks, n), and its
    σ: the block's own residuals' meat or the white noise's share, the larger (NaN where the
    block holds no information on the parameter). ``white_meat``: the noise model's meat of the
    whole fit (n, n)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        H = np.where(information > 0, information, np.nan)
        own = np.clip(np.diagonal(meats, axis1=1, axis2=2), 0.0, None)
        white = np.clip(np.diag(white_meat), 0.0, None) * H / np.nansum(H, axis=0)
        return -scores / H, np.sqrt(np.fmax(own, white)) / H


def chi2_about_mean(
    step: np.ndarray, std: np.ndarray, information: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per parameter, the χ² of the blocks that determine it about their weighted mean and its
    degrees of freedom (0 where fewer than :data:`MIN_BLOCKS` do)."""
    share = information / np.where(information.sum(axis=0) > 0, information.sum(axis=0), 1.0)
    counts = np.isfinite(step) & np.isfinite(std) & (std > 0) & (share >= MIN_SHARE)
    w = np.where(counts, 1.0 / np.where(counts, std, 1.0) ** 2, 0.0)
    v = np.where(counts, step, 0.0)
    total = w.sum(axis=0)
    mean = (w * v).sum(axis=0) / np.where(total > 0, total, 1.0)
    chi2 = (w * (v - mean) ** 2).sum(axis=0)
    dof = counts.sum(axis=0) - 1
    return chi2, np.where(dof + 1 >= MIN_BLOCKS, dof, 0)


def birge_spread(chi2: np.ndarray, dof: np.ndarray, std: np.ndarray) -> np.ndarray:
    """``std`` scaled by the Birge ratio where the χ² lies beyond its :data:`LEVEL` point; NaN
    elsewhere."""
    out = np.full(std.shape, np.nan)
    for i, (c, d) in enumerate(zip(chi2, dof)):
        if d >= 1 and np.isfinite(std[i]) and chi2_tail(float(c), int(d)) < LEVEL:
            out[i] = std[i] * math.sqrt(c / d)
    return out


def block_scatter(
    rows: tuple[np.ndarray, np.ndarray, np.ndarray], white_meat: np.ndarray, std: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per free parameter: the spread (``std`` times the Birge ratio where the blocks disagree,
    NaN elsewhere), the blocks' χ² and its degrees of freedom (0: not judged). ``rows``: each
    block's score, information diagonal and residuals' meat (``ScoreRows``' batches)."""
    scores, information, meats = rows
    if scores.shape[0] < MIN_BLOCKS:
        n = std.size
        return np.full(n, np.nan), np.full(n, np.nan), np.zeros(n, dtype=int)
    step, sd = block_estimates(scores, information, meats, white_meat)
    chi2, dof = chi2_about_mean(step, sd, information)
    return birge_spread(chi2, dof, std), np.where(dof > 0, chi2, np.nan), dof
