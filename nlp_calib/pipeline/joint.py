"""Several logs calibrated together: one set of kinematic and mounting parameters for all of them.

Each log is first set up on its own (:class:`~nlp_calib.pipeline.calibration.Calibration` of a
single-log scenario): its samples, its encoder faults and its tracker lag are its own. The joint
fit then lays the logs' fitted records end to end and binds one evaluator to the windows of all
of them; no window crosses from one log into the next. Every solver, the uncertainty, the
observability analysis, the blocked cross-validation and the direction check see the joint
windows. A log's figures are its own trajectory metrics with the joint parameters.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from nlp_calib.analysis import uncertainty as unc
from nlp_calib.analysis.consistency import ConsistencyCheck, compare_logs
from nlp_calib.analysis.crossval import CrossValidation
from nlp_calib.analysis.direction import DirectionCheck
from nlp_calib.analysis.metrics import TrajectoryMetrics, trajectory_metrics
from nlp_calib.analysis.observability import Observability, analyse
from nlp_calib.core.errors import ScenarioError
from nlp_calib.logs import Log
from nlp_calib.pipeline import steps, validation
from nlp_calib.pipeline.calibration import Calibration, CalibrationRun, SolverReport, Solving
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.problem import joined
from nlp_calib.solvers import Solver


@dataclass(frozen=True)
class JointRun:
    """A calibration from several logs: ``parts`` holds one run per log, each carrying the joint
    results (same parameters, uncertainty and cross-validation) beside that log's own figures."""

    scenario: Scenario
    parts: tuple[CalibrationRun, ...]
    n_residuals: int
    crossval: CrossValidation | None = None
    direction: DirectionCheck | None = None
    observability: Observability | None = None
    warnings: tuple[str, ...] = field(default=())

    @property
    def reports(self) -> dict[str, SolverReport]:
        """The joint results by solver (the trajectory metrics are the first log's)."""
        return dict(self.parts[0].reports)

    def std(self, solver: str) -> dict[str, float]:
        """The 1σ to believe for ``solver``'s joint estimate (see :meth:`CalibrationRun.std`)."""
        return self.parts[0].std(solver)


def _joined(pieces: Sequence[np.ndarray], joint: bool) -> np.ndarray:
    """Per-log masks end to end, with ``joint`` for the interval joining one log to the next."""
    out: list[np.ndarray] = []
    for i, piece in enumerate(pieces):
        if i:
            out.append(np.array([joint]))
        out.append(piece)
    return np.concatenate(out)


