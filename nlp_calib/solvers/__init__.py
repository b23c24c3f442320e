"""Solver layer: evaluation of the problem's Functions on data (backends, evaluator) and the solvers.

Adding a solver is one file implementing :class:`~nlp_calib.solvers.base.Solver` and one entry
in :data:`SOLVERS`; scenarios, the command line and the reports read the registry.
"""

from __future__ import annotations

from nlp_calib.core.errors import OptionsError
from nlp_calib.results.solver import IterationRecord, SolverResult
from nlp_calib.solvers.base import Solver
from nlp_calib.solvers.evaluation import Priors, ProblemEvaluator, Sensitivities
from nlp_calib.solvers.gauss_newton import GaussNewton, GaussNewtonOptions
from nlp_calib.solvers.ipopt import Ipopt, IpoptOptions

SOLVERS: dict[str, type[Solver]] = {s.name: s for s in (GaussNewton, Ipopt)}


def get_solver(name: str) -> type[Solver]:
    """The solver registered under ``name``."""
    try:
        return SOLVERS[name]
    except KeyError:
        raise OptionsError(f"unknown solver {name!r}; valid solvers: {', '.join(SOLVERS)}") from None


def solver_label(name: str) -> str:
    """Display name of a solver (its registry name when it is not registered)."""
    solver = SOLVERS.get(name)
    return solver.label if solver is not None else name


__all__ = [
    "SOLVERS",
    "GaussNewton",
    "GaussNewtonOptions",
    "Ipopt",
    "IpoptOptions",
    "IterationRecord",
    "Priors",
    "ProblemEvaluator",
    "Sensitivities",
    "Solver",
    "SolverResult",
    "get_solver",
    "solver_label",
]
