"""The verdict on a run: is the calibration good, usable with caveats, or not determined, and why.

The rules a reader can check:

- **not determined**, and no hand-off file written: the estimate cannot be a real robot of its
  kind although it fits the data: a mirror image (e.g. swapped wheel encoders, one wheel counting
  backwards; the model says), a 3-D sensor's mount upside down that no given mount asked for (what
  reversed or swapped joints give a camera), or a parameter outside what the model can have (a
  wheel's radius of millimetres: joints logged in degrees);
- **not determined**: no solver converged, or the drive leaves a parameter undetermined (its σ
  is infinite, or a direction of the information matrix is beyond
  :data:`~nlp_calib.results.checks.NOT_OBSERVABLE` reference units);
- **not usable**: converged and determined, but farther from the tracker than a given initial guess
  (segment ATE; a start computed from the data itself, ``initial_guess: auto``, is already a fit
  of it, so doing no better than it is a caveat), or, fitted to several logs, some log's own fit
  disagrees with theirs beyond their honest σ (they are not one robot): whatever else holds, such
  a calibration is not to be used;
- **usable with caveats**: converged and determined, but something needs a look first: a weakly
  observable direction, a parameter whose σ to believe exceeds
  :data:`~nlp_calib.results.checks.WEAK` times the precision a useful calibration needs,
  solvers that disagree, a parameter held at its initial value, forward and reverse driving that
  disagree, faults kept in the fit or not checked, or no gain over the initial guess;
- **good**: none of these.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.models import KinematicModel
from nlp_calib.models.base import reference_scale
from nlp_calib.models.mount import mirrored_mount
from nlp_calib.results import CalibrationRun, Verdict
from nlp_calib.results.checks import NOT_OBSERVABLE, WEAK
from nlp_calib.results.run import CAVEATS, GOOD, NOT_USABLE, UNDETERMINED

#: Relative parameter difference beyond which two converged solvers disagree.
AGREE = 1e-4


def _loose(run: CalibrationRun, solver: str, model: KinematicModel) -> list[str]:
    """Parameters known too loosely, in words."""
    params = run.reports[solver].result.param_dict()
    out = []
    obs = run.checks.observability
    if obs is not None:
        out += [w.words() for w in obs.weak if w.std_reference <= NOT_OBSERVABLE]
    for name, sd in run.std(solver).items():
        ref = reference_scale(model, name, params[name])
        if sd > WEAK * ref:
            unit = run.scenario.units[name]
            out.append(f"{name} is known only to ±{sd:.2g} {unit} (over {WEAK:g}× the {ref:.2g} needed)")
    return out


def _checks(run: CalibrationRun) -> list[str]:
    """What the checks found that needs a look, in words."""
    out = [w for w in run.warnings if " held at its initial value" in w]
    direction, findings = run.checks.direction, run.checks.findings
    if direction is not None and direction.significant:
        name, z = direction.worst
        out.append(f"forward and reverse driving disagree ({name} by {abs(z):.1f}σ)")
    if findings is not None:
        rep = findings.report
        if rep.unchecked:
            out.append("encoder faults not checked")
        elif rep.faults and findings.handling == "keep":
            out.append(f"{len(rep.faults)} faults kept in the fit (faults.handling: keep)")
    return out


def caveats(run: CalibrationRun, solver: str, model: KinematicModel) -> list[str]:
    """Why ``solver``'s converged, determined estimate needs a look before it is used."""
    out = _loose(run, solver, model)
    converged = [s for s in run.solver_order() if run.reports[s].result.converged]
    for other in converged[1:]:
        if (d := run.relative_difference(solver, other)) > AGREE:
            out.append(f"{solver} and {other} disagree by {d:.1e} (relative)")
    out += _checks(run)
    ours, base = run.reports[solver].metrics.segment_ate.mean, run.baseline.segment_ate.mean
    if np.isfinite(base) and not ours < base:
        start = "the data-driven start" if _fitted_start(run) else "the initial guess"
        out.append(f"no better than {start} (segment ATE {ours:.3g} m against {base:.3g} m)")
    return out


def _fitted_start(run: CalibrationRun) -> bool:
    """Whether the initial guess was computed from this data (``initial_guess: auto``)."""
    return run.scenario.initial_guess == "auto"


def implausible(run: CalibrationRun, solver: str, model: KinematicModel) -> str:
    """Why ``solver``'s estimate cannot be the robot although it fits the data: a mirror image
    (the model's, or a 3-D mount's upside down) or a parameter outside what the model can have;
    "" when it can be."""
    params = run.reports[solver].result.param_dict()
    if mirror := model.implausible(params):
        return mirror
    if run.scenario.sensor_3d:
        given = None if _fitted_start(run) else run.initial
        if mirror := mirrored_mount(params, given):
            return mirror
    for name in model.kinematic_params:
        lo, hi = model.physical_ranges.get(name, (-np.inf, np.inf))
        if name in params and not lo <= params[name] <= hi:
            unit = run.scenario.units.get(name, "")
            return (
                f"{name} came out {params[name]:.4g} {unit}, outside what a {model.name} can have "
                f"([{lo:g}, {hi:g}]): are the encoders (or joints) the scenario names the right ones, in "
                "the units it says?"
            )
    return ""


def verdict(run: CalibrationRun, model: KinematicModel, hint: str = "") -> Verdict:
    """The run's verdict and why (see the module's rules); ``hint``: what the data source says of
    a mirror image's likely cause (e.g. the joints' order it was given)."""
    solver = run.chosen_solver()
    if solver is not None and (mirror := implausible(run, solver, model)):
        return Verdict(UNDETERMINED, (mirror + hint,), handoff=False)
    obs = run.checks.observability
    loose = [w.words() for w in obs.weak if w.std_reference > NOT_OBSERVABLE] if obs is not None else []
    if solver is None:
        failures = dict.fromkeys(run.reports[s].result.reason for s in run.solver_order())
        return Verdict(UNDETERMINED, (*loose, *(f"no solver converged: {r}" for r in failures)))
    missing = [n for n, sd in run.std(solver).items() if not np.isfinite(sd)]
    if missing or loose:
        why = loose or [f"{', '.join(missing)} not determined by this drive"]
        return Verdict(UNDETERMINED, tuple(why))
    check = run.checks.consistency
    if check is not None and check.significant:
        return Verdict(NOT_USABLE, (check.words(),))
    ours, base = run.reports[solver].metrics.segment_ate.mean, run.baseline.segment_ate.mean
    if ours > base and not _fitted_start(run):
        return Verdict(
            NOT_USABLE,
            (f"worse than the initial guess (segment ATE {ours:.3g} m against {base:.3g} m uncalibrated)",),
        )
    found = caveats(run, solver, model)
    if found:
        return Verdict(CAVEATS, tuple(found))
    rep = run.reports[solver]
    gain = run.baseline.segment_ate.mean / max(rep.metrics.segment_ate.mean, 1e-12)
    reasons = [f"{solver} converged", "every parameter determined to the precision a calibration needs"]
    if len([s for s in run.reports if run.reports[s].result.converged]) > 1:
        reasons.append("the solvers agree")
    reasons.append(f"{gain:.0f}× closer to the tracker than the initial guess")
    return Verdict(GOOD, tuple(reasons))
