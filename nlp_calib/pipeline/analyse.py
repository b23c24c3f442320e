"""The analyse stage: what the fitted estimates are worth, computed once and kept in the result.

For the fit (one log, or several end to end): each solver's uncertainty, the observability, the
blocked cross-validation and the forward/reverse comparison. For each log: the fair figures of
each estimate and of the initial guess, and, when asked for, the series behind the figures
(tracks, residuals before and after, fault zones, the model check) and the odometry with its
covariance. The outputs only format what this stage computed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.analysis import uncertainty as unc
from nlp_calib.analysis.crossval import combine
from nlp_calib.analysis.degeneracy import motion_scale
from nlp_calib.analysis.determinacy import Information
from nlp_calib.analysis.handoff import Shown, odometry_noise
from nlp_calib.analysis.jitter import input_jitter
from nlp_calib.analysis.metrics import each_metrics, first_order, geometry, integrate, segments, steps
from nlp_calib.analysis.noise_rates import ground_rate, model_covariances, noise_rates
from nlp_calib.analysis.observability import analyse as observability_of
from nlp_calib.analysis.odometry import (
    DRIFT_LENGTHS,
    beyond_motion,
    beyond_motion_words,
    covering_noise,
    drift_noise,
    one_arc_errors,
    propagate,
    reference_step,
    segment_drift,
)
from nlp_calib.analysis.odometry import Drift as DriftSegments
from nlp_calib.analysis.plan import Setting, plan
from nlp_calib.analysis.precision import clock_needed
from nlp_calib.analysis.tracks import dead_reckoned, segment_figures
from nlp_calib.core import memory
from nlp_calib.logs import Log
from nlp_calib.models import header_parameters
from nlp_calib.pipeline import validation
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.prepare import PreparedLog
from nlp_calib.pipeline.stored import StoredCalibration
from nlp_calib.pipeline.windows import LogWindows
from nlp_calib.problem import ProblemFunctions, over_columns
from nlp_calib.problem.windows import tracker_poses
from nlp_calib.results import SolverResult
from nlp_calib.results.checks import (
    ConsistencyCheck,
    CostComparison,
    CrossValidation,
    DirectionCheck,
    Fold,
    LagEffect,
    Observability,
    PivotSpread,
)
from nlp_calib.results.faults import Findings
from nlp_calib.results.figures import TrajectoryMetrics
from nlp_calib.results.handoff import NoiseRates, OdometryNoise
from nlp_calib.results.layout import Layout
from nlp_calib.results.preflight import Plan
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
from nlp_calib.solvers import GaussNewton, ProblemEvaluator
from nlp_calib.solvers.gauss_newton import one_optimum

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
    #: For several logs: each log's own fit against the other logs'.
    consistency: ConsistencyCheck | None = None
    #: How each time offset moves the other parameters (the first solver's uncertainty).
    lag_effects: tuple[LagEffect, ...] = ()
    #: For several logs: the joint fit without each log in turn.
    logs: CrossValidation | None = None
    #: The fit against its start, and against the robot's nominal values where they are known.
    start: CostComparison | None = None
    nominal: CostComparison | None = None
    #: The nominal values scored (nominal where known, the fit's estimate elsewhere; model order).
    nominal_params: np.ndarray | None = None
    #: What to drive next, when a parameter is not determined well enough (see :func:`plan_after`).
    plan: Plan | None = None
    #: Each pivot of the drive fitted on its own (None: too few pivots, or one log of several).
    pivots: PivotSpread | None = None


@dataclass(frozen=True)
class LogAnalysis:
    """One log's figures: each solver's and the initial guess's scores, its series and odometry."""

    scores: Mapping[str, Scores]
    baseline: Scores
    series: RunSeries | None
    odometry: OdometryTrack | None
    #: The nominal robot's figures (None: no nominal values known).
    nominal: Scores | None = None
    #: The handed-off solver's odometry noise as its controller publishes it.
    noise: Mapping[str, OdometryNoise | None] = dataclasses.field(default_factory=dict)
    #: What the odometry noise's drift found worth saying: the reference's steps it left out, why
    #: no noise is handed off where it withheld one.
    noise_notes: tuple[str, ...] = ()


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
    #: Per interval, where the records do not connect (gaps, missing increments, one log's end).
    breaks: np.ndarray | None = None

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
            breaks=self.breaks,
        )


