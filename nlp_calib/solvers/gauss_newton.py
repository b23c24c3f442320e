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
from numpy.typing import ArrayLike

from nlp_calib.core.errors import OptionsError
from nlp_calib.results.solver import IterationRecord, SolverResult, SolverTrace
from nlp_calib.solvers.evaluation import (
    NAN_START_REASON,
    SINGULAR_REASON,
    NormalEquations,
    ProblemEvaluator,
    is_singular,
)


@dataclass(frozen=True)
class GaussNewtonOptions:
    """Stopping rules and damping of :class:`GaussNewton`.

    Stops when the undamped Gauss-Newton step predicts a relative cost decrease below
    ``function_tolerance`` (the optimum, to rounding), when the scaled gradient
    ``max |g_i| / sqrt(H_ii)`` is below ``gradient_tolerance``, or when an undamped accepted step
    is below ``step_tolerance`` (relative to ``|x|``) and lowered the cost by less than
    ``function_tolerance``; where no step lowers the cost, converged when the scaled gradient or
    the decrement is within ``_ROUNDING_SLACK`` times its tolerance (the cost's own rounding).
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
#: Where no step lowers the cost, the optimum to the cost's own rounding: a scaled gradient or an
#: undamped decrement within this many times its tolerance. A long drive's cost rounds above
#: ``function_tolerance`` (a highway car's 700 m: its evaluations about the optimum scatter by
#: 1e-13 of it), so a fit started there finds no lower cost while the decrement, still 1e-13 of
#: the cost, fails the test that stops an iteration; 1e3 of the tolerance still leaves each parameter
#: within 0.01 of its white σ on a log of up to a million windows (:func:`one_optimum`'s bound).
_ROUNDING_SLACK = 1e3
#: A leap (:meth:`_Iteration._leap`) follows steps this undamped, this aligned (cosine) with the
#: last, and shrinking by a share in this range of it (a linear approach, not a quadratic one).
_LEAP_DAMPING = 1e-6
_LEAP_ALIGNED = 0.99
_LEAP_RATIO = (0.5, 0.999)


def _scaled_gradient(ne: NormalEquations) -> float:
    d = np.sqrt(np.maximum(np.diag(ne.H), 1e-300))
    return float(np.max(np.abs(ne.g) / d)) if ne.g.size else 0.0


def one_optimum(H: np.ndarray, cost: float, delta: np.ndarray, tolerance: float) -> bool:
    """Whether two estimates ``delta`` apart (a tangent step) are one optimum to the decrement test
    (``tolerance``: :attr:`GaussNewtonOptions.function_tolerance`), ``H`` and ``cost`` the normal
    equations at either."""
    # The test stops where the decrement gᵀH⁻¹g is at most tolerance·cost. Near the optimum x* the
    # cost is quadratic, g = H(x − x*), so the decrement is ‖x − x*‖²_H: the test leaves an
    # estimate anywhere within √(tolerance·cost) of x* in the metric of H, and two estimates that
    # both pass it are at most twice that apart. Two closer than that the test cannot tell apart;
    # two farther apart are not both at x*. Per parameter, |δᵢ| ≤ √((H⁻¹)ᵢᵢ)·‖δ‖_H: about
    # √(tolerance·dof) of the white σ (σ² ≈ cost/dof), a share that grows with the data as the
    # test's own slack does, where a fixed share of σ does not.
    return bool(delta @ H @ delta <= 4.0 * tolerance * abs(cost))


@dataclass(frozen=True)
class Box:
    """Bounds on the free parameters (±inf where there are none). A coordinate at a bound whose
    gradient pushes it outwards is held for the step (the active set), and every trial point is
    projected back into the box: projected Levenberg-Marquardt."""

    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def of(cls, n: int, lower: ArrayLike | None, upper: ArrayLike | None) -> Box | None:
        """The box of ``n`` parameters, or None when neither bound is given."""
        if lower is None and upper is None:
            return None
        lo = np.full(n, -np.inf) if lower is None else np.asarray(lower, dtype=float)
        hi = np.full(n, np.inf) if upper is None else np.asarray(upper, dtype=float)
        return cls(lo, hi)

    def free(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        """The coordinates a step may move: not at a bound the descent direction pushes against."""
        return ~(((x <= self.lower) & (g > 0)) | ((x >= self.upper) & (g < 0)))

    def project(self, x: np.ndarray) -> np.ndarray:
        return np.clip(x, self.lower, self.upper)


def _restricted(ne: NormalEquations, free: np.ndarray | None) -> NormalEquations:
    """The normal equations of the ``free`` coordinates alone (all of them when None)."""
    if free is None:
        return ne
    return NormalEquations(ne.H[np.ix_(free, free)], ne.g[free], ne.cost, ne.chi2, ne.inliers)


class _Iteration:
    """The state of one run of the damped iteration: the point, its normal equations, λ and ν."""

    def __init__(self, evaluator: ProblemEvaluator, x: np.ndarray, opts: GaussNewtonOptions, box: Box | None):
        self.evaluator, self.opts, self.box = evaluator, opts, box
        self.x = x
        self.ne = evaluator.normal_equations(x)
        self.lam, self.nu = opts.initial_damping, 2.0
        self.last_step: np.ndarray | None = None
        self.history = [IterationRecord(0, self.ne.cost, self.ne.chi2, self.ne.inliers, 0.0, self.lam)]

    def restricted(self) -> tuple[NormalEquations, np.ndarray | None]:
        free = None if self.box is None else self.box.free(self.x, self.ne.g)
        return _restricted(self.ne, free), free

    def step(self, iteration: int) -> tuple[bool, str, bool] | None:
        """One iteration; when it ends the run: converged, the reason, and whether it counts as an
        iteration (a test before any step does not). None otherwise."""
        opts = self.opts
        ne, free = self.restricted()
        if _scaled_gradient(ne) < opts.gradient_tolerance * max(1.0, np.sqrt(ne.cost)):
            return True, "gradient below tolerance", False
        D = np.maximum(np.diag(ne.H), 1e-12 * max(float(np.max(np.diag(ne.H))), 1e-300))
        try:
            part = np.linalg.solve(ne.H + self.lam * np.diag(D), -ne.g)
        except np.linalg.LinAlgError:
            return False, "singular damped normal matrix", True
        if ne.decrement() <= opts.function_tolerance * ne.cost:
            # Even the undamped step could not lower the cost by more than its rounding.
            return True, "Gauss-Newton decrement below tolerance", False
        predicted = -(2.0 * ne.g @ part + part @ ne.H @ part)
        step = part
        if free is not None:
            step = np.zeros(free.size)
            step[free] = part
        return self._try(iteration, step, predicted)

    def _leap(self, iteration: int, step: np.ndarray) -> None:
        """After an undamped step along the last one and a steady share of it, the rest of the
        geometric series at once, kept if it lowers the cost: a robust kernel's reweighting with
        many windows past its threshold approaches its fixed point linearly (steps shrinking 5 % an
        iteration: hundreds of them), each step short by the weights' curvature it lacks."""
        last, self.last_step = self.last_step, step
        if last is None or self.lam >= _LEAP_DAMPING:
            return
        n0, n1 = float(np.linalg.norm(last)), float(np.linalg.norm(step))
        if n0 == 0.0 or n1 == 0.0 or float(step @ last) < _LEAP_ALIGNED * n0 * n1:
            return
        r = n1 / n0
        if not _LEAP_RATIO[0] <= r <= _LEAP_RATIO[1]:
            return
        x_new = self.evaluator.boxplus(self.x, step * (r / (1.0 - r)))
        if self.box is not None:
            x_new = self.box.project(x_new)
        ne_new = self.evaluator.normal_equations(x_new)
        if np.isfinite(ne_new.cost) and ne_new.cost < self.ne.cost:
            self.x, self.ne, self.last_step = x_new, ne_new, None
            self.history.append(
                IterationRecord(
                    iteration, ne_new.cost, ne_new.chi2, ne_new.inliers, n1 * r / (1 - r), self.lam
                )
            )

    def _try(self, iteration: int, step: np.ndarray, predicted: float) -> tuple[bool, str, bool] | None:
        """Move to ``x ⊞ step`` if the true cost falls; adapt λ either way."""
        opts, ne = self.opts, self.ne
        step_norm = float(np.linalg.norm(step))
        x_new = self.evaluator.boxplus(self.x, step)
        if self.box is not None:
            x_new = self.box.project(x_new)
        # The trial point's normal equations carry its cost: most steps are accepted, so one
        # evaluation per iteration is cheaper than a cost-only check followed by another.
        ne_new = self.evaluator.normal_equations(x_new)
        gain = (ne.cost - ne_new.cost) / predicted
        if np.isfinite(ne_new.cost) and gain > 0:
            decrease = ne.cost - ne_new.cost
            self.x, self.ne = x_new, ne_new
            self.lam *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
            self.nu = 2.0
            self.history.append(
                IterationRecord(iteration, ne_new.cost, ne_new.chi2, ne_new.inliers, step_norm, self.lam)
            )
            self._leap(iteration, step)
            tol = opts.step_tolerance
            small_step = bool(np.all(np.abs(step) <= tol * (np.abs(self.x) + tol)))
            if decrease <= opts.function_tolerance * ne_new.cost and small_step and self.lam < 1.0:
                return True, "cost and step below tolerance", True
            return None
        self.history.append(
            IterationRecord(iteration, ne_new.cost, step_norm=step_norm, damping=self.lam, accepted=False)
        )
        self.lam *= self.nu
        self.nu *= 2.0
        if self.lam > _MAX_DAMPING:
            ne_free, _ = self.restricted()
            small = (
                _scaled_gradient(ne_free)
                < _ROUNDING_SLACK * opts.gradient_tolerance * max(1.0, np.sqrt(ne_free.cost))
                or ne_free.decrement() <= _ROUNDING_SLACK * opts.function_tolerance * ne_free.cost
            )
            return small, "no further decrease possible" + ("" if small else " (gradient not small)"), True
        return None


