"""The pre-flight: what a recording holds and whether the drive determines each parameter, before any fit.

In seconds and without a fit: each log is read and selected as a run reads it (the prepare
stage), the problem is built as the run builds it, and its Jacobian is evaluated at a start (the
scenario's initial guess, or the closed-form start on the stretch of at most
:data:`START_RECORDS` records that turns most; the nominal values where that fails). From it each
parameter is determined, weakly determined or not, with the reason
(:mod:`nlp_calib.analysis.determinacy`, the run's own definitions); the drive's excitation and
what the data imply of units and signs come from the tracker and the encoders; when a parameter
is not determined well enough, the plan ranks what to drive next (:mod:`nlp_calib.analysis.plan`).
:func:`refuse` stops a calibration that cannot succeed with the pre-flight's words.
"""

from __future__ import annotations

import functools
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from nlp_calib.analysis import determinacy as det
from nlp_calib.analysis import uncertainty as unc
from nlp_calib.analysis.crossval import combine
from nlp_calib.analysis.degeneracy import scales
from nlp_calib.analysis.excitation import combined, of_log, smoothed, turns_both_ways
from nlp_calib.analysis.observability import IN_DIRECTION, directions, not_observable
from nlp_calib.analysis.plan import Setting, believed, plan
from nlp_calib.analysis.precision import log_precision, tightest
from nlp_calib.analysis.uncertainty import range_std
from nlp_calib.analysis.verdict import RANGE_SIGMAS, way_out
from nlp_calib.core.errors import DatasetError, NlpCalibError, PreflightError
from nlp_calib.logs import Log, resample_encoders
from nlp_calib.models import counted_inputs
from nlp_calib.pipeline import slip_check, units_check
from nlp_calib.pipeline.align import MAX_RESAMPLINGS, estimate_tracker_lag, lag_held, stays, white_std
from nlp_calib.pipeline.assemble import fit_info
from nlp_calib.pipeline.build import (
    INTERNAL_SOLVER,
    Binder,
    StartingPoint,
    build_problem,
    no_priors,
    prepare_backend,
    starting_point,
)
from nlp_calib.pipeline.prepare import PreparedLog, joint_residual, prepare
from nlp_calib.pipeline.recording import recording
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.pipeline.stages import Aligned, align_log
from nlp_calib.pipeline.units_check import implausible
from nlp_calib.pipeline.validation import leave_out, on_threads
from nlp_calib.problem import ProblemFunctions, ResidualData, build_residual_data
from nlp_calib.results.checks import CheckResult, Fold, LagEstimate, believed_std
from nlp_calib.results.layout import CLOCK
from nlp_calib.results.preflight import NOT_DETERMINED, WEAKLY, Excitation, ParameterStatus, Preflight
from nlp_calib.solvers.backends import Backend
from nlp_calib.solvers.evaluation import NormalEquations, ProblemEvaluator, is_singular, singular_share

#: The closed-form start is taken on the stretch of at most this many records that turns most.
START_RECORDS = 5000
#: The start is brought to the data by at most this many Gauss-Newton steps (a far nominal start
#: takes a few), until a step gains less than this share of the misfit.
ROUGH_STEPS = 4
ROUGH_GAIN = 0.1

#: A converged fit: its free parameters, the windows' information there, where it stands in words
#: and what computes each free parameter's σ as the run does (once, for the fit finally judged).
Fitted = tuple[np.ndarray, "det.Information", str, Callable[[], np.ndarray]]


@dataclass(frozen=True)
class Drive:
    """The logs as prepared, the scenario they are fitted with (one horizon), the problem, its
    windows over every log's fitted records and the start the Jacobian is taken at, in words."""

    parts: tuple[PreparedLog, ...]
    scenario: Scenario
    fns: ProblemFunctions
    data: ResidualData
    start: StartingPoint
    start_words: str
    #: Each log as read (its encoders are re-sampled from it at a fitted time offset).
    read: tuple[Log, ...] = ()
    #: The run's own evaluation backend, where the pre-flight judges inside a run (None: one of
    #: its own): a second would build its maps again and reset what the run set for its helpers.
    backend: Backend | None = None
    #: Each free time offset's estimate by the run's alignment of its log, by name (the run's
    #: return check: a lag it holds, or whose σ it widens, is so here too; empty: none known).
    lags: Mapping[str, LagEstimate] = field(default_factory=dict)


def _prepared(
    sc: Scenario, logs: Sequence[Log] | None, run: Aligned | None = None
) -> tuple[tuple[PreparedLog, ...], Scenario, dict[str, str]]:
    """Each log prepared as a run prepares it (``run``: a one-log run's stages, its log prepared
    already), the scenario with one record horizon, and the parameters the drive cannot determine
    at all (the run holds them)."""
    if run is not None and not sc.data.joint:
        return (run.prepared,), run.prepared.scenario, dict(run.prepared.held)
    per_log = sc.per_log()
    given: Sequence[Log | None] = list(logs) if logs is not None else [None] * len(per_log)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the run says what preparing says; the pre-flight says it otherwise
        parts = tuple(prepare(s, log) for s, log in zip(per_log, given))
        if not sc.data.joint:
            return parts, parts[0].scenario, dict(parts[0].held)
        one = sc.with_options(residual=joint_residual(sc, parts))
    model = parts[0].model
    inputs = np.concatenate(
        [model.inputs(p.log.select(p.start, p.split), sc.objective.residual.steering_sample) for p in parts],
        axis=1,
    )
    held = {n: why for n, why in model.undetermined(inputs).items() if n not in sc.parameters.fixed}
    return parts, one, held


