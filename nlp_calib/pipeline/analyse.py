"""The analyse stage: what the fitted estimates are worth, computed once and kept in the result.

For the fit (one log, or several end to end): each solver's uncertainty, the observability, the
blocked cross-validation and the forward/reverse comparison. For each log: the fair figures of
each estimate and of the initial guess, and, when asked for, the series behind the figures
(tracks, residuals before and after, fault zones, the model check) and the odometry with its
covariance. The outputs only format what this stage computed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis import uncertainty as unc
from nlp_calib.analysis.metrics import each_metrics, geometry, integrate, segments
from nlp_calib.analysis.observability import analyse as observability_of
from nlp_calib.analysis.odometry import drift_coverage, drift_noise, propagate, segment_drift
from nlp_calib.analysis.tracks import dead_reckoned, segment_figures
from nlp_calib.core import memory
from nlp_calib.models import header_parameters
from nlp_calib.pipeline import validation
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.prepare import PreparedLog
from nlp_calib.pipeline.windows import LogWindows
from nlp_calib.problem import ProblemFunctions, over_columns
from nlp_calib.problem.windows import tracker_poses
from nlp_calib.results import SolverResult
from nlp_calib.results.checks import (
    ConsistencyCheck,
    CrossValidation,
    DirectionCheck,
    LagEffect,
    Observability,
)
from nlp_calib.results.faults import Findings
from nlp_calib.results.figures import TrajectoryMetrics
from nlp_calib.results.series import (
    FaultSpan,
    ModelCheckSeries,
    OdometryTrack,
    ResidualSeries,
    RunSeries,
    Track,
    TrackSeries,
)
from nlp_calib.results.uncertainty import Uncertainty

#: Fits of this many windows let go of their evaluator's buffers after the solvers and again before
#: the refits (each later use binds only what it evaluates).
RELEASE_FROM = 100_000

#: A figure of one parameter set on one log: full range and hold-out.
Scores = tuple[TrajectoryMetrics, TrajectoryMetrics | None]


@dataclass(frozen=True)
class FitAnalysis:
    """What the fit's estimates are worth, whatever log they are scored on."""

    uncertainty: Mapping[str, Uncertainty]
    observability: Observability
    crossval: CrossValidation | None
    direction: DirectionCheck | None
    #: For several logs: each log's own fit against theirs.
    consistency: ConsistencyCheck | None = None
    #: How each time offset moves the other parameters (the first solver's uncertainty).
    lag_effects: tuple[LagEffect, ...] = ()


@dataclass(frozen=True)
class LogAnalysis:
    """One log's figures: each solver's and the initial guess's scores, its series and odometry."""

    scores: Mapping[str, Scores]
    baseline: Scores
    series: RunSeries | None
    odometry: OdometryTrack | None


@dataclass(frozen=True)
class Scorer:
    """Fair figures of parameter sets over records of one stretch of data (one log's used records,
    or several logs' fitted records end to end); record ``r`` of the whole fit is ``r - offset``."""

    fns: ProblemFunctions
    inputs: np.ndarray
    T_world_sensor: np.ndarray
    bad_intervals: np.ndarray
    bad_records: np.ndarray
    offset: int
    rpe_window: int
    #: With a mount per log: the log whose view scores the records, or each interval's log.
    logs: int | np.ndarray = 0

    def viewed(self, params: np.ndarray) -> np.ndarray:
        """``params`` as the full-parameter Functions take them over these records (one log's
        view, or one view per interval)."""
        fns = self.fns
        if fns.spec.mounts == 1 or isinstance(self.logs, int):
            return fns.view(params, 0 if isinstance(self.logs, np.ndarray) else self.logs)
        views = np.stack([fns.view(params, i) for i in range(fns.spec.mounts)], axis=1)
        return np.ascontiguousarray(views[:, self.logs])

    def __call__(self, params: np.ndarray, a: int | None = None, b: int | None = None) -> TrajectoryMetrics:
        """The figures of ``params`` over records ``[a, b)`` (all of them by default)."""
        return self.each([params], a, b)[0]

    def each(
        self, param_sets: Sequence[np.ndarray], a: int | None = None, b: int | None = None
    ) -> list[TrajectoryMetrics]:
        """The figures of each parameter set over records ``[a, b)``, the reference's side once."""
        return each_metrics(
            self.fns,
            [self.viewed(p) for p in param_sets],
            self.inputs,
            self.T_world_sensor,
            start=0 if a is None else a - self.offset,
            stop=None if b is None else b - self.offset,
            rpe_window=self.rpe_window,
            bad_intervals=self.bad_intervals,
            bad_records=self.bad_records,
        )


