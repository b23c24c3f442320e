"""A scenario set up once (:meth:`Calibration.setup`), then solved by any registered solver.

Set-up chains the named steps of :mod:`nlp_calib.pipeline.steps`: load the log, select its
records, build the problem's Functions, find the starting point, prepare the backend, weigh the
priors, align the encoders to the tracker's clock and bind the evaluator to the fitted windows.
Solving only calls the built Functions. :meth:`Calibration.run` adds what a user judges a result
by: uncertainty, trajectory metrics and observability per solver, next to the uncalibrated
baseline.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nlp_calib.analysis import uncertainty as unc
from nlp_calib.analysis.alignment import LagEstimate
from nlp_calib.analysis.crossval import CrossValidation, believed_std
from nlp_calib.analysis.direction import DirectionCheck
from nlp_calib.analysis.metrics import TrajectoryMetrics, trajectory_metrics
from nlp_calib.analysis.observability import Observability, analyse
from nlp_calib.analysis.odometry import OdometryTrack, propagate
from nlp_calib.core import interrupts
from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.logs import Log
from nlp_calib.models import canonical
from nlp_calib.models.base import KinematicModel
from nlp_calib.pipeline import align, steps, validation
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.problem import ProblemFunctions, over_columns
from nlp_calib.solvers import ProblemEvaluator, Solver, SolverResult, get_solver


@dataclass(frozen=True)
class SolverReport:
    """One solver's result with its uncertainty and trajectory metrics."""

    result: SolverResult
    uncertainty: unc.Uncertainty
    metrics: TrajectoryMetrics
    holdout: TrajectoryMetrics | None


@dataclass(frozen=True)
class CalibrationRun:
    """Everything a run produced; ``baseline`` scores the initial guess.

    ``log`` is the log as read (before any time alignment); ``used`` and ``fit`` are record
    ranges of it.
    """

    scenario: Scenario
    log: Log
    used: tuple[int, int]
    fit: tuple[int, int]
    initial: Mapping[str, float]
    baseline: TrajectoryMetrics
    baseline_holdout: TrajectoryMetrics | None
    reports: Mapping[str, SolverReport]
    setup_time_s: float
    n_residuals: int
    dropped_stationary: int
    tracker_lag_s: float = 0.0
    lag_estimate: LagEstimate | None = None
    observability: Observability | None = None
    warnings: tuple[str, ...] = field(default=())
    findings: steps.Findings | None = None
    dropped_faulty: int = 0
    crossval: CrossValidation | None = None
    direction: DirectionCheck | None = None

    def std(self, solver: str) -> dict[str, float]:
        """The 1σ to believe for ``solver``'s estimate: the larger of the white-noise σ and the
        block cross-validation's jackknife σ (see :mod:`nlp_calib.analysis.crossval`)."""
        u = self.reports[solver].uncertainty
        blocked = self.crossval.std if self.crossval is not None else np.full(len(u.names), np.nan)
        return dict(zip(u.names, map(float, believed_std(u.std, blocked))))

    def std_blocks(self) -> dict[str, float] | None:
        """The jackknife σ of the block cross-validation, when it has enough converged folds."""
        if self.crossval is None or not self.crossval.available:
            return None
        return self.crossval.std_dict()


class Solving:
    """Solving and the canonical form, for a set-up object with ``scenario``, ``model``, ``fns``,
    ``start`` and ``evaluator`` (one log or several)."""

    scenario: Scenario
    model: KinematicModel
    fns: ProblemFunctions
    start: steps.StartingPoint
    evaluator: ProblemEvaluator
    _solvers: dict[str, Solver]

    def solver(self, name: str) -> Solver:
        """The solver ``name`` set up on this calibration's evaluator (once)."""
        if name not in self._solvers:
            with steps.scenario_key(self.scenario, name):
                self._solvers[name] = get_solver(name)(self.evaluator, self.scenario.options_for(name))
        return self._solvers[name]

    def solve(self, solver: str) -> SolverResult:
        """Run one solver from the initial guess; the result is in the model's canonical form."""
        result = self.solver(solver).solve(self.start.x0, self.start.lower, self.start.upper)
        interrupts.check()  # IPOPT catches the signal that stops it and returns as if it had failed
        steps.refuse_rejected_options(self.scenario, result)
        return self._canonical(result)

    def _canonical(self, result: SolverResult) -> SolverResult:
        """``result`` mapped onto the model's canonical form (same cost: an exact symmetry)."""
        params = self.canonical_params(result.params)
        if np.array_equal(params, result.params):
            return result
        x = params[[self.fns.names.index(n) for n in self.fns.free]]
        return dataclasses.replace(result, params=params, x=x)

    def canonical_params(self, params: np.ndarray) -> np.ndarray:
        """The full parameter vector ``params`` in the model's canonical form."""
        canon = canonical(self.model, dict(zip(self.fns.names, map(float, params))), self.fns.fixed)
        return np.array([canon[n] for n in self.fns.names])


