"""The assemble stage: the result of a run, self-contained, with its notes and its verdict.

One log's run and a run over several logs are assembled by the same functions: a joint run is
one run per log, each with the joint estimates and checks beside that log's own figures.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from nlp_calib.analysis.handoff import controller_params
from nlp_calib.analysis.verdict import verdict
from nlp_calib.models import KinematicModel, param_units
from nlp_calib.models.mount import MOUNT_UNITS
from nlp_calib.pipeline.align import Alignment, lag_at_edge
from nlp_calib.pipeline.analyse import FitAnalysis, LogAnalysis
from nlp_calib.pipeline.build import StartingPoint
from nlp_calib.pipeline.prepare import PreparedLog
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.pipeline.truth import against_truth
from nlp_calib.pipeline.windows import LogWindows
from nlp_calib.results import (
    CalibrationRun,
    Checks,
    DataInfo,
    DroppedLine,
    Encoder,
    LogInfo,
    ScenarioInfo,
    SolverReport,
    SolverResult,
    Verdict,
)
from nlp_calib.results.checks import believed_std
from nlp_calib.results.faults import Findings
from nlp_calib.solvers import solver_label
from nlp_calib.sources import BagSource


def scenario_info(sc: Scenario, model: KinematicModel) -> ScenarioInfo:
    """What the outputs say about ``sc``."""
    joint = sc.data.joint
    return ScenarioInfo(
        name=sc.name,
        path=None if sc.path is None else str(Path(sc.path).absolute()),
        model=sc.model,
        units=_units(sc, model),
        headline=tuple(model.headline),
        dataset=str(sc.dataset),
        datasets=tuple(str(e.path) for e in sc.data.logs) if joint else (),
        solvers=sc.solvers,
        labels={name: solver_label(name) for name in sc.solvers},
        residual=dataclasses.asdict(sc.objective.residual),
        robust=dataclasses.asdict(sc.objective.robust),
        initial_guess=sc.parameters.initial_guess
        if isinstance(sc.parameters.initial_guess, str)
        else "mapping",
    )


def _units(sc: Scenario, model: KinematicModel) -> dict[str, str]:
    """Every parameter's unit: the model's, then its sensor's mount (a 3-D one's and the scale's)."""
    if not sc.objective.sensor.is_3d:
        return param_units(model)
    kinematic = {n: model.units[n] for n in model.kinematic_params}
    return {**kinematic, **{n: MOUNT_UNITS[n] for n in sc.objective.sensor.params()}}


def log_info(prepared: PreparedLog, windows: LogWindows) -> LogInfo:
    """What the outputs say about a log as read."""
    log, model = prepared.log, prepared.model
    kinds = model.encoder_kinds
    unit = "rad" if log.header.encoder_units == "radians" else "ticks"
    encoders = tuple(
        Encoder(name, kinds.get(name, "counter"), unit, int(vmax))
        for name, vmax in zip(log.header.encoder_names, log.header.encoder_max)
    )
    t = log.time_s[windows.used[0] : windows.used[1]]
    return LogInfo(
        path=str(prepared.scenario.dataset),
        records=log.n_records,
        dropped=tuple(DroppedLine(d.line, d.reason) for d in log.dropped),
        sensor_frame=log.header.sensor_frame,
        encoders=encoders,
        start_ns=log.start_ns,
        duration_s=float(t[-1] - t[0]) if t.size else 0.0,
        sensor_z_roll_pitch=log.header.sensor_z_roll_pitch,
    )


def data_info(windows: LogWindows, alignment: Alignment, start_dropped: Mapping[str, int] | None) -> DataInfo:
    """What of a log the fit used (``start_dropped``: the windows a camera's start left out)."""
    data = windows.data
    return DataInfo(
        used=windows.used,
        fit=windows.fit,
        n_residuals=data.n_residuals,
        dropped_stationary=data.dropped_stationary,
        dropped_faulty=data.dropped_faulty,
        tracker_lag_s=alignment.lag_s,
        lag_estimate=alignment.estimate,
        start_dropped=start_dropped,
        fit_dropped=None if data.dropped_selection is None else dict(data.dropped_selection),
    )


def fit_notes(results: Mapping[str, SolverResult], fitted: FitAnalysis, held: Mapping[str, str]) -> list[str]:
    """What the fit found worth saying, whatever log it is read for."""
    notes = list(fitted.observability.warnings)
    notes += [f"{name} held at its initial value: {why}" for name, why in held.items()]
    notes += [f"{name}: {r.reason}" for name, r in results.items() if not r.converged]
    if fitted.direction is not None and fitted.direction.significant:
        name, z = fitted.direction.worst
        notes.append(
            f"forward-only and reverse-only fits disagree: {name} by {abs(z):.1f}σ; the model misses "
            "something that depends on the direction of travel"
        )
    return notes