def log_scorer(
    fns: ProblemFunctions, windows: LogWindows, steering_sample: str, rpe_window: int, log: int = 0
) -> Scorer:
    """The scorer over one log's used records (log ``log`` of a fit's)."""
    bad_i, bad_r = windows.masks()
    inputs = windows.inputs(steering_sample)
    poses = tracker_poses(fns, windows.selected)
    return Scorer(fns, inputs, poses, bad_i, bad_r, windows.used[0], rpe_window, log)


def scores(scorer: Scorer, windows: LogWindows, param_sets: Sequence[np.ndarray]) -> list[Scores]:
    """Full-range and hold-out figures of each parameter set on one log."""
    full = scorer.each(param_sets)
    holdout: list[TrajectoryMetrics | None] = [None] * len(full)
    if windows.fit[1] < windows.used[1] - 1:
        holdout = list(scorer.each(param_sets, windows.fit[1]))
    return list(zip(full, holdout))


def analyse_fit(
    fit: Fit, results: Mapping[str, SolverResult], noise: np.ndarray, blocks: Scorer
) -> FitAnalysis:
    """Uncertainty of each result; observability at the first estimate with a finite cost (a solver
    may not have started); cross-validation and the direction check from the first converged one,
    with each held-out block scored by ``blocks``."""
    ev, data = fit.evaluator, fit.data
    big = data.n_residuals >= RELEASE_FROM
    if big:
        ev.release()  # the solvers' buffers: each analysis binds again only what it evaluates
        memory.give_back()
    start = fit.problem.start
    ranges = unc.range_std(start.lower, start.upper, fit.fns.n_free)
    uncertainty = {name: unc.estimate(ev, r.x, data, noise, ranges) for name, r in results.items()}
    finite = [r for r in results.values() if np.isfinite(r.cost)] or list(results.values())
    observability = observability_of(ev, finite[0].x, data.T_world_sensor)
    converged = [r for r in results.values() if r.converged]
    effects = unc.lag_effects(uncertainty[next(iter(results))]) if results else ()
    k = fit.problem.binder.scenario.validation.blocks
    if not converged or not k:
        return FitAnalysis(uncertainty, observability, None, None, lag_effects=effects)
    binder, x = fit.problem.binder, converged[0].x
    # Blocks are numbered as the scorer's records: the fitted records start at its offset.
    span = (blocks.offset, blocks.offset + data.n_records)
    full = fit.canonical_params(converged[0].params)
    whole = ev.normal_equations(x) if data.n_residuals >= validation.DOWNDATE_FROM else None
    if big:
        ev.release()  # the refits bind evaluators of their own; a later use binds this one again
    crossval = validation.cross_validate(binder, data, span, x, k, fit.canonical_params, blocks, full, whole)
    inputs = np.concatenate([np.zeros((data.inputs.shape[0], span[0])), data.inputs], axis=1)
    model = fit.fns.model
    direction = validation.direction_check(
        binder,
        data,
        span,
        x,
        model.travel_direction(inputs),
        lambda part: model.undetermined(inputs[:, part]),
        k,
        fit.canonical_params,
    )
    return FitAnalysis(uncertainty, observability, crossval, direction, lag_effects=effects)


def residual_series(fit: Fit, results: Mapping[str, SolverResult], windows: np.ndarray) -> ResidualSeries:
    """The residuals of the windows ``windows`` of the fit at the initial guess and at each estimate.

    Each evaluation's errors are copied at once: the evaluator reuses its buffers."""
    ev = fit.evaluator
    e0, s0, _ = ev.robust_terms(fit.problem.start.x0)
    before, inliers_before = np.array(e0[:, windows]), int(np.sum(s0[windows] <= ev.delta**2))
    after: dict[str, np.ndarray] = {}
    inliers: dict[str, int] = {}
    for name, r in results.items():
        e, s, _ = ev.robust_terms(r.x)
        after[name] = np.array(e[:, windows])
        inliers[name] = int(np.sum(s[windows] <= ev.delta**2))
    errs = list(after.values())
    scale = max((float(np.max(np.abs(e))) for e in errs if e.size), default=0.0)
    # Solvers that met the same optimum give residual sets indistinguishable in a histogram.
    agree = len(errs) > 1 and all(
        np.allclose(e, errs[0], rtol=0.0, atol=1e-6 * max(scale, 1e-12)) for e in errs
    )
    sc = fit.problem.binder.scenario
    return ResidualSeries(
        time_s=np.zeros(0),
        before=before,
        after=after,
        inliers_before=inliers_before,
        inliers_after=inliers,
        thresholds=ev.delta / np.sqrt(np.asarray(ev.omega, dtype=float)),
        kernel=sc.objective.robust.kernel,
        delta=ev.delta,
        solvers_agree=agree,
    )


