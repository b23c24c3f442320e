"""A calibration as named stages: prepare, build, screen, align, bind, fit, analyse, assemble.

Each log goes through the stages before the fit on its own (:func:`setup_log`): its records are
read and selected once, the problem is built, faults are screened, the tracker lag is estimated,
and its windows are bound. The fit then binds one evaluator to the windows of one log or of several
laid end to end (one :class:`Calibration` either way: one log is N = 1), every solver runs on it,
and the same analyse and assemble stages turn the estimates into one self-contained
:class:`~nlp_calib.results.CalibrationRun` (over several logs, with each log's run in its
``logs``).
"""

from __future__ import annotations

import dataclasses
import itertools
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from nlp_calib.analysis.consistency import compare_logs, determined
from nlp_calib.analysis.precision import clock_needed, log_precision, tightest, with_clocks
from nlp_calib.core import memory
from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.core.said import each_once, kept
from nlp_calib.logs import Log
from nlp_calib.logs.resample import Resampler, speeds_read
from nlp_calib.models import KinematicModel, reference_scales
from nlp_calib.pipeline import consistency_check, validation
from nlp_calib.pipeline.align import Alignment
from nlp_calib.pipeline.analyse import (
    RELEASE_FROM,
    FitAnalysis,
    LogAnalysis,
    LogView,
    Scorer,
    Scores,
    Wanted,
    analyse_fit,
    analyse_log,
    log_scorer,
    logs_crossval,
    plan_after,
    scores,
)
from nlp_calib.pipeline.assemble import (
    MountViews,
    assemble_run,
    bias_notes,
    fit_info,
    fit_notes,
    joint_run,
    pinned_alike,
)
from nlp_calib.pipeline.build import Problem, StartingPoint, build_stage, mount_count, restarted
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.prepare import joint_residual
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.pipeline.stages import Aligned, LogSetup, setup_log
from nlp_calib.pipeline.stored import StoredCalibration
from nlp_calib.pipeline.windows import LogWindows
from nlp_calib.problem import ProblemFunctions, ResidualData, joined
from nlp_calib.problem.blocks import per_log_kinds
from nlp_calib.results import CalibrationRun, ScenarioInfo, SolverResult
from nlp_calib.results.checks import WEAK, ConsistencyCheck, CrossValidation, PivotSpread
from nlp_calib.results.faults import Findings
from nlp_calib.sensors import sensor_for
from nlp_calib.solvers import ProblemEvaluator
from nlp_calib.solvers.backends import Backend


def _joined(pieces: Sequence[np.ndarray], joint: bool) -> np.ndarray:
    """Per-log masks end to end, with ``joint`` for the interval joining one log to the next."""
    out: list[np.ndarray] = []
    for i, piece in enumerate(pieces):
        if i:
            out.append(np.array([joint]))
        out.append(piece)
    return np.concatenate(out)


def blocks_scorer(fns: ProblemFunctions, parts: Sequence[LogSetup], data: ResidualData) -> Scorer:
    """The scorer of validation blocks over the fitted records of ``parts`` end to end; the joining
    interval counts as a fault, so dead reckoning restarts at each log's start."""
    sc = parts[0].prepared.scenario
    W = sc.validation.rpe_window
    if len(parts) == 1:
        return log_scorer(fns, parts[0].windows, sc.objective.residual.steering_sample, W)
    intervals = [p.windows.bad_intervals[p.fit[0] : p.fit[1] - 1] for p in parts]
    records = [p.windows.bad_records[p.fit[0] : p.fit[1]] for p in parts]
    breaks = [p.windows.breaks_between(*p.fit) for p in parts]
    logs = data.log_of(np.arange(data.inputs.shape[1]))  # each interval's mount, with one per log
    masks = (_joined(intervals, True), _joined(records, False))
    return Scorer(fns, data.inputs, data.T_world_sensor, *masks, 0, W, logs, _joined(breaks, True))


