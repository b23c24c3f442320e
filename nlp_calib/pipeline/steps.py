"""The calibration's named steps: load, select, build, start, bind, weigh priors, align.

Each step takes what it needs and returns an immutable record; :class:`~nlp_calib.pipeline.
calibration.Calibration` chains them. This is also where library errors, raised in neutral words,
are translated once into the scenario's language (:func:`scenario_key`).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.analysis import uncertainty
from nlp_calib.analysis.faults import FaultReport, repair, screen
from nlp_calib.core.errors import (
    DatasetError,
    ModelError,
    OptionsError,
    ProblemError,
    ScenarioError,
)
from nlp_calib.logs import Log
from nlp_calib.models import (
    SENSOR_PARAMS,
    KinematicModel,
    get_model,
    header_parameters,
    param_names,
)
from nlp_calib.pipeline.bags import load_dataset
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.problem import (
    ProblemFunctions,
    ProblemSpec,
    ResidualData,
    build,
    build_residual_data,
    interval_inputs,
    over_columns,
)
from nlp_calib.solvers import Priors, ProblemEvaluator, SolverResult, get_solver
from nlp_calib.solvers.backends import Backend, BackendOptions, make_backend
from nlp_calib.solvers.evaluation import requests

#: The solver the pipeline's own fits use (prior scaling, the tracker-lag search): the fastest.
INTERNAL_SOLVER = "gauss_newton"


@contextmanager
def scenario_key(sc: Scenario, key: str, hint: str = "") -> Iterator[None]:
    """Library errors raised inside become :class:`ScenarioError` naming the scenario's ``key``."""
    try:
        yield
    except (ProblemError, OptionsError, ModelError) as exc:
        raise ScenarioError(f"{sc.path or sc.name}: {key}: {exc}" + (f"; {hint}" if hint else "")) from None


#: Return statuses with which a solver says its options, not the data, are at fault.
REJECTED_OPTIONS = ("Invalid_Option",)


def refuse_rejected_options(sc: Scenario, result: SolverResult) -> None:
    """A solver that stopped because it rejected its options is an input error, not a result."""
    status = result.stats.get("return_status")
    if status not in REJECTED_OPTIONS:
        return
    options = sc.options_for(result.solver)
    linear = getattr(options, "options", {}).get("linear_solver", getattr(options, "linear_solver", None))
    hint = f"; is linear_solver {linear!r} installed? (mumps always is)" if linear is not None else ""
    raise ScenarioError(
        f"{sc.path or sc.name}: {result.solver}: the solver rejected its options when it started "
        f"({status}){hint}; check {result.solver}.linear_solver and {result.solver}.options"
    )


def load(sc: Scenario, log: Log | None = None) -> tuple[KinematicModel, Log]:
    """The scenario's model and its log, read with the model's encoder kinds (or ``log`` as given)."""
    with scenario_key(sc, "model"):
        model = get_model(sc.model)
    if log is not None:
        if log.header.kinematic_model not in model.log_names:
            raise ModelError(
                f"{log.path}: the log is of kind {log.header.kinematic_model!r}, but the scenario's "
                f"model {model.name!r} reads {', '.join(model.log_names)}"
            )
        return model, log
    try:
        return model, load_dataset(sc.dataset, sc.bag, model, strict=sc.strict)
    except DatasetError as exc:
        if exc.droppable:
            raise exc.with_hint("set 'strict: false' in the scenario to drop such records") from None
        if exc.line is None and exc.problem == "no such file":
            key = sc.origin or "dataset"
            raise exc.with_hint(f"pass the log with --data or fix '{key}' in the scenario") from None
        raise


def read_checked(sc: Scenario) -> Log:
    """The scenario's log, read and checked against what costs nothing to check (samples, horizon):
    several scenarios are all checked before the first is solved."""
    _, log = load(sc)
    select(sc, log)
    return log


def select(sc: Scenario, log: Log) -> tuple[int, int]:
    """The record range ``[start, stop)`` the scenario's ``samples`` ask for."""
    n = log.n_records
    start = sc.samples.start
    stop = n if sc.samples.stop is None else sc.samples.stop
    if stop > n or start >= stop - 1:
        raise ScenarioError(f"samples: the range [{start}, {stop}) does not fit the log's {n} records")
    check_windows(sc, start, stop)
    return start, stop