class Calibration(Solving):
    """A scenario ready to solve: log, Functions, data and evaluator built once.

    ``log`` is the log as read; ``aligned`` the same records with the encoders re-sampled on the
    tracker's clock (``log`` itself when the lag is 0); ``selected`` the used records of
    ``aligned``.
    """

    def __init__(
        self, scenario: Scenario, log: Log | None = None, solvers: Sequence[str] | None = None
    ) -> None:
        t0 = time.perf_counter()
        self.scenario = sc = scenario
        self.solvers = tuple(solvers or sc.solvers)
        self.model, self.log = steps.load(sc, log)
        start, stop = steps.select(sc, self.log)
        self.held = steps.held(sc, self.model, self.log, start, steps.split(sc, start, stop))
        for name, why in self.held.items():
            warnings.warn(
                f"{name} is held at its initial value: {why} in the fitted records",
                NlpCalibWarning,
                stacklevel=2,
            )
        self.fns = steps.build_problem(sc, self.model, tuple(self.held))
        self.start = steps.starting_point(sc, self.fns, self.log, start, steps.split(sc, start, stop))
        self.backend = steps.prepare_backend(sc, self.fns, self.solvers, stop - start)
        binder = steps.Binder(
            sc, self.fns, self.backend, self.start.x_fixed, steps.no_priors(self.fns.n_free)
        )
        priors, self.residual_sigma = steps.weigh_priors(
            binder, self.log, start, steps.split(sc, start, stop), self.start.x0
        )
        binder = steps.with_priors(binder, priors)
        # Faults are screened once, on the records as logged (re-sampling would smear a bad
        # reading into its neighbours), before the lag search, which they are kept out of.
        report = steps.find_faults(binder, self.log, start, stop, self.start.x0)
        fitted_log, self.findings = steps.handle_faults(self.log, report, sc.faults.handling)
        dt = align.median_interval(self.log)
        search = sc.alignment.search if sc.alignment.tracker_lag == "auto" else (0.0, 0.0)
        reach = max(abs(search[0]), abs(search[1]))
        search_binder = steps.exclude_faults(binder, self.findings, self.log.n_records, reach, dt)
        self.alignment = align.align(search_binder, fitted_log, start, stop, self.start.x0)
        lag = self.alignment.lag_s
        self.binder = steps.exclude_faults(binder, self.findings, self.log.n_records, lag, dt)
        # Every detected fault shapes the fair figures, whatever the handling: like with like.
        self.fault_masks = steps.fault_masks(report, self.log.n_records, lag, dt)
        if report.unchecked:
            warnings.warn(f"encoder faults not checked: {report.unchecked}", NlpCalibWarning, stacklevel=2)
        self.aligned = self.alignment.log
        start, stop = max(start, self.alignment.valid[0]), min(stop, self.alignment.valid[1])
        self.used = (start, stop)
        self.fit = (start, steps.split(sc, start, stop))
        self.selected = self.aligned.select(start, stop)
        self.data, self.evaluator = self.binder.bind(self.aligned, *self.fit)
        self.evaluator.prepare(steps.evaluated(sc, self.solvers))
        self.input_noise_std = self.model.input_noise_std(self.aligned, sc.encoder_noise)
        self._solvers: dict[str, Solver] = {}
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
    def initial(self) -> Mapping[str, float]:
        """The starting values of every parameter."""
        return self.start.initial

    @property
    def x0(self) -> np.ndarray:
        """The starting values of the free parameters."""
        return self.start.x0

    def score(self, params: np.ndarray) -> tuple[TrajectoryMetrics, TrajectoryMetrics | None]:
        """Full-range and hold-out trajectory metrics of ``params``."""
        inputs = self.model.inputs(self.selected, self.scenario.residual.steering_sample)
        poses = self.selected.T_world_sensor
        a, b = self.used
        bad_i, bad_r = self.fault_masks[0][a : b - 1], self.fault_masks[1][a:b]
        W = self.scenario.validation.rpe_window
        full = trajectory_metrics(
            self.fns, params, inputs, poses, rpe_window=W, bad_intervals=bad_i, bad_records=bad_r
        )
        holdout = None
        split = self.fit[1] - self.used[0]
        if self.fit[1] < self.used[1] - 1:
            holdout = trajectory_metrics(
                self.fns,
                params,
                inputs,
                poses,
                start=split,
                rpe_window=W,
                bad_intervals=bad_i,
                bad_records=bad_r,
            )
        return full, holdout

    def cross_validate(self, x: np.ndarray, k: int) -> CrossValidation:
        """``k`` folds over the fitted records from the estimate ``x`` (free parameters); each block
        scored on its own: dead reckoning restarted at its start and after each fault inside it."""
        inputs = self.model.inputs(self.selected, self.scenario.residual.steering_sample)
        a0, b0 = self.used
        bad_i, bad_r = self.fault_masks[0][a0 : b0 - 1], self.fault_masks[1][a0:b0]

        def score(params: np.ndarray, a: int, b: int) -> TrajectoryMetrics:
            return trajectory_metrics(
                self.fns,
                params,
                inputs,
                self.selected.T_world_sensor,
                start=a - a0,
                stop=b - a0,
                rpe_window=self.scenario.validation.rpe_window,
                bad_intervals=bad_i,
                bad_records=bad_r,
            )

        return validation.cross_validate(self.binder, self.data, self.fit, x, k, self.canonical_params, score)

    def direction_check(self, x: np.ndarray, k: int = 10) -> DirectionCheck | None:
        """Forward-only and reverse-only fits from ``x``, compared in units of their own σ."""
        inputs = self.model.inputs(self.aligned, self.scenario.residual.steering_sample)
        direction = self.model.travel_direction(inputs)

        def undetermined(part: np.ndarray) -> dict[str, str]:
            return self.model.undetermined(inputs[:, part])

        return validation.direction_check(
            self.binder, self.data, self.fit, x, direction, undetermined, k, self.canonical_params
        )

    def odometry(self, params: np.ndarray) -> OdometryTrack:
        """Base-link odometry with ``params`` over the used records, with its propagated covariance,
        started at the base pose the tracker's first pose implies."""
        sel, fns = self.selected, self.fns
        inputs = self.model.inputs(sel, self.scenario.residual.steering_sample)
        T_world_base_0 = np.asarray(fns.base_from_sensor(sel.T_world_sensor[0], params)).ravel()
        poses, cov = propagate(fns, params, inputs, T_world_base_0, self.input_noise_std)
        return OdometryTrack(time_s=sel.time_s, T_world_base=poses, covariance=cov)

    def base_reference(self, params: np.ndarray) -> np.ndarray:
        """The base poses ``(n, 3)`` the tracker's sensor poses imply with ``params``' mounting pose."""
        sel = self.selected
        return over_columns(self.fns.base_from_sensor, sel.T_world_sensor.T, np.ravel(params))[0].T

    def run(self, solvers: Sequence[str] | None = None) -> CalibrationRun:
        """Solve with each solver and score every result."""
        reports: dict[str, SolverReport] = {}
        for name in solvers or self.scenario.solvers:
            result = self.solve(name)
            full, holdout = self.score(result.params)
            reports[name] = SolverReport(
                result=result,
                uncertainty=unc.estimate(self.evaluator, result.x, self.data, self.input_noise_std),
                metrics=full,
                holdout=holdout,
            )
        p0 = np.array([self.initial[n] for n in self.fns.names])
        base, base_holdout = self.score(p0)
        # Observability at the first estimate with a finite cost (a solver may not have started).
        results = [rep.result for rep in reports.values()]
        first = next((r for r in results if np.isfinite(r.cost)), results[0])
        observability = analyse(self.evaluator, first.x, self.data.T_world_sensor)
        notes = list(observability.warnings) + self.lag_notes()
        notes += [f"{name} held at its initial value: {why}" for name, why in self.held.items()]
        notes += [f"{name}: {rep.result.reason}" for name, rep in reports.items() if not rep.result.converged]
        crossval = None
        converged = [r for r in results if r.converged]
        if converged and self.scenario.validation.blocks:
            crossval = self.cross_validate(converged[0].x, self.scenario.validation.blocks)
        direction = None
        if converged and self.scenario.validation.blocks:
            direction = self.direction_check(converged[0].x, self.scenario.validation.blocks)
            if direction is not None and direction.significant:
                name, z = direction.worst
                notes.append(
                    f"forward-only and reverse-only fits disagree: {name} by {abs(z):.1f}σ; the model misses "
                    "something that depends on the direction of travel"
                )
        return self.as_run(reports, (base, base_holdout), observability, notes, crossval, direction)

    def lag_notes(self) -> list[str]:
        """What the time alignment found worth saying: a lag at the edge of its search."""
        if self.alignment.estimate is not None and self.alignment.estimate.at_edge:
            return [align.lag_at_edge(self.scenario, self.alignment.lag_s)]
        return []

    def as_run(
        self,
        reports: Mapping[str, SolverReport],
        baseline: tuple[TrajectoryMetrics, TrajectoryMetrics | None],
        observability: Observability,
        notes: Sequence[str],
        crossval: CrossValidation | None,
        direction: DirectionCheck | None,
        initial: Mapping[str, float] | None = None,
    ) -> CalibrationRun:
        """A run of this log from solver ``reports`` (a joint fit's, or its own) and the
        ``initial`` values they started from (its own)."""
        return CalibrationRun(
            scenario=self.scenario,
            log=self.log,
            used=self.used,
            fit=self.fit,
            initial=dict(self.initial if initial is None else initial),
            baseline=baseline[0],
            baseline_holdout=baseline[1],
            reports=reports,
            setup_time_s=self.setup_time_s,
            n_residuals=self.data.n_residuals,
            dropped_stationary=self.data.dropped_stationary,
            tracker_lag_s=self.alignment.lag_s,
            lag_estimate=self.alignment.estimate,
            observability=observability,
            warnings=tuple(notes),
            findings=self.findings,
            dropped_faulty=self.data.dropped_faulty,
            crossval=crossval,
            direction=direction,
        )