class Calibration:
    """A scenario through the stages up to the fit, ready to solve with any solver: its log, or
    with ``datasets`` each log set up on its own (its samples, faults and lag), then their windows
    laid end to end and fitted together (no window crosses from one log into the next).

    :meth:`run` fits with each solver, analyses and assembles the result.
    """

    def __init__(
        self,
        scenario: Scenario,
        log: Log | Sequence[Log] | None = None,
        solvers: Sequence[str] | None = None,
        aligned: Aligned | None = None,
        start: Mapping[str, float] | None = None,
    ) -> None:
        """``log``: the log already read (with ``datasets``: one per entry), or None to read;
        ``aligned``: one log's stages before its windows are bound, done already; ``start``: the
        values the fit starts from instead of the scenario's (a stored calibration's, for a
        check), every stage before the fit done as a run of the scenario does it."""
        t0 = time.perf_counter()
        self.scenario = sc = scenario
        self.solvers = tuple(solvers or sc.solvers)
        per_log = sc.per_log() if sc.data.joint else (sc,)
        given = [log] if isinstance(log, Log) else list(log) if log is not None else [None] * len(per_log)
        assert aligned is None or len(per_log) == 1, "stages done already are one log's"
        with kept() as said:
            self.parts = [setup_log(s, log, self.solvers, aligned, start) for s, log in zip(per_log, given)]
            self.stages = self.parts[0]
            self.held, self.fitting = self._fitting(start)
        # What reading the logs and the stages before the fit warned of, done here or before.
        self.said = each_once(*(p.said for p in self.parts), said)
        self.setup_time_s = time.perf_counter() - t0

    def _fitting(self, start: Mapping[str, float] | None) -> tuple[Mapping[str, str], Fit]:
        """The parameters the fit holds, with why, and the fit of the set-up logs."""
        if len(self.parts) > 1:
            return _joint_fit(self.scenario, self.parts, self.solvers, start)
        windows = self.stages.windows
        fit = fit_of(self.stages.problem, windows.data, self.solvers, windows.input_noise, self.parts)
        return self.stages.prepared.held, fit

    @classmethod
    def setup(
        cls,
        scenario: Scenario,
        data: str | Path | None = None,
        log: Log | None = None,
        solvers: Sequence[str] | None = None,
        logs: Sequence[Log] | None = None,
    ) -> Calibration:
        """Build everything ``scenario`` needs (``data`` replaces its log path; ``log``, already read,
        replaces reading it, and ``logs`` each of its ``datasets``; ``solvers``, the ones to get
        ready, the scenario's)."""
        return cls(scenario.with_dataset(data) if data is not None else scenario, logs or log, solvers)

    @property
    def model(self) -> KinematicModel:
        return self.fitting.fns.model

    @property
    def log(self) -> Log:
        """The (first) log as read."""
        return self.stages.prepared.log

    @property
    def alignment(self) -> Alignment:
        return self.stages.alignment

    @property
    def findings(self) -> Findings:
        return self.stages.screening.findings

    @property
    def aligned(self) -> Log:
        """The (first) log with the encoders re-sampled on the tracker's clock."""
        return self.stages.windows.aligned

    @property
    def used(self) -> tuple[int, int]:
        return self.stages.windows.used

    @property
    def fit(self) -> tuple[int, int]:
        return self.stages.windows.fit

    @property
    def fns(self) -> ProblemFunctions:
        return self.fitting.fns

    @property
    def data(self) -> ResidualData:
        return self.fitting.data

    @property
    def evaluator(self) -> ProblemEvaluator:
        return self.fitting.evaluator

    @property
    def initial(self) -> Mapping[str, float]:
        """The starting values of every parameter."""
        return self.fitting.problem.start.initial

    @property
    def backend(self) -> Backend:
        return self.fitting.problem.binder.backend

    @property
    def start(self) -> StartingPoint:
        """Where the solvers start, the fixed values and the bounds."""
        return self.fitting.problem.start

    @property
    def x0(self) -> np.ndarray:
        """The starting values of the free parameters."""
        return self.fitting.problem.start.x0

    def solve(self, solver: str) -> SolverResult:
        """Run one solver from the initial guess; the result is in the model's canonical form."""
        return self.fitting.solve(solver)

    def score(self, params: np.ndarray) -> Scores:
        """Full-range and hold-out trajectory metrics of the full parameter vector ``params`` on
        the (first) log."""
        sc, windows = self.stages.prepared.scenario, self.stages.windows
        scorer = log_scorer(
            self.fns, windows, sc.objective.residual.steering_sample, sc.validation.rpe_window
        )
        return scores(scorer, windows, [params])[0]

    def run(self, solvers: Sequence[str] | None = None, wanted: Wanted | None = None) -> CalibrationRun:
        """Fit with each solver (the scenario's by default), analyse and assemble the result. Over
        several logs: refit without each log in turn, and each log on its own, to check that they
        tell one robot's story; the result is the joint fit scored on every log, with each log's
        run (its figures with the joint estimates) in ``logs``."""
        names = tuple(solvers or self.scenario.solvers)
        with kept() as said:
            if len(self.parts) == 1:
                run = _run(self.scenario, self.fitting, self.parts, names, wanted or Wanted())[2][0]
            else:
                run = _joint_run(self, names, wanted or Wanted())
                # Each log's own result: what reading it and its stages said.
                own = [part.with_said(p.said) for part, p in zip(run.logs, self.parts)]
                run = dataclasses.replace(run, logs=tuple(own))
        # Every warning the run printed is in its result: what setting it up said, then running it.
        return run.with_said(each_once(self.said, said))