class JointCalibration(Solving):
    """A scenario with ``datasets``, ready to solve: each log set up on its own, then bound together."""

    def __init__(
        self, scenario: Scenario, logs: Sequence[Log] | None = None, solvers: Sequence[str] | None = None
    ) -> None:
        if not scenario.datasets:
            raise ScenarioError(f"{scenario.path or scenario.name}: a joint calibration needs 'datasets'")
        t0 = time.perf_counter()
        self.scenario = sc = scenario
        self.solvers = tuple(solvers or sc.solvers)
        per_log = sc.per_log()
        given = list(logs) if logs is not None else [None] * len(per_log)
        self.parts = [Calibration(s, log, self.solvers) for s, log in zip(per_log, given)]
        first = self.parts[0]
        self.model = first.model
        # A parameter is held only when no log determines it.
        self.held = {n: why for n, why in first.held.items() if all(n in p.held for p in self.parts)}
        self.fns = steps.build_problem(sc, self.model, tuple(self.held))
        split = first.fit[1]
        self.start = steps.starting_point(sc, self.fns, first.log, first.used[0], split)
        n_records = sum(p.fit[1] - p.fit[0] for p in self.parts)
        self.backend = steps.prepare_backend(sc, self.fns, self.solvers, n_records)
        no_priors = steps.no_priors(self.fns.n_free)
        binder = steps.Binder(sc, self.fns, self.backend, self.start.x_fixed, no_priors)
        # The priors are weighed in the first log's noise units (see steps.weigh_priors).
        priors, _ = steps.weigh_priors(binder, first.log, first.used[0], split, self.start.x0)
        self.binder = steps.with_priors(binder, priors)
        # Each log's own windows (its samples, faults and lag), laid end to end.
        self.data = joined([p.data for p in self.parts])
        self.evaluator = self.binder.evaluate(self.data)
        self.evaluator.prepare(steps.evaluated(sc, self.solvers))
        # The same robot: the encoders' noise is the largest any log's header implies.
        self.input_noise_std = np.max([p.input_noise_std for p in self.parts], axis=0)
        self._solvers: dict[str, Solver] = {}
        self.setup_time_s = time.perf_counter() - t0

    @property
    def initial(self) -> dict[str, float]:
        return dict(self.start.initial)

    def _fault_masks(self) -> tuple[np.ndarray, np.ndarray]:
        """Every log's fault masks over its fitted records, end to end; the joining interval is
        marked too, so dead reckoning restarts at each log's start."""
        intervals = [p.fault_masks[0][p.fit[0] : p.fit[1] - 1] for p in self.parts]
        records = [p.fault_masks[1][p.fit[0] : p.fit[1]] for p in self.parts]
        return _joined(intervals, True), _joined(records, False)

    def _score_blocks(self) -> validation.Score:
        bad_i, bad_r = self._fault_masks()

        def score(params: np.ndarray, a: int, b: int) -> TrajectoryMetrics:
            return trajectory_metrics(
                self.fns,
                params,
                self.data.inputs,
                self.data.T_world_sensor,
                start=a,
                stop=b,
                rpe_window=self.scenario.validation.rpe_window,
                bad_intervals=bad_i,
                bad_records=bad_r,
            )

        return score

    def run(self, solvers: Sequence[str] | None = None) -> JointRun:
        """Solve with each solver on every log's windows; score the result on each log."""
        sc = self.scenario
        results = {name: self.solve(name) for name in solvers or sc.solvers}
        ev, data, noise = self.evaluator, self.data, self.input_noise_std
        uncertainties = {name: unc.estimate(ev, r.x, data, noise) for name, r in results.items()}
        finite = [r for r in results.values() if np.isfinite(r.cost)] or list(results.values())
        observability = analyse(self.evaluator, finite[0].x, self.data.T_world_sensor)
        converged = [r for r in results.values() if r.converged]
        fit = (0, self.data.n_records)
        crossval = direction = None
        if converged and sc.validation.blocks:
            k = sc.validation.blocks
            crossval = validation.cross_validate(
                self.binder, self.data, fit, converged[0].x, k, self.canonical_params, self._score_blocks()
            )
            inputs = self.data.inputs
            direction = validation.direction_check(
                self.binder,
                self.data,
                fit,
                converged[0].x,
                self.model.travel_direction(inputs),
                lambda part: self.model.undetermined(inputs[:, part]),
                k,
                self.canonical_params,
            )
        notes = list(observability.warnings)
        notes += [f"{name} held at its initial value: {why}" for name, why in self.held.items()]
        notes += [f"{name}: {r.reason}" for name, r in results.items() if not r.converged]
        if direction is not None and direction.significant:
            name, z = direction.worst
            notes.append(f"forward-only and reverse-only fits disagree: {name} by {abs(z):.1f}σ")
        p0 = np.array([self.initial[n] for n in self.fns.names])
        parts = []
        for part in self.parts:
            reports = {}
            for name, r in results.items():
                full, holdout = part.score(r.params)
                reports[name] = SolverReport(r, uncertainties[name], full, holdout)
            notes_part = notes + part.lag_notes()
            base = part.score(p0)
            parts.append(
                part.as_run(reports, base, observability, notes_part, crossval, direction, self.initial)
            )
        return JointRun(
            scenario=sc,
            parts=tuple(parts),
            n_residuals=self.data.n_residuals,
            crossval=crossval,
            direction=direction,
            observability=observability,
            warnings=tuple(notes),
        )


def consistency(joint: JointRun, own: Sequence[CalibrationRun], solver: str) -> ConsistencyCheck:
    """Each log's own fit (``own``, one run per log in the joint run's order) against the joint
    fit, in honest σ (see :mod:`nlp_calib.analysis.consistency`)."""
    result = joint.reports[solver].result
    std = joint.std(solver)
    logs = [run.log.path for run in own]
    estimates = np.array([run.reports[solver].result.params for run in own])
    stds = np.array([[run.std(solver)[n] for n in result.names] for run in own])
    return compare_logs(
        result.names, logs, result.params, np.array([std[n] for n in result.names]), estimates, stds
    )
