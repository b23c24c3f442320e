"""The build stage: the problem's Functions, where the solvers start, the backend and the binder.

:class:`Binder` binds the built problem to the windows of any record range; every internal fit
(the priors' noise scale, the fault screen, the lag search, the validation refits) and the final
fit use one, so nothing is built twice.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.analysis import uncertainty
from nlp_calib.core.errors import ScenarioError
from nlp_calib.logs import Log
from nlp_calib.models import SENSOR_PARAMS, KinematicModel, header_parameters
from nlp_calib.models.camera_start import FIT_REASONS, CameraStart, Selection
from nlp_calib.models.mount import SCALE_PARAM, mount_rotation
from nlp_calib.pipeline.keys import scenario_key
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
from nlp_calib.problem.camera import camera_initial_guess, fit_selection
from nlp_calib.solvers import Priors, ProblemEvaluator, get_solver
from nlp_calib.solvers.backends import Backend, BackendOptions, make_backend
from nlp_calib.solvers.evaluation import requests

#: The solver the pipeline's own fits use (prior scaling, the fault screen, the lag search,
#: validation refits): the fastest.
INTERNAL_SOLVER = "gauss_newton"


def build_problem(sc: Scenario, model: KinematicModel, also_fixed: tuple[str, ...] = ()) -> ProblemFunctions:
    """The problem's Functions for the scenario's residual form, kernel and fixed parameters."""
    residual, sensor = sc.objective.residual, sc.objective.sensor
    spec = ProblemSpec(
        horizon=residual.horizon,
        integration=residual.integration,
        kernel=sc.objective.robust.kernel,
        fixed=(*sc.parameters.fixed, *also_fixed),
        sensor=sensor.mount,
        scale=sensor.scale,
    )
    with scenario_key(sc, "residual"):
        return build(model, spec)


def initial_parameters(sc: Scenario, model: KinematicModel, log: Log) -> dict[str, float]:
    """The log header's values, overridden by the scenario's mapping (``auto`` fills in later). A
    3-D mount's held ``sensor_z`` is 0 and its scale 1 unless the scenario gives them."""
    p, sensor = sc.parameters, sc.objective.sensor
    guess = dict(model.defaults)
    guess.update(
        {n: v for n, v in header_parameters(model, log.header).items() if n in model.kinematic_params}
    )
    if sensor.is_3d:
        guess.update(dict.fromkeys(sensor.held(), 0.0))
        guess.update({SCALE_PARAM: 1.0} if SCALE_PARAM in sensor.params() else {})
    else:
        guess.update(zip(SENSOR_PARAMS, log.header.T_base_sensor))
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


@dataclass(frozen=True)
class StartingPoint:
    """Where the solvers start (free parameters ``x0``), the fixed values and the bounds."""

    initial: Mapping[str, float]
    auto: Mapping[str, float] | None
    #: A 3-D sensor's start (closed-form, or the given mount's floor normal; None: planar): the
    #: floor normal the fit's windows are selected by, and the windows the closed form left out.
    camera: CameraStart | None
    x0: np.ndarray
    x_fixed: np.ndarray
    lower: np.ndarray | None
    upper: np.ndarray | None