def _joint_fit(
    sc: Scenario, parts: Sequence[LogSetup], solvers: Sequence[str], start: Mapping[str, float] | None = None
) -> tuple[dict[str, str], Fit]:
    """The fit of several set-up logs' windows end to end, and the parameters it holds (``start``:
    the values the fit starts from instead of the scenario's, as :class:`Calibration` takes them)."""
    first = parts[0]
    data = joined([p.windows.data for p in parts])
    # A parameter is held only when the logs together do not determine it (two logs that each
    # reverse a little may together reverse enough).
    model = first.prepared.model
    held = {n: why for n, why in model.undetermined(data.inputs).items() if n not in sc.parameters.fixed}
    for name, why in held.items():
        warnings.warn(
            f"{name} is held at its initial value: {why} in the logs' fitted records",
            NlpCalibWarning,
            stacklevel=3,
        )
    n_records = sum(p.fit[1] - p.fit[0] for p in parts)
    start_from = (first.prepared.log, first.used[0], first.fit[1])
    one_horizon = sc.with_options(residual=joint_residual(sc, [p.prepared for p in parts]))
    lags = [p.alignment.lag_s for p in parts]
    # A mount per log: each starts where its log's own start put it; windows say their log.
    mounts = [p.problem.start.initial for p in parts] if mount_count(sc, len(parts)) > 1 else []
    data = data.with_selector() if mounts or per_log_kinds(model, len(parts)) else data
    problem = build_stage(one_horizon, model, tuple(held), start_from, solvers, n_records, lags, mounts, data)
    if start is not None:
        # As each log's (see stages.started): what ``start`` lacks, where the first log's start put it.
        restart = one_horizon.with_options(initial_guess={**first.problem.start.initial, **start})
        problem = restarted(problem, restart, start_from, lags, mounts)
    return held, fit_of(problem, data, solvers, joint_noise(parts), parts)


def _joint_run(calib: Calibration, names: Sequence[str], wanted: Wanted) -> CalibrationRun:
    """:meth:`Calibration.run` over several logs."""
    fitting, parts = calib.fitting, calib.parts
    results, fitted, notes, infos = _fit(fitting, parts, names, calib.held, wanted.against is not None)
    scorer = blocks_scorer(fitting.fns, parts, fitting.data)
    logs = logs_crossval(fitting, results, scorer, log_ranges(parts))
    own = [_own_run(p, names) for p in parts]
    clocks = clock_needed(infos[0].layout)
    check = consistency(results, own, logs, (calib.model, fit_info(calib.scenario, calib.fns)), clocks)
    if check is not None and (check.significant or consistency_check.limits(check)):
        notes.append(consistency_check.words(check))
    fitted = dataclasses.replace(fitted, consistency=check, logs=logs)
    # A stored calibration is checked against the joint fit, not each log's view of it.
    runs = _assemble(
        fitting, parts, (results, infos), fitted, notes, dataclasses.replace(wanted, against=None)
    )
    joint = _joint(fitting, (scorer, parts[0]), runs, results, fitted, (notes, wanted.against))
    return pinned_alike(dataclasses.replace(joint, logs=tuple(runs)))


