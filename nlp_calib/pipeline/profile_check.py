"""The ``profile`` plug-in check: does the drive tell a parameter from (nearly) zero?

Some parameters enter the motion only at second order where a drive turns little: a car's rear
track moves the travel only through the rear wheels' split, by the square of its relative error, so
its cost can have two near-equal valleys, one near zero and one near its length, and a fit stops in
either (which one turned on 1 ms of re-sampling). The white-noise σ of the valley the fit stopped
in (±0.11 m on a simulated car whose cost is as low at 0.02 m as at 0.6 m) then says nothing of
the other. For each free parameter the model says a drive may not determine (its
``undetermined`` on a drive with no motion), the scenario is fitted again with it held at its
estimate, :data:`SIGMAS` σ towards zero from it and at :data:`NEAR_ZERO` of it (all three alike: on
the run's own evaluator and windows, its time offset held where the encoders were re-sampled, from
its estimate); the rise of the cost near zero over its rise at the yardstick
gives how many σ away zero lies by the cost (as in a quadratic valley). Within :data:`WITHIN` σ the
parameter is not determined; :data:`UNDERSTATED` times nearer than its σ says, its σ understates
the valley (a simulated car's rear track ±0.011 m, ±0.13 m by its cost): either is a caveat
concerning it, so its value is never handed off as calibrated. The check needs no scale of the
cost: the run's σ is the yardstick.
"""

from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext

import numpy as np

from nlp_calib.core.errors import NlpCalibError
from nlp_calib.models import KinematicModel
from nlp_calib.pipeline.analyse import RELEASE_FROM
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.keys import scenario_key
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, CheckResult
from nlp_calib.results.layout import CLOCK
from nlp_calib.solvers import get_solver
from nlp_calib.solvers.evaluation import NormalEquations, ProblemEvaluator

NAME = "profile"
#: Where the other valley is looked for: this share of the estimate.
NEAR_ZERO = 0.05
#: The yardstick: the fit held this many σ (to believe) towards zero from the estimate.
SIGMAS = 2.0
#: Near zero within this many σ by the cost (its rise against the yardstick's, as a quadratic
#: valley's): not determined.
WITHIN = 3.0
#: Zero this many times nearer by the cost than by the σ: the σ understates the valley (it is the
#: curvature at the bottom of a valley that widens further out).
UNDERSTATED = 2.0
#: The solver the profile is fitted with.
SOLVER = "gauss_newton"


class _Holding:
    """The run's evaluator seen with some free coordinates held at ``x``'s values: the others'
    normal equations alone (the problem in which the held ones are known, on the same windows:
    nothing is built or bound again)."""

    def __init__(self, evaluator: ProblemEvaluator, x: np.ndarray, held: np.ndarray) -> None:
        self.evaluator, self.fns = evaluator, evaluator.fns
        self.x, self.kept = np.asarray(x, dtype=float), ~held

    @property
    def n_residuals(self) -> int:
        return self.evaluator.n_residuals

    def full(self, x: np.ndarray) -> np.ndarray:
        out = self.x.copy()
        out[self.kept] = x
        return out

    def normal_equations(self, x: np.ndarray) -> NormalEquations:
        ne, k = self.evaluator.normal_equations(self.full(x)), self.kept
        return NormalEquations(ne.H[np.ix_(k, k)], ne.g[k], ne.cost, ne.chi2, ne.inliers)

    def boxplus(self, x: np.ndarray, step: np.ndarray) -> np.ndarray:
        full = np.zeros(self.x.size)
        full[self.kept] = step
        return np.asarray(self.evaluator.boxplus(self.full(x), full))[self.kept]

    def params(self, x: np.ndarray) -> np.ndarray:
        return self.evaluator.params(self.full(x))

    def recalling(self) -> AbstractContextManager[None]:
        """Nothing recalled: each profile point's fit holds other values (hashing the run's
        windows for each would cost more than the passes it could save)."""
        return nullcontext()


def _held_cost(fit: Fit, run: CalibrationRun, name: str, value: float) -> float | None:
    """The run's fit again with ``name`` held at ``value``, from the run's estimate, its time offset
    held at the run's lag (where the encoders were re-sampled: no search again; held there, the
    cost can only be higher than at its own best lag, which errs towards telling the two apart):
    its cost (None: it did not converge)."""
    fns, start = fit.fns, fit.problem.start
    x = np.array(run.reports[run.chosen_solver() or SOLVER].result.x, dtype=float)
    values = {name: value, **{n: run.data.tracker_lag_s for n in fns.free if fns.layout.in_block(n, CLOCK)}}
    held = np.array([n in values for n in fns.free])
    x[held] = [values[n] for n in fns.free if n in values]
    view = _Holding(fit.evaluator, x, held)
    bounds = [None if b is None else np.asarray(b, dtype=float)[~held] for b in (start.lower, start.upper)]
    sc = fit.problem.binder.scenario
    try:
        with scenario_key(sc, SOLVER):
            solver = get_solver(SOLVER)(view, sc.options_for(SOLVER))  # type: ignore[arg-type]
            result = solver.solve(x[~held], *bounds)
    except (NlpCalibError, np.linalg.LinAlgError, ArithmeticError):
        return None
    return result.cost if result.converged and result.n_residuals else None