def auto_guess(
    sc: Scenario, fns: ProblemFunctions, log: Log, start: int, stop: int, gaps: np.ndarray | None = None
) -> dict[str, float]:
    """The model's closed-form estimate from the windows of records ``start:stop`` that cross no
    gap (no guess needed)."""
    residual = sc.objective.residual
    data = build_residual_data(
        fns, log.select(start, stop), residual, bad_intervals=_within(gaps, start, stop)
    )
    rows = fns.n_inputs * data.horizon
    # Windows overlapping by three quarters carry nearly all the information at a fraction
    # of the cost of every window.
    step = max(1, data.horizon // (4 * residual.stride))
    columns = data.columns_of(np.arange(0, data.n_residuals, step))

    def base_motion(params: Mapping[str, float]) -> np.ndarray:
        return over_columns(fns.predict_window, np.array([params[n] for n in fns.names]), columns[:rows])[0]

    return fns.model.initial_guess(columns[:rows], columns[rows : rows + 3], base_motion)


def camera_guess(
    sc: Scenario, fns: ProblemFunctions, data: ResidualData, initial: Mapping[str, float]
) -> CameraStart:
    """A 3-D sensor's closed-form start (:func:`~nlp_calib.problem.camera.camera_initial_guess`) on
    ``data``, the held and fixed parameters at their ``initial`` values."""
    known = {n: initial[n] for n in fns.fixed}
    with scenario_key(sc, "initial_guess"):
        return camera_initial_guess(fns, data, known=known)


def _bounds(sc: Scenario, fns: ProblemFunctions, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    bounds = sc.parameters.bounds
    lower = np.array([bounds[n][0] if n in bounds else -np.inf for n in fns.free])
    upper = np.array([bounds[n][1] if n in bounds else np.inf for n in fns.free])
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
    sc: Scenario, fns: ProblemFunctions, log: Log, start: int, stop: int, gaps: np.ndarray | None = None
) -> StartingPoint:
    """Initial values (header, scenario, or ``auto`` from the windows of records ``start:stop``
    that cross no gap) and bounds."""
    initial = initial_parameters(sc, fns.model, log)
    auto, camera = None, None
    if sc.parameters.initial_guess == "auto" and sc.objective.sensor.is_3d:
        data = build_residual_data(
            fns, log.select(start, stop), sc.objective.residual, bad_intervals=_within(gaps, start, stop)
        )
        camera = camera_guess(sc, fns, data, initial)
        auto = camera.params
    elif sc.parameters.initial_guess == "auto":
        auto = auto_guess(sc, fns, log, start, stop, gaps)
    if auto is not None:
        initial.update({n: v for n, v in auto.items() if n not in sc.parameters.fixed})
    if camera is None and sc.objective.sensor.is_3d:
        camera = given_mount(initial)
    x0 = np.array([initial[n] for n in fns.free])
    lower, upper = _bounds(sc, fns, x0) if sc.parameters.bounds else (None, None)
    x_fixed = np.array([initial[n] for n in fns.fixed])
    return StartingPoint(initial, auto, camera, x0, x_fixed, lower, upper)


def given_mount(initial: Mapping[str, float]) -> CameraStart:
    """A given 3-D mount as a start: its floor normal in the camera frame is the third row of its
    rotation (no windows were selected)."""
    R = mount_rotation(initial)
    return CameraStart(dict(initial), R[2], Selection(np.zeros(0, dtype=np.int64)))


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
    return backend


def camera_selected(fns: ProblemFunctions, data: ResidualData, camera: CameraStart) -> ResidualData:
    """``data`` without the windows :func:`~nlp_calib.problem.camera.fit_selection` leaves out,
    their number by reason kept with it."""
    selection = fit_selection(fns, data, camera)
    counts = {r: n for r, n in selection.counts().items() if r in FIT_REASONS}
    return replace(data.select(selection.kept(FIT_REASONS)), dropped_selection=counts)


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
    #: A 3-D sensor's start: windows whose rotation axis is off its floor normal, or that turn
    #: against the wheels, are left out (``FIT_REASONS``).
    camera: CameraStart | None = None
    #: Per interval of the whole log: gaps in time, which no window crosses whatever the faults.
    gaps: np.ndarray | None = None

    def crossing(self) -> np.ndarray | None:
        """The intervals no window may cross: the faults' and the gaps."""
        if self.gaps is None or self.bad_intervals is None:
            return self.bad_intervals if self.gaps is None else self.gaps
        return self.bad_intervals | self.gaps

    def windows(self, log: Log, start: int, stop: int) -> ResidualData:
        """The residual windows of records ``start:stop`` of ``log`` (those the masks allow)."""
        sc = self.scenario
        data = build_residual_data(
            self.fns,
            log.select(start, stop),
            sc.objective.residual,
            drop_stationary=sc.log.samples.drop_stationary,
            bad_intervals=_within(self.crossing(), start, stop),
            bad_records=None if self.bad_records is None else self.bad_records[start:stop],
        )
        if self.camera is not None and data.n_residuals:
            data = camera_selected(self.fns, data, self.camera)
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
            omega=np.array(sc.objective.information.omega(self.fns.error_rows)),
            delta=sc.objective.robust.delta,
            priors=self.priors,
            backend=self.backend,
        )

    def inputs(self, log: Log, start: int, stop: int) -> np.ndarray:
        """The interval inputs of records ``start:stop`` of ``log`` (what :meth:`bind` binds)."""
        steering = self.scenario.objective.residual.steering_sample
        return interval_inputs(self.fns.model, [log.select(start, stop)], steering)

    def fit(
        self, evaluator: ProblemEvaluator, x0: np.ndarray, tolerance: float | None = None
    ) -> tuple[float, np.ndarray, bool]:
        """The internal solver's cost, estimate and convergence from ``x0``; with ``tolerance``,
        converged once the undamped step would lower the cost by less than that fraction of it."""
        name = INTERNAL_SOLVER
        with scenario_key(self.scenario, name):
            options = self.scenario.options_for(name)
            if tolerance is not None:
                options = replace(options, function_tolerance=max(options.function_tolerance, tolerance))
            res = get_solver(name)(evaluator, options).solve(x0)
        return res.cost, res.x, res.converged


def weigh_priors(
    binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray
) -> tuple[Priors, float | None]:
    """The scenario's priors weighed against the data in the data's own noise units.

    The data term ``Σ ρ(eᵀΩe)`` is not divided by the residual variance σ², so a prior
    ``((x − μ)/std)²`` enters multiplied by σ², which is estimated from a fit without priors.
    Both solvers then minimise ``σ²·(data/σ² + priors)``: a MAP estimate. Returns the priors and σ.
    """
    fns, priors = binder.fns, binder.scenario.parameters.priors
    if not priors:
        return no_priors(fns.n_free), None
    _, ev = binder.bind(log, start, stop)
    _, x, _ = binder.fit(ev, x0)
    _, s, weight = ev.robust_terms(x)
    sigma = float(np.sqrt(float(np.sum(weight * s)) / max(fns.error_rows * ev.n_residuals - fns.n_free, 1)))
    mean = np.array([priors[n].mean if n in priors else 0.0 for n in fns.free])
    sqrt_info = np.array([sigma / priors[n].std if n in priors else 0.0 for n in fns.free])
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
    gaps: np.ndarray | None = None,
) -> Problem:
    """Build the Functions (``held`` parameters fixed), start from the records ``start_from`` (a log
    and a range), get the backend ready for ``solvers`` over ``n_records`` and weigh the priors;
    no window crosses ``gaps`` (per interval of the log)."""
    fns = build_problem(sc, model, tuple(held))
    log, start, stop = start_from
    point = starting_point(sc, fns, log, start, stop, gaps)
    backend = prepare_backend(sc, fns, solvers, n_records)
    binder = Binder(sc, fns, backend, point.x_fixed, no_priors(fns.n_free), camera=point.camera, gaps=gaps)
    priors, _ = weigh_priors(binder, log, start, stop, point.x0)
    return Problem(fns, point, replace(binder, priors=priors))
