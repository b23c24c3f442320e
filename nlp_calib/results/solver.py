"""What a solve produced: the record every solver returns."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class IterationRecord:
    """One solver iteration. Fields a solver does not track are ``nan``."""

    iteration: int
    cost: float
    chi2: float = float("nan")
    inliers: int = -1
    step_norm: float = float("nan")
    damping: float = float("nan")
    accepted: bool = True
    constraint_violation: float = float("nan")
    dual_infeasibility: float = float("nan")


@dataclass(frozen=True)
class SolverTrace:
    """How a solve went: its iterations, wall time (s), per-iteration record and the solver's own
    statistics (e.g. IPOPT's return status)."""

    iterations: int
    time_s: float
    history: tuple[IterationRecord, ...] = ()
    stats: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SolverResult:
    """What a solve produced; ``converged`` is False with a ``reason`` whenever it failed.

    ``params`` is the full parameter vector in ``names`` order (fixed ones included); ``x`` the
    free part the solver moved; ``trace`` how the solve went.
    """

    solver: str
    names: tuple[str, ...]
    params: np.ndarray
    x: np.ndarray
    cost: float
    chi2: float
    inliers: int
    n_residuals: int
    converged: bool
    reason: str
    trace: SolverTrace

    @property
    def iterations(self) -> int:
        return self.trace.iterations

    @property
    def time_s(self) -> float:
        return self.trace.time_s

    def param_dict(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, self.params)}