def log_scorer(
    fns: ProblemFunctions, windows: LogWindows, steering_sample: str, rpe_window: int, log: int = 0
) -> Scorer:
    """The scorer over one log's used records (log ``log`` of a fit's)."""
    bad_i, bad_r = windows.masks()
    inputs = windows.inputs(steering_sample)
    poses = tracker_poses(fns, windows.selected)
    return Scorer(fns, inputs, poses, bad_i, bad_r, windows.used[0], rpe_window, log, windows.used_breaks())


def scores(scorer: Scorer, windows: LogWindows, param_sets: Sequence[np.ndarray]) -> list[Scores]:
    """Full-range and hold-out figures of each parameter set on one log."""
    full = scorer.each(param_sets)
    holdout: list[TrajectoryMetrics | None] = [None] * len(full)
    if windows.fit[1] < windows.used[1] - 1:
        holdout = list(scorer.each(param_sets, windows.fit[1]))
    return list(zip(full, holdout))


def analyse_fit(
    fit: Fit,
    results: Mapping[str, SolverResult],
    noise: tuple[np.ndarray, np.ndarray],
    blocks: Scorer,
    layout: Layout,
) -> FitAnalysis:
    """Uncertainty of each result; observability at the first estimate with a finite cost (a solver
    may not have started); cross-validation, the direction check and the comparisons with the start
    and the nominal robot from the first converged one, with each held-out block scored by
    ``blocks``; ``layout``: the precision each parameter needs on the drive (the direction check's
    floor; the weak directions' of the clock offsets)."""
    ev, data = fit.evaluator, fit.data
    big = data.n_residuals >= RELEASE_FROM
    if big:
        ev.release()  # the solvers' buffers: each analysis binds again only what it evaluates
        memory.give_back()
    start = fit.problem.start
    ranges = unc.range_std(start.lower, start.upper, fit.fns.n_free)
    finite = [r for r in results.values() if np.isfinite(r.cost)] or list(results.values())
    # Before the uncertainty, which evaluates the residuals at the same estimate (kept by the
    # evaluator) and then lets go of their buffers.
    observability = observability_of(ev, finite[0].x, data.T_world_sensor, clock_needed(layout))
    uncertainty = uncertainties(fit, results, noise, ranges)
    converged = [r for r in results.values() if r.converged]
    effects = unc.lag_effects(uncertainty[next(iter(results))], fit.fns.layout) if results else ()
    if not converged:
        return FitAnalysis(uncertainty, observability, None, None, lag_effects=effects)
    x = converged[0].x
    # The nominal values go into the canonical form's other values (a symmetric twin would mix).
    canonical = fit.canonical_params(converged[0].params)
    against = _against(fit, canonical[[fit.fns.names.index(n) for n in fit.fns.free]])
    k = fit.problem.binder.scenario.validation.blocks
    crossval = direction = None
    if k:
        crossval, direction = _refits(fit, converged[0], blocks, k, [v for _, v in against.values()], layout)
    costs = comparisons(fit, x, against, crossval.converged if crossval is not None else ())
    nominal = against.get("nominal")
    return FitAnalysis(
        uncertainty,
        observability,
        crossval,
        direction,
        start=costs["start"],
        nominal=costs.get("nominal"),
        nominal_params=None
        if nominal is None
        else np.asarray(fit.fns.assemble(nominal[1], ev.x_fixed)).ravel(),
        lag_effects=effects,
    )


def uncertainties(
    fit: Fit,
    results: Mapping[str, SolverResult],
    noise: tuple[np.ndarray, np.ndarray],
    ranges: np.ndarray | None,
) -> dict[str, Uncertainty]:
    """Each result's uncertainty at its estimate; a result at the optimum of one computed before
    (both solvers met it within the stopping tolerance) takes that one's."""
    out: dict[str, Uncertainty] = {}
    done: list[tuple[SolverResult, Uncertainty]] = []
    # The optimum to the tolerance of Gauss-Newton's stopping test, as the scenario sets it.
    tolerance = fit.problem.binder.scenario.options_for(GaussNewton.name).function_tolerance
    for name, r in results.items():
        same = [u for prior, u in done if same_optimum(fit.evaluator, prior, r, tolerance)]
        out[name] = (
            same[0] if same else unc.estimate(fit.evaluator, r.x, fit.data, noise[0], ranges, noise[1])
        )
        done.append((r, out[name]))
    return out