def check_windows(sc: Scenario, start: int, stop: int) -> None:
    """Refuse, before anything is built, a horizon that leaves fewer windows than parameters."""
    H, stride = sc.residual.horizon, sc.residual.stride
    fit_stop = split(sc, start, stop)
    intervals = fit_stop - start - 1
    windows = 0 if intervals < H else (intervals - H) // stride + 1
    n_free = len(param_names(get_model(sc.model))) - len(set(sc.fixed))
    if windows >= n_free:
        return
    longest = intervals - (n_free - 1) * stride
    fix = f"shorten residual.horizon to at most {longest}" if longest >= 1 else "select more samples"
    part = f"{sc.origin} ({sc.dataset.name}): " if sc.origin else ""
    raise ScenarioError(
        f"{sc.path or sc.name}: {part}residual.horizon {H} (stride {stride}) leaves {windows} residual "
        f"window(s) in the {fit_stop - start} fitted records of samples [{start}, {stop}) for "
        f"{n_free} parameters; {fix}, or widen samples"
    )


def split(sc: Scenario, start: int, stop: int) -> int:
    """The first record of the hold-out (``stop`` when there is none)."""
    hf = sc.validation.holdout_fraction
    return stop if hf is None else start + round((1.0 - hf) * (stop - start))


def held(sc: Scenario, model: KinematicModel, log: Log, start: int, stop: int) -> dict[str, str]:
    """Free parameters the records ``start:stop`` cannot determine at all, with the reason: the
    fit holds them at their initial values (with a warning) instead of failing as singular."""
    inputs = model.inputs(log.select(start, stop), sc.residual.steering_sample)
    return {n: why for n, why in model.undetermined(inputs).items() if n not in sc.fixed}


def build_problem(sc: Scenario, model: KinematicModel, also_fixed: tuple[str, ...] = ()) -> ProblemFunctions:
    """The problem's Functions for the scenario's residual form, kernel and fixed parameters."""
    with scenario_key(sc, "residual"):
        return build(
            model,
            ProblemSpec(
                horizon=sc.residual.horizon,
                integration=sc.residual.integration,
                kernel=sc.robust.kernel,
                fixed=(*sc.fixed, *also_fixed),
            ),
        )


def initial_parameters(sc: Scenario, model: KinematicModel, log: Log) -> dict[str, float]:
    """The log header's values, overridden by the scenario's mapping (``auto`` fills in later)."""
    guess = dict(model.defaults)
    guess.update(
        {n: v for n, v in header_parameters(model, log.header).items() if n in model.kinematic_params}
    )
    guess.update(zip(SENSOR_PARAMS, log.header.T_base_sensor))
    if isinstance(sc.initial_guess, Mapping):
        guess.update(sc.initial_guess)
    needed = sc.fixed if sc.initial_guess == "auto" else (*model.kinematic_params, *SENSOR_PARAMS)
    missing = [n for n in needed if n not in guess]
    if missing:
        raise ScenarioError(
            f"the log header gives no initial value for {missing}; set them under initial_guess"
        )
    return guess


@dataclass(frozen=True)
class StartingPoint:
    """Where the solvers start (free parameters ``x0``), the fixed values and the bounds."""

    initial: Mapping[str, float]
    auto: Mapping[str, float] | None
    x0: np.ndarray
    x_fixed: np.ndarray
    lower: np.ndarray | None
    upper: np.ndarray | None