def lag_notes(sc: Scenario, alignment: Alignment) -> list[str]:
    """What a log's time alignment found worth saying: a lag at the edge of its search."""
    if alignment.estimate is not None and alignment.estimate.at_edge:
        return [lag_at_edge(sc, alignment.lag_s)]
    return []


def _report(
    prepared: PreparedLog, name: str, result: SolverResult, fitted: FitAnalysis, figures: LogAnalysis
) -> SolverReport:
    """One solver's report, with its estimate in the controller's terms."""
    u = fitted.uncertainty[name]
    blocked = fitted.crossval.std if fitted.crossval is not None else np.full(len(u.names), np.nan)
    header = prepared.log.header
    ranges = dict(zip(header.encoder_names, header.encoder_max))
    std = believed_std(u.std, blocked)
    controller = controller_params(prepared.model, result.names, result.params, std, u.correlation, ranges)
    return SolverReport(result, u, *figures.scores[name], controller)


def mount_notes(sc: Scenario, start: StartingPoint) -> list[str]:
    """A 3-D sensor's held height, said once."""
    if not sc.objective.sensor.is_3d:
        return []
    z = start.initial.get("sensor_z", 0.0)
    return [
        f"sensor_z is held at {z:g} m: planar driving cannot determine a 3-D sensor's height "
        "(give the measured one as known.sensor_z)"
    ]


#: Below this share of windows within the robust threshold, the threshold is said to be too tight.
MIN_INLIER_SHARE = 0.5


def threshold_notes(sc: Scenario, results: Mapping[str, SolverResult]) -> list[str]:
    """A robust threshold that treats most windows as outliers, said once: their weight is then
    set by δ rather than by the noise, and the white-noise σ comes out too large."""
    converged = [r for r in results.values() if r.converged and r.n_residuals]
    if not converged or sc.objective.robust.kernel == "none":
        return []
    r = converged[0]
    if r.inliers >= MIN_INLIER_SHARE * r.n_residuals:
        return []
    return [
        f"only {r.inliers} of {r.n_residuals} windows lie within the robust threshold "
        f"(robust.delta = {sc.objective.robust.delta:g}): the kernel treats most of the log as "
        "outliers and the white-noise σ is too large; raise robust.delta (a bound on √(eᵀΩe)) or "
        "check that information: matches the tracker's noise"
    ]


def _start_dropped(start: StartingPoint) -> dict[str, int] | None:
    """The windows a 3-D sensor's closed-form start left out, by reason (None: no closed form)."""
    if start.camera is None or start.auto is None:
        return None
    return start.camera.selection.counts()


def assemble_run(
    scenario: ScenarioInfo,
    log: tuple[PreparedLog, LogWindows, Alignment, Findings],
    start: StartingPoint,
    results: Mapping[str, SolverResult],
    fitted: FitAnalysis,
    figures: LogAnalysis,
    notes: Sequence[str],
) -> CalibrationRun:
    """One log's run: the fit's estimates and checks beside this log's figures, with its verdict."""
    prepared, windows, alignment, findings = log
    reports = {name: _report(prepared, name, r, fitted, figures) for name, r in results.items()}
    run = CalibrationRun(
        scenario=scenario,
        log=log_info(prepared, windows),
        data=data_info(windows, alignment, _start_dropped(start)),
        initial=dict(start.initial),
        baseline=figures.baseline[0],
        baseline_holdout=figures.baseline[1],
        reports=reports,
        checks=Checks(fitted.observability, fitted.crossval, fitted.direction, findings, fitted.consistency),
        warnings=(
            *notes,
            *lag_notes(prepared.scenario, alignment),
            *mount_notes(prepared.scenario, start),
            *threshold_notes(prepared.scenario, results),
        ),
        verdict=Verdict("", ()),
        series=figures.series,
        odometry=figures.odometry,
    )
    source = prepared.scenario.log.source
    hint = (
        f" (this scenario gives joints: [{', '.join(source.joints)}])"
        if isinstance(source, BagSource)
        else ""
    )
    # Joints in radians: the simulator's truth is in the counts form's names and units.
    convert = getattr(prepared.model, "from_counts", dict)
    checks = dataclasses.replace(run.checks, truth=against_truth(run, source.files(), convert))
    run = dataclasses.replace(run, checks=checks)
    return dataclasses.replace(run, verdict=verdict(run, prepared.model, hint))