def same_optimum(evaluator: ProblemEvaluator, a: SolverResult, b: SolverResult, tolerance: float) -> bool:
    """Whether converged ``a`` and ``b`` are one optimum to Gauss-Newton's stopping test
    (:func:`~nlp_calib.solvers.gauss_newton.one_optimum`), in ``a``'s normal equations (kept from
    its uncertainty: no evaluation)."""
    if not (a.converged and b.converged) or a.x.shape != b.x.shape:
        return False
    ne = evaluator.normal_equations(a.x)
    if not (np.isfinite(ne.cost) and np.all(np.isfinite(ne.H))):
        return False
    # The tangent step from a to b: x ⊞ δ ≈ x + Mδ to first order (the distance is at rounding).
    M = np.asarray(evaluator.tangent_map(a.x), dtype=float)
    delta = np.linalg.lstsq(M, np.asarray(b.x - a.x, dtype=float), rcond=None)[0]
    return one_optimum(ne.H, ne.cost, delta, tolerance)


def _against(fit: Fit, x: np.ndarray) -> dict[str, tuple[str, np.ndarray]]:
    """The free values the fit (``x``: its free values in canonical form) is judged against, by
    key: its start and, where some are known, the robot's nominal values (the fit's own elsewhere),
    each with its name in words."""
    start = fit.problem.start
    free = fit.fns.free
    auto = fit.problem.binder.scenario.parameters.initial_guess == "auto"
    out = {"start": ("the data-driven start" if auto else "the initial guess", start.x0)}
    if start.nominal:
        x_nominal = np.array(x, dtype=float)
        for name, value in start.nominal.items():
            if name in free:
                x_nominal[free.index(name)] = value
        out["nominal"] = ("the nominal robot", x_nominal)
    return out


def _refits(
    fit: Fit,
    result: SolverResult,
    blocks: Scorer,
    k: int,
    against: Sequence[np.ndarray],
    layout: Layout,
) -> tuple[CrossValidation, DirectionCheck | None]:
    """The blocked cross-validation (each fold costed on its block beside ``against``) and the
    direction check (no finding within ``layout``'s needed precision), refitted from ``result``."""
    ev, data = fit.evaluator, fit.data
    binder, x = fit.problem.binder, result.x
    # Blocks are numbered as the scorer's records: the fitted records start at its offset.
    span = (blocks.offset, blocks.offset + data.n_records)
    full = fit.canonical_params(result.params)
    whole = ev.normal_equations(x) if data.n_residuals >= validation.DOWNDATE_FROM else None
    if data.n_residuals >= RELEASE_FROM:
        ev.release()  # the refits bind evaluators of their own; a later use binds this one again
    crossval = validation.cross_validate(
        binder, data, span, x, k, fit.canonical_params, blocks.each, full, whole, against
    )
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
        layout,
    )
    return crossval, direction


def logs_crossval(
    fit: Fit, results: Mapping[str, SolverResult], blocks: Scorer, ranges: Sequence[tuple[int, int]]
) -> CrossValidation | None:
    """The joint fit without each log in turn (``ranges``: each log's records, numbered as
    ``blocks``'s), from the first converged estimate, each scored on the log it left out; its σ
    needs every fold (None: fewer than two logs, or no converged estimate)."""
    converged = [r for r in results.values() if r.converged]
    if not converged or len(ranges) < 2:
        return None
    result = converged[0]
    span = (blocks.offset, blocks.offset + fit.data.n_records)
    start = (result.x, fit.canonical_params(result.params))
    # A fold without a log knows nothing of that log's time offset (nor of its own mount, with a
    # mount per log): held where the joint fit put them.
    held = [list(fit.fns.layout.owned(i)) for i in range(len(ranges))]
    folds = validation.folds_over(
        fit.problem.binder, fit.data, span, ranges, start, fit.canonical_params, blocks.each, held=held
    )
    return combine(fit.fns.names, folds, min_folds=len(folds))