def auto_guess(sc: Scenario, fns: ProblemFunctions, log: Log, start: int, stop: int) -> dict[str, float]:
    """The model's closed-form estimate from the windows of records ``start:stop`` (no guess needed)."""
    data = build_residual_data(fns, log.select(start, stop), sc.residual)
    rows = fns.n_inputs * data.horizon
    # Windows overlapping by three quarters carry nearly all the information at a fraction
    # of the cost of every window.
    step = max(1, data.horizon // (4 * sc.residual.stride))
    columns = data.columns_of(np.arange(0, data.n_residuals, step))

    def base_motion(params: Mapping[str, float]) -> np.ndarray:
        return over_columns(fns.predict_window, np.array([params[n] for n in fns.names]), columns[:rows])[0]

    return fns.model.initial_guess(columns[:rows], columns[rows : rows + 3], base_motion)


def starting_point(sc: Scenario, fns: ProblemFunctions, log: Log, start: int, stop: int) -> StartingPoint:
    """Initial values (header, scenario, or ``auto`` from records ``start:stop``) and bounds."""
    initial = initial_parameters(sc, fns.model, log)
    auto = None
    if sc.initial_guess == "auto":
        auto = auto_guess(sc, fns, log, start, stop)
        initial.update({n: v for n, v in auto.items() if n not in sc.fixed})
    x0 = np.array([initial[n] for n in fns.free])
    lower, upper = None, None
    if sc.bounds:
        lower = np.array([sc.bounds[n][0] if n in sc.bounds else -np.inf for n in fns.free])
        upper = np.array([sc.bounds[n][1] if n in sc.bounds else np.inf for n in fns.free])
        for name, lo, hi, x in zip(fns.free, lower, upper, x0):
            if not lo <= x <= hi:
                origin = "from initial_guess: auto" if sc.initial_guess == "auto" else "from the log header"
                raise ScenarioError(
                    f"{sc.path or sc.name}: bounds.{name}: the initial guess {x:g} lies outside "
                    f"[{lo:g}, {hi:g}] (it comes {origin}); widen the bounds or set initial_guess.{name}"
                )
    return StartingPoint(
        initial=initial,
        auto=auto,
        x0=x0,
        x_fixed=np.array([initial[n] for n in fns.fixed]),
        lower=lower,
        upper=upper,
    )


def evaluated(sc: Scenario, solvers: Sequence[str]) -> set[str]:
    """The per-residual Functions a run with ``solvers`` evaluates (the pipeline's own fits and
    the analyses included)."""
    names = {"normal_equations", "cost", *uncertainty.FUNCTIONS}
    for name in solvers:
        names.update(get_solver(name).functions(sc.options_for(name)))
    return names


def prepare_backend(sc: Scenario, fns: ProblemFunctions, solvers: Sequence[str], n_records: int) -> Backend:
    """The scenario's evaluation backend, getting ready every Function a run with ``solvers`` maps
    over the windows of about ``n_records`` records."""
    with scenario_key(sc, "backend"):
        backend = make_backend(BackendOptions(kind=sc.backend, threads=sc.threads))
    backend.prepare(requests(fns, evaluated(sc, solvers), n_records // sc.residual.stride))
    return backend


@dataclass(frozen=True)
class Binder:
    """Binds the problem to the windows of a record range: evaluators share everything else."""

    scenario: Scenario
    fns: ProblemFunctions
    backend: Backend
    x_fixed: np.ndarray
    priors: Priors
    #: Per interval / record of the whole log: windows must not cross / start or end at them.
    bad_intervals: np.ndarray | None = None
    bad_records: np.ndarray | None = None

    def bind(
        self, log: Log, start: int, stop: int, evaluator: ProblemEvaluator | None = None
    ) -> tuple[ResidualData, ProblemEvaluator]:
        """Residual data of records ``start:stop`` of ``log`` and an evaluator bound to it (``evaluator``
        re-bound, when given)."""
        sc = self.scenario
        data = build_residual_data(
            self.fns,
            log.select(start, stop),
            sc.residual,
            drop_stationary=sc.samples.drop_stationary,
            bad_intervals=None if self.bad_intervals is None else self.bad_intervals[start : stop - 1],
            bad_records=None if self.bad_records is None else self.bad_records[start:stop],
        )
        if data.n_residuals < self.fns.n_free:
            at_faults = (
                f" ({data.dropped_faulty} windows crossing faults were left out; "
                "'faults: {handling: keep}' fits them)"
                if data.dropped_faulty
                else ""
            )
            raise ScenarioError(
                f"only {data.n_residuals} residuals in records [{start}, {stop}) for "
                f"{self.fns.n_free} parameters; widen 'samples' or shorten the horizon{at_faults}"
            )
        return data, self.evaluate(data, evaluator)

    def evaluate(self, data: ResidualData, evaluator: ProblemEvaluator | None = None) -> ProblemEvaluator:
        """An evaluator on the windows ``data`` (``evaluator`` re-bound, when given)."""
        if evaluator is not None:
            evaluator.bind(data)
            return evaluator
        return ProblemEvaluator(
            self.fns,
            data,
            x_fixed=self.x_fixed,
            omega=np.array(self.scenario.information.omega()),
            delta=self.scenario.robust.delta,
            priors=self.priors,
            backend=self.backend,
        )

    def inputs(self, log: Log, start: int, stop: int) -> np.ndarray:
        """The interval inputs of records ``start:stop`` of ``log`` (what :meth:`bind` binds)."""
        return interval_inputs(
            self.fns.model, [log.select(start, stop)], self.scenario.residual.steering_sample
        )

    def fit(self, evaluator: ProblemEvaluator, x0: np.ndarray) -> tuple[float, np.ndarray, bool]:
        """The internal solver's cost, estimate and convergence from ``x0``."""
        name = INTERNAL_SOLVER
        with scenario_key(self.scenario, name):
            res = get_solver(name)(evaluator, self.scenario.options_for(name)).solve(x0)
        return res.cost, res.x, res.converged


def no_priors(n_free: int) -> Priors:
    return Priors(np.zeros(n_free), np.zeros(n_free))


def weigh_priors(
    binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray
) -> tuple[Priors, float | None]:
    """The scenario's priors weighed against the data in the data's own noise units.

    The data term ``Σ ρ(eᵀΩe)`` is not divided by the residual variance σ², so a prior
    ``((x − μ)/std)²`` enters multiplied by σ², which is estimated from a fit without priors.
    Both solvers then minimise ``σ²·(data/σ² + priors)``: a MAP estimate. Returns the priors and σ.
    """
    sc, fns = binder.scenario, binder.fns
    if not sc.priors:
        return no_priors(fns.n_free), None
    _, ev = binder.bind(log, start, stop)
    _, x, _ = binder.fit(ev, x0)
    _, s, weight = ev.robust_terms(x)
    sigma = float(np.sqrt(float(np.sum(weight * s)) / max(3 * ev.n_residuals - fns.n_free, 1)))
    return (
        Priors(
            mean=np.array([sc.priors[n].mean if n in sc.priors else 0.0 for n in fns.free]),
            sqrt_info=np.array([sigma / sc.priors[n].std if n in sc.priors else 0.0 for n in fns.free]),
        ),
        sigma,
    )


def with_priors(binder: Binder, priors: Priors) -> Binder:
    """The same binder with other priors."""
    return replace(binder, priors=priors)


@dataclass(frozen=True)
class Findings:
    """The faults found in the used records, how they were handled and what a repair changed."""

    report: FaultReport
    handling: str
    repairs: tuple[str, ...] = ()


def find_faults(binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray) -> FaultReport:
    """Faults in records ``start:stop`` of ``log`` as logged (nothing re-sampled), the counters
    judged with a fit to the windows the binder keeps and the streams' own glitches spoil not, at
    the scenario's tracker lag (or, when it is estimated, the screen's own estimate in its range)."""

    def judge(bad_intervals: np.ndarray, bad_records: np.ndarray) -> np.ndarray | None:
        masks = np.zeros(log.n_records - 1, dtype=bool), np.zeros(log.n_records, dtype=bool)
        masks[0][start : stop - 1], masks[1][start:stop] = bad_intervals, bad_records
        masked = replace(binder, bad_intervals=masks[0], bad_records=masks[1])
        _, ev = masked.bind(log, start, stop)
        _, x, converged = masked.fit(ev, x0)
        return ev.params(x) if converged and np.all(np.isfinite(x)) else None

    al = binder.scenario.alignment
    lag = al.search if al.tracker_lag == "auto" else float(al.tracker_lag)
    sample = binder.scenario.residual.steering_sample
    return screen(binder.fns, log.select(start, stop), sample, lag, judge).shifted(start, log)


def handle_faults(log: Log, report: FaultReport, handling: str) -> tuple[Log, Findings]:
    """The log to fit (repaired when ``handling`` asks for it) and what was found and done."""
    if handling == "repair" and report.encoder_faults:
        log, repairs = repair(log, report)
        return log, Findings(report, handling, repairs)
    return log, Findings(report, handling)


def exclude_faults(binder: Binder, findings: Findings, n_records: int, lag_s: float, dt_s: float) -> Binder:
    """A binder that skips the windows the findings spoil on a log re-sampled by ``lag_s``.

    Re-sampling the encoders by a lag spreads a faulty reading over the records within the lag,
    so a fault's stretch is widened by that many records (plus one) on each side.
    """
    if findings.handling == "keep" or not findings.report.faults:
        return binder
    faults = findings.report.faults
    if findings.handling == "repair":
        faults = tuple(f for f in faults if f.kind == "tracker_jump")
    bad_intervals, bad_records = fault_masks(replace(findings.report, faults=faults), n_records, lag_s, dt_s)
    return replace(binder, bad_intervals=bad_intervals, bad_records=bad_records)


def fault_masks(
    report: FaultReport, n_records: int, lag_s: float, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """The intervals (widened by the records a lag re-samples across) and the tracker records the
    findings mark as bad, per interval and per record of the whole log."""
    reach = int(np.ceil(abs(lag_s) / dt_s)) + 1 if lag_s else 0
    return dilate(report.bad_intervals(n_records - 1), reach), report.bad_records(n_records)


def dilate(mask: np.ndarray, reach: int) -> np.ndarray:
    """``mask`` widened by ``reach`` elements on each side of every true run."""
    if reach <= 0 or not mask.any():
        return mask
    idx = np.flatnonzero(mask)
    out = np.zeros_like(mask)
    for i in idx:
        out[max(i - reach, 0) : i + reach + 1] = True
    return out
