"""The options of a scenario, one frozen dataclass per section of the file, each checking its own
values when it is made (in neutral words naming the field; the loader adds the file and place)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from nlp_calib.core.errors import FieldError, ProblemError
from nlp_calib.core.ranges import MAGNITUDE, Range, check_choice, check_range, check_ros_name
from nlp_calib.problem import ResidualOptions
from nlp_calib.sensors import BESIDE, SCALES, SENSORS, Sensor, sensor_for
from nlp_calib.solvers.backends import BACKENDS
from nlp_calib.sources import DatasetSource
from nlp_calib.symbolic.kernels import KERNELS

#: ``validation.blocks`` (or 0: none): each block costs one more fit.
BLOCKS = Range(2, 100, integer=True)
DELTA = Range(0.0, 1e6, lo_open=True)
WEIGHT = Range(0.0, 1e12, lo_open=True)
TICKS = Range(0.0, 1e9, lo_open=True)
COUNTS_PER_TURN = Range(0.0, 2.0**32, lo_open=True)
PRIOR_STD = Range(1e-9, 1e6)
THREADS = Range(1, 64, integer=True)
RPE_WINDOW = Range(1, 1_000_000, integer=True)
#: A steered wheel's largest angle (degrees): more than none, at most a quarter turn.
STEERING_DEG = Range(0.0, 90.0, lo_open=True)
_FINITE = Range(-math.inf, math.inf, lo_open=True, hi_open=True)
FAULT_HANDLINGS = ("exclude", "repair", "keep")
#: Several logs' sensor mounts: one shared, or one per log (the kinematic parameters shared).
MOUNTS = ("shared", "per_log")
INITIAL_GUESSES = ("from_file", "auto")


@dataclass(frozen=True)
class SampleSelection:
    """Records ``start:stop`` of the log; ``drop_stationary`` drops windows with no motion."""

    start: int = 0
    stop: int | None = None
    drop_stationary: bool = False

    def __post_init__(self) -> None:
        if self.start < 0 or (self.stop is not None and self.stop <= self.start + 1):
            raise FieldError("start", f"need 0 <= start < stop - 1, got start={self.start} stop={self.stop}")


@dataclass(frozen=True)
class RobustOptions:
    """Kernel name and its threshold ``delta`` on the Mahalanobis norm ``sqrt(eᵀΩe)``."""

    kernel: str = "huber"
    delta: float = 0.05

    def __post_init__(self) -> None:
        check_choice("kernel", self.kernel, KERNELS)
        check_range("delta", self.delta, DELTA)


@dataclass(frozen=True)
class InformationWeights:
    """Diagonal of Ω: weight of the x/y error (1/m²) and of the angle error (1/rad²); ``gyro``: of a
    gyro's integrated angle beside another reference (1/rad²; its own noise, not the reference's;
    default: ``rotation``)."""

    translation: float = 1.0
    rotation: float = 1.0
    gyro: float | None = None

    def __post_init__(self) -> None:
        check_range("translation", self.translation, WEIGHT)
        check_range("rotation", self.rotation, WEIGHT)
        if self.gyro is not None:
            check_range("gyro", self.gyro, WEIGHT)

    def omega(self, error_rows: int = 3, weights: tuple[str, ...] = ()) -> tuple[float, ...]:
        """Ω's diagonal for a residual of ``error_rows`` rows: translation first, then rotation
        (planar: x, y, θ; a 3-D sensor: x, y, z, then three rotation components); or each row's
        weight by name where the sensor names them (``weights``: a reference beside a gyro)."""
        if weights:
            named = {"translation": self.translation, "rotation": self.rotation}
            named["gyro"] = self.rotation if self.gyro is None else self.gyro
            return tuple(named[w] for w in weights)
        half = error_rows // 2
        return (self.translation,) * (error_rows - half) + (self.rotation,) * half


@dataclass(frozen=True)
class ValidationOptions:
    """``holdout_fraction``: trailing fraction of the records kept out of the fit and scored;
    ``blocks``: contiguous blocks of the blocked cross-validation that gives the data-driven σ
    (0: none); ``rpe_window``: records of the fixed-window RPE."""

    holdout_fraction: float | None = None
    rpe_window: int = 25
    blocks: int = 10

    def __post_init__(self) -> None:
        hf = self.holdout_fraction
        if hf is not None and not 0.0 < hf < 1.0:
            raise FieldError("holdout_fraction", f"must lie in (0, 1), got {hf}")
        if self.blocks != 0 and (why := BLOCKS.problem(self.blocks)):
            raise FieldError("blocks", f"0 (none) or {why}")
        check_range("rpe_window", self.rpe_window, RPE_WINDOW)


@dataclass(frozen=True)
class HandoffOptions:
    """``controller_name``: the name the robot's controller_manager gives its ros2_control
    controller, the top key of ``ros2_control.yaml`` (None: the controller's type, with a first
    line saying to rename it); ``--controller-name`` overrides it."""

    controller_name: str | None = None

    def __post_init__(self) -> None:
        if self.controller_name is not None:
            check_ros_name("controller_name", self.controller_name)


@dataclass(frozen=True)
class VehicleOptions:
    """What the robot can drive beyond what its model says: ``max_steering_deg``, its steered
    wheels' largest angle (degrees; None: the model's own, 35° for a car, 90° for a tricycle),
    which the plan's turns keep within."""

    max_steering_deg: float | None = None

    def __post_init__(self) -> None:
        if self.max_steering_deg is not None:
            check_range("max_steering_deg", self.max_steering_deg, STEERING_DEG)

    @property
    def steer_max(self) -> float | None:
        """The limit in radians (None: the model's own)."""
        return None if self.max_steering_deg is None else math.radians(self.max_steering_deg)


