"""The assemble stage: the result of a run, self-contained, with its notes and its verdict.

One log's run and a run over several logs are assembled by the same functions: a joint run is
one run per log, each with the joint estimates and checks beside that log's own figures.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from nlp_calib.analysis.excitation import combined, of_log
from nlp_calib.analysis.handoff import controller_params, driven_turn_rates
from nlp_calib.analysis.plan import believed
from nlp_calib.analysis.verdict import verdict
from nlp_calib.logs import LogHeader
from nlp_calib.models.controllers import EncoderScales
from nlp_calib.pipeline.align import Alignment, lag_at_edge, lag_loose, lag_not_fitted
from nlp_calib.pipeline.analyse import FitAnalysis, LogAnalysis, Scores
from nlp_calib.pipeline.build import StartingPoint
from nlp_calib.pipeline.checks import CheckContext, run_checks
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.prepare import PreparedLog
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.pipeline.stored import StoredCalibration
from nlp_calib.pipeline.windows import LogWindows
from nlp_calib.problem import ProblemFunctions
from nlp_calib.results import (
    CalibrationRun,
    Checks,
    DataInfo,
    DroppedLine,
    Encoder,
    LogInfo,
    ScenarioInfo,
    SensorInfo,
    SolverReport,
    SolverResult,
    Verdict,
)
from nlp_calib.results.checks import NominalCheck
from nlp_calib.results.faults import FaultReport, Findings
from nlp_calib.results.layout import KNOWN, MODEL, MOUNT, Layout
from nlp_calib.results.mount import LogMount, SensorMount
from nlp_calib.results.preflight import Excitation
from nlp_calib.results.run import lags_in, pinned_in
from nlp_calib.sensors import Sensor
from nlp_calib.solvers import solver_label
from nlp_calib.sources import BagSource, BesideSource
from nlp_calib.sources.text_gyro import TextPosesSource


def scenario_info(sc: Scenario, layout: Layout) -> ScenarioInfo:
    """What the outputs say about ``sc`` fitted with the parameters ``layout``."""
    joint = sc.data.joint
    # The sensor's own keys beside each log's own mount's names (what one log's view calls them).
    keys = {p.key: p.unit for p in layout.parameters if p.block == MOUNT}
    units = layout.units
    return ScenarioInfo(
        name=sc.name,
        path=None if sc.path is None else str(Path(sc.path).absolute()),
        model=sc.model,
        units={**{n: units[n] for n in layout.block(MODEL)}, **keys, **units},
        layout=layout,
        sensor=sensor_info(sc),
        dataset=str(sc.dataset),
        datasets=tuple(str(e.path) for e in sc.data.logs) if joint else (),
        labels={name: solver_label(name) for name in sc.solvers},
        residual=dataclasses.asdict(sc.objective.residual),
        robust=dataclasses.asdict(sc.objective.robust),
        initial_guess=sc.parameters.initial_guess
        if isinstance(sc.parameters.initial_guess, str)
        else "mapping",
    )


def fit_info(sc: Scenario, fns: ProblemFunctions) -> ScenarioInfo:
    """:func:`scenario_info` of ``sc`` as the problem ``fns`` fits it (its time offsets and mounts;
    what the scenario fixes is known, what the drive cannot determine held)."""
    known = fns.layout.named(sc.parameters.fixed)
    return scenario_info(sc, fns.layout.with_status(dict.fromkeys(known, KNOWN)))


def sensor_info(sc: Scenario) -> SensorInfo:
    """What the outputs say about the sensor: what its plug-in says of itself."""
    sensor = sc.objective.sensor.sensor
    return SensorInfo(
        kind=sensor.kind,
        group=sensor.group,
        scale=sc.objective.sensor.scale,
        params=sensor.params,
        held=sensor.held,
        held_why=sensor.held_why,
        convention=sensor.convention,
        no_position=sensor.lengths_unseen,
    )


def log_info(prepared: PreparedLog, windows: LogWindows) -> LogInfo:
    """What the outputs say about a log as read."""
    log, model = prepared.log, prepared.model
    kinds = model.encoder_kinds
    unit = "rad" if log.header.encoder_units == "radians" else "ticks"
    per_turn = encoder_scales(prepared).per_turn
    encoders = tuple(
        Encoder(name, kinds.get(name, "counter"), unit, int(vmax), per_turn.get(name))
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
        numbered=log.reference.numbered,
    )


def data_info(
    prepared: PreparedLog, windows: LogWindows, alignment: Alignment, start_dropped: Mapping[str, int] | None
) -> DataInfo:
    """What of a log the fit used (``start_dropped``: the windows a camera's start left out) and how
    its fitted records excite the robot."""
    data = windows.data
    steering = prepared.scenario.objective.residual.steering_sample
    fitted = prepared.log.select(prepared.start, prepared.split)
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
        excitation=of_log(fitted, windows.binder.fns.sensor, prepared.model, steering),
    )


def _combined(parts: Sequence[Excitation | None]) -> Excitation | None:
    """Several logs' excitation as one drive's (None where any log's is unknown)."""
    known = [p for p in parts if p is not None]
    return combined(known) if known and len(known) == len(parts) else None


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


#: A bias step beyond this share of a parameter's σ is said: the estimate moved that much.
SAID = 1.0


def bias_notes(step: Mapping[str, float], std: Mapping[str, float]) -> list[str]:
    """The inputs' bias step (:meth:`~nlp_calib.pipeline.fit.Fit.bias_taken`) where it moved a
    parameter by more than :data:`SAID` of its white-noise σ ``std``."""
    z = {n: abs(v) / std[n] for n, v in step.items() if std.get(n, 0.0) > 0.0}
    worst = max(z, key=z.__getitem__, default=None)
    if worst is None or not z[worst] > SAID:
        return []
    return [
        f"the encoders' rounding biased {worst} by {z[worst]:.1f}σ over windows this short; the "
        "estimate is corrected for it (longer windows, residual.horizon, leave less to correct)"
    ]


def lag_notes(sc: Scenario, alignment: Alignment) -> list[str]:
    """What a log's time alignment found worth saying: a lag at the edge of its search, a lag no
    fit converged at, or one the drive does not determine."""
    est = alignment.estimate
    if est is not None and not est.converged:
        return [lag_not_fitted(sc, alignment.lag_s)]
    if est is not None and est.at_edge:
        return [lag_at_edge(sc, alignment.lag_s)]
    if est is not None and est.loose:
        return [lag_loose(sc, est)]
    return []


@dataclass(frozen=True)
class MountViews:
    """The mounts of a fit, seen from one of its logs: the problem (its mount per log, if any),
    which log this is, and each log's name and header (its sensor's frame and nominal mount)."""

    fns: ProblemFunctions
    part: int
    logs: tuple[tuple[str, LogHeader | LogInfo], ...]

    def mounts(
        self, sensor: Sensor, params: Mapping[str, float], std: Mapping[str, float]
    ) -> tuple[SensorMount, tuple[LogMount, ...]]:
        """This log's mount, and every log's own when each has one (each its own sensor link,
        numbered where logs share a frame's name)."""
        fns = self.fns
        frames = [h.sensor_frame for _, h in self.logs]
        every = tuple(
            LogMount(
                name,
                sensor.mount_pose(
                    fns.view_dict(params, i),
                    fns.view_dict(std, i),
                    frame if frames.count(frame) == 1 or not fns.own_poses else f"{frame}_{i + 1}",
                    header.sensor_z_roll_pitch,
                ),
            )
            for i, ((name, header), frame) in enumerate(zip(self.logs, frames))
        )
        # One pose shared (each log's own parameters beside it, if any: a gyro's bias): one joint.
        if not fns.own_poses:
            return every[self.part].mount, ()
        return every[self.part].mount, every


def _report(
    prepared: PreparedLog,
    name: str,
    result: SolverResult,
    fitted: tuple[FitAnalysis, Checks],
    figures: tuple[LogAnalysis, MountViews | None],
) -> SolverReport:
    """One solver's report, with its estimate in the controller's terms and its mount (every log's,
    with a mount per log)."""
    u = fitted[0].uncertainty[name]
    scored, views = figures
    std = fitted[1].believed(u)
    scales = encoder_scales(prepared)
    estimate = (result.params, std, u.correlation)
    given = given_params(prepared)
    extra = (scored.noise.get(name), prepared.held, given)
    controller = controller_params(prepared.model, result.names, estimate, scales, extra)
    sensor, header = prepared.scenario.objective.sensor.sensor, prepared.log.header
    sd = dict(zip(result.names, map(float, std)))
    held = {c: given[n] for c, n in sensor.components.items() if n in given}
    listed = {**{n: f"held at its initial value: {why}" for n, why in prepared.held.items()}, **given}
    beside = sensor.beside_mount(result.param_dict(), sd, header)
    if views is None:
        mount = sensor.mount_pose(result.param_dict(), sd, header.sensor_frame, header.sensor_z_roll_pitch)
        return SolverReport(
            result, u, *scored.scores[name], controller, mount.holding(held), held=listed, beside=beside
        )
    mount, every = views.mounts(sensor, result.param_dict(), sd)
    every = tuple(dataclasses.replace(m, mount=m.mount.holding(held)) for m in every)
    return SolverReport(
        result, u, *scored.scores[name], controller, mount.holding(held), every, held=listed, beside=beside
    )


def _checked(
    run: CalibrationRun,
    context: CheckContext,
    prepared: PreparedLog,
    analysed: tuple[FitAnalysis, LogAnalysis, MountViews | None],
) -> CalibrationRun:
    """``run`` with its plug-in checks' results, its reports made again where the checks widened
    the σ to believe (the slip's σ and the held values', which only a check measures): the mount
    and the controller's figures state the σ every file does. ``analysed``: the fit's analysis,
    the log's figures and the mounts' views the reports were made from."""
    checks = dataclasses.replace(run.checks, more=run_checks(run, context))
    fitted, figures, views = analysed
    if not any(math.isfinite(v) for r in run.reports.values() for v in checks.shifts(r.uncertainty.names)):
        return dataclasses.replace(run, checks=checks)
    reports = {
        name: _report(prepared, name, r.result, (fitted, checks), (figures, views))
        for name, r in run.reports.items()
    }
    return dataclasses.replace(run, checks=checks, reports=reports)


def given_params(prepared: PreparedLog) -> dict[str, str]:
    """The parameters the user gave rather than the fit estimated, with where each comes from
    (``known:``, or held at its initial value under ``fixed:``); not those the drive could not
    determine (``PreparedLog.held``), whose guesses no hand-off file carries."""
    params = prepared.scenario.parameters
    out = {n: f"given under known: ({v:g})" for n, v in params.known.items()}
    for n in params.fixed:
        if n not in out and n not in prepared.held:
            out[n] = "held at its initial value under fixed:"
    return out


def encoder_scales(prepared: PreparedLog) -> EncoderScales:
    """The encoders' ranges in the log and their counts per wheel turn where the user gives them
    (the scenario's ``counts_per_turn`` over ``ROBOT.yaml``'s), and the turn rates the used
    records drove at."""
    log = prepared.log
    header = log.header
    per_turn = {**header.counts_per_turn, **prepared.scenario.data.counts_per_turn}
    used = slice(prepared.start, prepared.stop)
    rates = driven_turn_rates(log.time_s[used], log.T_world_sensor[used, 2])
    ranges = dict(zip(header.encoder_names, header.encoder_max))
    return EncoderScales(ranges, per_turn, driven_turn_rates=rates)


def fit_checks(
    fitted: FitAnalysis, findings: Findings | None, start: StartingPoint, nominal: Scores | None
) -> Checks:
    """The checks of the fit (the same for every log it is read for) with one log's ``findings``
    and the nominal robot's figures on it (``nominal``; None: no nominal values known)."""
    check = None
    if nominal is not None and fitted.nominal_params is not None:
        check = NominalCheck(
            dict(start.nominal), start.nominal_source, fitted.nominal_params, nominal[0], fitted.nominal
        )
    return Checks(
        fitted.observability,
        fitted.crossval,
        fitted.direction,
        findings,
        fitted.consistency,
        logs=fitted.logs,
        start=fitted.start,
        nominal=check,
        lag_effects=fitted.lag_effects,
        plan=fitted.plan,
        pivots=fitted.pivots,
    )


def mount_notes(sc: Scenario, start: StartingPoint) -> list[str]:
    """What the start said (it gave way to the nominal robot), and the sensor's held parameters,
    said once, with why they are held."""
    sensor = sc.objective.sensor.sensor
    said = [start.sensor.note] if start.sensor is not None and start.sensor.note else []
    return said + [
        f"{n} is held at {start.initial.get(n, 0.0):g} {sensor.units[n]}: {sensor.held_why}"
        for n in sensor.held
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
    """The windows the sensor's closed-form start left out, by reason (None: it selects none)."""
    if start.sensor is None or start.auto is None or start.sensor.dropped is None:
        return None
    return dict(start.sensor.dropped)


def assemble_run(
    scenario: ScenarioInfo,
    log: tuple[PreparedLog, LogWindows, Alignment, Findings],
    start: StartingPoint,
    results: Mapping[str, SolverResult],
    fitted: FitAnalysis,
    figures: LogAnalysis,
    notes: Sequence[str],
    views: MountViews | None = None,
    against: StoredCalibration | None = None,
    fit: Fit | None = None,
) -> CalibrationRun:
    """One log's run: the fit's estimates and checks beside this log's figures, with its verdict
    (``views``: the fit's mounts seen from this log; ``against``: a stored calibration it checks;
    ``fit``: the run's fit, which a check may fit again)."""
    prepared, windows, alignment, findings = log
    checks = fit_checks(fitted, findings, start, figures.nominal)
    reports = {
        name: _report(prepared, name, r, (fitted, checks), (figures, views)) for name, r in results.items()
    }
    run = CalibrationRun(
        scenario=dataclasses.replace(scenario, layout=scenario.layout.with_start(start.initial)),
        log=log_info(prepared, windows),
        data=data_info(prepared, windows, alignment, _start_dropped(start)),
        baseline=figures.baseline[0],
        baseline_holdout=figures.baseline[1],
        reports=reports,
        checks=checks,
        warnings=(
            *notes,
            *lag_notes(prepared.scenario, alignment),
            *mount_notes(prepared.scenario, start),
            *threshold_notes(prepared.scenario, results),
            *figures.noise_notes,
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
    # Joints in radians: the simulator's truth is in the counts form's names and units; a log's
    # truth is of its own mount.
    convert = _own_truth(_per_count_left_out(getattr(prepared.model, "from_counts", dict), prepared), views)
    context = CheckContext(source.files(), convert, prepared.scenario, prepared.model, against, fit)
    run = _believed_plan(_checked(run, context, prepared, (fitted, figures, views)))
    return judged(
        run, verdict(run, prepared.model, hint), prepared.scenario.objective.sensor.sensor.components
    )


def _per_count_left_out(
    convert: Callable[[Mapping[str, float]], dict[str, float]], prepared: PreparedLog
) -> Callable[[Mapping[str, float]], dict[str, float]]:
    """``convert`` of a text log's truth read in radians beside a gyro: what it states per count
    (a wheel's metres per tick) is left out, the counts per turn the scenario's, not the simulator's."""
    source = prepared.scenario.log.source
    if not (isinstance(source, BesideSource) and isinstance(source.reference, TextPosesSource)):
        return convert
    model = prepared.model
    counts_units = getattr(getattr(model, "model", model), "units", {})
    per_count = {n for n, r in getattr(model, "renamed", {}).items() if counts_units.get(n) != r.unit}
    return lambda truth: convert({n: v for n, v in truth.items() if n not in per_count})


def _own_truth(
    convert: Callable[[Mapping[str, float]], dict[str, float]], views: MountViews | None
) -> Callable[[Mapping[str, float]], dict[str, float]]:
    """``convert`` of a log's truth, its mount also under its own names in a fit with one per log."""
    if views is None or views.fns.spec.mounts == 1:
        return convert
    fns, part = views.fns, views.part

    def mine(truth: Mapping[str, float]) -> dict[str, float]:
        out = convert(truth)
        out.update({n: out[p] for n, p in fns.mount_keys(part).items() if p in out})
        return out

    return mine


def merged_findings(runs: Sequence[CalibrationRun]) -> Findings | None:
    """Every log's findings as one (faults numbered within their own log; each log's unchecked
    reason named with its log), for the joint fit read as one run."""
    found = [(run.log.path, run.checks.findings) for run in runs if run.checks.findings is not None]
    if not found:
        return None
    reports = [f.report for _, f in found]
    stale: dict[str, int] = {}
    for rep in reports:
        for name, n in rep.stale.items():
            stale[name] = stale.get(name, 0) + n
    unchecked = "; ".join(f"{path}: {f.report.unchecked}" for path, f in found if f.report.unchecked)
    report = FaultReport(
        faults=tuple(fault for rep in reports for fault in rep.faults),
        stale=stale,
        noise=reports[0].noise,
        unchecked=unchecked,
        unit=reports[0].unit,
    )
    return Findings(report, found[0][1].handling, tuple(r for _, f in found for r in f.repairs))


def _joint_log(parts: Sequence[CalibrationRun]) -> LogInfo:
    """The logs of a joint fit as one: the first's model, encoders and sensor frame, every log's
    records, drops and duration."""
    first = parts[0]
    return LogInfo(
        path=f"{len(parts)} logs: " + ", ".join(run.log.path for run in parts),
        records=sum(run.log.records for run in parts),
        dropped=tuple(d for run in parts for d in run.log.dropped),
        sensor_frame=first.log.sensor_frame,
        encoders=first.log.encoders,
        start_ns=first.log.start_ns,
        duration_s=sum(run.log.duration_s for run in parts),
        sensor_z_roll_pitch=first.log.sensor_z_roll_pitch,
        numbered=first.log.numbered,
    )


def joint_run(
    scenario: ScenarioInfo,
    parts: Sequence[CalibrationRun],
    fit: tuple[PreparedLog, StartingPoint, int],
    results: Mapping[str, SolverResult],
    fitted: FitAnalysis,
    figures: LogAnalysis,
    notes: Sequence[str],
    views: MountViews | None = None,
    against: StoredCalibration | None = None,
    fitting: Fit | None = None,
) -> CalibrationRun:
    """The joint fit as one run: its figures over every log's fitted records (``figures``), the
    fit's checks, every log's findings, and its own verdict. ``fit``: the first log (its model,
    encoders and sensor frame), where the solvers started and the fitted windows; ``fitting``: the
    joint fit itself, for the checks that refit its windows."""
    prepared, start, n_residuals = fit
    records = sum(run.data.fit[1] - run.data.fit[0] for run in parts)
    log = _joint_log(parts)
    data = DataInfo(
        used=(0, records),
        fit=(0, records),
        n_residuals=n_residuals,
        dropped_stationary=sum(run.data.dropped_stationary for run in parts),
        dropped_faulty=sum(run.data.dropped_faulty for run in parts),
        tracker_lag_s=float("nan"),
        lag_estimate=None,
        excitation=_combined([run.data.excitation for run in parts]),
        # Its logs' lags pinned on their searches' edges: its checks hold them there (held_check).
        pinned=pinned_in(scenario.layout, parts),
        # Its logs' own lags as each log's alignment found them: their return checks (std, verdict).
        lags=lags_in(scenario.layout, parts),
    )
    checks = fit_checks(fitted, merged_findings(parts), start, figures.nominal)
    reports = {
        name: _report(prepared, name, r, (fitted, checks), (figures, views)) for name, r in results.items()
    }
    warned = dict.fromkeys((*notes, *(w for run in parts for w in run.warnings)))
    run = CalibrationRun(
        scenario=dataclasses.replace(scenario, layout=scenario.layout.with_start(start.initial)),
        log=log,
        data=data,
        baseline=figures.baseline[0],
        baseline_holdout=None,
        reports=reports,
        checks=checks,
        warnings=tuple(warned),
        verdict=Verdict("", ()),
    )
    # The plug-in checks on the joint fit: no log source's files (a simulated log's truth is each log's).
    context = CheckContext(model=prepared.model, against=against, fit=fitting)
    run = _believed_plan(_checked(run, context, prepared, (fitted, figures, views)))
    return judged(run, verdict(run, prepared.model), prepared.scenario.objective.sensor.sensor.components)


def pinned_alike(run: CalibrationRun) -> CalibrationRun:
    """``run`` whose per-log views leave out the σ of every clock offset the joint fit holds without
    one (a log's pinned lag is no log's to state a σ of: each view's σ is the joint fit's), and read
    each log's lag as the joint does (:attr:`~nlp_calib.results.run.DataInfo.lags`: a view's own
    estimate is its own log's lag's, not the others')."""
    pinned = run.pinned()
    lags = run.data.lags
    views = tuple(dataclasses.replace(p, data=dataclasses.replace(p.data, lags=lags)) for p in run.logs)
    if not pinned:
        return dataclasses.replace(run, logs=views)
    # The joint's held check holds those lags (its σ of them is the joint fit's): each view takes it.
    held = run.checks.plugin("held")
    views = tuple(
        dataclasses.replace(
            p,
            data=dataclasses.replace(p.data, pinned=pinned),
            checks=dataclasses.replace(
                p.checks, more=(*(c for c in p.checks.more if c.name != "held"), *([held] if held else []))
            ),
        )
        for p in views
    )
    return dataclasses.replace(run, logs=views)


def judged(run: CalibrationRun, found: Verdict, components: Mapping[str, str]) -> CalibrationRun:
    """``run`` with its verdict, each estimate's mount (every log's own too) stating the
    components (``components``: each one's parameter key) the run leaves not determined well
    enough to use (:meth:`CalibrationRun.doubts`) as such: no hand-off file writes them as
    calibrated."""
    run = dataclasses.replace(run, verdict=found)
    laid = run.scenario.layout.parameters
    reports = {}
    for solver, rep in run.reports.items():
        doubts = run.doubts(solver)

        def of(log: int | None, doubts: Mapping[str, str] = doubts) -> dict[str, str]:
            return {
                c: doubts[p.name]
                for c, key in components.items()
                for p in laid
                if p.key == key and p.name in doubts and (log is None or p.log in (log, None))
            }

        every = tuple(dataclasses.replace(m, mount=m.mount.doubting(of(i))) for i, m in enumerate(rep.mounts))
        mount = rep.mount.doubting(of(None)) if rep.mount is not None else None
        reports[solver] = dataclasses.replace(rep, mount=mount, mounts=every)
    return dataclasses.replace(run, reports=reports)


def _believed_plan(run: CalibrationRun) -> CalibrationRun:
    """``run`` whose plan states its target's σ as the run's σ to believe (one σ per parameter in
    plan.md, the summary and the observability; :func:`nlp_calib.analysis.plan.believed`)."""
    solver = run.chosen_solver()
    if run.checks.plan is None or solver is None:
        return run
    plan = believed(run.checks.plan, run.std(solver))
    return dataclasses.replace(run, checks=dataclasses.replace(run.checks, plan=plan))