@dataclass(frozen=True)
class LogView:
    """One log as the analyse stage sees it: as read, its windows, its scorer and its faults."""

    prepared: PreparedLog
    windows: LogWindows
    scorer: Scorer
    findings: Findings
    #: Its place among the fit's logs (0 for a single log).
    part: int = 0


def _window_times(fit: Fit, part: int) -> tuple[np.ndarray, np.ndarray]:
    """The fit's windows that belong to log ``part`` (indices) and their start times."""
    data = fit.data
    owner = np.searchsorted(np.asarray(data.offsets), data.starts, side="right") - 1
    idx = np.flatnonzero(owner == part)
    local = data.starts[idx] - data.offsets[part]
    return idx, np.asarray(data.logs[part].time_s)[local]


def track_series(
    fit: Fit,
    results: Mapping[str, SolverResult],
    view: LogView,
    figures: LogAnalysis,
    labels: Mapping[str, str],
) -> TrackSeries:
    """The tracker's poses and the tracks of the initial guess and of every estimate over one
    log's used records, restarted after each fault as the segment ATE scores them."""
    windows, inputs = view.windows, view.scorer.inputs
    ref = np.asarray(tracker_poses(fit.fns, windows.selected))
    bad_i, bad_r = windows.masks()
    parts = tuple(segments(ref.shape[0], bad_i))
    p0 = np.array([fit.problem.start.initial[n] for n in fit.fns.names])
    initial = dead_reckoned(fit.fns, fit.fns.view(p0, view.part), inputs, ref, parts)[0]
    tracks = [Track("uncalibrated (initial guess)", None, initial, figures.baseline[0].ate_mean)]
    again: dict[str, np.ndarray] = {}
    rows = []
    for name, r in results.items():
        full, again[name] = dead_reckoned(fit.fns, fit.fns.view(r.params, view.part), inputs, ref, parts)
        tracks.append(
            Track(labels.get(name, name), name, full, figures.scores[name][0].ate_mean, r.converged)
        )
        rows += segment_figures(name, again[name], ref, parts, ~bad_r, geometry(fit.fns))
    a, b = windows.used
    return TrackSeries(
        time_s=np.asarray(windows.selected.time_s),
        tracker=ref,
        good=~bad_r,
        parts=parts,
        tracks=tuple(tracks),
        restarted=again,
        faults=tuple((f.record - a, f.kind) for f in view.findings.report.faults if a <= f.record < b),
        holdout_start=windows.fit[1] - a if windows.fit[1] < b - 1 else None,
        segments=tuple(rows),
        tracker_z=fit.fns.sensor.heights(windows.selected),
        level=_level(fit, results, ref, view.part),
    )


def _level(fit: Fit, results: Mapping[str, SolverResult], ref: np.ndarray, part: int) -> np.ndarray | None:
    """The sensor's world frame turned onto the base's frame at the first record (None where they
    are one: a planar tracker's), by the first converged estimate's mount (the start's when none
    converged) on log ``part``."""
    names = fit.fns.names
    done = [r.params for r in results.values() if r.converged]
    params = done[0] if done else np.array([fit.problem.start.initial[n] for n in names])
    viewed = fit.fns.view(params, part)
    return fit.fns.sensor.level(dict(zip(fit.fns.view_names, map(float, viewed))), ref[0])


