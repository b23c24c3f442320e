"""The verdict on a run and the closing summary: is the calibration good, what was written, what next.

The verdict is one of four levels, decided by rules a reader can check:

- **not determined**: no solver converged, or the drive leaves a parameter undetermined (its σ
  is infinite, or a direction of the information matrix is beyond
  :data:`~nlp_calib.analysis.observability.NOT_OBSERVABLE` reference units);
- **not usable**: converged and determined, but farther from the tracker than the initial guess
  (segment ATE): whatever else holds, such a calibration is not to be used;
- **usable with caveats**: converged and determined, but something needs a look first: a weakly
  observable direction, a parameter whose σ to believe exceeds
  :data:`~nlp_calib.analysis.observability.WEAK` times the precision a useful calibration needs,
  solvers that disagree, a parameter held at its initial value, forward and reverse driving that
  disagree, faults kept in the fit or not checked, or no gain over the initial guess;
- **good**: none of these.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.analysis.faults import count_kinds
from nlp_calib.analysis.observability import NOT_OBSERVABLE, WEAK
from nlp_calib.models import get_model, param_units
from nlp_calib.models.base import reference_scale
from nlp_calib.outputs.handoff import (
    CALIBRATION_FILE,
    ROBOT_URDF_FILE,
    URDF_FILE,
    chosen_solver,
    solver_order,
)
from nlp_calib.outputs.results import ODOMETRY_CSV
from nlp_calib.pipeline import CalibrationRun

GOOD = "good"
CAVEATS = "usable with caveats"
UNDETERMINED = "not determined"
NOT_USABLE = "not usable"
#: Relative parameter difference beyond which two converged solvers disagree.
AGREE = 1e-4


@dataclass(frozen=True)
class Verdict:
    """``level`` (:data:`GOOD`, :data:`CAVEATS` or :data:`UNDETERMINED`) and its reasons."""

    level: str
    reasons: tuple[str, ...]

    def line(self) -> str:
        return f"{self.level.upper()}: " + "; ".join(self.reasons)


def _relative_difference(run: CalibrationRun, a: str, b: str) -> float:
    pa, pb = run.reports[a].result.params, run.reports[b].result.params
    return float(np.max(np.abs(pa - pb) / np.maximum(np.abs(pa), 1e-12)))


def _caveats(run: CalibrationRun, solver: str) -> list[str]:
    model = get_model(run.scenario.model)
    params = run.reports[solver].result.param_dict()
    units = param_units(model)
    out = []
    obs = run.observability
    if obs is not None:
        out += [w.words() for w in obs.weak if w.std_reference <= NOT_OBSERVABLE]
    for name, sd in run.std(solver).items():
        ref = reference_scale(model, name, params[name])
        if sd > WEAK * ref:
            out.append(
                f"{name} is known only to ±{sd:.2g} {units[name]} (over {WEAK:g}× the {ref:.2g} needed)"
            )
    converged = [s for s in solver_order(run) if run.reports[s].result.converged]
    for other in converged[1:]:
        if (d := _relative_difference(run, solver, other)) > AGREE:
            out.append(f"{solver} and {other} disagree by {d:.1e} (relative)")
    out += [w for w in run.warnings if " held at its initial value" in w]
    if run.direction is not None and run.direction.significant:
        name, z = run.direction.worst
        out.append(f"forward and reverse driving disagree ({name} by {abs(z):.1f}σ)")
    if run.findings is not None:
        rep = run.findings.report
        if rep.unchecked:
            out.append("encoder faults not checked")
        elif rep.faults and run.findings.handling == "keep":
            out.append(f"{len(rep.faults)} faults kept in the fit (faults.handling: keep)")
    ours, base = run.reports[solver].metrics.segment_ate.mean, run.baseline.segment_ate.mean
    if np.isfinite(base) and not ours < base:
        out.append(f"no better than the initial guess (segment ATE {ours:.3g} m against {base:.3g} m)")
    return out


def verdict(run: CalibrationRun) -> Verdict:
    """The run's verdict and why (see the module's rules)."""
    solver = chosen_solver(run)
    obs = run.observability
    loose = [w.words() for w in obs.weak if w.std_reference > NOT_OBSERVABLE] if obs is not None else []
    if solver is None:
        failures = dict.fromkeys(run.reports[s].result.reason for s in solver_order(run))
        return Verdict(UNDETERMINED, (*loose, *(f"no solver converged: {r}" for r in failures)))
    missing = [n for n, sd in run.std(solver).items() if not np.isfinite(sd)]
    if missing or loose:
        why = loose or [f"{', '.join(missing)} not determined by this drive"]
        return Verdict(UNDETERMINED, tuple(why))
    ours, base = run.reports[solver].metrics.segment_ate.mean, run.baseline.segment_ate.mean
    if ours > base:
        return Verdict(
            NOT_USABLE,
            (f"worse than the initial guess (segment ATE {ours:.3g} m against {base:.3g} m uncalibrated)",),
        )
    caveats = _caveats(run, solver)
    if caveats:
        return Verdict(CAVEATS, tuple(caveats))
    rep = run.reports[solver]
    gain = run.baseline.segment_ate.mean / max(rep.metrics.segment_ate.mean, 1e-12)
    reasons = [f"{solver} converged", "every parameter determined to the precision a calibration needs"]
    if len([s for s in run.reports if run.reports[s].result.converged]) > 1:
        reasons.append("the solvers agree")
    reasons.append(f"{gain:.0f}× closer to the tracker than the initial guess")
    return Verdict(GOOD, tuple(reasons))


def _faults_line(run: CalibrationRun) -> str:
    if run.findings is None:
        return "not checked (no fault check ran)"
    rep, handling = run.findings.report, run.findings.handling
    if rep.unchecked:
        return f"not checked: {rep.unchecked}"
    if not rep.faults:
        return "none found"
    kinds = count_kinds(rep.faults)
    done = {
        "exclude": f"left out ({run.dropped_faulty} windows)",
        "repair": "counter faults repaired",
        "keep": "kept in the fit",
    }[handling]
    return f"{len(rep.faults)} found ({kinds}), {done}"


def _observability_line(run: CalibrationRun) -> str:
    obs = run.observability
    if obs is None:
        return "not analysed"
    if not obs.warnings:
        return f"every parameter determined (condition number {obs.condition_number:.3g})"
    more = len(obs.warnings) - 1
    return obs.warnings[0] + (f" (and {more} more, above)" if more else "")


def _accuracy_line(run: CalibrationRun, solver: str) -> str:
    m, b = run.reports[solver].metrics, run.baseline
    rpe5, base5 = m.rpe_distance[5.0].mean, b.rpe_distance[5.0].mean
    text = f"segment ATE {m.segment_ate.mean:.3g} m (uncalibrated {b.segment_ate.mean:.3g} m)"
    if np.isfinite(rpe5):
        text += (
            f", RPE over 5 m {rpe5:.3g} m = {100 * rpe5 / 5:.2g} % of the distance "
            f"(uncalibrated {100 * base5 / 5:.2g} %)"
        )
    cv = run.crossval
    if cv is not None and cv.available:
        text += f"; cross-validated segment ATE {cv.heldout_mean('segment ATE mean [m]'):.3g} m"
    return text


def _next_steps(run: CalibrationRun, level: str, files: Sequence[str]) -> list[str]:
    steps = []
    if CALIBRATION_FILE in files:
        steps.append(f"{CALIBRATION_FILE}: the parameters with units and 1σ, for your robot's configuration")
    if URDF_FILE in files:
        steps.append(f"{URDF_FILE}: paste its <joint> into your robot's URDF (planar: z, roll, pitch 0)")
    if ROBOT_URDF_FILE in files:
        steps.append(f"{ROBOT_URDF_FILE}: the same joint in a complete robot description, for URDF tools")
    if ODOMETRY_CSV in files:
        steps.append(f"{ODOMETRY_CSV}: the base link's odometry with its covariance, one row per record")
    if "report.md" in files:
        steps.append("report.md: the figures and tables of this run on one page")
    if level != UNDETERMINED and run.scenario.path is not None:
        steps.append(
            f"C code of the residual and its Jacobian: nlp-calib codegen {run.scenario.path} --out DIR"
        )
    if level in (UNDETERMINED, NOT_USABLE):
        obs = run.observability
        hints = [w for w in obs.warnings if "drive" in w] if obs is not None else []
        steps.append(
            hints[0]
            if hints
            else "check the initial guess (or use initial_guess: auto) and the log, then run again"
        )
    elif level == CAVEATS:
        steps.insert(0, "read the caveats above before using the result")
    return steps


def summary_lines(run: CalibrationRun, written: Sequence[Path] = ()) -> list[str]:
    """The closing summary of a run: one line per solver, accuracy, faults, observability, verdict
    and next steps; ``written`` are the files the run wrote (their names are cited)."""
    sel = run.log.time_s[run.used[0] : run.used[1]]
    duration = float(sel[-1] - sel[0]) if sel.size else 0.0
    lines = [
        f"summary of {run.scenario.name}: model {run.scenario.model}, {run.used[1] - run.used[0]} records "
        f"over {duration:.1f} s; the sensor travelled {run.baseline.distance_m:.1f} m (tracker path)"
    ]
    chosen = chosen_solver(run)
    for s in solver_order(run):
        res = run.reports[s].result
        if not res.converged:
            lines.append(f"  {s}: did not converge ({res.reason}); not used")
            continue
        state = f"converged in {res.iterations} iterations, {1e3 * res.time_s:.0f} ms"
        if s == chosen:
            state += f"; the result written (first converged of {', '.join(solver_order(run))})"
        else:
            state += f"; agrees with {chosen} to {_relative_difference(run, chosen, s):.1e}" if chosen else ""
        lines.append(f"  {s}: {state}")
    if chosen is not None:
        lines.append(f"  accuracy ({chosen}): {_accuracy_line(run, chosen)}")
    lines.append(f"  faults: {_faults_line(run)}")
    lines.append(f"  observability: {_observability_line(run)}")
    v = verdict(run)
    lines.append(f"  verdict: {v.line()}")
    names = [p.name for p in written]
    for i, step in enumerate(_next_steps(run, v.level, names)):
        lines.append(f"  {'next: ' if i == 0 else '      '}{step}")
    return lines