def log_ranges(parts: Sequence[LogSetup]) -> list[tuple[int, int]]:
    """Each log's fitted records in the joint fit's numbering (the logs end to end)."""
    edges = np.cumsum([0, *(p.fit[1] - p.fit[0] for p in parts)])
    return [(int(a), int(b)) for a, b in itertools.pairwise(edges)]


def _joint(
    fitting: Fit,
    scoring: tuple[Scorer, LogSetup],
    parts: Sequence[CalibrationRun],
    results: Mapping[str, SolverResult],
    fitted: FitAnalysis,
    said: tuple[Sequence[str], StoredCalibration | None],
) -> CalibrationRun:
    """The joint fit as one run, scored over every log's fitted records by ``scoring[0]``, with the
    notes and the stored calibration it checks (``said``)."""
    scorer, first = scoring
    notes, against = said
    start = fitting.problem.start
    p0 = np.array([start.initial[n] for n in fitting.fns.names])
    nominal = [] if fitted.nominal_params is None else [fitted.nominal_params]
    metrics = scorer.each([*(r.params for r in results.values()), p0, *nominal])
    n = len(results)
    figures = LogAnalysis(
        scores={name: (m, None) for name, m in zip(results, metrics)},
        baseline=(metrics[n], None),
        series=None,
        odometry=None,
        nominal=(metrics[n + 1], None) if nominal else None,
    )
    info = fit_info(fitting.problem.binder.scenario, fitting.fns)
    info = dataclasses.replace(info, layout=tightest(info.layout, [run.scenario.layout for run in parts]))
    fit = (first.prepared, start, fitting.data.n_residuals)
    views = MountViews(fitting.fns, 0, tuple((run.scenario.name, run.log) for run in parts))
    return joint_run(info, parts, fit, results, fitted, figures, notes, views, against, fitting)


def _own_run(part: LogSetup, solvers: Sequence[str]) -> CalibrationRun:
    """One log of several fitted on its own (its stages' windows and problem, nothing built again)."""
    fit = fit_of(part.problem, part.windows.data, solvers, part.windows.input_noise, [part])
    return _run(part.prepared.scenario, fit, [part], solvers, Wanted())[2][0]


def fit_of(
    problem: Problem,
    data: ResidualData,
    solvers: Sequence[str],
    noise: tuple[np.ndarray, np.ndarray],
    parts: Sequence[LogSetup],
) -> Fit:
    """The fit of ``data`` with every other reading of ``parts``' logs the held check weighs (a
    given lag's, the speeds', the steer angle's, the re-sampled counts')."""
    readings = (given_lag(parts), read_speeds(parts), read_steering(parts), read_kinked(parts))
    return Fit(problem, data, solvers, noise, *readings)


def consistency(
    results: Mapping[str, SolverResult],
    own: Sequence[CalibrationRun],
    logs: CrossValidation | None,
    model: tuple[KinematicModel, ScenarioInfo],
    clocks: Mapping[str, float],
) -> ConsistencyCheck | None:
    """Each log's own fit (``own``, in the joint fit's order of logs) against the other logs' (the
    folds of ``logs``), for the first solver that converged in the joint fit, on what each log
    determines on its own; ``model``: the model and what the outputs say of the fit (its units and
    parameter layout); ``clocks``: the precision each log's drive needs of its clock offset."""
    solver = next((name for name, r in results.items() if r.converged), None)
    if solver is None or logs is None:
        return None
    result = results[solver]
    names = result.names
    kind, info = model
    nan = np.full(len(names), np.nan)
    estimates, stds = [], []
    for i, run in enumerate(own):
        mine = run.reports.get(solver)
        if mine is None or not mine.result.converged:
            estimates.append(nan)
            stds.append(nan)
            continue
        # Each log's own lag is the joint fit's lag of that log; the other logs' lags it has not.
        own_names = [info.layout.own(n, i) for n in names]
        values, sd = mine.result.param_dict(), run.std(solver)
        estimates.append(np.array([values.get(n, np.nan) for n in own_names]))
        stds.append(np.array([sd.get(n, np.nan) for n in own_names]))
    est, std = np.array(estimates), np.array(stds)
    others = np.array([f.params if f.converged else nan for f in logs.folds])
    sensor = own[0].scenario.sensor
    reference = sensor_for(sensor.kind, sensor.scale).reference
    keys = info.layout.keys(names)

    def needed(values: np.ndarray) -> np.ndarray:
        return with_clocks(reference_scales(kind, keys, values, reference), names, clocks)

    known = np.array([determined(kind, keys, e, sd, reference, needed(e)) for e, sd in zip(est, std)])
    apart = WEAK * needed(result.params)
    paths = [run.log.path for run in own]
    unit = tuple(info.units.get(n, "") for n in names)
    return compare_logs(names, paths, result.params, (est, std), others, known, apart, unit)