def model_check(fit: Fit, prepared: PreparedLog) -> ModelCheckSeries | None:
    """Our model's base-link track with the log header's parameters next to the vendor's odometry
    (``model_pose``), on the records as logged (the vendor integrated the encoders as logged);
    None when the log carries no vendor odometry."""
    log, model = prepared.log, prepared.model
    vendor = np.asarray(log.model_pose, dtype=float)
    if not np.any(vendor):
        return None
    header = header_parameters(model, log.header)
    initial = fit.problem.start.initial
    params = {n: float(header.get(n, initial[n])) for n in model.kinematic_params}
    params.update(dict.fromkeys(fit.fns.sensor.params, 0.0))
    params.update({n: 0.0 for n in fit.fns.view_names if n not in params})
    p = np.array([params[n] for n in fit.fns.view_names])
    residual = prepared.scenario.objective.residual
    inputs = model.inputs(log, residual.steering_sample)
    ours = integrate(fit.fns, p, inputs, vendor[0])
    kinematic = {n: params[n] for n in model.kinematic_params}
    return ModelCheckSeries(np.asarray(log.time_s), vendor, ours, residual.integration, kinematic)


def run_series(
    fit: Fit,
    results: Mapping[str, SolverResult],
    view: LogView,
    figures: LogAnalysis,
    labels: Mapping[str, str],
) -> RunSeries:
    """Everything one log's figures and trajectory files show."""
    windows = view.windows
    idx, times = _window_times(fit, view.part)
    residuals = dataclasses.replace(residual_series(fit, results, idx), time_s=times)
    t = np.asarray(windows.aligned.time_s)
    last = t.size - 1
    spans = tuple(
        FaultSpan(float(t[f.first]), float(t[min(f.last + 1, last)]), f.kind)
        for f in view.findings.report.faults
    )
    holdout = float(t[windows.fit[1]]) if windows.fit[1] < windows.used[1] - 1 else None
    tracks = track_series(fit, results, view, figures, labels)
    return RunSeries(tracks, residuals, spans, holdout, model_check(fit, view.prepared))


def odometry(
    fit: Fit, windows: LogWindows, params: np.ndarray, steering_sample: str, part: int = 0
) -> OdometryTrack:
    """Base-link odometry with ``params`` over the used records, started at the base pose the
    tracker's first pose implies, beside the base poses the tracker implies throughout; its
    covariance propagated from each input's noise calibrated on the drift this log shows against
    the tracker (never below the encoders' quantisation)."""
    sel, fns = windows.selected, fit.fns
    params = fns.view(params, part)
    inputs = windows.inputs(steering_sample)
    reference = over_columns(fns.base_from_sensor, sel.T_world_sensor.T, np.ravel(params))[0].T
    bad_i, bad_r = windows.masks()
    drift = segment_drift(fns, params, inputs, reference, segments(reference.shape[0], bad_i), ~bad_r)
    noise, reference_var = drift_noise(drift, windows.input_noise_std)
    track, cov = propagate(fns, params, inputs, reference[0], noise)
    names = fns.model.input_names
    return OdometryTrack(
        np.asarray(sel.time_s),
        track,
        cov,
        reference,
        input_noise=dict(zip(names, map(float, noise))),
        quantisation=dict(zip(names, map(float, windows.input_noise_std))),
        coverage=drift_coverage(drift, noise, reference_var),
    )


@dataclass(frozen=True)
class Wanted:
    """What the analyse stage computes beyond the figures: the series behind a report, and the
    odometry of one solver's estimate."""

    series: bool = False
    odometry: str | None = None


def analyse_log(
    fit: Fit,
    results: Mapping[str, SolverResult],
    view: LogView,
    wanted: Wanted,
    labels: Mapping[str, str],
) -> LogAnalysis:
    """One log's figures with the fit's estimates (and its series and odometry when wanted)."""
    windows, scorer = view.windows, view.scorer
    p0 = np.array([fit.problem.start.initial[n] for n in fit.fns.names])
    # The initial guess scored last: its figures are the baseline.
    *solved, baseline = scores(scorer, windows, [*(r.params for r in results.values()), p0])
    figures = LogAnalysis(
        scores=dict(zip(results, solved)),
        baseline=baseline,
        series=None,
        odometry=None,
    )
    series = run_series(fit, results, view, figures, labels) if wanted.series else None
    odo = None
    if wanted.odometry is not None and wanted.odometry in results:
        steering = view.prepared.scenario.objective.residual.steering_sample
        odo = odometry(fit, windows, results[wanted.odometry].params, steering, view.part)
    return dataclasses.replace(figures, series=series, odometry=odo)
