"""Gauss-Newton with Levenberg-Marquardt damping and iteratively reweighted robust kernels.

Each iteration takes the robust-weighted normal equations ``(H, g)`` at ``x`` (weights ρ'(s),
so the step is IRLS), solves ``(H + λ·D) δ = −g`` with ``D = diag(H)``, moves ``x ⊞ δ`` and keeps
the step only if the true cost falls. λ follows Nielsen's rule (Madsen, Nielsen & Tingleff,
*Methods for non-linear least squares problems*, 2004), which makes the iteration converge
from the log's own initial guess where undamped Gauss-Newton diverges.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from nlp_calib.core.errors import OptionsError
from nlp_calib.solvers.evaluation import (
    NAN_START_REASON,
    SINGULAR_REASON,
    NormalEquations,
    ProblemEvaluator,
    is_singular,
)
from nlp_calib.solvers.result import IterationRecord, SolverResult


@dataclass(frozen=True)
class GaussNewtonOptions:
    """Stopping rules and damping of :class:`GaussNewton`.

    Stops when the undamped Gauss-Newton step predicts a relative cost decrease below
    ``function_tolerance`` (the optimum, to rounding), when the scaled gradient
    ``max |g_i| / sqrt(H_ii)`` is below ``gradient_tolerance``, or when an undamped accepted step
    is below ``step_tolerance`` (relative to ``|x|``) and lowered the cost by less than
    ``function_tolerance``.
    """

    max_iterations: int = 200
    initial_damping: float = 1e-2
    function_tolerance: float = 1e-14
    step_tolerance: float = 1e-10
    gradient_tolerance: float = 1e-10

    def __post_init__(self) -> None:
        if self.max_iterations < 1:
            raise OptionsError(f"max_iterations must be >= 1, got {self.max_iterations}")
        for name in (
            "initial_damping",
            "function_tolerance",
            "step_tolerance",
            "gradient_tolerance",
        ):
            if not getattr(self, name) > 0:
                raise OptionsError(f"{name} must be > 0, got {getattr(self, name)}")


#: λ beyond this means no step can reduce the cost any more.
_MAX_DAMPING = 1e16


def _decrement(ne: NormalEquations) -> float:
    """``gᵀH⁻¹g``: the cost decrease the undamped Gauss-Newton step predicts (×½ convention)."""
    try:
        return float(ne.g @ np.linalg.solve(ne.H, ne.g))
    except np.linalg.LinAlgError:
        return float("inf")


def _scaled_gradient(ne: NormalEquations) -> float:
    d = np.sqrt(np.maximum(np.diag(ne.H), 1e-300))
    return float(np.max(np.abs(ne.g) / d)) if ne.g.size else 0.0


class GaussNewton:
    """Levenberg-Marquardt damped IRLS on the evaluator's normal equations (no bounds)."""

    name: ClassVar[str] = "gauss_newton"
    label: ClassVar[str] = "Gauss-Newton"
    options_type: ClassVar[type] = GaussNewtonOptions
    supports_bounds: ClassVar[bool] = False

    def __init__(self, evaluator: ProblemEvaluator, options: GaussNewtonOptions | None = None) -> None:
        self.evaluator = evaluator
        self.options = options or GaussNewtonOptions()

    @staticmethod
    def functions(options: GaussNewtonOptions) -> tuple[str, ...]:
        return ("normal_equations",)

    def solve(
        self,
        x0: np.ndarray,
        lower: np.ndarray | Sequence[float] | None = None,
        upper: np.ndarray | Sequence[float] | None = None,
    ) -> SolverResult:
        """Minimise the robust cost from ``x0`` (free parameters); bounds are not used."""
        return solve(self.evaluator, x0, self.options)


def solve(
    evaluator: ProblemEvaluator, x0: np.ndarray, options: GaussNewtonOptions | None = None
) -> SolverResult:
    """Minimise the robust cost from ``x0`` (free parameters)."""
    opts = options or GaussNewtonOptions()
    t0 = time.perf_counter()
    x = np.asarray(x0, dtype=float).copy()
    ne = evaluator.normal_equations(x)
    history = [IterationRecord(0, ne.cost, ne.chi2, ne.inliers, 0.0, opts.initial_damping)]
    lam, nu = opts.initial_damping, 2.0
    converged, reason = False, ""
    iteration = 0
    if not np.isfinite(ne.cost) or not np.all(np.isfinite(ne.H)):
        reason = NAN_START_REASON
    else:
        while iteration < opts.max_iterations:
            iteration += 1
            if _scaled_gradient(ne) < opts.gradient_tolerance * max(1.0, np.sqrt(ne.cost)):
                converged, reason = True, "gradient below tolerance"
                iteration -= 1
                break
            D = np.maximum(np.diag(ne.H), 1e-12 * max(float(np.max(np.diag(ne.H))), 1e-300))
            try:
                step = np.linalg.solve(ne.H + lam * np.diag(D), -ne.g)
            except np.linalg.LinAlgError:
                reason = "singular damped normal matrix"
                break
            if _decrement(ne) <= opts.function_tolerance * ne.cost:
                # Even the undamped step could not lower the cost by more than its rounding.
                converged, reason = True, "Gauss-Newton decrement below tolerance"
                iteration -= 1
                break
            predicted = -(2.0 * ne.g @ step + step @ ne.H @ step)
            step_norm = float(np.linalg.norm(step))
            x_new = evaluator.boxplus(x, step)
            # The trial point's normal equations carry its cost: most steps are accepted, so one
            # evaluation per iteration is cheaper than a cost-only check followed by another.
            ne_new = evaluator.normal_equations(x_new)
            cost_new = ne_new.cost
            gain = (ne.cost - cost_new) / predicted
            if np.isfinite(cost_new) and gain > 0:
                decrease = ne.cost - cost_new
                x, ne = x_new, ne_new
                lam *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
                nu = 2.0
                history.append(IterationRecord(iteration, ne.cost, ne.chi2, ne.inliers, step_norm, lam))
                small_step = bool(
                    np.all(np.abs(step) <= opts.step_tolerance * (np.abs(x) + opts.step_tolerance))
                )
                if decrease <= opts.function_tolerance * ne.cost and small_step and lam < 1.0:
                    converged, reason = True, "cost and step below tolerance"
                    break
            else:
                history.append(
                    IterationRecord(iteration, cost_new, step_norm=step_norm, damping=lam, accepted=False)
                )
                lam *= nu
                nu *= 2.0
                if lam > _MAX_DAMPING:
                    converged = _scaled_gradient(ne) < 1e3 * opts.gradient_tolerance * max(
                        1.0, np.sqrt(ne.cost)
                    )
                    reason = "no further decrease possible" + ("" if converged else " (gradient not small)")
                    break
        else:
            reason = f"iteration limit ({opts.max_iterations}) reached before convergence"
    if converged and is_singular(ne.H):
        converged, reason = False, SINGULAR_REASON
    return SolverResult(
        solver=GaussNewton.name,
        names=evaluator.fns.names,
        params=evaluator.params(x),
        x=x,
        cost=ne.cost,
        chi2=ne.chi2,
        inliers=ne.inliers,
        n_residuals=evaluator.n_residuals,
        iterations=iteration,
        converged=converged,
        reason=reason,
        time_s=time.perf_counter() - t0,
        history=tuple(history),
    )
