"""The ``profile`` plug-in check: does the drive tell a parameter from (nearly) zero?

Some parameters enter the motion only at second order where a drive turns little: a car's rear
track moves the travel only through the rear wheels' split, by the square of its relative error, so
its cost can have two near-equal valleys, one near zero and one near its length, and a fit stops in
either (which one turned on 1 ms of re-sampling). The white-noise σ of the valley the fit stopped
in (±0.11 m on a simulated car whose cost is as low at 0.02 m as at 0.6 m) then says nothing of
the other. For each free parameter the model says a drive may not determine (its
``undetermined`` on a drive with no motion), the scenario is fitted again with it held at
:data:`NEAR_ZERO` of its estimate; where that fit's cost is within :data:`COMPARABLE` (in units of
χ², the cost over its cost per residual) of the run's, the parameter is not determined: a caveat
concerning it, so its value is never handed off as calibrated.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from nlp_calib.core.errors import NlpCalibError
from nlp_calib.models import KinematicModel
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.pipeline.stages import setup_log
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, CheckResult

NAME = "profile"
#: Where the other valley is looked for: this share of the estimate.
NEAR_ZERO = 0.05
#: Two fits are comparable where the held one's cost exceeds the run's by less than this, in units
#: of χ² (the residuals' count times the relative increase): a 2σ likelihood-ratio bound. Windows
#: that overlap make the residuals count more than they are worth, so a difference reads larger
#: than it is: the bound errs towards calling the two fits different.
COMPARABLE = 4.0
#: The solver the profile is fitted with.
SOLVER = "gauss_newton"


def _held_cost(sc: Scenario, name: str, value: float) -> tuple[float, int] | None:
    """``sc`` fitted with ``name`` held at ``value``: its cost and number of residuals (None: it
    cannot be fitted, or did not converge)."""
    held = dataclasses.replace(sc.parameters, known={**sc.parameters.known, name: value})
    try:
        part = setup_log(dataclasses.replace(sc, parameters=held), None, (SOLVER,))
        result = Fit(part.problem, part.windows.data, (SOLVER,)).solve(SOLVER)
    except NlpCalibError:
        return None
    return (result.cost, result.n_residuals) if result.converged and result.n_residuals else None


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


def check(run: CalibrationRun, sc: Scenario | None, model: KinematicModel | None) -> CheckResult | None:
    """Each candidate's fit held near zero against the run's (None: nothing to profile)."""
    solver = run.chosen_solver()
    if sc is None or model is None or sc.data.joint or solver != SOLVER:
        return None
    found = candidates(run, model, solver)
    if not found:
        return None
    ours = run.reports[solver].result
    table: dict[str, dict[str, float]] = {"held_at": {}, "chi2_above": {}}
    concerns: dict[str, str] = {}
    for name, value in found.items():
        held = _held_cost(sc, name, NEAR_ZERO * value)
        if held is None:
            continue
        cost, n = held
        rise = n * (cost - ours.cost) / ours.cost
        table["held_at"][name], table["chi2_above"][name] = NEAR_ZERO * value, rise
        if rise < COMPARABLE:
            unit = run.scenario.units[name]
            concerns[name] = (
                f"{name} is not determined: the drive fits it about as well at {NEAR_ZERO * value:.3g} "
                f"{unit} as at {value:.3g} {unit} (χ² {rise:+.2g}; two valleys, its σ is the one the fit "
                "stopped in)"
            )
    if not table["held_at"]:
        return None
    if not concerns:
        said = ", ".join(f"{n} (χ² +{r:.3g} at {NEAR_ZERO:g}× it)" for n, r in table["chi2_above"].items())
        return CheckResult(NAME, FINE, f"the drive tells from zero: {said}", table=table)
    first, *rest = concerns.values()
    return CheckResult(
        NAME, CAVEAT, first, tuple(rest), table=table, caveat=first, caveats=tuple(rest), concerns=concerns
    )
