"""A model read from joint positions in radians: the same base, its parameters in robot units.

ROS publishes joint positions in radians (REP 103): a wheel's angle, which grows without wrapping,
and a steering joint's angle. Read that way, a wheel's gain in metres per tick becomes its radius
in metres (its travel is radius × Δangle) and the parameters take the names a robot's stack gives
them. Each model declares, once, a :class:`RadiansForm`: for every parameter or input whose
meaning changes, its name, unit and factor in the radians form (the counts form's value is the
factor times the radians form's); for every input, the encoder that drives it (and whether it is
that joint's rate over the interval). :class:`InRadians`
wraps the model with it: the symbolic increment is the model's own on the parameters and inputs
mapped back, and every fact (units, ranges, reference precision, symmetries, defaults, the
controller's parameters, the closed-form start) is the model's, renamed and rescaled. Nothing of
a model is written twice.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from nlp_calib.core.errors import ModelError
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.logs import EncoderKind, Log
from nlp_calib.models.base import (
    STEERING_SAMPLES,
    KinematicModel,
    OdometryInverse,
    Reach,
    Reference,
    Symmetry,
    record_rates,
    sampled_angle,
)
from nlp_calib.models.controllers import ControllerMap, EncoderScales

if TYPE_CHECKING:
    from nlp_calib.models.drives import Drive

#: Below this (rad) a joint's noise is not taken from its resolution: positions published as
#: unquantised floats (or integrated from velocities) show no step to take it from.
MIN_RESOLUTION = 1e-6
#: A joint logged in degrees makes every gain per radian this much too small.
DEGREE = 180.0 / np.pi
#: A wheel's radius a real robot has (m): a few millimetres (a desk robot) to a couple of metres.
WHEEL_RADIUS = (0.004, 2.0)
#: What the controller's values assume of joints in radians.
ASSUMES = (
    "the joints' positions are in radians as the robot publishes them (REP 103): the radii are "
    "per radian of the wheel joint, whatever gearing lies between the encoder and that joint"
)


@dataclass(frozen=True)
class Renamed:
    """A quantity's name and unit in the radians form, and ``factor``: its value in the counts form
    per unit of the radians form. For an input, ``encoder`` is the encoder that drives it, and
    ``rate``: the input is that joint's rate per second over the interval (a level), not its
    increment or angle."""

    name: str
    unit: str
    factor: float = 1.0
    encoder: str = ""
    rate: bool = False
    #: What a real robot's value can be, in this form's unit (a wheel's radius: millimetres to
    #: metres): outside it the estimate is not the robot's (:meth:`InRadians.implausible`); the
    #: form's physical range holds it.
    plausible: tuple[float, float] | None = None


@dataclass(frozen=True)
class RadiansForm:
    """How a model reads joints in radians: its renamed parameters (by counts-form name; the others
    keep their names and values) and every input (by counts-form name)."""

    params: Mapping[str, Renamed]
    inputs: Mapping[str, Renamed]


class InRadians:
    """``model`` read from joint positions in radians (see the module docstring)."""

    def __init__(self, model: KinematicModel, form: RadiansForm) -> None:
        self.model = model
        self.form = form
        self.renamed = {n: form.params.get(n, Renamed(n, model.units[n])) for n in model.kinematic_params}
        self.counts_names = {r.name: n for n, r in self.renamed.items()}

    # --- names and units ---------------------------------------------------------------------

    @property
    def name(self) -> str:
        return self.model.name

    @property
    def log_names(self) -> tuple[str, ...]:
        return self.model.log_names

    @property
    def kinematic_params(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.renamed.values())

    @property
    def units(self) -> Mapping[str, str]:
        return {r.name: r.unit for r in self.renamed.values()}

    @property
    def header_names(self) -> Mapping[str, str]:
        return {n: n for n in self.kinematic_params}

    @property
    def header_aliases(self) -> Mapping[str, str]:
        return {n.lower(): n for n in self.kinematic_params}

    @property
    def encoder_kinds(self) -> Mapping[str, EncoderKind]:
        return self.model.encoder_kinds

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(self.form.inputs[n].name for n in self.model.input_names)

    @property
    def level_inputs(self) -> tuple[str, ...]:
        return tuple(self.form.inputs[n].name for n in self.model.level_inputs)

    @property
    def input_units(self) -> Mapping[str, str]:
        return {self.form.inputs[n].name: self.form.inputs[n].unit for n in self.model.input_names}

    # --- facts, renamed and rescaled ---------------------------------------------------------

    def rename(self, name: str) -> str:
        """A parameter's name in the radians form (the sensor's and unknown names unchanged)."""
        return self.renamed[name].name if name in self.renamed else name

    def words(self, text: str) -> str:
        """``text`` with the counts form's parameter names in the radians form's."""
        changed = {n: r.name for n, r in self.renamed.items() if r.name != n}
        if not changed:
            return text
        return re.sub(r"\b(" + "|".join(map(re.escape, changed)) + r")\b", lambda m: changed[m[1]], text)

    def _factor(self, name: str) -> float:
        return self.renamed[name].factor if name in self.renamed else 1.0

    def from_counts(self, params: Mapping[str, float]) -> dict[str, float]:
        """Values in the counts form's names, in the radians form's."""
        return {self.rename(n): float(v) / self._factor(n) for n, v in params.items()}

    def to_counts(self, params: Mapping[str, float]) -> dict[str, float]:
        """Values in the radians form's names, in the counts form's."""
        out = {}
        for n, v in params.items():
            counts = self.counts_names.get(n, n)
            out[counts] = float(v) * self._factor(counts)
        return out

    @property
    def turning_params(self) -> tuple[str, ...]:
        return tuple(self.rename(n) for n in self.model.turning_params)

    @property
    def turning_note(self) -> str:
        return self.words(self.model.turning_note)

    @property
    def physical_ranges(self) -> Mapping[str, tuple[float, float]]:
        """The counts form's ranges in this form's units, each widened to what a real robot's value
        can be (:attr:`Renamed.plausible`): a metre per tick is a 1 m wheel per radian, and a wheel
        of 1.2 m (a tractor's, or a car's speed in m/s read as a 1 m wheel's rad/s) is a robot's."""
        out = {}
        for n, (lo, hi) in self.model.physical_ranges.items():
            lo, hi = lo / self._factor(n), hi / self._factor(n)
            plausible = self.renamed[n].plausible if n in self.renamed else None
            if plausible is not None:
                lo, hi = min(lo, plausible[0]), max(hi, plausible[1])
            out[self.rename(n)] = (lo, hi)
        return out

    @property
    def reference(self) -> Mapping[str, Reference]:
        return {
            self.rename(n): (kind, amount / self._factor(n) if kind == "absolute" else amount)
            for n, (kind, amount) in self.model.reference.items()
        }

    @property
    def headline(self) -> tuple[str, ...]:
        return tuple(self.rename(n) for n in self.model.headline)

    @property
    def defaults(self) -> Mapping[str, float]:
        return self.from_counts(self.model.defaults)

    @property
    def symmetries(self) -> tuple[Symmetry, ...]:
        return tuple(
            Symmetry(
                s.description,
                self.rename(s.sign),
                tuple(map(self.rename, s.negate)),
                tuple(map(self.rename, s.turn)),
            )
            for s in self.model.symmetries
        )

    @property
    def angle_params(self) -> tuple[str, ...]:
        return tuple(self.rename(n) for n in self.model.angle_params)

    @property
    def steer_max(self) -> float | None:
        return self.model.steer_max

    def reach(self, params: Mapping[str, float], steer_max: float | None = None) -> Reach:
        return self.model.reach(self.to_counts(params), steer_max)

    @property
    def drive(self) -> Drive:
        """The simulator's drive, which simulates the counts form (:func:`default_guess` renames)."""
        return self.model.drive

    # --- the increment and the inputs --------------------------------------------------------

    def increment(self, k: ca.SX, u: ca.SX, integration: str) -> ca.SX:
        """The model's increment on the parameters and inputs mapped back to the counts form."""
        kf = [r.factor for r in self.renamed.values()]
        uf = [self.form.inputs[n].factor for n in self.model.input_names]
        k_counts = ca.vertcat(*[k[i] * f if f != 1.0 else k[i] for i, f in enumerate(kf)])
        u_counts = ca.vertcat(*[u[j] * f if f != 1.0 else u[j] for j, f in enumerate(uf)])
        return self.model.increment(k_counts, u_counts, integration)

    def input_rates(self, log: Log) -> np.ndarray | None:
        """Each wheel's angular rate (rad/s) and each steering angle (rad) at the records, the joint
        stream's (:meth:`~nlp_calib.logs.log.JointStream.slopes`; None without a joint stream)."""
        rates = log.joint_rates()
        if rates is None and not any(r.rate for r in self.form.inputs.values()):
            return None
        if rates is None:  # a rate is a level: the intervals' own, never wrapped as an angle is
            positions = np.stack([log.joint_position(e) for e in log.header.encoder_names], 1)
            rates = record_rates(np.diff(positions, axis=0).T, np.asarray(log.time_s)).T
        rows = []
        for name in self.model.input_names:
            encoder = self.form.inputs[name].encoder
            j = log.header.encoder_index(encoder)
            counter = self.encoder_kinds[encoder] == "counter" or self.form.inputs[name].rate
            rows.append(rates[:, j] if counter else wrap_angle(log.joint_position(encoder)))
        return np.vstack(rows)

    def inputs(self, log: Log, steering_sample: str) -> np.ndarray:
        """Rows: each wheel's angle increment and each steering angle (sampled as asked), in rad."""
        if steering_sample not in STEERING_SAMPLES:
            raise ModelError(f"steering_sample must be one of {STEERING_SAMPLES}, got {steering_sample!r}")
        missing = [e for e in self.encoder_kinds if e not in log.header.encoder_names]
        if missing:
            raise ModelError(
                f"{log.path}: the {self.name} model needs joints read as {list(self.encoder_kinds)}; "
                f"the log has {list(log.header.encoder_names)}"
            )
        stream = log.joint_stream
        lost = [e for e in (stream.integrated if stream else ()) if self.encoder_kinds[e] == "absolute"]
        if lost:
            raise ModelError(
                f"{log.path}: the joint read as {lost[0]!r} publishes only its velocity; an angle cannot be "
                "integrated from velocities (its start is unknown): publish its position"
            )
        rows = []
        for name in self.model.input_names:
            encoder = self.form.inputs[name].encoder
            position = log.joint_position(encoder)
            if self.form.inputs[name].rate:
                # Over the times the joints are read at: a gyro's record beside a reference's is
                # read on its own clock, the interval between them as long as the reads are apart.
                dt = np.diff(log.read_times())
                rows.append(np.diff(position) / np.where(dt != 0, dt, np.inf))
            elif self.encoder_kinds[encoder] == "counter":
                rows.append(np.diff(position))
            else:
                rows.append(self._steering(log, encoder, steering_sample))
        return np.vstack(rows)

    def _steering(self, log: Log, encoder: str, steering_sample: str) -> np.ndarray:
        """A steering joint's angle per interval: its ``mean`` (or ``travel``) over the interval as
        the wheels travelled it where the joints stream finer than the records
        (:meth:`~nlp_calib.logs.log.JointStream.travelled_angle`), else read at the records
        (``travel``: weighed by the wheel joints' summed increments)."""
        stream = log.joint_stream
        wheels = [log.header.encoder_index(e) for e, kind in self.encoder_kinds.items() if kind == "counter"]
        if steering_sample not in ("mean", "travel") or stream is None:
            travel = sum(
                np.diff(log.joint_position(e)) for e, k in self.encoder_kinds.items() if k == "counter"
            )
            angle = wrap_angle(log.joint_position(encoder))
            return sampled_angle(
                angle, steering_sample, np.asarray(travel, dtype=float), np.asarray(log.time_s)
            )
        read = log.read_times()
        return wrap_angle(stream.travelled_angle(read, log.header.encoder_index(encoder), wheels))

    def moving(self, inputs: np.ndarray) -> np.ndarray:
        return self.model.moving(inputs)

    def travel_direction(self, inputs: np.ndarray) -> np.ndarray:
        return self.model.travel_direction(inputs)

    def undetermined(self, inputs: np.ndarray) -> dict[str, str]:
        return {self.rename(n): self.words(why) for n, why in self.model.undetermined(inputs).items()}

    def counter_rows(self, log: Log) -> dict[str, tuple[int, float]]:
        """Each wheel joint drives its own row, in rad."""
        return {
            self.form.inputs[n].encoder: (row, 1.0)
            for row, n in enumerate(self.model.input_names)
            if self.encoder_kinds[self.form.inputs[n].encoder] == "counter" and not self.form.inputs[n].rate
        }

    def input_noise_std(self, log: Log, encoder_noise: Mapping[str, float] | None = None) -> np.ndarray:
        """1σ of each input (rad): the joint's ``encoder_noise`` (rad), else its resolution's
        rounding (``resolution/√12``, never below :data:`MIN_RESOLUTION`)."""
        stream = log.joint_stream
        noise = []
        for name in self.model.input_names:
            encoder = self.form.inputs[name].encoder
            if self.form.inputs[name].rate:  # a rate's noise is its increment's, counted there
                noise.append(0.0)
                continue
            given = (encoder_noise or {}).get(encoder)
            if given is not None:
                noise.append(float(given))
                continue
            step = stream.resolution[log.header.encoder_index(encoder)] if stream is not None else 0.0
            noise.append(max(step, MIN_RESOLUTION) / np.sqrt(12.0))
        return np.array(noise)

    # --- the hand-off and the start ----------------------------------------------------------

    def controller(self, params: Mapping[str, float], scales: EncoderScales) -> ControllerMap:
        """The model's controller with every wheel turn 2π of its joint and the readings joint
        angles; a controller parameter that is one of the model's own (same name:
        ``wheel_radius``, ``wheelbase``...) is the parameter itself, not its round trip through
        the counts form."""
        turns = dict.fromkeys(self.encoder_kinds, 2.0 * np.pi)
        joints = EncoderScales(turns, turns, joint_angles=True, driven_turn_rates=scales.driven_turn_rates)
        found = self.model.controller(self.to_counts(params), joints)
        own = {n: float(params[n]) if _round_trip(params, n, v) else v for n, v in found.parameters.items()}
        return ControllerMap(
            found.controller,
            own,
            {self.rename(n): self.words(w) for n, w in found.places.items()},
            {n: self.words(w) for n, w in found.omitted.items()},
            ASSUMES,
            found.settings,
        )

    def implausible(self, params: Mapping[str, float]) -> str:
        """The model's mirror images, in this form's names; else a parameter no robot has, with
        joints logged in degrees named when that explains it."""
        mirror = self.words(self.model.implausible(self.to_counts(params)))
        if mirror:
            return mirror
        for r in self.renamed.values():
            if r.plausible is None or r.name not in params:
                continue
            lo, hi = r.plausible
            value = abs(params[r.name])
            if lo <= value <= hi:
                continue
            said = (
                f"{r.name} came out {params[r.name]:.3g} {r.unit}, not what a real robot has "
                f"([{lo:g}, {hi:g}] {r.unit})"
            )
            if lo <= value * DEGREE <= hi:
                return (
                    f"{said}; times 180/π it is {value * DEGREE:.3g} {r.unit}: the joints look logged in "
                    "degrees; ROS publishes radians (REP 103): convert them (× π/180) and run again"
                )
            return f"{said}: are the joints named in the scenario the wheels', in radians?"
        return ""

    def initial_guess(
        self,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: Callable[[Mapping[str, float]], np.ndarray],
    ) -> dict[str, float]:
        """The model's closed-form start on the inputs mapped back, its values renamed."""
        factors = np.array([self.form.inputs[n].factor for n in self.model.input_names])
        U_counts = U * np.tile(factors, U.shape[0] // factors.size)[:, None]

        def counts_motion(params: Mapping[str, float]) -> np.ndarray:
            return base_motion(self.from_counts(params))

        return self.from_counts(self.model.initial_guess(U_counts, z, counts_motion))

    def readings_from_odometry(self, base: np.ndarray, params: Mapping[str, float]) -> dict[str, np.ndarray]:
        """The model's own, in joint angles (rad): its parameters mapped back, each reading scaled
        by the factor of the input it drives."""
        if not isinstance(self.model, OdometryInverse):
            raise ModelError(f"the {self.name} model cannot turn a robot's odometry back into its joints")
        own = self.model.readings_from_odometry(base, self.to_counts(params))
        factor = {r.encoder: r.factor for r in self.form.inputs.values() if r.encoder and not r.rate}
        return {encoder: np.asarray(v) / factor.get(encoder, 1.0) for encoder, v in own.items()}

    def in_radians(self) -> KinematicModel:
        return self


def units_of(model: KinematicModel) -> str:
    """``radians`` for a model read from joint positions in radians, else ``counts``."""
    return "radians" if isinstance(model, InRadians) else "counts"


def in_units(model: KinematicModel, units: str) -> KinematicModel:
    """``model`` in the form that reads encoders in ``units`` (``counts`` or ``radians``): one
    radians form per model object, so that the problems built for it (once per model object and
    problem) are built once per process, not at every scenario's set-up."""
    if units == "radians":
        with _FORMS_LOCK:
            if id(model) not in _FORMS:
                _FORMS[id(model)] = (model, model.in_radians())
            return _FORMS[id(model)][1]
    return model.model if isinstance(model, InRadians) else model


#: Each model's radians form, with the model (which keeps its id its own).
_FORMS: dict[int, tuple[KinematicModel, KinematicModel]] = {}
_FORMS_LOCK = threading.Lock()


def default_guess(model: KinematicModel) -> dict[str, float]:
    """The simulator's guess of every parameter, in ``model``'s own names."""
    guess = dict(model.drive.default_guess)
    return model.from_counts(guess) if isinstance(model, InRadians) else guess


def _round_trip(params: Mapping[str, float], name: str, value: float) -> bool:
    """Whether the controller's ``value`` of ``name`` is the model's own parameter of that name
    through the counts form (not a value derived from it, as a skid-steer's turning track is)."""
    return name in params and bool(np.isclose(value, params[name], rtol=1e-9, atol=0.0))