def given_lag(parts: Sequence[LogSetup]) -> Callable[[float], np.ndarray] | None:
    """Where every log's tracker lag is given as a number, the fitted windows' interval inputs
    (the logs end to end) with each log's encoders read ``d`` s later than at its lag (None: a lag
    is a parameter of the problem)."""
    if any(p.prepared.scenario.log.alignment.tracker_lag == "auto" for p in parts):
        return None
    # Each aligned log is re-sampled on from its own lag: what ``d`` adds is the offset from it.
    resamplers = [Resampler(p.alignment.log, p.problem.fns.model.encoder_kinds) for p in parts]
    return lambda d: _inputs_of(parts, [r.at(d)[0] for r in resamplers])


def read_speeds(parts: Sequence[LogSetup]) -> Callable[[float], np.ndarray] | None:
    """Where a log's joints were integrated from speeds, the fitted windows' interval inputs (the
    logs end to end) with each speed read as held over the interval after its stamp (``side`` +1)
    or as the mean over the interval before (−1), not sampled at it (None: no log's were)."""
    logs = [p.alignment.log for p in parts]
    if all(lg.joint_stream is None or lg.joint_stream.quadrature is None for lg in logs):
        return None

    return lambda side: _inputs_of(parts, [speeds_read(lg, side) for lg in logs])


def _inputs_of(parts: Sequence[LogSetup], logs: Sequence[Log], sample: str | None = None) -> np.ndarray:
    """The fitted windows' interval inputs of ``parts`` (end to end) read from ``logs``, one each:
    the same logs read another way (re-sampled, speeds read otherwise, each interval's steer angle
    read as ``sample`` rather than the scenario's steering_sample)."""
    data = [
        p.windows.data.with_inputs(p.windows.binder.inputs(lg, *p.windows.fit, sample))
        for p, lg in zip(parts, logs)
    ]
    return data[0].inputs if len(data) == 1 else joined(data).inputs


def read_steering(parts: Sequence[LogSetup]) -> Callable[[str], np.ndarray] | None:
    """Where the model reads a steer angle (an absolute encoder), the fitted windows' interval
    inputs (the logs end to end) with each interval's steer angle read as ``sample`` (a
    ``steering_sample``) instead of the scenario's (None: no steer angle)."""
    model = parts[0].problem.fns.model
    if "absolute" not in model.encoder_kinds.values():
        return None

    logs = [p.alignment.log for p in parts]
    return lambda sample: _inputs_of(parts, logs, sample)


def read_kinked(parts: Sequence[LogSetup]) -> Callable[[], np.ndarray] | None:
    """Where a log's encoder readings were re-sampled between its records (at its lag), the fitted
    windows' interval inputs (the logs end to end) with each such reading less its interpolation's
    expected error where the rate changes inside the interval (:func:`~nlp_calib.logs.resample.kink_error`;
    the other logs' as fitted; None: no log's readings were re-sampled between records)."""
    shifted = [_kinkable(p) for p in parts]
    if not any(shifted):
        return None

    def inputs() -> np.ndarray:
        logs = []
        for p, kinkable in zip(parts, shifted):
            a, kinds = p.alignment, p.problem.fns.model.encoder_kinds
            if kinkable and a.source is not None:
                beside = a.log.clock.beside_lag_s
                logs.append(Resampler(a.source, kinds).at(a.lag_s, beside_lag_s=beside, kinked=True)[0])
            else:
                logs.append(a.log)
        return _inputs_of(parts, logs)

    return inputs