def comparisons(
    fit: Fit, x: np.ndarray, against: Mapping[str, tuple[str, np.ndarray]], folds: Sequence[Fold]
) -> dict[str, CostComparison]:
    """The fit ``x`` against each set of ``against`` (key: (words, free values)) by their data
    costs: held out over ``folds`` (costed in the order of ``against``) and on every window."""
    ev = fit.evaluator

    def data_cost(v: np.ndarray) -> float:
        prior = ev.prior_terms(v)[0] if ev.priors.active else 0.0
        return float(ev.cost(v)) - float(prior)

    mine = data_cost(x)
    costed = [f.costs for f in folds if len(f.costs) == len(against) + 1]
    out = {}
    for i, (key, (words, v)) in enumerate(against.items()):
        heldout = np.array([[c[i + 1], c[0]] for c in costed]).reshape(-1, 2)
        out[key] = CostComparison(words, heldout, (data_cost(v), mine))
    return out


def plan_setting(fit: Fit, results: Mapping[str, SolverResult], units: Mapping[str, str]) -> Setting | None:
    """What a plan after this fit starts from: the first converged estimate (else the starting
    point: a solver's last iterate on a drive that leaves directions free can lie anywhere along
    them), the fit's information there and the residuals' variance as the observability takes it;
    None when nothing can be evaluated."""
    ev, fns, data = fit.evaluator, fit.fns, fit.data
    converged = [(n, r) for n, r in results.items() if r.converged]
    start = fit.problem.start
    x = converged[0][1].x if converged else start.x0
    if data.n_residuals == 0:
        return None
    ne = ev.normal_equations(x)
    if not (np.isfinite(ne.cost) and np.all(np.isfinite(ne.H))):
        return None
    # Kept from the observability's evaluation at the same estimate (its residuals' buffers are
    # let go of by then): no pass over the windows.
    sigma2 = max(ev.weighted_chi2(x) / max(fns.error_rows * ev.n_residuals - fns.n_free, 1), 1e-300)
    info = Information(ne.H, ev.n_residuals, motion_scale(fns, data.z, ev.omega), ne.g, ne.chi2, sigma2)
    sc = fit.problem.binder.scenario
    ranges = unc.range_std(start.lower, start.upper, fns.n_free)
    model_from = f"the fit ({converged[0][0]})" if converged else "the initial guess (no solver converged)"
    return Setting(
        fns, data, info, (x, ev.x_fixed, ev.omega), sigma2, ranges, sc.objective.residual,
        sc.objective.robust.delta, units, model_from, sc.parameters.vehicle.steer_max,
    )  # fmt: skip


def plan_after(fit: Fit, results: Mapping[str, SolverResult], units: Mapping[str, str]) -> Plan | None:
    """What to drive next (:mod:`nlp_calib.analysis.plan`), simulated with the fit (see
    :func:`plan_setting`); without a converged fit, only when the drive leaves a direction free."""
    setting = plan_setting(fit, results, units)
    if setting is None:
        return None
    return plan(setting, free_only=not any(r.converged for r in results.values()))


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
    euler = first_order(steps(fit.fns, p, inputs), vendor[0])
    return ModelCheckSeries(np.asarray(log.time_s), vendor, ours, residual.integration, kinematic, euler)


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


#: The used records the hand-off's odometry noise is calibrated on at most (from the first): a
#: few hundred drift segments determine it, and a long log's cost stays that of a short one.
NOISE_RECORDS = 20_000


