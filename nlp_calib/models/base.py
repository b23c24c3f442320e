"""What a kinematic model provides to the rest of the package.

A model is one file: its parameter names and units, how the log header names them, which encoders
it reads and of what kind, how raw readings become per-interval inputs (numeric, once per log),
the symbolic base-link increment those inputs produce, the precision a useful calibration must
reach, its closed-form start, its canonical form and the drive the simulator uses. Everything
above this layer uses a model only through :class:`KinematicModel`; adding one is one file and
one line in :mod:`nlp_calib.models`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Protocol, runtime_checkable

import casadi as ca
import numpy as np

from nlp_calib.core.errors import ModelError
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.logs import EncoderKind, Log, LogHeader
from nlp_calib.models.clock import LAG_REFERENCE
from nlp_calib.models.controllers import ControllerMap, EncoderScales

if TYPE_CHECKING:
    from nlp_calib.models.drives import Drive

#: The sensor mounting pose ``T_base_sensor`` closes every parameter vector, in this order.
SENSOR_PARAMS: tuple[str, str, str] = ("sensor_x", "sensor_y", "sensor_theta")
SENSOR_UNITS: Mapping[str, str] = {"sensor_x": "m", "sensor_y": "m", "sensor_theta": "rad"}

INTEGRATIONS = ("exact", "euler")
#: 1σ of rounding to whole ticks (uniform over one tick).
QUANTISATION = 1.0 / np.sqrt(12.0)
STEERING_SAMPLES = ("start", "end", "mean", "travel")

#: A reference precision: a fraction of the parameter's value, or an absolute amount in its unit.
Reference = tuple[Literal["relative", "absolute"], float]
#: What a useful calibration must resolve of the sensor pose: 1 cm and 5 mrad.
SENSOR_REFERENCE: Mapping[str, Reference] = {
    "sensor_x": ("absolute", 0.01),
    "sensor_y": ("absolute", 0.01),
    "sensor_theta": ("absolute", 0.005),
}


#: A car's steered wheels' largest angle when the scenario gives none (rad): road cars and car-like
#: robots steer their road wheels about 30–40°.
CAR_STEER_MAX = math.radians(35.0)
#: A steered wheel that drives the base (a tricycle's): it turns a quarter turn, about the rear axle.
QUARTER_TURN = 0.5 * math.pi


@dataclass(frozen=True)
class Reach:
    """What a base can drive, so that a plan asks for nothing else: its base link's tightest turn
    radius (m; 0: it turns on the spot) and the steered wheel's largest angle that gives it (rad;
    None: no wheel steers)."""

    min_radius_m: float
    steer_max_rad: float | None = None

    @property
    def spot_turns(self) -> bool:
        return self.min_radius_m == 0.0


def steered_reach(length: float, steer_max: float, beside: float = 0.0) -> Reach:
    """The reach of a base whose steered wheel, ``length`` ahead of the base link, turns at most
    ``steer_max`` (rad): radius ``length / tan(steer_max)`` (plus ``beside``, an inner wheel's
    distance from the midline); a wheel that turns a quarter turn turns the base on the spot."""
    steer = min(abs(steer_max), QUARTER_TURN)
    if steer >= QUARTER_TURN - 1e-9:
        return Reach(0.0, steer)
    return Reach(abs(length) / math.tan(steer) + abs(beside), steer)


@dataclass(frozen=True)
class Symmetry:
    """An exact symmetry of a model: ``negate`` and ``turn`` (+π) map a parameter set onto another
    that predicts the same motion. The canonical form has ``sign`` > 0."""

    description: str
    sign: str
    negate: tuple[str, ...]
    turn: tuple[str, ...]

    @property
    def moves(self) -> frozenset[str]:
        return frozenset((*self.negate, *self.turn))

    def apply(self, params: Mapping[str, float]) -> dict[str, float]:
        out = dict(params)
        for n in self.negate:
            out[n] = -out[n]
        for n in self.turn:
            out[n] += np.pi
        return out


#: The base frame turned round: the mounting pose rotated by π (a part of most symmetries).
SENSOR_TURNED: tuple[tuple[str, ...], tuple[str, ...]] = (("sensor_x", "sensor_y"), ("sensor_theta",))


class KinematicModel(Protocol):
    """A wheeled base: parameters, encoder inputs and the symbolic SE(2) increment."""

    #: Name used in scenarios (``model:``).
    @property
    def name(self) -> str: ...
    #: ``#kinematic_model:`` values of logs this model reads.
    @property
    def log_names(self) -> tuple[str, ...]: ...
    #: Kinematic parameter names, in state order (the sensor pose follows them), and their units.
    @property
    def kinematic_params(self) -> tuple[str, ...]: ...
    @property
    def units(self) -> Mapping[str, str]: ...
    #: Header (``#parameters``) spelling of each kinematic parameter, written by the simulator;
    #: ``header_aliases`` maps every accepted spelling (lower case) onto a parameter name.
    @property
    def header_names(self) -> Mapping[str, str]: ...
    @property
    def header_aliases(self) -> Mapping[str, str]: ...
    #: The encoders (``#joints_max_enc`` names) the model reads, in input order, with their kind.
    @property
    def encoder_kinds(self) -> Mapping[str, EncoderKind]: ...
    #: Names of the per-interval inputs :meth:`inputs` returns, in row order, and their units.
    @property
    def input_names(self) -> tuple[str, ...]: ...
    #: The inputs that are a level read at the interval (an angle) rather than an increment over
    #: it: a shorter interval keeps their value (the time offset's end corrections need this).
    @property
    def level_inputs(self) -> tuple[str, ...]: ...
    @property
    def input_units(self) -> Mapping[str, str]: ...
    #: Kinematic parameters a log without turning cannot determine, and a note on what else.
    @property
    def turning_params(self) -> tuple[str, ...]: ...
    @property
    def turning_note(self) -> str: ...
    #: Plausible ranges, used to reject absurd initial guesses and as basin-study ranges.
    @property
    def physical_ranges(self) -> Mapping[str, tuple[float, float]]: ...
    #: Precision a useful calibration must reach on each kinematic parameter.
    @property
    def reference(self) -> Mapping[str, Reference]: ...
    #: The kinematic parameters a one-line summary shows.
    @property
    def headline(self) -> tuple[str, ...]: ...
    #: Values of kinematic parameters a log header need not carry (used when it does not).
    @property
    def defaults(self) -> Mapping[str, float]: ...
    #: The model's exact symmetries, applied in this order to reach the canonical form, and the
    #: angles the canonical form wraps onto (-π, π].
    @property
    def symmetries(self) -> tuple[Symmetry, ...]: ...
    @property
    def angle_params(self) -> tuple[str, ...]: ...
    #: The steered wheel's largest angle when the scenario gives none (rad; None: no wheel steers).
    @property
    def steer_max(self) -> float | None: ...

    def reach(self, params: Mapping[str, float], steer_max: float | None = None) -> Reach:
        """What the base with ``params`` can drive (its tightest turn, whether it turns on the spot),
        its steered wheel turned at most ``steer_max`` (rad; None: :attr:`steer_max`)."""
        ...

    @property
    def drive(self) -> Drive:
        """The simulator's independent numpy drive of this base."""
        ...

    def increment(self, k: ca.SX, u: ca.SX, integration: str) -> ca.SX:
        """Base-link motion ``(x, y, theta)`` over one interval for parameters ``k``, inputs ``u``."""
        ...

    def inputs(self, log: Log, steering_sample: str) -> np.ndarray:
        """Per-interval inputs, ``(len(input_names), n_records - 1)``, from the raw encoders."""
        ...

    def input_rates(self, log: Log) -> np.ndarray | None:
        """Each input's rate per second at each record (a level: its value), ``(len(input_names),
        n_records)``, where the log says exactly (joints with a stream of their own); None: the
        problem takes them from the intervals' inputs (:mod:`nlp_calib.problem.clock`)."""
        ...

    def moving(self, inputs: np.ndarray) -> np.ndarray:
        """Boolean mask of intervals in which the encoders report motion."""
        ...

    def travel_direction(self, inputs: np.ndarray) -> np.ndarray:
        """Per interval: +1 when the base drives forward, -1 backward, 0 when it does not move."""
        ...

    def undetermined(self, inputs: np.ndarray) -> dict[str, str]:
        """Kinematic parameters these inputs cannot determine at all, each with the reason (the
        pipeline holds them at their initial value)."""
        ...

    def counter_rows(self, log: Log) -> dict[str, tuple[int, float]]:
        """For each counter encoder: the input row it drives and the ticks per unit of that input."""
        ...

    def controller(self, params: Mapping[str, float], scales: EncoderScales) -> ControllerMap:
        """The ros2_control controller of this base, its parameters from ``params`` (and what the
        encoders' ``scales`` make of them), where each kinematic parameter with no place among them
        belongs and why any of the controller's parameters is left out."""
        ...

    def in_radians(self) -> KinematicModel:
        """The same base read from joint positions in radians, its parameters in robot units
        (:mod:`nlp_calib.models.radians`)."""
        ...

    def implausible(self, params: Mapping[str, float]) -> str:
        """Why an estimate cannot be a real robot of this kind even though it fits the data (a mirror
        image: e.g. swapped wheel encoders), with the likely cause; "" when it can."""
        ...

    def input_noise_std(self, log: Log, encoder_noise: Mapping[str, float] | None = None) -> np.ndarray:
        """1σ noise of each input row, from each encoder's noise in ticks (default: quantisation)."""
        ...

    def initial_guess(
        self,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: Callable[[Mapping[str, float]], np.ndarray],
    ) -> dict[str, float]:
        """All parameters from horizon windows (inputs ``U``, sensor motions ``z``), no guess needed.

        ``base_motion(params)`` evaluates the windows' base motion ``(3, M)`` for given parameters.
        """
        ...