def _kinkable(part: LogSetup) -> bool:
    """Whether ``part``'s encoder readings (counts, angles; not joints re-sampled from their own
    stream) were re-sampled between its records."""
    source = part.alignment.source
    return source is not None and source.joint_stream is None and part.alignment.log is not source


def joint_noise(parts: Sequence[LogSetup]) -> tuple[np.ndarray, np.ndarray]:
    """The inputs' noise of logs fitted together: the largest any has; the counters the model's."""
    return np.max([p.windows.input_noise_std for p in parts], axis=0), parts[0].windows.counted


def _fit(
    fitting: Fit,
    parts: Sequence[LogSetup],
    solvers: Sequence[str],
    held: Mapping[str, str],
    from_estimate: bool = False,
) -> tuple[dict[str, SolverResult], FitAnalysis, list[str], list[ScenarioInfo]]:
    """The fit stage and the fit's analysis over ``parts`` (one log, or several end to end);
    ``held``: the parameters held because the fitted records do not determine them;
    ``from_estimate``: the start is a stored calibration's estimate (:meth:`Fit.solve`). Last,
    what the outputs say of each log's fit (:func:`_part_info`), for its assembly."""
    results = {name: fitting.solve(name, from_estimate) for name in solvers}
    noise = joint_noise(parts)
    info = fit_info(parts[0].prepared.scenario, fitting.fns)
    # The precision each parameter needs: the tightest any log's drive asks (as the joint run's).
    infos = [_part_info(fitting, part, i)[1] for i, part in enumerate(parts)]
    needed = tightest(info.layout, [i.layout for i in infos])
    # Each log's view: every log's clock offset at what that log's drive needs of it.
    infos = [
        dataclasses.replace(i, layout=tightest(i.layout, [o.layout for o in infos], False)) for i in infos
    ]
    fitted = analyse_fit(fitting, results, noise, blocks_scorer(fitting.fns, parts, fitting.data), needed)
    fitted = dataclasses.replace(
        fitted, plan=plan_after(fitting, results, info.units), pivots=_pivots(fitting, parts, results)
    )
    if fitting.data.n_residuals >= RELEASE_FROM:
        # The plan's terms bound the windows again, their last use before the files (a report's
        # series binds them anew): held, they stayed resident through the figures and the writing.
        fitting.evaluator.release()
        memory.give_back()
    white = fitted.uncertainty[solvers[0]]
    notes = fit_notes(results, fitted, held) + bias_notes(
        fitting.bias_taken(), dict(zip(white.names, white.std))
    )
    return results, fitted, notes, infos


def _pivots(
    fitting: Fit, parts: Sequence[LogSetup], results: Mapping[str, SolverResult]
) -> PivotSpread | None:
    """The drive's pivots, each fitted on its own from the first converged estimate, the slipped
    pivots the fit left out among them (each log's windows bound again; see
    :func:`validation.pivot_spread`). Over several logs every log's pivots are one population and
    their records the joint fit's (the logs end to end). None without blocked cross-validation
    (``validation.blocks: 0``: no refits) or without a converged estimate."""
    converged = [r for r in results.values() if r.converged]
    if not converged or not fitting.problem.binder.scenario.validation.blocks:
        return None
    data = fitting.data
    if any(_slipped(p.windows) for p in parts):
        logs = [_with_slipped(p.windows) for p in parts]
        # A joint fit's windows say their log where its problem asks (a mount per log).
        data = logs[0] if len(logs) == 1 else _like(joined(logs), fitting.data)
    offset = parts[0].windows.fit[0] if len(parts) == 1 else 0
    binder = fitting.problem.binder
    return validation.pivot_spread(binder, data, converged[0].x, fitting.canonical_params, offset)