@dataclass(frozen=True)
class Drift:
    """A log's odometry against the base poses the tracker implies over its first ``records``
    used records: the inputs, those poses, the segments' drift, each input's noise per interval
    (with the reference's own variances) that explains it, and what the joints' own noise gives
    each input per interval (:func:`~nlp_calib.analysis.jitter.input_jitter`); ``whole``: the
    noise fitted with no segment left out, which judges whether the model explains the motion;
    ``arc``: each interval's one-arc integration error (:func:`one_arc`; None: not known)."""

    inputs: np.ndarray
    reference: np.ndarray
    drift: DriftSegments
    noise: np.ndarray
    reference_var: np.ndarray
    jitter: np.ndarray
    whole: np.ndarray
    arc: np.ndarray | None = None
    #: The records a step of the reference the fault checks missed ended at (no segment crosses it).
    stepped: tuple[int, ...] = ()

    def beyond(self) -> tuple[int, ...]:
        """The inputs whose noise per interval, fitted on every segment, reaches their own motion's
        scale (:func:`~nlp_calib.analysis.odometry.beyond_motion`)."""
        return beyond_motion(self.inputs, self.whole)


def calibrated_drift(
    fit: Fit, windows: LogWindows, params: np.ndarray, steering_sample: str, records: int | None = None
) -> Drift:
    """Each input's noise per interval calibrated on the drift of the used records (the first
    ``records`` of them) against the tracker (a random walk beside the readings' rounding, the
    encoders' quantisation, which does not add up along a drive)."""
    fns, sel = fit.fns, windows.selected
    n = sel.n_records if records is None else min(records, sel.n_records)
    sel = sel.select(0, n)
    inputs = windows.binder.fns.model.inputs(sel, steering_sample)
    reference = over_columns(fns.base_from_sensor, sel.T_world_sensor.T, np.ravel(params))[0].T
    bad_intervals, bad_records = windows.masks()
    # The fit's own windows are segments too: a log of short fault-free parts (a scan matcher's
    # increments between bad matches) still shows its drift over them.
    spans = windows.data.stops - windows.data.starts
    own = int(np.bincount(spans).argmax()) if spans.size else DRIFT_LENGTHS[0]
    lever = reference[:, :2] - np.asarray(sel.T_world_sensor)[:, :2]
    arc = one_arc(fns, params, (sel, inputs), steering_sample)
    drift, stepped = _stepless_drift(
        lambda parts: segment_drift(
            fns, params, inputs, reference, parts, ~bad_records[:n], (own, *DRIFT_LENGTHS), lever, arc
        ),
        (bad_intervals[: n - 1], reference),
    )
    floor = windows.input_noise_std
    # A tracker's poses tell its own noise from the wheels' (by the drift's growth with length);
    # a reference's own increments, one per window, do not tell their heading's: the heading's
    # drift is the odometry's (at least what the windows show).
    credited = (True, windows.data.increment is None)
    noise, reference_var = drift_noise(drift, floor, credited)
    noise = covering_noise(drift, noise, floor, reference_var)
    # The errors the moments leave out (a reference's glitch) may instead be the model's own,
    # as large as the motion: whether the noise reaches that is judged with every segment in.
    whole, whole_var = drift_noise(drift, floor, credited, far_out=None)
    whole = covering_noise(drift, whole, floor, whole_var)
    jitter = input_jitter(windows.binder.fns.model, sel, steering_sample)
    return Drift(inputs, reference, drift, noise, reference_var, jitter, whole, arc, stepped)


#: The most steps of the reference :func:`_stepless_drift` takes out of one log's segments.
MOST_STEPS = 4


def _stepless_drift(
    drift_over: Callable[[list[tuple[int, int]]], DriftSegments], against: tuple[np.ndarray, np.ndarray]
) -> tuple[DriftSegments, tuple[int, ...]]:
    """The drift segments (``drift_over`` the fault-free parts) inside the parts the bad intervals
    leave (``against``: those, and the reference's base poses), none across a step of the
    reference the fault checks missed (:func:`~nlp_calib.analysis.odometry.reference_step`), and
    the records those steps end at."""
    bad, reference = np.array(against[0], dtype=bool), against[1]
    drift, stepped = drift_over(segments(bad.size + 1, bad)), []
    for _ in range(MOST_STEPS):
        step = reference_step(drift, reference)
        if step is None:
            break
        bad[step[0] : step[1]] = True
        stepped.append(step[1])
        drift = drift_over(segments(bad.size + 1, bad))
    return drift, tuple(stepped)