def _busiest(log: Log, a: int, b: int, size: int) -> tuple[int, int]:
    """The stretch of ``size`` records of ``[a, b)`` over which the tracker's heading turns most."""
    if b - a <= size:
        return a, b
    heading = smoothed(log.time_s[a:b], np.unwrap(log.T_world_sensor[a:b, 2])[:, None], 1.0)[:, 0]
    c = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(heading)))])
    starts = np.arange(0, b - a - size + 1, max(1, size // 4))
    best = int(starts[np.argmax(c[starts + size - 1] - c[starts])])
    return a + best, a + best + size


def _start(
    sc: Scenario,
    fns: ProblemFunctions,
    first: PreparedLog,
    n_logs: int,
    mounts: Sequence[Mapping[str, float]] = (),
) -> tuple[StartingPoint, str]:
    """Where the Jacobian is taken: the run's starting point (the closed form on the busiest
    stretch when ``auto``), or the nominal values where the closed form fails. A closed form
    outside the model's plausible ranges is kept, and said: it is where a drive that barely
    determines some combination sends it, and where the run starts too. ``mounts``: each log's own
    start, with a mount per log (each log's mount starts there, as the run's does)."""
    auto = sc.parameters.initial_guess == "auto"
    a, b = (
        _busiest(first.log, first.start, first.split, START_RECORDS) if auto else (first.start, first.split)
    )
    lags = [0.0] * n_logs if n_logs > 1 else []
    try:
        point = starting_point(sc, fns, first.log, a, b, lags, mounts)
        if np.all(np.isfinite(point.x0)):
            words = "the closed-form start (initial_guess: auto)" if auto else "the initial guess"
            words += f" on records {a} to {b}" if (a, b) != (first.start, first.split) else ""
            outside = implausible(fns.model, point.initial)
            return point, words + (f", outside the plausible ranges in {outside}" if outside else "")
        why = "it is not finite"
    except DatasetError:
        raise  # the data at fault (a gyro in degrees), not the start
    except (NlpCalibError, np.linalg.LinAlgError, ValueError, ZeroDivisionError) as exc:
        if not auto:
            raise
        why = f"it failed: {exc}"
    nominal = sc.with_options(initial_guess="from_file")
    point = starting_point(nominal, fns, first.log, a, b, lags, mounts)
    return point, f"the nominal values (not the closed-form start: {why})"


def drive(
    sc: Scenario, logs: Sequence[Log] | None = None, run: Aligned | None = None
) -> tuple[Drive, dict[str, str]]:
    """The scenario's logs prepared, its problem built and bound to every log's fitted records, and
    the start (see the module docstring); with the parameters the run would hold. ``run``: a
    one-log run's stages before its windows are bound (its prepared log and its backend used)."""
    parts, one, held = _prepared(sc, logs, run)
    fns = build_problem(one, parts[0].model, tuple(held), len(parts))
    mounts = []
    if fns.spec.mounts > 1:
        single = build_problem(one, parts[0].model, tuple(held), 1)
        mounts = [_start(one, single, p, 1)[0].initial for p in parts]
    point, words = _start(one, fns, parts[0], len(parts), mounts)
    data = build_residual_data(
        fns,
        [p.log.select(p.start, p.split) for p in parts],
        one.objective.residual,
        drop_stationary=one.log.samples.drop_stationary,
        gaps=_gaps(parts),
    )
    backend = None if run is None else run.problem.binder.backend
    return Drive(parts, one, fns, data, point, words, tuple(p.log for p in parts), backend), held


def _rough(d: Drive, omega: np.ndarray) -> tuple[np.ndarray, det.Information, str]:
    """The start brought to the data by Gauss-Newton steps on the directions the drive determines
    (halved up to twice where a full step does not lower the robust cost; at most
    :data:`ROUGH_STEPS`, until one gains less than :data:`ROUGH_GAIN` of it), on the
    windows whose information is finally judged (a smaller subsample's noise can carry a weakly
    determined parameter to where its Jacobian vanishes: the rear track of a car-like base halfway
    to its value); the windows' information at the point reached and where it stands, in words."""
    fns, start, delta = d.fns, d.start, d.scenario.objective.robust.delta
    box = None if start.lower is None or start.upper is None else (start.lower, start.upper)

    def at(x: np.ndarray) -> det.Information:
        return det.information(fns, d.data, x, start.x_fixed, omega, delta, det.MAX_WORK)

    x, info, steps = start.x0, at(start.x0), 0
    while steps < ROUGH_STEPS:
        dx = det.step(fns, info, x)
        for alpha in (1.0, 0.5, 0.25):
            moved = np.asarray(fns.boxplus(x, alpha * dx)).ravel()
            moved = moved if box is None else np.clip(moved, *box)
            found = at(moved) if np.all(np.isfinite(moved)) else None
            if found is not None and np.isfinite(found.chi2) and found.chi2 < info.chi2:
                break
        else:
            break
        gain = 1.0 - found.chi2 / max(info.chi2, 1e-300)
        x, info, steps = moved, found, steps + 1
        if gain < ROUGH_GAIN:
            break
    if not steps:
        return x, info, d.start_words
    said = "one Gauss-Newton step" if steps == 1 else f"{steps} Gauss-Newton steps"
    return x, info, f"{d.start_words}, moved by {said} toward the data"


def _judged(d: Drive) -> ResidualData:
    """The windows whose information is judged: a spread subsample of at most
    :data:`~nlp_calib.analysis.determinacy.MAX_WORK` windows × horizon."""
    n = d.data.n_residuals
    idx = det.spread(n, max(1, det.MAX_WORK // max(d.data.horizon, 1)))
    return d.data if idx.size == n else d.data.select(idx)


@dataclass(frozen=True)
class Stalled:
    """Where the run's internal solver stopped without converging on a normal matrix it calls
    singular (:func:`~nlp_calib.solvers.evaluation.is_singular`, the solver's own test): the run's
    fit from the same start stops there too, and its verdict is NOT DETERMINED. ``undetermined``:
    each free parameter the information there leaves free, as the run's observability reads it
    (:func:`~nlp_calib.analysis.observability.not_observable`), else the solver's own near-null
    directions' parameters."""

    undetermined: np.ndarray


def _fitted(d: Drive, omega: np.ndarray, x0: np.ndarray | None = None) -> Fitted | Stalled | None:
    """The start fitted to convergence by the run's internal solver on the windows whose information
    is judged (robust kernel, bounds), and the information there: the σ a fit will give is read
    where the fit ends, never at the start, whose misfit is no noise. Where the fit stops on a
    singular normal matrix, what it leaves free there (:class:`Stalled`: a drive whose every
    relative motion is alike, circles of one radius one way, leaves the start's information weak,
    not free, yet the fit runs along it to where it is free); None where it does not converge
    otherwise. The information is the fit's own normal equations at its optimum (not evaluated
    again). Last, what computes each free parameter's σ as the run does there
    (:func:`_propagated`). ``x0``: where the fit starts (the start's)."""
    fns, start = d.fns, d.start
    windows = _judged(d)
    if windows.n_residuals < fns.n_free:
        return None
    binder = _binder(d, windows.n_residuals)
    try:
        evaluator = binder.evaluate(windows)
        _, x, converged = binder.fit(evaluator, start.x0 if x0 is None else x0)
        if not np.all(np.isfinite(x)):
            return None
        # The fit's own normal equations at its optimum are the windows' information there.
        whole = evaluator.normal_equations(x)
        _, s, weight = evaluator.robust_terms(x)
    except (NlpCalibError, np.linalg.LinAlgError, ValueError, ArithmeticError):
        return None
    info = det.of_terms(fns, windows, omega, (whole.H, whole.g, whole.cost), s, weight)
    if not np.isfinite(info.chi2) or not np.all(np.isfinite(info.H)):
        return None
    if not converged:
        return _stalled(d, omega, x, info)
    words = f"{d.start_words}, fitted to convergence on the windows judged"
    sigma = functools.partial(_propagated, d, binder, x, windows, (evaluator, whole))
    return np.asarray(x, dtype=float), info, words, sigma


def _stalled(d: Drive, omega: np.ndarray, x: np.ndarray, info: det.Information) -> Stalled | None:
    """:class:`Stalled` where the fit that ended at ``x`` (the windows' information there:
    ``info``) stopped on a singular normal matrix, else None."""
    if not is_singular(info.H):
        return None
    sigma2, _ = det.noise(d.fns, [p.log for p in d.parts], omega, info, "the fit's end")
    found = directions(info.H, sigma2, scales(d.fns, x), info.n_windows, info.motion2)
    free = not_observable(found)
    if not free.any():  # the solver's own rank test: the directions it calls singular
        free = singular_share(info.H) > IN_DIRECTION
    return Stalled(np.asarray(free))


def _binder(d: Drive, n_windows: int) -> Binder:
    """The run's internal fit of ``d``'s problem on ``n_windows`` windows (robust kernel, bounds,
    no priors)."""
    fns, start, sc = d.fns, d.start, d.scenario
    box = None if start.lower is None or start.upper is None else (start.lower, start.upper)
    records = n_windows * sc.objective.residual.stride
    backend = d.backend or prepare_backend(sc, fns, [INTERNAL_SOLVER], records)
    return Binder(sc, fns, backend, start.x_fixed, no_priors(fns.n_free), bounds=box)


def _as_the_run_aligns(
    d: Drive, omega: np.ndarray, found: LagEstimate | None = None
) -> tuple[Drive, Fitted | Stalled | None] | None:
    """One log whose time offset is fitted: the lag found by the run's own alignment
    (:func:`~nlp_calib.pipeline.align.estimate_tracker_lag`: re-sampled until it stays, then the
    other valleys of its profile), the encoders re-sampled there and the fit from the start with
    that lag, as the run's fit stage starts. Along a direction the drive barely holds the fit
    stops where the lag sends it (a car's rear track near zero or at its length, on encoders
    re-sampled 1 ms apart): the run's lag is where the run's fit stops. ``found``: the run's own
    estimate where the run has searched already (inside ``run``: on the screened log it fits), else
    searched here on the log as read. None where the problem has several logs or no free time
    offset, or no fit converged at any lag."""
    clocks = _clocks(d)
    if len(d.parts) != 1 or len(clocks) != 1:
        return None
    part, column = d.parts[0], clocks[0][0]
    try:
        found = (
            found
            if found is not None
            else estimate_tracker_lag(
                _binder(d, d.data.n_residuals), d.read[0], part.start, part.stop, d.start.x0
            )
        )
    except (NlpCalibError, np.linalg.LinAlgError, ValueError, ArithmeticError):
        return None
    if not found.converged:
        return None
    x0 = np.array(d.start.x0, dtype=float)
    x0[column] = found.lag_s
    moved = replace(_resampled(d, x0), lags={d.fns.free[column]: found})
    fitted = _fitted(moved, omega, x0)
    if not isinstance(fitted, tuple):
        return moved, fitted
    return moved, (
        fitted[0],
        fitted[1],
        f"{fitted[2]}, the encoders re-sampled at the lag the run finds",
        fitted[3],
    )


def _clocks(d: Drive) -> list[tuple[int, list[int]]]:
    """Each free time offset's place among the free parameters and the logs it re-samples (a
    shared one: every log)."""
    fns, every = d.fns, list(range(len(d.parts)))
    return [
        (i, every if (log := fns.layout.param(n).log) is None else [log])
        for i, n in enumerate(fns.free)
        if fns.layout.in_block(n, CLOCK)
    ]


def _resampled(d: Drive, x: np.ndarray) -> Drive:
    """``d`` with each log's encoders re-sampled at its time offset in the free ``x`` (from the log
    as read: a re-sampling adds to a log's own) and its windows rebuilt on the records they stay
    valid for."""
    lags: dict[int, dict[str, float]] = {}
    for i, logs in _clocks(d):
        for log in logs:
            lags.setdefault(log, {})[d.fns.layout.param(d.fns.free[i]).key] = float(x[i])
    clocks = d.fns.sensor.clocks
    parts = list(d.parts)
    for log, own in lags.items():
        p, read = parts[log], d.read[log]
        # Each sensor's records at its own clock's offset (a gyro's beside the reference).
        lag = own.get(clocks[0], next(iter(own.values())))
        beside = own[clocks[1]] - lag if len(clocks) > 1 and len(own) > 1 else None
        kinds = p.model.encoder_kinds
        shifted, (a, b) = resample_encoders(read, lag - read.encoder_lag_s, kinds, beside_lag_s=beside)
        parts[log] = replace(p, log=shifted, start=max(d.parts[log].start, a), split=min(p.split, b))
    data = build_residual_data(
        d.fns,
        [p.log.select(p.start, p.split) for p in parts],
        d.scenario.objective.residual,
        drop_stationary=d.scenario.log.samples.drop_stationary,
        gaps=_gaps(parts),
    )
    return replace(d, parts=tuple(parts), data=data)


def _gaps(parts: Sequence[PreparedLog]) -> np.ndarray | None:
    """The intervals of the logs' fitted records end to end that are gaps in time (and the
    junctions between logs, which no window crosses anyway): as a run's windows, the pre-flight's
    never cross one (a window over a car's 21 s without GNSS moves 300 m, and the mean motion it
    inflates is what the fidelity floor of a free direction scales with). None: no gap."""
    if all(p.gaps is None or not p.gaps[p.start : p.split - 1].any() for p in parts):
        return None
    masks = []
    for i, p in enumerate(parts):
        n = p.split - p.start - 1
        masks.append(
            np.zeros(n, dtype=bool) if p.gaps is None else np.asarray(p.gaps[p.start : p.split - 1], bool)
        )
        if i < len(parts) - 1:
            masks.append(np.zeros(1, dtype=bool))
    return np.concatenate(masks)


def _read_at(d: Drive, column: int, log: int) -> float:
    """The offset log ``log``'s encoders are read at for the clock of free parameter ``column`` (a
    second sensor's: the reference's and its own over it)."""
    clock = d.parts[log].log.clock
    clocks = d.fns.sensor.clocks
    second = len(clocks) > 1 and d.fns.layout.param(d.fns.free[column]).key == clocks[1]
    return clock.encoder_lag_s + (clock.beside_lag_s if second else 0.0)


def _aligned(
    d: Drive, omega: np.ndarray, fitted: Fitted | Stalled | None
) -> tuple[Drive, Fitted | Stalled | None]:
    """The fit on the encoders re-sampled at its own time offsets until each stays
    (:func:`~nlp_calib.pipeline.align.stays`), as the run's alignment re-samples them (the clock
    correction is exact only to first order away from the lag the encoders were re-sampled at):
    for several logs, whose run aligns each log on its own before their joint fit. Each fit starts
    at the start, its time offsets where the encoders were re-sampled. ``fitted``: the fit on the
    encoders as read."""
    clocks = _clocks(d)
    for _ in range(MAX_RESAMPLINGS if clocks else 0):
        if not isinstance(fitted, tuple):
            break
        x, info = fitted[0], fitted[1]
        sigma2 = info.chi2 / max(d.fns.error_rows * info.n_windows - d.fns.n_free, 1)
        at = [_read_at(d, i, logs[0]) for i, logs in clocks]
        if all(stays(float(x[i]) - a, white_std(info.H, sigma2, i)) for (i, _), a in zip(clocks, at)):
            break
        moved = _resampled(d, x)
        # From the start, its time offsets where the encoders now are, as the run's fit starts.
        x0 = np.array(d.start.x0, dtype=float)
        x0[[i for i, _ in clocks]] = x[[i for i, _ in clocks]]
        again = _fitted(moved, omega, x0)
        if not isinstance(again, tuple):
            break
        d, fitted = moved, (again[0], again[1], f"{again[2]} re-sampled at its time offset", again[3])
    return d, fitted


def _propagated(
    d: Drive,
    binder: Binder,
    x: np.ndarray,
    windows: ResidualData,
    fitted: tuple[ProblemEvaluator, NormalEquations],
) -> np.ndarray:
    """Each free parameter's σ at the converged ``x`` as the run computes the σ to believe: the
    tracker's noise propagated through the windows that share its poses and the encoders' own (a
    pose tracker's noise telescopes along a chain of windows, which white residuals do not say),
    or the jackknife of ``validation.blocks`` folds each without one block of windows (the
    cross-validation's folds, from the normal equations at ``x`` less the block's) where it
    exceeds that beyond its own noise (errors that vary along the drive); NaN where it cannot.
    ``fitted``: the fit's evaluator of ``windows`` and its normal equations at ``x``."""
    fns = d.fns
    noise = np.max([p.model.input_noise_std(p.log, d.scenario.data.encoder_noise) for p in d.parts], axis=0)
    bounds = range_std(d.start.lower, d.start.upper, fns.n_free)
    evaluator, whole = fitted
    try:
        counted = counted_inputs(d.parts[0].model, d.parts[0].log)
        found = unc.estimate(evaluator, x, windows, noise, bounds, counted)
    except (NlpCalibError, np.linalg.LinAlgError, ValueError, ArithmeticError):
        return np.full(fns.n_free, np.nan)
    white = found.std
    k = min(d.scenario.validation.blocks, windows.n_residuals)
    spread = np.full(len(fns.names), np.nan)
    if k:
        folds = on_threads(functools.partial(_fold, binder, x, windows, whole), _blocks(windows, k))
        spread = combine(fns.names, folds).beyond(white)
    std = dict(zip(fns.names, believed_std(white, *found.spreads(), spread)))
    return np.array([std.get(n, np.nan) for n in fns.free], dtype=float)


def _blocks(windows: ResidualData, k: int) -> list[np.ndarray]:
    """``k`` blocks of the windows, each the ``j``-th contiguous stretch of every log's (a fold
    without one log's whole stretch would leave that log's own parameters, its lag, free)."""
    log = windows.log_of(windows.starts)
    parts = [np.array_split(np.flatnonzero(log == i), k) for i in np.unique(log)]
    return [np.concatenate([p[j] for p in parts]) for j in range(k)]


def _fold(
    binder: Binder, x: np.ndarray, windows: ResidualData, whole: NormalEquations, block: np.ndarray
) -> Fold:
    """The fold without the windows ``block``, as a cross-validation fold (no scores): the folds'
    own (:func:`~nlp_calib.pipeline.validation.leave_out`), from the fit's normal equations
    ``whole`` at ``x`` less the block's."""
    crossing = np.zeros(windows.n_residuals, dtype=bool)
    crossing[block] = True
    try:
        params, converged, _, left = leave_out(binder, windows, crossing, x, whole)
        if left is not None:
            left.release()
    except (NlpCalibError, np.linalg.LinAlgError, ValueError, ArithmeticError):
        params, converged = np.asarray(binder.fns.assemble(x, binder.x_fixed)).ravel(), False
    first, stop = (int(block.min()), int(block.max()) + 1) if block.size else (0, 0)
    return Fold(first, stop, params, bool(converged) and bool(np.all(np.isfinite(params))), None)


def _needed(d: Drive, x: np.ndarray) -> np.ndarray:
    """What the run's verdict will need of each free parameter at ``x`` on this drive: the
    precision of its layout as the run sets it from each log's drive at the start's values (an
    offset's from the drive's speed, a clock offset's from the sensor's own), the tightest of the
    logs' (:mod:`nlp_calib.analysis.precision`)."""
    fns = d.fns
    layout = fit_info(d.scenario, fns).layout
    params = np.array([d.start.initial[n] for n in fns.names], dtype=float)
    logs = []
    for i, p in enumerate(d.parts):
        log = p.log.select(p.start, p.split)
        inputs = p.model.inputs(log, p.scenario.objective.residual.steering_sample)
        logs.append(log_precision(layout, fns, fns.view(params, i), inputs, np.asarray(log.time_s), log, i))
    layout = tightest(layout, logs) if len(logs) > 1 else logs[0]
    return np.array([layout.param(n).needed(float(v)) for n, v in zip(fns.free, x)])


def _omega(d: Drive) -> np.ndarray:
    """The information weights of an error's rows in ``d``'s problem."""
    return np.array(d.scenario.objective.information.omega(d.fns.error_rows, d.fns.sensor.weights))


@dataclass(frozen=True)
class Assessment:
    """What the pre-flight judges the parameters from: the drive (:class:`Drive`) and the
    parameters the run would hold, the point the Jacobian is taken at (free ``x``, in words
    ``where``), the windows' information there, the residuals' variance it assumes (``noise`` in
    words) and the bounds' 1σ."""

    drive: Drive
    held: Mapping[str, str]
    x: np.ndarray
    where: str
    info: det.Information
    sigma2: float
    noise: str
    bounds_std: np.ndarray
    #: Each free parameter's σ at ``x`` as the run computes it, where the run's internal solver
    #: converged on the judged windows (None: it did not, ``x`` is a rough start, or not computed
    #: yet: :attr:`pending`; NaN: no σ).
    propagated: np.ndarray | None = None
    #: What the run's verdict will need of each free parameter (None: the model's references).
    needed: np.ndarray | None = None
    #: How the run's internal solver ended on the judged windows: True, converged (``x``: its
    #: fit); :class:`Stalled`, on a singular normal matrix (``x``: the rough start); False, else.
    ended: bool | Stalled = False
    #: What computes ``propagated`` and ``needed`` where they are not computed yet (None: they
    #: are): whether a run stops needs neither (:func:`stops`).
    pending: Callable[[], tuple[np.ndarray | None, np.ndarray, Mapping[str, LagEstimate]]] | None = None

    @property
    def converged(self) -> bool:
        """Whether the run's internal solver converged on the judged windows (``x``: its fit)."""
        return self.ended is True

    @property
    def omega(self) -> np.ndarray:
        """The information weights of an error's rows."""
        return _omega(self.drive)

    @property
    def delta(self) -> float:
        """The robust kernel's threshold."""
        return self.drive.scenario.objective.robust.delta

    def completed(self) -> Assessment:
        """This assessment with its σ to believe and the needed precisions computed."""
        if self.pending is None:
            return self
        propagated, needed, lags = self.pending()
        drive = replace(self.drive, lags=lags)
        return replace(self, drive=drive, propagated=propagated, needed=needed, pending=None)

    def fitted(self) -> dict[str, float] | None:
        """Every parameter where the fit converged (None: it did not)."""
        if not self.converged:
            return None
        fns = self.drive.fns
        return dict(zip(fns.names, np.asarray(fns.assemble(self.x, self.drive.start.x_fixed)).ravel()))

    def misplaced(self, white: np.ndarray) -> np.ndarray:
        """Which free parameters the converged fit puts outside what the model can have, known so
        loosely (``white``: their white-noise σ, which the gate has too) that the model's range is
        within :data:`~nlp_calib.analysis.verdict.RANGE_SIGMAS` of them: a weak direction's stop,
        which the run's verdict calls not determined (a wheel's gain negative on one circle one way
        reads as its encoder mirrored, 9.9σ off the truth), not a value."""
        fitted = self.fitted()
        if fitted is None:
            return np.zeros(len(white), dtype=bool)
        ranges = self.drive.fns.model.physical_ranges
        out = []
        for name, std in zip(self.drive.fns.free, white):
            lo, hi = ranges.get(name, (-np.inf, np.inf))
            v, reach = fitted[name], RANGE_SIGMAS * std
            out.append(
                not lo <= v <= hi and (not np.isfinite(reach) or (v + reach >= lo and v - reach <= hi))
            )
        return np.array(out, dtype=bool)

    def standing(self, info: det.Information | None = None) -> det.Standing:
        """Each free parameter's standing on these windows (or on those whose information is ``info``)."""
        d = self.drive
        st = det.standing(d.fns, info or self.info, self.sigma2, self.x, self.bounds_std)
        if info is not None:
            return st
        free = self.ended.undetermined if isinstance(self.ended, Stalled) else self.misplaced(st.std)
        if free.any():  # not determined where the run's fit stops: no σ holds them
            st = replace(st, undetermined=st.undetermined | free, std=np.where(free, np.inf, st.std))
        # One σ and one needed precision with the run's: the white σ says what the drive leaves
        # free, the run's how well the rest is known, against what the run's verdict needs.
        std = st.std
        if self.propagated is not None:
            std = np.where(np.isfinite(st.std) & np.isfinite(self.propagated), self.propagated, st.std)
        std = _returned(d, st.std, std)
        needed = st.reference if self.needed is None else self.needed
        # Not determined as the run's verdict says it (its observability's directions, in the
        # reference units at the start both share); weak against what the verdict needs.
        return det.believed(replace(st, std=std, std_reference=std / needed, reference=needed))


def _returned(d: Drive, white: np.ndarray, std: np.ndarray) -> np.ndarray:
    """``std`` with each time offset whose run's fits re-sampled off it take back only part of the
    offset at its white σ (``white``) over that share where larger, as the run's σ
    (:meth:`~nlp_calib.results.checks.LagEstimate.returned_std`)."""
    out = np.array(std, dtype=float)
    for name, est in d.lags.items():
        i = d.fns.free.index(name)
        wide = est.returned_std(float(white[i]))
        if np.isfinite(wide) and np.isfinite(out[i]):
            out[i] = max(out[i], wide)
    return out


def _held_lags(
    statuses: Sequence[ParameterStatus], lags: Mapping[str, LagEstimate]
) -> tuple[ParameterStatus, ...]:
    """``statuses`` with each time offset the run holds with no σ (its alignment's estimate
    pinned: on its search's edge, or not determined by the drive, :attr:`LagEstimate.loose`)
    held as the run holds it: a caveat of the run's verdict, not a σ. One the drive leaves free
    anyway stays not determined."""
    out = []
    for s in statuses:
        est = lags.get(s.name)
        if est is None or not est.pinned or s.status == NOT_DETERMINED:
            out.append(s)
            continue
        because = lag_held(est)
        out.append(
            replace(
                s,
                status=NOT_DETERMINED,
                std=np.inf,
                std_reference=np.inf,
                trades_with=(),
                because=because,
                held=True,
            )
        )
    return tuple(out)


def assess(
    sc: Scenario,
    logs: Sequence[Log] | None = None,
    found: LagEstimate | None = None,
    complete: bool = True,
    run: Aligned | None = None,
) -> Assessment:
    """The drive of ``sc`` prepared and its Jacobian evaluated at the start brought to the data
    (``found``: the run's own lag estimate, where it has one; ``complete``: with the σ to believe
    and the needed precisions, else left :attr:`~Assessment.pending`; ``run``: a one-log run's
    stages before its windows are bound, whose prepared log and backend it judges with)."""
    d, held = drive(sc, logs, run)
    fns = d.fns
    omega = _omega(d)
    aligned = _as_the_run_aligns(d, omega, found)
    d, ended = aligned if aligned is not None else _aligned(d, omega, _fitted(d, omega))
    fitted = ended if isinstance(ended, tuple) else None
    x, info, where = fitted[:3] if fitted is not None else _rough(d, omega)
    if isinstance(ended, Stalled):
        where += "; the run's solver, fitted from it, stops on a singular normal matrix"
    at = "the fit" if fitted is not None else "the start"
    sigma2, noise = det.noise(fns, [p.log for p in d.parts], omega, info, at)
    if fitted is not None:
        noise += (
            "; each σ as the run computes the σ to believe (the tracker's noise propagated through the "
            "windows, or the blocks' jackknife where larger)"
        )
    bounds = range_std(d.start.lower, d.start.upper, fns.n_free)
    sigma = fitted[3] if fitted is not None else None

    def pending() -> tuple[np.ndarray | None, np.ndarray, Mapping[str, LagEstimate]]:
        return (sigma() if sigma is not None else None), _needed(d, x), _own_lags(sc, logs, d)

    state = ended if isinstance(ended, Stalled) else fitted is not None
    a = Assessment(d, held, x, where, info, sigma2, noise, bounds, ended=state, pending=pending)
    return a.completed() if complete else a


def _own_lags(sc: Scenario, logs: Sequence[Log] | None, d: Drive) -> Mapping[str, LagEstimate]:
    """Each log's own free time offset with the estimate the run's alignment finds on that log alone
    (several logs: the run aligns each before their joint fit, and holds, or widens the σ of, a lag
    its return check finds loose; one log: the estimate the pre-flight fitted at). Whether the
    pre-flight stops a run needs none (a held lag is no parameter the run cannot determine), so
    they are searched only for the full report. ``logs``: the logs as read (None: from their
    sources)."""
    if len(d.parts) < 2:
        return d.lags
    per_log, out = sc.per_log(), {}
    for i, own in _clocks(d):
        if len(own) != 1:  # one offset shared by every log: no one log's alignment holds it
            continue
        k = own[0]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the run says what its alignment says
                one, _ = drive(per_log[k], None if logs is None else [logs[k]])
                part = one.parts[0]
                if len(_clocks(one)) != 1:
                    continue
                binder = _binder(one, one.data.n_residuals)
                est = estimate_tracker_lag(binder, one.read[0], part.start, part.stop, one.start.x0)
        except (NlpCalibError, np.linalg.LinAlgError, ValueError, ArithmeticError):
            continue
        if est.converged:
            out[d.fns.free[i]] = est
    return out


#: A pre-flight check: what the pre-flight assessed (the drive, the fit where one converged) to a
#: result, or None when it has nothing to say; one at :data:`~nlp_calib.results.checks.UNUSABLE`
#: stops a run before any fit, in its reasons.
PreflightCheck = Callable[[Assessment], "CheckResult | None"]

#: The pre-flight's plug-in checks, by name, in the order its report names them.
PREFLIGHT_CHECKS: dict[str, PreflightCheck] = {
    units_check.NAME: lambda a: units_check.check(
        a.drive.parts, a.drive.fns, a.drive.start.initial, a.fitted()
    ),
    slip_check.NAME: lambda a: slip_check.ahead(
        a.drive.fns, a.drive.data, a.fitted() or _values(a.drive.fns, a.x, a.drive.start.x_fixed)
    ),
}


def preflight_checks(assessed: Assessment) -> tuple[CheckResult, ...]:
    """Every registered pre-flight check's result (those with something to say)."""
    found = (check(assessed) for check in PREFLIGHT_CHECKS.values())
    return tuple(r for r in found if r is not None)


def preflight(sc: Scenario, logs: Sequence[Log] | None = None, found: LagEstimate | None = None) -> Preflight:
    """The pre-flight check of ``sc`` (its logs read from their sources unless given; ``found``: the
    run's own lag estimate, where the run has searched already). One log whose lag is fitted goes
    through the run's own stages first (prepared, screened, its lag searched on the screened log:
    :func:`~nlp_calib.pipeline.stages.align_log`), as a run's pre-flight does: a lag searched on
    the log as read settles elsewhere where the screen leaves windows out (a real car's gaps and
    faults: held at 20.8 ms against the run's 45 ± 31 ms)."""
    t0 = time.perf_counter()
    run = _run_stages(sc, logs) if found is None else None
    found = found if run is None else run.alignment.estimate
    return _report(sc, assess(sc, logs, found, run=run), t0)


def _run_stages(sc: Scenario, logs: Sequence[Log] | None) -> Aligned | None:
    """A one-log scenario's run stages before its windows are bound, where its lag is fitted (None:
    several logs, a lag given, or stages that fail: the pre-flight then prepares and searches its
    own, and says what fails in its own words)."""
    if sc.data.joint or sc.log.alignment.tracker_lag != "auto":
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the run says what its stages say
            run = align_log(sc, None if logs is None else logs[0], tuple(sc.solvers))
    except Exception:  # the pre-flight reports on inputs a run would refuse: in its own words
        return None
    return run if run.alignment.estimate is not None else None


def stops(
    sc: Scenario,
    logs: Sequence[Log] | None = None,
    found: LagEstimate | None = None,
    run: Aligned | None = None,
) -> Preflight | None:
    """The pre-flight's report (:func:`preflight`'s) where it stops a calibration of ``sc``, else
    None. Whether it stops needs neither the σ to believe (the jackknife's refits, the noise
    propagated over every record) nor the needed precisions nor the plan: a parameter is not
    determined by the drive's directions and a blocking finding is the units check's, at the fit.
    So those are computed only where it stops, once: a run that goes on computes its own.
    ``run``: a one-log run's stages before its windows are bound (:func:`assess`)."""
    t0 = time.perf_counter()
    a = assess(sc, logs, found, complete=False, run=run)
    if not _report(sc, a, t0, ahead=False).stop_words():
        return None
    return _report(sc, a.completed(), t0)


def _report(sc: Scenario, a: Assessment, t0: float, ahead: bool = True) -> Preflight:
    """The pre-flight's report of ``sc`` from what it assessed (``ahead``: with the plan where a
    parameter is loose; ``t0``: when it started)."""
    d = a.drive
    fns, one = d.fns, d.scenario
    exs = []
    for p in d.parts:
        steering = p.scenario.objective.residual.steering_sample
        exs.append(of_log(p.log.select(p.start, p.split), fns.sensor, p.model, steering))
    units = fit_info(one, fns).units
    standing = a.standing()
    statuses = _held_lags(det.statuses(fns, standing, a.held, units, combined(exs)), d.lags)
    loose = [s.name for s in statuses if s.status in (NOT_DETERMINED, WEAKLY) and not s.held]
    plan_ahead = None
    if loose and ahead:
        point = (a.x, d.start.x_fixed, a.omega)
        residual = one.objective.residual
        setting = Setting(
            fns, d.data, a.info, point, a.sigma2, a.bounds_std, residual, a.delta, units, a.where
        )
        plan_ahead = plan(replace(setting, steer_max=one.parameters.vehicle.steer_max))
        # The plan's σ of its target as the statuses state it (the run's σ where the fit converged).
        plan_ahead = believed(plan_ahead, dict(zip(standing.names, map(float, standing.std))))
    return Preflight(
        scenario=sc.name,
        model=sc.model,
        recordings=tuple(recording(p.scenario, p.log) for p in d.parts),
        excitation=tuple(exs),
        checks=preflight_checks(a),
        parameters=statuses,
        start=a.where,
        noise=a.noise,
        plan=plan_ahead,
        way_out=_way_out(fns, statuses, loose, _values(fns, a.x, d.start.x_fixed), combined(exs))
        if loose
        else "",
        time_s=time.perf_counter() - t0,
    )


def _way_out(
    fns: ProblemFunctions,
    statuses: Sequence[ParameterStatus],
    loose: list[str],
    values: dict[str, float],
    ex: Excitation | None,
) -> str:
    """The way out for the loose parameters the verdict refuses for: those not determined when any
    is (a weakly determined lag beside them would turn the advice to the clocks), else the loosest
    weakly determined one (its σ over the precision it needs) and those it trades off with (a lag
    at 53× its needed precision beside two kinematic parameters that traded at 120× had the advice
    give the lag only); on
    a drive that already turns both ways (:func:`turns_both_ways`), not "turn more"."""
    undetermined = [s.name for s in statuses if s.name in loose and s.status == NOT_DETERMINED]
    weak = [s for s in statuses if s.name in loose and np.isfinite(s.std_reference)]
    if not undetermined and weak:
        worst = max(weak, key=lambda s: s.std_reference)
        group = {worst.name, *worst.trades_with}
        undetermined = [s.name for s in statuses if s.name in loose and s.name in group]
    return way_out(undetermined or loose, fns.model, fns.layout, fns.sensor, values, turns_both_ways(ex))


def _values(fns: ProblemFunctions, x: np.ndarray, x_fixed: np.ndarray) -> dict[str, float]:
    """Every parameter's value at the free ``x`` and the fixed ``x_fixed``."""
    return {**dict(zip(fns.free, map(float, x))), **dict(zip(fns.fixed, map(float, x_fixed)))}


def refuse(report: Preflight, hint: str = "") -> None:
    """Stop a calibration that cannot succeed (a unit or sign the data get wrong, a parameter the
    drive does not determine) with the pre-flight's words (and ``hint``)."""
    words = report.stop_words()
    if words:
        raise PreflightError(f"pre-flight: {report.scenario}: {words}{hint}", report.exit_code)
