"""The build stage: the problem's Functions, where the solvers start, the backend and the binder.

:class:`Binder` binds the built problem to the windows of any record range; every internal fit
(the priors' noise scale, the fault screen, the lag search, the validation refits) and the final
fit use one, so nothing is built twice.
"""

from __future__ import annotations

import functools
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from nlp_calib.analysis import uncertainty
from nlp_calib.core.errors import ScenarioError
from nlp_calib.logs import Log
from nlp_calib.models import KinematicModel, header_parameters
from nlp_calib.pipeline.keys import scenario_key
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.problem import (
    ProblemFunctions,
    ProblemSpec,
    ResidualData,
    build,
    build_residual_data,
    interval_inputs,
)
from nlp_calib.problem.blocks import kinds_for
from nlp_calib.problem.functions import problem_layout
from nlp_calib.problem.start import closed_form_start, fit_windows
from nlp_calib.problem.windows import BLOCK, COMPILED_FROM, ColumnMap, compile_columns, resampled_data
from nlp_calib.results.layout import CLOCK, own_name
from nlp_calib.sensors import SensorStart, sensor_for
from nlp_calib.solvers import Priors, ProblemEvaluator, get_solver
from nlp_calib.solvers.backends import Backend, BackendOptions, make_backend
from nlp_calib.solvers.evaluation import requests

#: The solver the pipeline's own fits use (prior scaling, the fault screen, the lag search,
#: validation refits): the fastest.
INTERNAL_SOLVER = "gauss_newton"

#: A refit stops when the undamped Gauss-Newton step's predicted cost decrease is below this
#: squared, times the cost per window: a step of about this fraction of the estimate's σ.
REFIT_SIGMAS = 0.01


def lag_count(sc: Scenario, n_logs: int) -> int:
    """Time offsets in the problem: one per log when the scenario estimates the lag, else none."""
    return n_logs if sc.log.alignment.tracker_lag == "auto" else 0


def mount_count(sc: Scenario, n_logs: int) -> int:
    """Sensor mounts in the problem: one per log when the scenario says so (``mounts: per_log``) or
    the sensor has parameters of each log's own (a gyro's bias)."""
    sensor = sc.objective.sensor
    own = sensor.mounts == "per_log" or bool(sensor.sensor.per_log)
    return n_logs if own and n_logs > 1 else 1


def shared_mount(sc: Scenario, n_logs: int) -> tuple[str, ...]:
    """With a mount per log, the mount's parameters every log shares: none with ``mounts:
    per_log``, else all but the sensor's own per log."""
    sensor = sc.objective.sensor
    if mount_count(sc, n_logs) == 1 or sensor.mounts == "per_log":
        return ()
    return tuple(p for p in sensor.sensor.params if p not in sensor.sensor.per_log)


def build_problem(
    sc: Scenario, model: KinematicModel, also_fixed: tuple[str, ...] = (), n_logs: int = 1
) -> ProblemFunctions:
    """The problem's Functions for the scenario's residual form, kernel and fixed parameters, with a
    time offset per log (``n_logs``) when the lag is estimated, and a mount per log when asked."""
    residual, sensor = sc.objective.residual, sc.objective.sensor
    spec = ProblemSpec(
        horizon=residual.horizon,
        integration=residual.integration,
        kernel=sc.objective.robust.kernel,
        sensor=sensor.kind,
        scale=sensor.scale,
        lags=lag_count(sc, n_logs),
        mounts=mount_count(sc, n_logs),
        shared=shared_mount(sc, n_logs),
        logs=n_logs,
        blocks=kinds_for(model, n_logs),
    )
    # A scenario names a parameter by its key: fixing it fixes every log's own.
    layout = problem_layout(model, sensor_for(spec.sensor, spec.scale), spec)
    # (A lag held outside the problem, re-sampled at, is no parameter of it.)
    clocks = sc.objective.sensor.sensor.clocks
    fixed = layout.named(k for k in (*sc.parameters.fixed, *also_fixed) if k not in clocks or spec.lags)
    with scenario_key(sc, "residual"):
        return build(model, replace(spec, fixed=fixed))