def one_arc(
    fns: ProblemFunctions, params: np.ndarray, records: tuple[Log, np.ndarray], steering_sample: str
) -> np.ndarray | None:
    """Each interval's one-arc integration error (:func:`~nlp_calib.analysis.odometry.one_arc_errors`)
    over the log ``records`` (with its inputs), where its joints have samples of their own between
    its records (None: they have none, and the error is not known)."""
    sel, inputs = records
    fine, at = sel.at_joint_samples()
    if at is None:
        return None
    return one_arc_errors(fns, params, inputs, (fns.model.inputs(fine, steering_sample), at))


def noise_model(
    fit: Fit, windows: LogWindows, params: np.ndarray, steering_sample: str
) -> tuple[Drift, NoiseRates]:
    """The one noise model at ``params``: the odometry's rates per metre and per radian calibrated
    on the drift of the first :data:`NOISE_RECORDS` used records, with that drift."""
    d = calibrated_drift(fit, windows, params, steering_sample, NOISE_RECORDS)
    checked = (d.drift, d.reference_var, windows.input_noise_std)
    rates = noise_rates(fit.fns, params, d.inputs, d.noise, checked, d.jitter)
    if windows.data.increment is not None and "heading" not in rates.bounded:
        # A reference's own increments do not tell their heading's noise from the wheels' drift
        # (:func:`calibrated_drift` credits it none): the heading's rate holds both, a bound.
        rates = replace(rates, bounded=(*rates.bounded, "heading"))
    if windows.ground is not None:
        n = d.inputs.shape[1] + 1
        ground = windows.ground[windows.used[0] : windows.used[0] + n - 1]
        rates = ground_rate(fit.fns, params, (d.inputs, d.reference), ground, rates)
    return d, rates


def odometry(
    fit: Fit,
    windows: LogWindows,
    params: np.ndarray,
    steering_sample: str,
    model: tuple[Drift, NoiseRates] | None = None,
) -> OdometryTrack:
    """Base-link odometry with ``params`` over the used records, started at the base pose the
    tracker's first pose implies, beside the base poses the tracker implies throughout; its
    covariance the one noise model's (``model``, :func:`noise_model`'s; None: computed), as the
    hand-off's, from the start (its reading's rounding, and the end's, included)."""
    d, rates = noise_model(fit, windows, params, steering_sample) if model is None else model
    floor = windows.input_noise_std
    sel = windows.selected
    inputs = windows.binder.fns.model.inputs(sel, steering_sample)
    reference = over_columns(fit.fns.base_from_sensor, sel.T_world_sensor.T, np.ravel(params))[0].T
    n = inputs.shape[1]
    names = fit.fns.model.input_names
    beyond = d.beyond()
    why = beyond_motion_words(names, fit.fns.model.input_units, d.whole, beyond) if beyond else ""
    cov = np.full((n + 1, 3, 3), np.nan)
    if not why:
        spans = np.c_[np.zeros(n, dtype=int), np.arange(1, n + 1)]
        # The track below integrates one arc per interval: its covariance carries that error too.
        arc = one_arc(fit.fns, params, (sel, inputs), steering_sample)
        C, _ = model_covariances(fit.fns, params, inputs, (rates, floor), spans, arc)
        c, s = np.cos(reference[0, 2]), np.sin(reference[0, 2])
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        cov = np.concatenate([np.zeros((1, 3, 3)), R @ C @ R.T])
    track = propagate(fit.fns, params, inputs, reference[0], np.zeros(floor.shape))[0]
    return OdometryTrack(
        np.asarray(sel.time_s),
        track,
        cov,
        reference,
        input_noise=dict(zip(names, map(float, d.noise))),
        quantisation=dict(zip(names, map(float, floor))),
        coverage=None if why else rates.coverage,
        rates=None if why else rates,
        undetermined=why,
    )