@dataclass(frozen=True)
class AlignmentOptions:
    """``tracker_lag``: seconds the tracker reports after the encoders, or ``auto`` (the default)
    to fit it with the other parameters, found over ``search`` (wide enough for a driver's or a
    network's late stamps: a profile of the cost over it gives the fit its start)."""

    tracker_lag: float | str = "auto"
    search: tuple[float, float] = (-0.5, 0.5)
    step: float = 0.01

    def __post_init__(self) -> None:
        if isinstance(self.tracker_lag, str):
            check_choice("tracker_lag", self.tracker_lag, ("auto",))
        lo, hi = self.search
        if not lo < hi:
            raise FieldError("search", f"needs [lo, hi] with lo < hi, got [{lo:g}, {hi:g}]")
        if not self.step > 0:
            raise FieldError("step", f"must be > 0 s, got {self.step:g}")
        if (hi - lo) / self.step > 1000:
            raise FieldError(
                "step",
                f"{self.step:g} s over search [{lo:g}, {hi:g}] makes {(hi - lo) / self.step:.0f} lags to "
                f"fit, more than 1000; use a step of at least {(hi - lo) / 1000:.3g} s or a narrower search",
            )


@dataclass(frozen=True)
class FaultOptions:
    """What to do with encoder and tracker faults found in the log (every run looks for them).

    ``exclude`` (default): drop every residual window that crosses a fault; ``repair``: correct
    the counts of counter faults (and say what changed), drop windows at tracker jumps; ``keep``:
    report the faults and fit every window.
    """

    handling: str = "exclude"

    def __post_init__(self) -> None:
        check_choice("handling", self.handling, FAULT_HANDLINGS)


@dataclass(frozen=True)
class Prior:
    """A Gaussian prior on one parameter."""

    mean: float
    std: float

    def __post_init__(self) -> None:
        check_range("mean", self.mean, MAGNITUDE)
        check_range("std", self.std, PRIOR_STD)


@dataclass(frozen=True)
class LogEntry:
    """One log of a calibration: where its records come from, and its ``samples`` and
    ``alignment`` (its own, or the scenario's)."""

    source: DatasetSource
    samples: SampleSelection = field(default_factory=SampleSelection)
    alignment: AlignmentOptions = field(default_factory=AlignmentOptions)

    @property
    def path(self) -> Path:
        return self.source.path


@dataclass(frozen=True)
class DataOptions:
    """The logs (one, or several fitted together: ``datasets``), how strictly they are read, the
    encoders' noise (ticks), each wheel encoder's counts per wheel turn (for the controller's
    radii) and what to do with faults."""

    logs: tuple[LogEntry, ...]
    joint: bool = False
    strict: bool = True
    encoder_noise: Mapping[str, float] = field(default_factory=dict)
    counts_per_turn: Mapping[str, float] = field(default_factory=dict)
    faults: FaultOptions = field(default_factory=FaultOptions)

    def __post_init__(self) -> None:
        for enc, ticks in self.encoder_noise.items():
            check_range(f"encoder_noise.{enc}", ticks, TICKS)
        for enc, counts in self.counts_per_turn.items():
            check_range(f"counts_per_turn.{enc}", counts, COUNTS_PER_TURN)


