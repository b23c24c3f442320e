"""The ``model`` plug-in check: does another model fit the vendor's odometry better than the one
declared?

A model that turns odometry back reads every step as an arc (:func:`~nlp_calib.models.drives.arcs`),
so any of them reproduces the vendor's odometry exactly and the declared model's own fit cannot say
it is the wrong one: one model's odometry declared as another's is fitted by whatever of the
declared model follows the turn rate, with a mount off by centimetres and a small σ. The other models
that turn odometry back are fitted to the same odometry and reference (from their controller's
usual values: the odometry is metric, so the fit finds the robot's own); one whose residual cost
per residual is :data:`BETTER` times lower, with at most one parameter more, is named as a caveat.
"""

from __future__ import annotations

import dataclasses
import math

from nlp_calib.core.errors import NlpCalibError
from nlp_calib.models import MODELS, OdometryInverse
from nlp_calib.models.drives import VendorController
from nlp_calib.models.radians import in_units
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.options import ParameterOptions
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.pipeline.stages import setup_log
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, CheckResult
from nlp_calib.sources.vendor import VendorSource

#: A rival model fits the odometry better where the declared model's cost per residual is this
#: many times the rival's: the right model's rivals with no more parameters cannot fit better, and
#: a parameter more buys about one over the number of independent windows (under 1 % on a drive
#: of a minute); the wrong model of a simulated 40 s drive costs 4.5–11 % more (docs/vendor.md).
BETTER = 1.03
#: A rival may have this many parameters more than the declared model.
EXTRA = 1
#: The solver the rivals are fitted with (fast, and every model's).
SOLVER = "gauss_newton"
#: How every model's steering is read in the comparison, the declared model's too (fitted again
#: where the scenario reads it otherwise): held over each interval from its start. A controller's
#: own steering moves smoothly and is matched so within its noise; a steering made up to reproduce
#: another model's arcs jumps from step to step and is not (read as the turning back wrote it, at
#: each interval's end, any model reproduces any arcs and only the parameters' corrections differ).
COMPARED = "start"


def rivals(declared: str) -> tuple[str, ...]:
    """The registered models other than ``declared`` that turn a controller's odometry back and
    whose drive knows a controller's usual values."""
    return tuple(
        name
        for name, model in MODELS.items()
        if name != declared
        and isinstance(model, OdometryInverse)
        and isinstance(model.drive, VendorController)
    )


def _usual(name: str) -> dict[str, float]:
    """Model ``name``'s controller's usual values, by the names of its form with joints in radians."""
    drive = MODELS[name].drive
    assert isinstance(drive, VendorController)  # rivals() holds only these
    return dict(getattr(in_units(MODELS[name], "radians"), "from_counts", dict)(drive.vendor_model))


def _alike(sc: Scenario, name: str, vendor: dict[str, float], parameters: ParameterOptions) -> Scenario:
    """``sc`` with model ``name`` turning the odometry back with ``vendor``'s values, its angle joints
    read as :data:`COMPARED`."""
    source = sc.log.source
    assert isinstance(source, VendorSource)
    entry = dataclasses.replace(sc.log, source=dataclasses.replace(source, vendor=vendor))
    residual = dataclasses.replace(sc.objective.residual, steering_sample=COMPARED)
    return dataclasses.replace(
        sc,
        model=name,
        data=dataclasses.replace(sc.data, logs=(entry,)),
        parameters=parameters,
        objective=dataclasses.replace(sc.objective, residual=residual),
    )


def _fitted(sc: Scenario) -> tuple[float, int] | None:
    """``sc`` fitted: its cost per residual and its number of free parameters, or None where it
    cannot be fitted."""
    try:
        part = setup_log(sc, None, (SOLVER,))
        fitting = Fit(part.problem, part.windows.data, (SOLVER,))
        result = fitting.solve(SOLVER)
    except NlpCalibError:  # a model that cannot be set up or fitted says nothing
        return None
    if not result.converged or result.n_residuals == 0:
        return None
    return result.cost / result.n_residuals, len(fitting.problem.start.x0)


def _rival_fit(sc: Scenario, name: str) -> tuple[float, int] | None:
    """Model ``name`` fitted to ``sc``'s vendor odometry and reference from its controller's usual
    values: its cost per residual and its number of free parameters, or None."""
    return _fitted(_alike(sc, name, _usual(name), ParameterOptions()))


def _declared_fit(run: CalibrationRun, sc: Scenario, solver: str) -> tuple[float, int] | None:
    """The declared model's cost per residual and free parameters with its angle joints read as the
    rivals' is: the run's own fit where it reads it so, else fitted again so."""
    ours = run.reports[solver].result
    if ours.n_residuals == 0:
        return None
    if sc.objective.residual.steering_sample == COMPARED or MODELS[sc.model].steer_max is None:
        return ours.cost / ours.n_residuals, int(ours.x.size)
    source = sc.log.source
    assert isinstance(source, VendorSource)
    return _fitted(_alike(sc, sc.model, dict(source.vendor), sc.parameters))


def check(run: CalibrationRun, sc: Scenario | None) -> CheckResult | None:
    """The declared model's fit against each rival's on the vendor's odometry (None: not a vendor
    source, or a joint fit of several logs)."""
    solver = run.chosen_solver()
    if sc is None or sc.data.joint or solver is None or not isinstance(sc.log.source, VendorSource):
        return None
    declared = _declared_fit(run, sc, solver)
    if declared is None:
        return None
    own, n_own = declared
    fitted = {name: f for name in rivals(sc.model) if (f := _rival_fit(sc, name)) is not None}
    if not fitted:
        return None
    table = {"cost_per_residual": {sc.model: own, **{n: c for n, (c, _) in fitted.items()}}}
    better = {n: c for n, (c, k) in fitted.items() if k <= n_own + EXTRA and own > BETTER * c}
    figures = ", ".join(f"{n} {c:.3g}" for n, c in table["cost_per_residual"].items())
    if not better:
        return CheckResult(
            "model",
            FINE,
            f"the vendor's odometry is fitted best by {sc.model} (cost per residual: {figures})",
            about={"model": sc.model},
            table=table,
        )
    best = min(better, key=lambda n: better[n])
    ratio = own / better[best] if better[best] > 0 else math.inf
    return CheckResult(
        "model",
        CAVEAT,
        f"the vendor's odometry looks integrated by a {best} controller, not the declared {sc.model}: "
        f"{best} fits it {ratio:.2f}× better (cost per residual: {figures}); "
        f"the {sc.model} estimates are of the wrong model: declare model: {best} with its vendor's values",
        about={"model": sc.model, "likely": best, "concerns": "all"},
        table=table,
    )