class GaussNewton:
    """Levenberg-Marquardt damped IRLS on the evaluator's normal equations; bounds by projection."""

    name: ClassVar[str] = "gauss_newton"
    label: ClassVar[str] = "Gauss-Newton"
    options_type: ClassVar[type] = GaussNewtonOptions
    supports_bounds: ClassVar[bool] = True

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
        """Minimise the robust cost from ``x0`` (free parameters) within the bounds, if any; the
        normal equations a recent run on the same windows evaluated are recalled, not evaluated
        again (:meth:`~nlp_calib.solvers.evaluation.ProblemEvaluator.recalling`)."""
        with self.evaluator.recalling():
            return solve(self.evaluator, x0, self.options, lower, upper)


def solve(
    evaluator: ProblemEvaluator,
    x0: np.ndarray,
    options: GaussNewtonOptions | None = None,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
) -> SolverResult:
    """Minimise the robust cost from ``x0`` (free parameters), within ``[lower, upper]`` if given."""
    opts = options or GaussNewtonOptions()
    t0 = time.perf_counter()
    x = np.asarray(x0, dtype=float).copy()
    state = _Iteration(evaluator, x, opts, Box.of(x.size, lower, upper))
    converged, reason, iteration = False, "", 0
    if not np.isfinite(state.ne.cost) or not np.all(np.isfinite(state.ne.H)):
        reason = NAN_START_REASON
    else:
        reason = f"iteration limit ({opts.max_iterations}) reached before convergence"
        while iteration < opts.max_iterations:
            iteration += 1
            ended = state.step(iteration)
            if ended is not None:
                converged, reason, counted = ended
                iteration -= not counted
                break
    ne = state.ne
    if converged and is_singular(ne.H):
        converged, reason = False, SINGULAR_REASON
    return SolverResult(
        solver=GaussNewton.name,
        names=evaluator.fns.names,
        params=evaluator.params(state.x),
        x=state.x,
        cost=ne.cost,
        chi2=ne.chi2,
        inliers=ne.inliers,
        n_residuals=evaluator.n_residuals,
        converged=converged,
        reason=reason,
        trace=SolverTrace(iteration, time.perf_counter() - t0, tuple(state.history)),
    )