@dataclass(frozen=True)
class SensorOptions:
    """What the reference is (scenario key ``sensor``): one of the sensor plug-ins
    (:data:`nlp_calib.sensors.SENSORS`: ``planar``, a tracker's planar pose; ``3d``, a camera's
    pose on the base, its mount ``x, y, z, roll, pitch, yaw``); ``scale: free`` for poses known
    only up to scale (monocular visual odometry). ``sensor: 3d`` is short for ``{mount: 3d}``.
    ``mounts: per_log``: logs fitted together (``datasets``) each have their own mount (the sensor
    moved between them, or each log is another sensor's), the wheels shared; ``shared`` (default):
    one mount for all. ``beside: gyro``: a gyro beside the reference, both fitted in one objective
    (:data:`nlp_calib.sensors.BESIDE`; docs/imu.md)."""

    mount: str = "planar"
    scale: str = "fixed"
    mounts: str = "shared"
    beside: str = ""

    def __post_init__(self) -> None:
        check_choice("mount", self.mount, tuple(SENSORS))
        check_choice("mounts", self.mounts, MOUNTS)
        check_choice("scale", self.scale, SCALES)
        if self.beside and (self.mount, self.beside) not in BESIDE:
            pairs = ", ".join(f"{{mount: {m}, beside: {b}}}" for m, b in BESIDE)
            raise FieldError(
                "beside", f"a second sensor fits beside: {pairs}; got {self.beside!r} beside {self.mount}"
            )
        try:
            sensor_for(self.kind, self.scale)
        except ProblemError as exc:
            raise FieldError("scale", str(exc)) from None

    @property
    def kind(self) -> str:
        """The registered sensor that fits the reference (and the sensor beside it)."""
        return BESIDE[(self.mount, self.beside)] if self.beside else self.mount

    @property
    def sensor(self) -> Sensor:
        """The sensor plug-in."""
        return sensor_for(self.kind, self.scale)

    def params(self) -> tuple[str, ...]:
        """The parameters of the sensor's mount (and the scale, when free), in state order."""
        return self.sensor.params

    def held(self) -> tuple[str, ...]:
        """The mount's parameters the drive never determines (held at their given values)."""
        return self.sensor.held


@dataclass(frozen=True)
class ObjectiveOptions:
    """What the fit minimises: the residual form, the sensor, the robust kernel and the information
    weights."""

    residual: ResidualOptions = field(default_factory=ResidualOptions)
    sensor: SensorOptions = field(default_factory=SensorOptions)
    robust: RobustOptions = field(default_factory=RobustOptions)
    information: InformationWeights = field(default_factory=InformationWeights)


@dataclass(frozen=True)
class ParameterOptions:
    """Where the parameters start (``from_file``, ``auto`` or values), bounds, fixed ones, priors,
    and ``known`` ones: measured values held fixed whatever the start (a camera's height, the one
    length a free scale needs), added to ``fixed``; ``vehicle``: what the robot can drive beyond
    its model's facts."""

    initial_guess: str | Mapping[str, float] = "from_file"
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    fixed: tuple[str, ...] = ()
    priors: Mapping[str, Prior] = field(default_factory=dict)
    known: Mapping[str, float] = field(default_factory=dict)
    vehicle: VehicleOptions = field(default_factory=VehicleOptions)

    def __post_init__(self) -> None:
        for n, value in self.known.items():
            check_range(f"known.{n}", value, MAGNITUDE)
            if n in self.bounds:
                raise FieldError(f"bounds.{n}", "a known parameter is held at its value; drop its bounds")
        object.__setattr__(self, "fixed", tuple(dict.fromkeys((*self.fixed, *self.known))))
        if isinstance(self.initial_guess, str):
            check_choice("initial_guess", self.initial_guess, INITIAL_GUESSES)
        else:
            for n, value in self.initial_guess.items():
                check_range(f"initial_guess.{n}", value, MAGNITUDE)
        for n, (lo, hi) in self.bounds.items():
            if not lo < hi:
                raise FieldError(f"bounds.{n}", f"needs lo < hi, got [{lo}, {hi}]")
            guess = self.guess(n)
            if guess is not None and not lo <= guess <= hi:
                raise FieldError(f"bounds.{n}", f"the initial guess {guess:g} lies outside [{lo:g}, {hi:g}]")
        for n in self.priors:
            if n in self.fixed:
                raise FieldError(f"priors.{n}", "a fixed parameter cannot also have a prior; drop one")

    def guess(self, name: str) -> float | None:
        """The scenario's own initial value of ``name``, if it gives one."""
        if name in self.known:
            return self.known[name]
        return self.initial_guess.get(name) if isinstance(self.initial_guess, Mapping) else None


@dataclass(frozen=True)
class ComputeOptions:
    """How the problem's Functions are evaluated: ``backend`` and ``threads``."""

    backend: str = "compiled"
    threads: int = 1

    def __post_init__(self) -> None:
        check_choice("backend", self.backend, BACKENDS)
        check_range("threads", self.threads, THREADS)
