"""A calibration as named stages: prepare, build, screen, align, bind, fit, analyse, assemble.

Each log goes through the stages before the fit on its own (:func:`setup_log`): its records are
read and selected once, the problem is built, faults are screened, the tracker lag is estimated,
and its windows are bound. The fit then binds one evaluator to the windows of one log
(:class:`Calibration`) or of several laid end to end (:class:`JointCalibration`), every solver
runs on it, and the same analyse and assemble stages turn the estimates into a self-contained
:class:`~nlp_calib.results.CalibrationRun` per log.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.logs import Log
from nlp_calib.models import KinematicModel
from nlp_calib.pipeline.align import Alignment, align, realign
from nlp_calib.pipeline.analyse import (
    FitAnalysis,
    LogView,
    Scorer,
    Scores,
    Wanted,
    analyse_fit,
    analyse_log,
    log_scorer,
    scores,
)
from nlp_calib.pipeline.assemble import assemble_run, fit_notes, scenario_info
from nlp_calib.pipeline.build import Problem, StartingPoint, build_stage
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.prepare import PreparedLog, joint_residual, prepare
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.pipeline.screen import Screening, exclude_faults, median_interval, screen
from nlp_calib.pipeline.windows import LogWindows, bind_windows
from nlp_calib.problem import ProblemFunctions, ResidualData, joined
from nlp_calib.results import CalibrationRun, Checks, JointRun, SolverResult
from nlp_calib.results.faults import Findings
from nlp_calib.solvers import ProblemEvaluator
from nlp_calib.solvers.backends import Backend


@dataclass(frozen=True)
class LogSetup:
    """One log through the stages before the fit."""

    prepared: PreparedLog
    problem: Problem
    screening: Screening
    alignment: Alignment
    windows: LogWindows

    @property
    def used(self) -> tuple[int, int]:
        return self.windows.used

    @property
    def fit(self) -> tuple[int, int]:
        return self.windows.fit

    @property
    def aligned(self) -> Log:
        return self.windows.aligned


def align_stage(problem: Problem, prepared: PreparedLog, screening: Screening) -> Alignment:
    """The tracker lag, searched with the windows that could cross a fault within the search's
    reach left out, applied to the encoders of the log to fit."""
    al = prepared.scenario.log.alignment
    search = al.search if al.tracker_lag == "auto" else (0.0, 0.0)
    reach = max(abs(search[0]), abs(search[1]))
    log = prepared.log
    binder = exclude_faults(problem.binder, screening.findings, log.n_records, reach, median_interval(log))
    return align(binder, screening.fitted_log, prepared.start, prepared.stop, problem.start.x0)


def setup_log(sc: Scenario, log: Log | None, solvers: Sequence[str]) -> LogSetup:
    """Prepare, build, screen, align and bind one log (``log``: already read, or None).

    Faults are screened first against the tracker as logged, to keep them out of the lag search,
    then, once a lag is known, again against the tracker re-sampled onto the encoders' clock.
    """
    prepared = prepare(sc, log)
    read = prepared.log
    records = (prepared.start, prepared.stop)
    start_from = (read, prepared.start, prepared.split)
    problem = build_stage(
        prepared.scenario, prepared.model, tuple(prepared.held), start_from, solvers, records[1] - records[0]
    )
    x0 = problem.start.x0
    screening = screen(problem.binder, read, records, x0)
    alignment = align_stage(problem, prepared, screening)
    if alignment.lag_s:
        judge = exclude_faults(
            problem.binder, screening.findings, read.n_records, alignment.lag_s, median_interval(read)
        )
        screening = screen(judge, read, records, x0, alignment.lag_s)
        alignment = realign(alignment, screening.fitted_log, prepared.model)
    windows = bind_windows(problem, prepared, screening, alignment)
    return LogSetup(prepared, problem, screening, alignment, windows)


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
    return Scorer(
        fns, data.inputs, data.T_world_sensor, _joined(intervals, True), _joined(records, False), 0, W
    )


class Calibration:
    """A single-log scenario through the stages up to the fit, ready to solve with any solver.

    :meth:`run` fits with each solver, analyses and assembles the result.
    """

    def __init__(
        self, scenario: Scenario, log: Log | None = None, solvers: Sequence[str] | None = None
    ) -> None:
        t0 = time.perf_counter()
        self.scenario = scenario
        self.solvers = tuple(solvers or scenario.solvers)
        self.stages = setup_log(scenario, log, self.solvers)
        self.fitting = Fit(self.stages.problem, self.stages.windows.data, self.solvers)
        self.setup_time_s = time.perf_counter() - t0

    @classmethod
    def setup(
        cls,
        scenario: Scenario,
        data: str | Path | None = None,
        log: Log | None = None,
        solvers: Sequence[str] | None = None,
    ) -> Calibration:
        """Build everything ``scenario`` needs (``data`` replaces its log path; ``log``, already read,
        replaces reading it; ``solvers``, the ones to get ready, the scenario's)."""
        return cls(scenario.with_dataset(data) if data is not None else scenario, log, solvers)

    @property
    def model(self) -> KinematicModel:
        return self.stages.prepared.model

    @property
    def log(self) -> Log:
        """The log as read."""
        return self.stages.prepared.log

    @property
    def held(self) -> Mapping[str, str]:
        return self.stages.prepared.held

    @property
    def alignment(self) -> Alignment:
        return self.stages.alignment

    @property
    def findings(self) -> Findings:
        return self.stages.screening.findings

    @property
    def aligned(self) -> Log:
        """The log with the encoders re-sampled on the tracker's clock."""
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
        return self.stages.problem.start.initial

    @property
    def backend(self) -> Backend:
        return self.stages.problem.binder.backend

    @property
    def start(self) -> StartingPoint:
        """Where the solvers start, the fixed values and the bounds."""
        return self.stages.problem.start

    @property
    def x0(self) -> np.ndarray:
        """The starting values of the free parameters."""
        return self.stages.problem.start.x0

    def solve(self, solver: str) -> SolverResult:
        """Run one solver from the initial guess; the result is in the model's canonical form."""
        return self.fitting.solve(solver)

    def score(self, params: np.ndarray) -> Scores:
        """Full-range and hold-out trajectory metrics of the full parameter vector ``params``."""
        sc, windows = self.scenario, self.stages.windows
        scorer = log_scorer(
            self.fns, windows, sc.objective.residual.steering_sample, sc.validation.rpe_window
        )
        return scores(scorer, windows, params)

    def run(self, solvers: Sequence[str] | None = None, wanted: Wanted | None = None) -> CalibrationRun:
        """Fit with each solver (the scenario's by default), analyse and assemble the result."""
        return _run(self.scenario, self.fitting, [self.stages], solvers, wanted or Wanted())[2][0]


class JointCalibration:
    """A scenario with ``datasets``: each log set up on its own (its samples, faults and lag), then
    their windows laid end to end and fitted together (no window crosses from one log into the
    next)."""

    def __init__(
        self, scenario: Scenario, logs: Sequence[Log] | None = None, solvers: Sequence[str] | None = None
    ) -> None:
        t0 = time.perf_counter()
        self.scenario = sc = scenario
        self.solvers = tuple(solvers or sc.solvers)
        per_log = sc.per_log()
        given: Sequence[Log | None] = list(logs) if logs is not None else [None] * len(per_log)
        self.parts = [setup_log(s, log, self.solvers) for s, log in zip(per_log, given)]
        first = self.parts[0]
        # A parameter is held only when no log determines it.
        held = [n for n in first.prepared.held if all(n in p.prepared.held for p in self.parts)]
        n_records = sum(p.fit[1] - p.fit[0] for p in self.parts)
        start_from = (first.prepared.log, first.used[0], first.fit[1])
        one_horizon = sc.with_options(residual=joint_residual(sc, [p.prepared for p in self.parts]))
        problem = build_stage(one_horizon, first.prepared.model, held, start_from, self.solvers, n_records)
        self.fitting = Fit(problem, joined([p.windows.data for p in self.parts]), self.solvers)
        self.setup_time_s = time.perf_counter() - t0

    @property
    def model(self) -> KinematicModel:
        return self.fitting.fns.model

    @property
    def fns(self) -> ProblemFunctions:
        return self.fitting.fns

    @property
    def data(self) -> ResidualData:
        return self.fitting.data

    def solve(self, solver: str) -> SolverResult:
        return self.fitting.solve(solver)

    def run(self, solvers: Sequence[str] | None = None, wanted: Wanted | None = None) -> JointRun:
        """Fit with each solver on every log's windows; score the result on each log."""
        fitted, notes, parts = _run(self.scenario, self.fitting, self.parts, solvers, wanted or Wanted())
        return JointRun(
            scenario=scenario_info(self.scenario, self.model),
            parts=tuple(parts),
            n_residuals=self.fitting.data.n_residuals,
            checks=Checks(fitted.observability, fitted.crossval, fitted.direction, None),
            warnings=tuple(notes),
        )


def _run(
    sc: Scenario, fitting: Fit, parts: Sequence[LogSetup], solvers: Sequence[str] | None, wanted: Wanted
) -> tuple[FitAnalysis, list[str], list[CalibrationRun]]:
    """The fit, analyse and assemble stages over ``parts`` (one log, or several end to end)."""
    results = {name: fitting.solve(name) for name in solvers or sc.solvers}
    noise = np.max([p.windows.input_noise_std for p in parts], axis=0)
    fitted = analyse_fit(fitting, results, noise, blocks_scorer(fitting.fns, parts, fitting.data))
    held = {n: why for n, why in parts[0].prepared.held.items() if n in fitting.fns.fixed}
    notes = fit_notes(results, fitted, held)
    runs = []
    for i, part in enumerate(parts):
        info = scenario_info(part.prepared.scenario, fitting.fns.model)
        steering = part.prepared.scenario.objective.residual.steering_sample
        scorer = log_scorer(fitting.fns, part.windows, steering, sc.validation.rpe_window)
        view = LogView(part.prepared, part.windows, scorer, part.screening.findings, i)
        figures = analyse_log(fitting, results, view, wanted, info.labels)
        stage = (part.prepared, part.windows, part.alignment, part.screening.findings)
        runs.append(assemble_run(info, stage, fitting.problem.start.initial, results, fitted, figures, notes))
    return fitted, notes, runs