def named(names: Sequence[str], vector: ca.SX) -> dict[str, ca.SX]:
    """The entries of a symbolic ``vector`` by name (``names`` in its order): models write their
    expressions with parameter and input names, never positions."""
    return {name: vector[i] for i, name in enumerate(names)}


@runtime_checkable
class OdometryInverse(Protocol):
    """A model that turns a controller's odometry back into the readings it integrated (a robot
    that publishes only its own odometry: :mod:`nlp_calib.sources.vendor`)."""

    def readings_from_odometry(self, base: np.ndarray, params: Mapping[str, float]) -> dict[str, np.ndarray]:
        """Each encoder's readings, in the unit of the input it drives (a counter's running sum
        from 0, an angle's level), that a controller running this model with ``params`` turned
        into the base poses ``base`` ``(n, 3)``."""
        ...


def rows_by_name(names: Sequence[str], U: np.ndarray) -> dict[str, np.ndarray]:
    """The rows of each named input in horizon windows ``U`` (``len(names)·H`` rows, the inputs of
    each interval in turn)."""
    return {name: U[i :: len(names)] for i, name in enumerate(names)}


def record_rates(increments: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """Each row's rate per second at each record: the increments of the two intervals around it
    over their duration (one interval at the log's ends)."""
    n_rows, n = increments.shape[0], time_s.size
    if n < 2:
        return np.zeros((n_rows, n))
    dt = np.diff(time_s)
    pad = np.zeros((n_rows, 1))
    span = np.concatenate([[0.0], dt]) + np.concatenate([dt, [0.0]])
    return (np.hstack([pad, increments]) + np.hstack([increments, pad])) / span


def sampled_angle(
    angle: np.ndarray,
    steering_sample: str,
    travel: np.ndarray | None = None,
    time_s: np.ndarray | None = None,
) -> np.ndarray:
    """Per interval, an angle read at each record (rad), taken at the interval's ``start``, its
    ``end``, the ``mean`` over the interval, or ``travel``: the angle the interval's travel saw
    (:func:`travel_weighted`; needs each interval's ``travel`` and the records' ``time_s``). Both
    ``mean`` and ``travel`` take the angle between the two readings (along the shorter arc) and
    correct it for the angle's curvature over the interval (:func:`curvature_correction`; records
    equally spaced where ``time_s`` is None)."""
    if steering_sample == "start":
        return angle[:-1]
    if steering_sample == "end":
        return angle[1:]
    change = wrap_angle(angle[1:] - angle[:-1])
    share = 0.5 if steering_sample == "mean" else travel_weighted(travel, time_s)
    times = np.arange(angle.size, dtype=float) if time_s is None else np.asarray(time_s, dtype=float)
    return wrap_angle(angle[:-1] + share * change + curvature_correction(angle, times))


def curvature_correction(angle: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """Per interval, what its angle's mean over time differs from its two readings' mean by:
    ``−φ̈·h²/12`` for an interval of ``h`` s, ``φ̈`` the mean of the second differences at its two
    records (0 at the log's ends). The same for the mean the travel saw, whatever the speed's
    linear change. A steering that turns one way and back peaks between its readings, whose mean
    reads every peak short: on the simulator's drives that put ``k_steer`` +1.5·10⁻⁴ high at 25 Hz
    (3σ at 0.2 mm tracker noise; ``benchmarks/steering_interval_study.py``). A record whose second
    difference has a neighbour of the opposite sign at least half its size is a reading off the
    line of both neighbours (a one-record spike, a reading held then caught up): it gives none,
    so a glitch moves only the two intervals that read it."""
    h = np.diff(time_s)
    if h.size < 2:
        return np.zeros(h.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(h > 0, wrap_angle(np.diff(angle)) / h, 0.0)
        span = h[:-1] + h[1:]
        inner = np.where(span > 0, 2.0 * np.diff(slope) / span, 0.0)
    acc = np.concatenate([[0.0], inner, [0.0]])
    around = np.concatenate([[0.0], acc, [0.0]])
    opposed = [(side * acc < 0) & (np.abs(side) >= 0.5 * np.abs(acc)) for side in (around[:-2], around[2:])]
    acc = np.where(opposed[0] | opposed[1], 0.0, acc)
    return -0.5 * (acc[:-1] + acc[1:]) * h * h / 12.0


def travel_weighted(travel: np.ndarray | None, time_s: np.ndarray | None) -> np.ndarray:
    """Per interval, where along its angle's change the travel's mean lies: ``½ + (v_b − v_a) / (6
    (v_a + v_b))`` for speeds ``v_a``, ``v_b`` at its two records (:func:`record_rates`), the
    angle and the speed each linear over it. The angle turns the motion in proportion to the
    travel, so an interval that speeds up while it steers (off a stop) turned by the angle nearer
    its end than the two readings' mean; the mean is half an interval's share of the change off,
    in opposite directions speeding up and slowing down, and a drive that starts off more sharply
    than it stops biases a time offset fitted on it (the tracker lag). ``½`` where the direction
    of travel changes within the interval."""
    if travel is None or time_s is None:
        raise ModelError(
            "steering_sample 'travel' is for a model that reads its travel from counters (a steered one)"
        )
    speed = np.abs(record_rates(np.asarray(travel, dtype=float)[None], np.asarray(time_s, dtype=float))[0])
    v_a, v_b = speed[:-1], speed[1:]
    total = v_a + v_b
    one_way = (travel[:-1] * travel[1:] >= 0) if travel.size > 1 else np.ones(0, dtype=bool)
    same = np.concatenate([[True], one_way]) & np.concatenate([one_way, [True]])
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.where((total > 0) & same, (v_b - v_a) / (6.0 * total), 0.0)
    return 0.5 + shift


def canonical(
    model: KinematicModel, params: Mapping[str, float], fixed: tuple[str, ...] = ()
) -> dict[str, float]:
    """The same physical calibration in the model's canonical form: each symmetry applied where its
    sign parameter is negative, then the angles wrapped. A symmetry that would move a parameter in
    ``fixed`` is skipped, and fixed angles are not wrapped."""
    p = dict(params)
    for sym in model.symmetries:
        if p[sym.sign] < 0 and not sym.moves & set(fixed):
            p = sym.apply(p)
    for name in model.angle_params:
        if name not in fixed:
            p[name] = float(wrap_angle(p[name]))
    return p


def counted_inputs(model: KinematicModel, log: Log) -> np.ndarray:
    """Which of ``model``'s inputs are a counter's increments (their noise lies on the readings,
    two of them per increment), one flag per input row."""
    counted = np.zeros(len(model.input_names), dtype=bool)
    counted[[row for row, _ in model.counter_rows(log).values()]] = True
    return counted


def rate_rows(model: KinematicModel) -> dict[int, int]:
    """Each input row that is a joint's rate over its interval (its increment over the interval's
    duration), with the row of that increment: a counter's noise reaches both."""
    form = model.in_radians()
    spec, names = form.form.inputs, form.model.input_names  # type: ignore[attr-defined]
    increments = {spec[n].encoder: row for row, n in enumerate(names) if not spec[n].rate}
    return {row: increments[spec[n].encoder] for row, n in enumerate(names) if spec[n].rate}


def param_names(model: KinematicModel) -> tuple[str, ...]:
    """The full state order: kinematic parameters then the sensor pose."""
    return (*model.kinematic_params, *SENSOR_PARAMS)


def param_units(model: KinematicModel) -> dict[str, str]:
    """The unit of every parameter, in state order."""
    return {**{n: model.units[n] for n in model.kinematic_params}, **SENSOR_UNITS}


def encoders(model: KinematicModel) -> tuple[str, ...]:
    """The encoder names the model reads, in input order."""
    return tuple(model.encoder_kinds)


def header_parameters(model: KinematicModel, header: LogHeader) -> dict[str, float]:
    """The header's initial guess under the model's parameter names (unknown names left out)."""
    out = {}
    for name, value in header.parameters.items():
        param = model.header_aliases.get(name.lower())
        if param is not None:
            out[param] = float(value)
    return out


def reference(model: KinematicModel, name: str, sensor: Mapping[str, Reference] | None = None) -> Reference:
    """The precision a calibration should reach on parameter ``name`` (its key: a per-log
    parameter's is its layout's, :meth:`~nlp_calib.results.layout.Layout.key`): ``relative`` (a fraction of
    its value: gains and lengths) or ``absolute`` (in its unit); ``sensor``: the sensor's own
    (its mount's; a planar mount's by default)."""
    known = {**model.reference, **(SENSOR_REFERENCE if sensor is None else sensor), **LAG_REFERENCE}
    return known.get(name, ("relative", 0.01))


def reference_scale(
    model: KinematicModel, name: str, value: float, sensor: Mapping[str, Reference] | None = None
) -> float:
    """The precision a calibration should reach on parameter ``name`` at ``value``."""
    kind, amount = reference(model, name, sensor)
    return amount * max(abs(value), 1e-9) if kind == "relative" else amount


def reference_scales(
    model: KinematicModel,
    names: tuple[str, ...],
    values: np.ndarray,
    sensor: Mapping[str, Reference] | None = None,
) -> np.ndarray:
    """:func:`reference_scale` of each named parameter."""
    return np.array([reference_scale(model, n, float(v), sensor) for n, v in zip(names, values)])
