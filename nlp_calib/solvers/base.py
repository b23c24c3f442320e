"""What a solver provides: the protocol every entry of the solver registry implements.

A solver is set up once on a :class:`~nlp_calib.solvers.evaluation.ProblemEvaluator` (the
problem's Functions bound to one data matrix) with its own frozen options dataclass, and may then
solve from any start. It calls the evaluator's Functions and never builds an expression itself.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar, Protocol

import numpy as np

from nlp_calib.results.solver import SolverResult
from nlp_calib.solvers.evaluation import ProblemEvaluator


class Solver(Protocol):
    """A solver of the robust calibration problem."""

    #: Registry and scenario key (``solvers: [name]``, and ``name:`` for its options block).
    name: ClassVar[str]
    #: Display name in tables and figures.
    label: ClassVar[str]
    #: The frozen dataclass of its options (the scenario block ``name:`` is validated against it).
    options_type: ClassVar[type]
    #: Whether it honours box bounds on the parameters.
    supports_bounds: ClassVar[bool]

    def __init__(self, evaluator: ProblemEvaluator, options: Any) -> None: ...

    @staticmethod
    def functions(options: Any) -> tuple[str, ...]:
        """The per-residual Functions it evaluates, so a backend can prepare them in advance."""
        ...

    def solve(
        self,
        x0: np.ndarray,
        lower: np.ndarray | Sequence[float] | None = None,
        upper: np.ndarray | Sequence[float] | None = None,
    ) -> SolverResult:
        """Minimise from ``x0`` (free parameters), within bounds when it supports them."""
        ...