def handoff_noise(
    fit: Fit, windows: LogWindows, params: np.ndarray, steering_sample: str
) -> tuple[OdometryNoise | None, tuple[Drift, NoiseRates] | None]:
    """The covariance a controller publishes with its odometry at ``params``, from the one noise
    model (:func:`noise_model`), with that model (None for a 3-D sensor, whose poses do not give
    the planar base's; the covariance None where the drift withholds it, :meth:`Drift.beyond`)."""
    if not fit.fns.sensor.planar_base:
        return None, None
    d, rates = noise_model(fit, windows, params, steering_sample)
    if d.beyond():
        return None, (d, rates)  # the hand-off then says the drift does not determine the noise
    walk = dict(zip(fit.fns.model.input_names, map(float, d.noise)))
    time_s = windows.selected.time_s[: d.inputs.shape[1] + 1]
    n = d.inputs.shape[1]
    lever = d.reference[:, :2] - np.asarray(windows.selected.T_world_sensor)[: n + 1, :2]
    bad_intervals, bad_records = windows.masks()
    chained = windows.data.increment is not None
    segments = d.drift.errors.shape[0]
    shown = Shown(
        bad_intervals[:n], d.reference, lever, d.reference_var, segments, chained, bad_records[: n + 1], d.arc
    )
    found = odometry_noise(fit.fns, params, d.inputs, time_s, (rates, windows.input_noise_std, walk), shown)
    return found, (d, rates)


@dataclass(frozen=True)
class Wanted:
    """What the analyse stage computes beyond the figures: the series behind a report, and the
    odometry of one solver's estimate; and the stored calibration the run checks (``against``:
    the ``drift`` plug-in's, None: none)."""

    series: bool = False
    odometry: str | None = None
    against: StoredCalibration | None = None


def analyse_log(
    fit: Fit,
    results: Mapping[str, SolverResult],
    view: LogView,
    wanted: Wanted,
    labels: Mapping[str, str],
    nominal: np.ndarray | None = None,
) -> LogAnalysis:
    """One log's figures with the fit's estimates and the nominal robot's (``nominal``: its full
    parameters, where known), and its series and odometry when wanted."""
    windows, scorer = view.windows, view.scorer
    p0 = np.array([fit.problem.start.initial[n] for n in fit.fns.names])
    # The initial guess scored after the estimates (its figures are the baseline), then the
    # nominal robot where it is known.
    extra = [] if nominal is None else [nominal]
    scored = scores(scorer, windows, [*(r.params for r in results.values()), p0, *extra])
    n = len(results)
    figures = LogAnalysis(
        scores=dict(zip(results, scored[:n])),
        baseline=scored[n],
        series=None,
        odometry=None,
        nominal=scored[n + 1] if extra else None,
    )
    series = run_series(fit, results, view, figures, labels) if wanted.series else None
    steering = view.prepared.scenario.objective.residual.steering_sample
    # The hand-off carries the first converged solver's estimate (in the scenario's order): its
    # odometry noise is the one a controller file states, and the odometry's where it is the same.
    order = [*view.prepared.scenario.solvers, *results]
    first = next((n for n in order if n in results and results[n].converged), None)
    noise, model = {}, None
    if first is not None:
        noise[first], model = handoff_noise(
            fit, windows, fit.fns.view(results[first].params, view.part), steering
        )
    odo = None
    if wanted.odometry is not None and wanted.odometry in results:
        params = fit.fns.view(results[wanted.odometry].params, view.part)
        odo = odometry(fit, windows, params, steering, model if wanted.odometry == first else None)
    notes = _noise_notes(fit, windows, model[0]) if model is not None else ()
    return dataclasses.replace(figures, series=series, odometry=odo, noise=noise, noise_notes=notes)


def _noise_notes(fit: Fit, windows: LogWindows, drift: Drift) -> tuple[str, ...]:
    """The reference's steps the odometry noise's segments left out, and why the hand-off states
    no odometry noise where the drift withholds it."""
    t = np.asarray(windows.selected.time_s, dtype=float)
    out = [
        f"the tracker's poses step at {t[k]:.3f} s (record {k} of those used), which the fault checks "
        "did not flag (a tracker that held a wrong pose, then relocked): the odometry noise's drift "
        "segments across it were left out (one event, not a drift the wheels have)"
        for k in drift.stepped
    ]
    if beyond := drift.beyond():
        names, units = fit.fns.model.input_names, fit.fns.model.input_units
        out.append(
            "no odometry noise handed off (calibration.yaml's odometry_noise, ros2_control.yaml's "
            f"covariance diagonals): {beyond_motion_words(names, units, drift.whole, beyond)}"
        )
    return tuple(out)