def _like(data: ResidualData, fitted: ResidualData) -> ResidualData:
    """``data`` saying each window's log where the fit's windows ``fitted`` do."""
    return data.with_selector() if fitted.clock is not None else data


def _slipped(windows: LogWindows) -> bool:
    """Whether the fit left out windows over pivots the ground slipped on."""
    ground, bad = windows.ground, windows.binder.bad_intervals
    return ground is not None and bool(ground.any()) and bad is not None


def _with_slipped(windows: LogWindows) -> ResidualData:
    """A log's fitted windows with those over the pivots the ground slipped on bound again."""
    if not _slipped(windows):
        return windows.data
    assert windows.ground is not None and windows.binder.bad_intervals is not None
    binder = dataclasses.replace(windows.binder, bad_intervals=windows.binder.bad_intervals & ~windows.ground)
    return binder.windows(windows.aligned, *windows.fit)


def _assemble(
    fitting: Fit,
    parts: Sequence[LogSetup],
    fits: tuple[Mapping[str, SolverResult], Sequence[ScenarioInfo]],
    fitted: FitAnalysis,
    notes: Sequence[str],
    wanted: Wanted,
) -> list[CalibrationRun]:
    """Each log's figures (analyse) and its run (assemble) with the fit's estimates and checks;
    ``fits``: the solvers' results and what the outputs say of each log's fit (from the fit stage:
    its drive's precision is not computed again)."""
    runs = []
    results, infos = fits
    logs = tuple((p.prepared.scenario.name, p.prepared.log.header) for p in parts)
    for i, part in enumerate(parts):
        scorer, info = _scorer(fitting, part, i), infos[i]
        view = LogView(part.prepared, part.windows, scorer, part.screening.findings, i)
        figures = analyse_log(fitting, results, view, wanted, info.labels, fitted.nominal_params)
        stage = (part.prepared, part.windows, part.alignment, part.screening.findings)
        views = MountViews(fitting.fns, i, logs)
        runs.append(
            assemble_run(
                info,
                stage,
                fitting.problem.start,
                results,
                fitted,
                figures,
                notes,
                views,
                wanted.against,
                fitting,
            )
        )
    return runs


def _scorer(fitting: Fit, part: LogSetup, index: int) -> Scorer:
    """Log ``index``'s scorer over its used records."""
    sc = part.prepared.scenario
    return log_scorer(
        fitting.fns, part.windows, sc.objective.residual.steering_sample, sc.validation.rpe_window, index
    )


def _part_info(fitting: Fit, part: LogSetup, index: int) -> tuple[Scorer, ScenarioInfo]:
    """Log ``index``'s scorer over its used records, and what the outputs say of its fit with the
    precision its drive needs (see :func:`_vehicle_precision`)."""
    sc = part.prepared.scenario
    scorer = _scorer(fitting, part, index)
    info = _vehicle_precision(fit_info(sc, fitting.fns), scorer, part, fitting.problem.start.initial, index)
    return scorer, info


def _vehicle_precision(
    info: ScenarioInfo, scorer: Scorer, part: LogSetup, start: Mapping[str, float], index: int
) -> ScenarioInfo:
    """``info`` with the precision its layout needs on this log's drive (at the start's values;
    the clock offset of log ``index`` from the sensor's own track)."""
    fns = scorer.fns
    view = scorer.viewed(np.array([start[n] for n in fns.names]))
    t = np.asarray(part.windows.selected.time_s)
    layout = log_precision(info.layout, fns, view, scorer.inputs, t, part.prepared.log, index)
    return dataclasses.replace(info, layout=layout)


def _run(
    sc: Scenario, fitting: Fit, parts: Sequence[LogSetup], solvers: Sequence[str] | None, wanted: Wanted
) -> tuple[FitAnalysis, list[str], list[CalibrationRun]]:
    """The fit, analyse and assemble stages over ``parts`` (one log, or several end to end)."""
    names, held = tuple(solvers or sc.solvers), parts[0].prepared.held
    results, fitted, notes, infos = _fit(fitting, parts, names, held, wanted.against is not None)
    return fitted, notes, _assemble(fitting, parts, (results, infos), fitted, notes, wanted)
