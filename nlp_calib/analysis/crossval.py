"""Cross-validation on contiguous blocks, and the uncertainty it implies.

The fitted records are cut into K contiguous blocks. Each fold fits every window that does not
touch one block and scores that block, unseen, with the fault-robust figures. The spread of the
K estimates gives the delete-one-block jackknife standard deviation

    σ_J² = (K − 1)/K · Σ_k (θ_k − θ̄)²,

which counts every error that varies along the drive (timing, slip, model error that depends on
how the robot moves), not only white tracker and encoder noise. The white-noise σ is a floor
(it counts white noise only); the jackknife σ has its own sampling error (K − 1 degrees of
freedom). The σ to believe is the larger of the two, parameter by parameter.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

from nlp_calib.results.checks import MIN_FOLDS, CrossValidation, Fold


def blocks(first: int, stop: int, k: int) -> list[tuple[int, int]]:
    """``k`` contiguous record ranges of nearly equal length covering ``[first, stop)``."""
    edges = np.linspace(first, stop, k + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in itertools.pairwise(edges) if b - a >= 2]


def jackknife_std(estimates: np.ndarray) -> np.ndarray:
    """Delete-one-group jackknife standard deviation of each column of ``estimates`` (K, n)."""
    K = estimates.shape[0]
    if K < 2:
        return np.full(estimates.shape[1], np.nan)
    dev = estimates - estimates.mean(axis=0)
    # A held parameter is the same in every fold: exactly 0, not the mean's rounding.
    same = np.all(estimates == estimates[0], axis=0)
    return np.where(same, 0.0, np.sqrt((K - 1) / K * np.sum(dev * dev, axis=0)))


def combine(names: Sequence[str], folds: Sequence[Fold], min_folds: int = MIN_FOLDS) -> CrossValidation:
    """The cross-validation of these folds (σ from the converged ones; NaN with fewer than
    ``min_folds``)."""
    good = [f.params for f in folds if f.converged]
    std = jackknife_std(np.array(good)) if len(good) >= min_folds else np.full(len(names), np.nan)
    return CrossValidation(names=tuple(names), folds=tuple(folds), std=std)
