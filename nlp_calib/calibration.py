"""A scenario set up once (``Calibration.setup``), then solved by any solver (``solve``/``run``).

Set-up reads the log, builds the symbolic Functions, stacks the data and binds the evaluator;
solving only calls them. :meth:`Calibration.run` adds what a user judges a result by:
uncertainty and trajectory metrics per solver, next to the uncalibrated baseline.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from nlp_calib.analysis import uncertainty as unc
from nlp_calib.analysis.alignment import LagEstimate, estimate_lag
from nlp_calib.analysis.metrics import TrajectoryMetrics, trajectory_metrics
from nlp_calib.analysis.observability import Observability, analyse
from nlp_calib.data import ResidualData, build_residual_data, shift_encoders
from nlp_calib.errors import ModelError, ScenarioError
from nlp_calib.io.logfile import Dataset, read_log
from nlp_calib.io.scenario import Scenario
from nlp_calib.models import get_model
from nlp_calib.models.base import SENSOR_PARAMS
from nlp_calib.solvers import gauss_newton
from nlp_calib.solvers.backend import BackendOptions, make_backend
from nlp_calib.solvers.evaluation import Priors, ProblemEvaluator
from nlp_calib.solvers.ipopt import IpoptSolver
from nlp_calib.solvers.result import SolverResult
from nlp_calib.symbolic.builder import ProblemFunctions, ProblemSpec, build


@dataclass(frozen=True)
class SolverReport:
    """One solver's result with its uncertainty and trajectory metrics."""

    result: SolverResult
    uncertainty: unc.Uncertainty
    metrics: TrajectoryMetrics
    holdout: TrajectoryMetrics | None


@dataclass(frozen=True)
class CalibrationRun:
    """Everything a run produced; ``baseline`` scores the initial guess."""

    scenario: Scenario
    dataset: Dataset
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


def initial_parameters(scenario: Scenario, dataset: Dataset) -> dict[str, float]:
    """The log header's values, overridden by the scenario's mapping (``auto`` fills in later)."""
    model = get_model(scenario.model)
    header = dataset.header
    guess = {n: float(header.parameters[n]) for n in model.kinematic_params if n in header.parameters}
    guess.update(zip(SENSOR_PARAMS, header.T_base_sensor))
    if isinstance(scenario.initial_guess, Mapping):
        guess.update(scenario.initial_guess)
    needed = scenario.fixed if scenario.initial_guess == "auto" else (*model.kinematic_params, *SENSOR_PARAMS)
    missing = [n for n in needed if n not in guess]
    if missing:
        raise ScenarioError(
            f"the log header gives no initial value for {missing}; set them under initial_guess"
        )
    return guess