def lag_start(sc: Scenario, n_logs: int, given: Sequence[float] = ()) -> dict[str, float]:
    """The time offsets' starting values, each of the sensor's clocks of each log: ``given`` (one
    per log), else the scenario's value for it (known, or under initial_guess), else 0."""
    p = sc.parameters
    guess = p.initial_guess if isinstance(p.initial_guess, Mapping) else {}
    lo, hi = sc.log.alignment.search
    out = {}
    for key in sc.objective.sensor.sensor.clocks:
        value = p.known.get(key, guess.get(key, 0.0))
        # A start outside the search (0 when the search is all one side of it) starts at its middle.
        start = float(value) if lo <= value <= hi else 0.5 * (lo + hi)
        for i in range(lag_count(sc, n_logs)):
            out[own_name(key, i, n_logs)] = float(given[i]) if given else start
    return out


def initial_parameters(sc: Scenario, model: KinematicModel, log: Log) -> dict[str, float]:
    """The log header's values, overridden by the scenario's mapping (``auto`` fills in later); the
    mount's from the sensor (a planar one: the header's nominal mount; a 3-D one: its held height
    0 and its scale 1) unless the scenario gives them."""
    p, sensor = sc.parameters, sc.objective.sensor
    guess = dict(model.defaults)
    guess.update(
        {n: v for n, v in header_parameters(model, log.header).items() if n in model.kinematic_params}
    )
    guess.update(sensor.sensor.initial(log.header))
    if isinstance(p.initial_guess, Mapping):
        guess.update(p.initial_guess)
    guess.update(p.known)
    mount = sensor.params()
    needed = p.fixed if p.initial_guess == "auto" else (*model.kinematic_params, *mount)
    missing = [n for n in needed if n not in guess]
    if missing:
        raise ScenarioError(
            f"the log header gives no initial value for {missing}; set them under initial_guess"
        )
    return guess


def nominal_values(
    sc: Scenario, model: KinematicModel, log: Log, guess: Mapping[str, float], free: Sequence[str]
) -> tuple[dict[str, float], str]:
    """The free parameters whose nominal values something knows (the log's header as its logger
    wrote it, ``ROBOT.yaml``, ``/tf_static``, the scenario's ``initial_guess`` mapping), at their
    values in ``guess`` (before a data-driven start replaces them), and where they come from in
    words. Model defaults are no robot's nominal values: a parameter only they give is left out."""
    header = log.header
    mount = tuple(sc.objective.sensor.sensor.nominal(header))
    if header.nominal is None:
        given = [*header_parameters(model, header), *mount]
        sources = {n: "the log's header" for n in given if n in model.kinematic_params or n in mount}
    else:
        sources = {
            n: where for n, where in header.nominal.items() if n in model.kinematic_params or n in mount
        }
    if isinstance(sc.parameters.initial_guess, Mapping):
        sources.update(dict.fromkeys(sc.parameters.initial_guess, "initial_guess"))
    sources = {n: where for n, where in sources.items() if n in free and n in guess}
    return {n: float(guess[n]) for n in sources}, ", ".join(dict.fromkeys(sources.values()))


@dataclass(frozen=True)
class StartingPoint:
    """Where the solvers start (free parameters ``x0``), the fixed values and the bounds; and the
    robot's nominal values where something knows them (``nominal``, from ``nominal_source``)."""

    initial: Mapping[str, float]
    auto: Mapping[str, float] | None
    #: The sensor's start (its closed form, or what it makes of a given mount; None: nothing to
    #: select the fit's windows by): its own record the fit's windows are selected by, and the
    #: windows the closed form left out.
    sensor: SensorStart | None
    x0: np.ndarray
    x_fixed: np.ndarray
    lower: np.ndarray | None
    upper: np.ndarray | None
    nominal: Mapping[str, float] = field(default_factory=dict)
    nominal_source: str = ""


def auto_start(
    sc: Scenario,
    fns: ProblemFunctions,
    log: Log,
    records: tuple[int, int],
    initial: Mapping[str, float],
    gaps: np.ndarray | None = None,
    nominal: Mapping[str, float] | None = None,
) -> SensorStart:
    """The sensor's closed-form start (:func:`~nlp_calib.problem.start.closed_form_start`) on the
    records ``records`` of ``log`` that cross no gap (``gaps``, per interval of the log), the fixed
    parameters at their ``initial`` values; the ``nominal`` robot in its place where it explains
    the windows better."""
    start, stop = records
    data = build_residual_data(
        fns, log.select(start, stop), sc.objective.residual, gaps=_within(gaps, start, stop)
    )
    known = {n: initial[n] for n in fns.fixed}
    with scenario_key(sc, "initial_guess"):
        return closed_form_start(fns, data, known, sc.objective.residual.stride, nominal)