def candidates(run: CalibrationRun, model: KinematicModel, solver: str) -> dict[str, float]:
    """The free parameters the model says a drive may leave undetermined, with their estimates,
    where the estimate is positive (a length, a gain) and its σ leaves zero outside 3σ."""
    names = model.undetermined(np.zeros((len(model.input_names), 0)))
    free = run.reports[solver].uncertainty.free
    estimate, std = run.reports[solver].result.param_dict(), run.std(solver)
    return {
        n: estimate[n]
        for n in names
        if n in free and estimate.get(n, 0.0) > 0.0 and (1.0 - NEAR_ZERO) * estimate[n] > 3.0 * std[n]
    }


def _profiled(fit: Fit, run: CalibrationRun, name: str, value: float) -> float | None:
    """How many σ from ``value`` (its estimate) the cost puts the parameter held near zero, with
    the run's σ as the yardstick: the fits held at the estimate, :data:`SIGMAS` σ towards zero and
    near zero, the rise to near zero over the rise to :data:`SIGMAS` σ (None: a fit failed, or the
    cost does not rise over those σ)."""
    std = run.std(run.chosen_solver() or SOLVER)[name]
    costs = [_held_cost(fit, run, name, v) for v in (value, value - SIGMAS * std, NEAR_ZERO * value)]
    if any(c is None for c in costs):
        return None
    at, off, near = (c for c in costs if c is not None)
    if not off > at:
        return None
    return SIGMAS * float(np.sqrt(max(near - at, 0.0) / (off - at)))


def check(
    run: CalibrationRun, sc: Scenario | None, model: KinematicModel | None, fit: Fit | None
) -> CheckResult | None:
    """Each candidate's fit held near zero measured in the run's σ, on the run's own ``fit`` (None:
    nothing to profile, or no fit at hand)."""
    solver = run.chosen_solver()
    if sc is None or model is None or fit is None or sc.data.joint or solver != SOLVER:
        return None
    found = candidates(run, model, solver)
    std = run.std(solver)
    table: dict[str, dict[str, float]] = {"held_at": {}, "sigmas_by_cost": {}, "sigmas_by_std": {}}
    concerns: dict[str, str] = {}
    profiled = {name: _profiled(fit, run, name, value) for name, value in found.items()}
    if found and fit.evaluator.n_residuals >= RELEASE_FROM:
        fit.evaluator.release()  # bound again by the held fits; a later use binds it again
    for name, value in found.items():
        by_cost = profiled[name]
        if by_cost is None:
            continue
        by_std = (1.0 - NEAR_ZERO) * value / std[name]
        table["held_at"][name] = NEAR_ZERO * value
        table["sigmas_by_cost"][name], table["sigmas_by_std"][name] = by_cost, by_std
        unit = run.scenario.units[name]
        if by_cost < WITHIN:
            concerns[name] = (
                f"{name} is not determined: the drive fits it at {NEAR_ZERO * value:.3g} {unit} within "
                f"{by_cost:.2g}σ of its {value:.3g} {unit} by the cost, {by_std:.3g}σ by its σ (a second "
                "valley or a plateau: its σ is the valley's the fit stopped in)"
            )
        elif by_cost < by_std / UNDERSTATED:
            wide = (1.0 - NEAR_ZERO) * value / by_cost
            concerns[name] = (
                f"{name}'s σ understates its cost's valley: zero lies {by_cost:.3g}σ away by the cost, "
                f"{by_std:.3g}σ by its σ; as the cost measures it, {name} is known only to ±{wide:.2g} {unit}"
            )
    if not table["held_at"]:
        return None
    if not concerns:
        said = ", ".join(f"{n} ({table['sigmas_by_cost'][n]:.3g}σ off by the cost)" for n in table["held_at"])
        return CheckResult(NAME, FINE, f"the drive tells from zero: {said}", table=table)
    first, *rest = concerns.values()
    return CheckResult(
        NAME, CAVEAT, first, tuple(rest), table=table, caveat=first, caveats=tuple(rest), concerns=concerns
    )