class Calibration:
    """A scenario ready to solve: dataset, Functions, data and evaluator built once."""

    def __init__(self, scenario: Scenario, dataset: Dataset | None = None) -> None:
        t0 = time.perf_counter()
        self.scenario = sc = scenario
        self.model = get_model(sc.model)
        self.log = dataset if dataset is not None else read_log(sc.dataset, strict=sc.strict)
        if self.log.header.kinematic_model not in self.model.log_names:
            raise ModelError(
                f"{self.log.path}: the log is of kind {self.log.header.kinematic_model!r}, "
                f"but the scenario's model {sc.model!r} reads {list(self.model.log_names)}"
            )
        n = self.log.n_records
        start = sc.samples.start
        stop = n if sc.samples.stop is None else sc.samples.stop
        if stop > n or start >= stop - 1:
            raise ScenarioError(f"samples: the range [{start}, {stop}) does not fit the log's {n} records")
        self.fns: ProblemFunctions = build(
            self.model,
            ProblemSpec(
                horizon=sc.residual.horizon,
                integration=sc.residual.integration,
                kernel=sc.robust.kernel,
                fixed=sc.fixed,
            ),
        )
        self.initial = initial_parameters(sc, self.log)
        self.auto_guess: dict[str, float] | None = None
        if sc.initial_guess == "auto":
            self.auto_guess = self._auto_guess(start, self._split(start, stop))
            self.initial.update({n: v for n, v in self.auto_guess.items() if n not in sc.fixed})
        self.x0 = np.array([self.initial[n] for n in self.fns.free])
        self.x_fixed = np.array([self.initial[n] for n in self.fns.fixed])
        self.lower, self.upper = self._bounds()
        self.backend = make_backend(BackendOptions(kind=sc.backend, threads=sc.threads))
        self.backend.prepare(self._functions_needed())
        self._ipopt: IpoptSolver | None = None
        self.priors = Priors(np.zeros(len(self.fns.free)), np.zeros(len(self.fns.free)))
        self.residual_sigma: float | None = None
        if sc.priors:
            self.priors = self._scaled_priors(start, self._split(start, stop))

        self.lag_estimate: LagEstimate | None = None
        lag = sc.alignment.tracker_lag
        if lag == "auto":
            self.lag_estimate = self._estimate_lag(start, stop)
            lag = self.lag_estimate.lag_s
        self.tracker_lag_s = float(lag)
        self.dataset, valid = shift_encoders(self.log, self.tracker_lag_s)
        start, stop = max(start, valid[0]), min(stop, valid[1])
        self.used = (start, stop)
        self.selected = self.dataset.select(start, stop)
        self.fit = (start, self._split(start, stop))
        self.data, self.evaluator = self.evaluator_for(self.dataset, *self.fit)
        self.input_noise_std = self.model.input_noise_std(self.dataset, sc.encoder_noise)
        self.setup_time_s = time.perf_counter() - t0

    def _functions_needed(self) -> list[tuple[ca.Function, tuple[str, ...], bool]]:
        """The per-residual Functions this scenario's solvers and reports will map."""
        f = self.fns
        needed = [
            (f.normal_equations, True),
            (f.cost, True),
            (f.robust_terms, False),
            (f.sensitivities, False),
        ]
        if "ipopt" in self.scenario.solvers:
            needed += [(f.cost_gradient, True)]
            hessian = {"exact": f.cost_hessian, "gauss_newton": f.gauss_newton_hessian}
            if self.scenario.ipopt.hessian in hessian:
                needed += [(hessian[self.scenario.ipopt.hessian], True)]
        return [(fn, ("data",), reduce) for fn, reduce in needed]

    def _split(self, start: int, stop: int) -> int:
        hf = self.scenario.validation.holdout_fraction
        return stop if hf is None else start + round((1.0 - hf) * (stop - start))

    def evaluator_for(self, dataset: Dataset, start: int, stop: int) -> tuple[ResidualData, ProblemEvaluator]:
        """Residual data of records ``start:stop`` of ``dataset`` and an evaluator bound to it."""
        sc = self.scenario
        data = build_residual_data(
            self.fns, dataset.select(start, stop), sc.residual, drop_stationary=sc.samples.drop_stationary
        )
        if data.n_residuals < len(self.fns.free):
            raise ScenarioError(
                f"only {data.n_residuals} residuals in records [{start}, {stop}) for "
                f"{len(self.fns.free)} parameters; widen 'samples' or shorten the horizon"
            )
        evaluator = ProblemEvaluator(
            self.fns,
            data.columns,
            x_fixed=self.x_fixed,
            omega=np.array(sc.information.omega()),
            delta=sc.robust.delta,
            priors=self.priors,
            backend=self.backend,
        )
        return data, evaluator

    def _scaled_priors(self, start: int, stop: int) -> Priors:
        """Priors weighed against the data in the data's own noise units.

        The data term ``Σ ρ(eᵀΩe)`` is not divided by the residual variance σ², so a prior
        ``((x − μ)/std)²`` enters multiplied by σ², which is estimated (once, at set-up) from a
        fit without priors. Both solvers then minimise ``σ²·(data/σ² + priors)``: a MAP estimate.
        """
        sc = self.scenario
        _, ev = self.evaluator_for(self.log, start, stop)
        res = gauss_newton.solve(ev, self.x0, sc.gauss_newton)
        _, s, weight = ev.robust_terms(res.x)
        sigma2 = float(np.sum(weight * s)) / max(3 * ev.n_residuals - len(self.fns.free), 1)
        self.residual_sigma = float(np.sqrt(sigma2))
        return Priors(
            mean=np.array([sc.priors[n].mean if n in sc.priors else 0.0 for n in self.fns.free]),
            sqrt_info=np.array(
                [self.residual_sigma / sc.priors[n].std if n in sc.priors else 0.0 for n in self.fns.free]
            ),
        )

    def _auto_guess(self, start: int, stop: int) -> dict[str, float]:
        """The model's closed-form estimate from the fit records' windows (no guess needed)."""
        data = build_residual_data(self.fns, self.log.select(start, stop), self.scenario.residual)
        rows = self.fns.n_inputs * data.horizon
        # Windows overlapping by three quarters carry nearly all the information at a fraction
        # of the cost of every window.
        step = max(1, data.horizon // (4 * self.scenario.residual.stride))
        columns = data.columns[:, ::step]
        predict = self.fns.predict_window.map(columns.shape[1])

        def base_motion(params: Mapping[str, float]) -> np.ndarray:
            p = np.array([params[n] for n in self.fns.names])
            return np.asarray(predict(p, columns))

        return self.model.initial_guess(columns[:rows], columns[rows : rows + 3], base_motion)

    def _estimate_lag(self, start: int, stop: int) -> LagEstimate:
        """Grid search of the tracker lag by the Gauss-Newton fit cost on a common record range."""
        al = self.scenario.alignment
        reach = max(abs(al.search[0]), abs(al.search[1]))
        t = self.log.time_s
        first = max(start, int(np.searchsorted(t, t[0] + reach, side="left")))
        last = min(stop, int(np.searchsorted(t, t[-1] - reach, side="right")))
        split = self._split(first, last)
        x_start = self.x0

        def fit_cost(lag: float) -> float:
            nonlocal x_start
            shifted, _ = shift_encoders(self.log, lag)
            _, ev = self.evaluator_for(shifted, first, split)
            res = gauss_newton.solve(ev, x_start, self.scenario.gauss_newton)
            if not res.converged:
                return float("nan")
            x_start = res.x
            return res.cost

        return estimate_lag(fit_cost, al.search, al.step)

    @classmethod
    def setup(cls, scenario: Scenario, data: str | Path | None = None) -> Calibration:
        """Build everything ``scenario`` needs (``data`` replaces its dataset path)."""
        return cls(scenario.with_dataset(data) if data is not None else scenario)

    def _bounds(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        b = self.scenario.bounds
        if not b:
            return None, None
        lower = np.array([b[n][0] if n in b else -np.inf for n in self.fns.free])
        upper = np.array([b[n][1] if n in b else np.inf for n in self.fns.free])
        for name, lo, hi, x in zip(self.fns.free, lower, upper, self.x0):
            if not lo <= x <= hi:
                sc = self.scenario
                origin = "from initial_guess: auto" if sc.initial_guess == "auto" else "from the log header"
                raise ScenarioError(
                    f"{sc.path or sc.name}: bounds.{name}: the initial guess {x:g} lies outside "
                    f"[{lo:g}, {hi:g}] (it comes {origin}); widen the bounds or set initial_guess.{name}"
                )
        return lower, upper

    def solve(self, solver: str) -> SolverResult:
        """Run one solver from the initial guess; the result is in the model's canonical form."""
        if solver == "gauss_newton":
            result = gauss_newton.solve(self.evaluator, self.x0, self.scenario.gauss_newton)
        elif solver == "ipopt":
            if self._ipopt is None:
                self._ipopt = IpoptSolver(self.evaluator, self.scenario.ipopt)
            result = self._ipopt.solve(self.x0, self.lower, self.upper)
        else:
            raise ScenarioError(f"unknown solver {solver!r}; valid solvers: gauss_newton, ipopt")
        return self._canonical(result)

    def _canonical(self, result: SolverResult) -> SolverResult:
        """``result`` mapped onto the model's canonical form (same cost: an exact symmetry)."""
        canon = self.model.canonical(result.param_dict(), self.fns.fixed)
        params = np.array([canon[n] for n in self.fns.names])
        if np.array_equal(params, result.params):
            return result
        x = np.array([canon[n] for n in self.fns.free])
        return dataclasses.replace(result, params=params, x=x)

    def score(self, params: np.ndarray) -> tuple[TrajectoryMetrics, TrajectoryMetrics | None]:
        """Full-range and hold-out trajectory metrics of ``params``."""
        inputs = self.model.inputs(self.selected, self.scenario.residual.steering_sample)
        poses = self.selected.T_world_sensor
        W = self.scenario.validation.rpe_window
        full = trajectory_metrics(self.fns, params, inputs, poses, rpe_window=W)
        holdout = None
        split = self.fit[1] - self.used[0]
        if self.fit[1] < self.used[1] - 1:
            holdout = trajectory_metrics(self.fns, params, inputs, poses, start=split, rpe_window=W)
        return full, holdout

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
        observability = analyse(self.evaluator, first.x, self.data.dataset.T_world_sensor)
        warnings = list(observability.warnings)
        warnings += [
            f"{name}: {rep.result.reason}" for name, rep in reports.items() if not rep.result.converged
        ]
        return CalibrationRun(
            scenario=self.scenario,
            dataset=self.log,
            used=self.used,
            fit=self.fit,
            initial=dict(self.initial),
            baseline=base,
            baseline_holdout=base_holdout,
            reports=reports,
            setup_time_s=self.setup_time_s,
            n_residuals=self.data.n_residuals,
            dropped_stationary=self.data.dropped_stationary,
            tracker_lag_s=self.tracker_lag_s,
            lag_estimate=self.lag_estimate,
            observability=observability,
            warnings=tuple(warnings),
        )