def _key(fns: ProblemFunctions, name: str, given: Mapping[str, object]) -> str:
    """The scenario's key for parameter ``name`` in ``given``: its own, else its key in the layout."""
    return name if name in given else fns.layout.key(name)


def _bounds(sc: Scenario, fns: ProblemFunctions, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The scenario's bounds; a time offset's, unless given, ``alignment.search``."""
    bounds = {**dict.fromkeys(fns.sensor.clocks, sc.log.alignment.search), **sc.parameters.bounds}
    keys = [_key(fns, n, bounds) for n in fns.free]
    lower = np.array([bounds[k][0] if k in bounds else -np.inf for k in keys])
    upper = np.array([bounds[k][1] if k in bounds else np.inf for k in keys])
    for name, lo, hi, x in zip(fns.free, lower, upper, x0):
        if not lo <= x <= hi:
            origin = (
                "from initial_guess: auto" if sc.parameters.initial_guess == "auto" else "from the log header"
            )
            raise ScenarioError(
                f"{sc.path or sc.name}: bounds.{name}: the initial guess {x:g} lies outside "
                f"[{lo:g}, {hi:g}] (it comes {origin}); widen the bounds or set initial_guess.{name}"
            )
    return lower, upper


def _within(mask: np.ndarray | None, start: int, stop: int) -> np.ndarray | None:
    """A per-interval mask of the whole log over the intervals of records ``start:stop``."""
    return None if mask is None else mask[start : stop - 1]


def starting_point(
    sc: Scenario,
    fns: ProblemFunctions,
    log: Log,
    start: int,
    stop: int,
    lags: Sequence[float] = (),
    mounts: Sequence[Mapping[str, float]] = (),
    gaps: np.ndarray | None = None,
) -> StartingPoint:
    """Initial values (header, scenario, or ``auto`` from the windows of records ``start:stop``
    that cross no gap in ``gaps``; the time offsets ``lags``, one per log, when given; each log's
    own mount from ``mounts``, its own start, when the problem has a mount per log) and bounds."""
    initial = initial_parameters(sc, fns.model, log)
    initial.update(lag_start(sc, fns.spec.lags, lags))
    # A registered block's parameters start at their defaults.
    initial.update({p.name: p.start for p in fns.layout.parameters if p.block in fns.spec.blocks})
    nominal, source = nominal_values(sc, fns.model, log, initial, fns.free)
    one = fns.spec.mounts == 1
    sensor = (
        auto_start(sc, fns, log, (start, stop), initial, gaps, nominal)
        if sc.parameters.initial_guess == "auto" and one
        else None
    )
    auto = None if sensor is None else sensor.params
    if auto is not None:
        initial.update({n: v for n, v in auto.items() if n not in sc.parameters.fixed})
    if not one:
        # Each log's mount as its own start found it, the wheels as the first log's did.
        given = [{**initial, **m} for m in mounts] if mounts else [initial] * fns.spec.mounts
        initial = fns.full_dict(given)
        auto = dict(initial) if sc.parameters.initial_guess == "auto" else None
    if sensor is None:
        sensor = fns.sensor.given(initial)
    x0 = np.array([initial[n] for n in fns.free])
    bounded = sc.parameters.bounds or any(fns.layout.in_block(n, CLOCK) for n in fns.free)
    lower, upper = _bounds(sc, fns, x0) if bounded else (None, None)
    x_fixed = np.array([initial[n] for n in fns.fixed])
    return StartingPoint(initial, auto, sensor, x0, x_fixed, lower, upper, nominal, source)


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
        backend = make_backend(BackendOptions(kind=sc.compute.backend, threads=sc.compute.threads))
    stride = sc.objective.residual.stride
    backend.prepare(requests(fns, evaluated(sc, solvers), n_records // stride))
    compile_columns(_column_map(backend) if n_records >= COMPILED_FROM else None)
    return backend


def _column_map(backend: Backend) -> ColumnMap | None:
    """The helper Functions' maps over blocks of columns: the backend's compiled chunks, by its
    maps of fixed sizes (None: interpreted, or blocks that are no whole number of its chunks)."""
    if backend.name != "compiled" or BLOCK % backend.chunk:
        return None
    return functools.partial(_column_pieces, backend)


def _column_pieces(
    backend: Backend, f: ca.Function, n: int, mapped: tuple[str, ...]
) -> list[tuple[ca.Function, int]]:
    return [(_column_piece(backend, f, cols, mapped), cols) for cols in backend.spans(n)]


@functools.lru_cache(maxsize=64)
def _column_piece(backend: Backend, f: ca.Function, n: int, mapped: tuple[str, ...]) -> ca.Function:
    """``backend.map`` over ``n`` columns, built once per Function and size (a map of a compiled
    chunk takes tens of milliseconds to build: each call built its own)."""
    return backend.map(f, n, mapped, False)


def sensor_selected(fns: ProblemFunctions, data: ResidualData, start: SensorStart) -> ResidualData:
    """``data`` without the windows the sensor's start leaves out (:func:`~nlp_calib.problem.start.
    fit_windows`), their number by reason kept with it."""
    keep, counts = fit_windows(fns, data, start)
    return replace(data.select(keep), dropped_selection=counts)


def no_priors(n_free: int) -> Priors:
    return Priors(np.zeros(n_free), np.zeros(n_free))


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
    #: The sensor's start, which may leave some windows out (a camera's: those whose rotation axis
    #: is off its floor normal, or that turn against the wheels).
    start: SensorStart | None = None
    #: Bounds of the free parameters every internal fit keeps to (None: none).
    bounds: tuple[np.ndarray, np.ndarray] | None = None
    #: Per interval of the whole log: gaps in time, which no window crosses whatever the faults.
    gaps: np.ndarray | None = None

    #: Each evaluator :meth:`rebind` bound where the sensor's start chooses the windows: its records
    #: and their windows before the choice (they do not depend on the encoders), while it lives.
    _unchosen: weakref.WeakKeyDictionary[ProblemEvaluator, tuple[tuple[int, int], ResidualData]] = field(
        default_factory=weakref.WeakKeyDictionary, init=False, repr=False, compare=False
    )

    def windows(self, log: Log, start: int, stop: int) -> ResidualData:
        """The residual windows of records ``start:stop`` of ``log`` (those the masks allow)."""
        return self._chosen(self._unchosen_windows(log, start, stop), start, stop)

    def _unchosen_windows(self, log: Log, start: int, stop: int) -> ResidualData:
        """:meth:`windows` before the sensor's start chooses among them."""
        sc = self.scenario
        return build_residual_data(
            self.fns,
            log.select(start, stop),
            sc.objective.residual,
            drop_stationary=sc.log.samples.drop_stationary,
            bad_intervals=_within(self.bad_intervals, start, stop),
            bad_records=None if self.bad_records is None else self.bad_records[start:stop],
            gaps=_within(self.gaps, start, stop),
        )

    def _chosen(self, data: ResidualData, start: int, stop: int) -> ResidualData:
        """The windows ``data`` the sensor's start keeps (enough of them for the parameters)."""
        if self.start is not None and self.start.selection is not None and data.n_residuals:
            data = sensor_selected(self.fns, data, self.start)
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
        return data

    def bind(
        self, log: Log, start: int, stop: int, evaluator: ProblemEvaluator | None = None
    ) -> tuple[ResidualData, ProblemEvaluator]:
        """Residual data of records ``start:stop`` of ``log`` and an evaluator bound to it (``evaluator``
        re-bound, when given)."""
        data = self.windows(log, start, stop)
        return data, self.evaluate(data, evaluator)

    def rebind(self, evaluator: ProblemEvaluator, log: Log, start: int, stop: int) -> ProblemEvaluator:
        """``evaluator``, bound by :meth:`bind` to records ``start:stop`` of a log, bound to the same
        records of ``log``, that log with its encoders re-sampled at another offset (the same result
        as :meth:`bind`). Only the inputs and clock data are computed again, where the windows do not
        depend on the encoders: no stationary windows dropped. Where the sensor's start chooses
        among them by the inputs, it chooses again among the windows kept from the evaluator's
        first rebind (a lag search's 41 lags built its windows and their motions 41 times)."""
        sc = self.scenario
        if sc.log.samples.drop_stationary:
            return self.bind(log, start, stop, evaluator)[1]
        steering = sc.objective.residual.steering_sample
        shifted = [log.select(start, stop)]
        if self.start is None or self.start.selection is None:
            evaluator.bind(resampled_data(self.fns, evaluator.data, shifted, steering))
            return evaluator
        kept = self._unchosen.get(evaluator)
        if kept is not None and kept[0] == (start, stop):
            unchosen = resampled_data(self.fns, kept[1], shifted, steering)
        else:
            unchosen = self._unchosen_windows(log, start, stop)
        self._unchosen[evaluator] = ((start, stop), unchosen)
        return self.evaluate(self._chosen(unchosen, start, stop), evaluator)

    def evaluate(self, data: ResidualData, evaluator: ProblemEvaluator | None = None) -> ProblemEvaluator:
        """An evaluator on the windows ``data`` (``evaluator`` re-bound, when given)."""
        if evaluator is not None:
            evaluator.bind(data)
            return evaluator
        sc = self.scenario
        return ProblemEvaluator(
            self.fns,
            data,
            x_fixed=self.x_fixed,
            omega=np.array(sc.objective.information.omega(self.fns.error_rows, self.fns.sensor.weights)),
            delta=sc.objective.robust.delta,
            priors=self.priors,
            backend=self.backend,
        )

    def inputs(self, log: Log, start: int, stop: int, sample: str | None = None) -> np.ndarray:
        """The interval inputs of records ``start:stop`` of ``log`` (what :meth:`bind` binds; with
        each interval's steer angle read as ``sample`` instead of the scenario's steering_sample)."""
        sample = sample or self.scenario.objective.residual.steering_sample
        return interval_inputs(self.fns.model, [log.select(start, stop)], sample)

    def lag_held(self, x0: np.ndarray) -> Binder:
        """This binder with the time offsets held at their values in ``x0`` (fits on the records as
        logged, whose clock correction the screen does not apply)."""
        lags = [i for i, n in enumerate(self.fns.free) if self.fns.layout.in_block(n, CLOCK)]
        if not lags:
            return self
        n = self.fns.n_free
        lower, upper = self.bounds if self.bounds is not None else (np.full(n, -np.inf), np.full(n, np.inf))
        lower, upper = lower.copy(), upper.copy()
        lower[lags] = upper[lags] = np.asarray(x0, dtype=float)[lags]
        return replace(self, bounds=(lower, upper))

    def fit(
        self, evaluator: ProblemEvaluator, x0: np.ndarray, tolerance: float | None = None
    ) -> tuple[float, np.ndarray, bool]:
        """The internal solver's cost, estimate and convergence from ``x0``; with ``tolerance``,
        converged once the undamped step would lower the cost by less than that fraction of it.
        A fit out of iterations goes on from where it stopped until its next step would move it by
        under :data:`REFIT_SIGMAS` of its σ, as a refit stops: what a stage reads of it (a fault's
        judgement, a lag, a fold) needs no more (a skid-steer whose pivots mostly slipped ran out
        of its 200 steps at its optimum but for the last digits, and its screen judged nothing);
        one still far from its optimum does not stop so."""
        name = INTERNAL_SOLVER
        with scenario_key(self.scenario, name):
            options = self.scenario.options_for(name)
            if tolerance is not None:
                options = replace(options, function_tolerance=max(options.function_tolerance, tolerance))
            lower, upper = self.bounds if self.bounds is not None else (None, None)
            res = get_solver(name)(evaluator, options).solve(x0, lower, upper)
            if not res.converged and res.iterations >= options.max_iterations and np.all(np.isfinite(res.x)):
                near = REFIT_SIGMAS**2 / max(evaluator.n_residuals, 1)
                options = replace(options, function_tolerance=max(options.function_tolerance, near))
                res = get_solver(name)(evaluator, options).solve(res.x, lower, upper)
        return res.cost, res.x, res.converged


def weigh_priors(
    binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray, data: ResidualData | None = None
) -> tuple[Priors, float | None]:
    """The scenario's priors weighed against the data in the data's own noise units.

    The data term ``Σ ρ(eᵀΩe)`` is not divided by the residual variance σ², so a prior
    ``((x − μ)/std)²`` enters multiplied by σ², which is estimated from a fit without priors.
    Both solvers then minimise ``σ²·(data/σ² + priors)``: a MAP estimate. Returns the priors and σ.
    ``data``: the windows to weigh them on (every log's, for a problem with a mount per log), else
    records ``start:stop`` of ``log``.
    """
    fns, priors = binder.fns, binder.scenario.parameters.priors
    if not priors:
        return no_priors(fns.n_free), None
    ev = binder.evaluate(data) if data is not None else binder.bind(log, start, stop)[1]
    _, x, _ = binder.fit(ev, x0)
    _, s, weight = ev.robust_terms(x)
    sigma = float(np.sqrt(float(np.sum(weight * s)) / max(fns.error_rows * ev.n_residuals - fns.n_free, 1)))
    keys = [_key(fns, n, priors) for n in fns.free]
    mean = np.array([priors[k].mean if k in priors else 0.0 for k in keys])
    sqrt_info = np.array([sigma / priors[k].std if k in priors else 0.0 for k in keys])
    return Priors(mean=mean, sqrt_info=sqrt_info), sigma


@dataclass(frozen=True)
class Problem:
    """A problem built for a scenario: its Functions, the starting point and the binder that binds
    it to windows (with the priors weighed)."""

    fns: ProblemFunctions
    start: StartingPoint
    binder: Binder

    @property
    def model(self) -> KinematicModel:
        return self.fns.model


def build_stage(
    sc: Scenario,
    model: KinematicModel,
    held: Sequence[str],
    start_from: tuple[Log, int, int],
    solvers: Sequence[str],
    n_records: int,
    lags: Sequence[float] = (),
    mounts: Sequence[Mapping[str, float]] = (),
    data: ResidualData | None = None,
    gaps: np.ndarray | None = None,
) -> Problem:
    """Build the Functions (``held`` parameters fixed; a time offset per log of ``lags``, or one;
    a mount per log, each starting from ``mounts``' values, when the scenario asks), start from
    the records ``start_from`` (a log and a range), get the backend ready for ``solvers`` over
    ``n_records`` and weigh the priors (on ``data``, every log's windows, with a lag or a mount
    per log); no window crosses ``gaps`` (per interval of the log)."""
    fns = build_problem(sc, model, tuple(held), max(len(lags), len(mounts), 1))
    log, start, stop = start_from
    # The backend first: the start's helpers over every window (the tracker's motions, a closed
    # form's predictions) then map its compiled chunks, not CasADi's interpreter.
    backend = prepare_backend(sc, fns, solvers, n_records)
    point = starting_point(sc, fns, log, start, stop, lags, mounts, gaps)
    bounds = None if point.lower is None or point.upper is None else (point.lower, point.upper)
    binder = Binder(
        sc, fns, backend, point.x_fixed, no_priors(fns.n_free), start=point.sensor, bounds=bounds, gaps=gaps
    )
    # Several logs' own lags or mounts: weighed on every log's windows (one log's alone would not
    # say which lag or mount is whose).
    on = data if data is not None and max(fns.spec.mounts, fns.spec.lags) > 1 else None
    priors, _ = weigh_priors(binder, log, start, stop, point.x0, on)
    return Problem(fns, point, replace(binder, priors=priors))


def at_lags(problem: Problem, lags: Sequence[float], beside: Sequence[float] = ()) -> Problem:
    """``problem`` starting at the time offsets ``lags`` (one per log; the data's own once they are
    re-sampled there, so the problem's clock correction starts at zero), a second sensor's clock
    (a gyro's beside the reference) ``beside`` later (one per log; none: the reference's)."""
    fns, start = problem.fns, problem.start
    clocks = fns.sensor.clocks

    def at(name: str) -> float:
        p = fns.layout.param(name)
        i = p.log or 0
        return lags[i] + (beside[i] if beside and len(clocks) > 1 and p.key == clocks[1] else 0.0)

    given = {n: at(n) for n in fns.layout.block(CLOCK)}
    if not any(n in given for n in fns.free):
        return problem
    initial = {**start.initial, **given}
    x0 = np.array([initial[n] for n in fns.free])
    return replace(problem, start=replace(start, initial=initial, x0=x0))


def restarted(
    problem: Problem,
    sc: Scenario,
    start_from: tuple[Log, int, int],
    lags: Sequence[float] = (),
    mounts: Sequence[Mapping[str, float]] = (),
) -> Problem:
    """``problem`` started from ``sc``'s initial guess (a stored calibration's values, for a check)
    on the records ``start_from``: its Functions, backend, priors and the sensor's start that
    selects its windows stay those it was built with, so a check fits the windows a run fits."""
    log, start, stop = start_from
    point = starting_point(sc, problem.fns, log, start, stop, lags, mounts, problem.binder.gaps)
    bounds = None if point.lower is None or point.upper is None else (point.lower, point.upper)
    binder = replace(problem.binder, scenario=sc, x_fixed=point.x_fixed, bounds=bounds)
    return Problem(problem.fns, point, binder)


def lags_held(problem: Problem) -> Problem:
    """``problem`` with its time offsets held at their starts (their bounds closed on them), in
    the solvers and in the pipeline's own fits: a lag no fit converged at is no parameter."""
    binder = problem.binder.lag_held(problem.start.x0)
    if binder is problem.binder or binder.bounds is None:
        return problem
    lower, upper = binder.bounds
    return replace(problem, binder=binder, start=replace(problem.start, lower=lower, upper=upper))
