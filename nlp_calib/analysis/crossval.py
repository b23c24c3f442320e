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
from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis.metrics import TrajectoryMetrics

#: With fewer converged folds than this the jackknife σ is not reported.
MIN_FOLDS = 5


@dataclass(frozen=True)
class Fold:
    """One fold: the held-out records ``[first, stop)``, the estimate without them and its scores."""

    first: int
    stop: int
    params: np.ndarray
    converged: bool
    heldout: TrajectoryMetrics | None


@dataclass(frozen=True)
class CrossValidation:
    """The folds of a blocked cross-validation and the jackknife σ of every parameter (model order)."""

    names: tuple[str, ...]
    folds: tuple[Fold, ...]
    std: np.ndarray

    @property
    def converged(self) -> tuple[Fold, ...]:
        return tuple(f for f in self.folds if f.converged)

    @property
    def available(self) -> bool:
        return len(self.converged) >= MIN_FOLDS

    def spread(self) -> np.ndarray:
        """Largest minus smallest estimate of each parameter over the converged folds."""
        P = np.array([f.params for f in self.converged])
        return np.ptp(P, axis=0) if P.size else np.full(len(self.names), np.nan)

    def std_dict(self) -> dict[str, float]:
        return {n: float(s) for n, s in zip(self.names, self.std)}

    def heldout_mean(self, figure: str) -> float:
        """The mean of one held-out figure over the folds, weighted by the records each scores."""
        values, weights = [], []
        for f in self.converged:
            if f.heldout is not None:
                values.append(dict(f.heldout.figures())[figure])
                weights.append(f.heldout.records)
        ok = np.isfinite(values)
        return (
            float(np.average(np.array(values)[ok], weights=np.array(weights)[ok]))
            if np.any(ok)
            else float("nan")
        )


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
    return np.sqrt((K - 1) / K * np.sum(dev * dev, axis=0))


def combine(names: Sequence[str], folds: Sequence[Fold]) -> CrossValidation:
    """The cross-validation of these folds (σ from the converged ones; NaN with too few)."""
    good = [f.params for f in folds if f.converged]
    std = jackknife_std(np.array(good)) if len(good) >= MIN_FOLDS else np.full(len(names), np.nan)
    return CrossValidation(names=tuple(names), folds=tuple(folds), std=std)


def believed_std(white: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """The σ to believe: the larger of the white-noise σ (a floor) and the jackknife σ."""
    return np.where(np.isfinite(blocked), np.fmax(white, blocked), white)
