"""What to simulate: the options of a synthetic log, validated on construction, and the drive's
speed and turning profiles they describe."""

from __future__ import annotations

import math
import typing
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Protocol

import numpy as np

from nlp_calib.core.errors import OptionsError
from nlp_calib.core.ranges import Range
from nlp_calib.models import DEFAULT_MODEL, MODELS
from nlp_calib.simulation.faults import COUNTER_FAULT_KINDS

TRAJECTORIES = ("s_curves", "straight", "no_reversals", "circles")
#: How the speed changes sign: through zero over seconds, or within :data:`ABRUPT_S`.
REVERSALS = ("smooth", "abrupt")
ABRUPT_S = 0.02

#: Accepted values of the numeric options (the command line checks its options against the same).
#: Written block by block (:func:`simulate_to_file`), a log of any length takes the memory of one
#: block; the ceiling on ``records`` only catches a typo (10⁹ records are about 140 GB of text).
LIMITS: Mapping[str, Range] = {
    "records": Range(3, 10**9, integer=True),
    "seed": Range(0, 2**32 - 1, integer=True),
    "rate_hz": Range(1.0, 1000.0),
    "jitter_s": Range(0.0, 0.1),
    "substeps": Range(1, 1000, integer=True),
    "max_speed": Range(0.0, 10.0, lo_open=True),
    "max_turn": Range(0.0, 1.5),
    "stop_fraction": Range(0.0, 1.0, hi_open=True),
    "tracker_noise_xy": Range(0.0, 1.0),
    "tracker_noise_theta": Range(0.0, 1.0),
    "outlier_fraction": Range(0.0, 1.0, hi_open=True),
    "outlier_magnitude": Range(0.0, 100.0),
    "latency_s": Range(0.0, 1.0),
    "wrap_after_ticks": Range(0, 2**32 - 1, integer=True),
    "counter_faults": Range(0, 1000, integer=True),
    "tracker_rate_hz": Range(0.0, 1000.0),
    "tracker_jitter_s": Range(0.0, 0.1),
    "steering_spikes": Range(0, 1000, integer=True),
    "steering_stuck": Range(0, 1000, integer=True),
}


def _check(options: object, prefix: str = "") -> None:
    """Each numeric field of ``options`` against :data:`LIMITS`, by its name."""
    for f in fields(options):  # type: ignore[arg-type]
        limit = LIMITS.get(f.name)
        reason = None if limit is None else limit.problem(getattr(options, f.name))
        if reason is not None:
            raise OptionsError(f"{prefix}{f.name} {reason}")


@dataclass(frozen=True)
class Sampling:
    """The encoders' sample clock: ``rate_hz`` with ``jitter_s`` of jitter, and the fine sub-steps
    the motion is integrated on between two samples."""

    rate_hz: float = 25.0
    jitter_s: float = 0.004
    substeps: int = 20

    def __post_init__(self) -> None:
        _check(self)


@dataclass(frozen=True)
class DriveShape:
    """How the base drives: ``trajectory`` (``s_curves``: turns, stops and reversals; ``straight``:
    no turning; ``no_reversals``: turns and stops, always forward; ``circles``: circles at constant
    speed, turning one way for the first half and the other for the second), the top speed (m/s), the
    turning profile's amplitude (each model's drive reads it in its own way, see its ``steps``),
    the fraction of stops, and ``reversals``: ``smooth`` (the speed passes through zero over
    seconds) or ``abrupt`` (within :data:`ABRUPT_S`)."""

    trajectory: str = "s_curves"
    max_speed: float = 0.6
    max_turn: float = 0.6
    stop_fraction: float = 0.15
    reversals: str = "smooth"

    def __post_init__(self) -> None:
        _check(self)
        if self.trajectory not in TRAJECTORIES:
            raise OptionsError(
                f"trajectory must be one of {', '.join(TRAJECTORIES)}, got {self.trajectory!r}"
            )
        if self.reversals not in REVERSALS:
            raise OptionsError(f"reversals must be one of {', '.join(REVERSALS)}, got {self.reversals!r}")


@dataclass(frozen=True)
class TrackerSim:
    """The tracker: noise (m, rad), gross outliers (the fraction of poses and their size), its
    latency behind the encoders, and ``tracker_rate_hz`` > 0 for a clock of its own (that rate,
    ``tracker_jitter_s``, a random phase), its poses then paired with the encoders' records as a
    bag import pairs them (interpolated at each encoder stamp)."""

    tracker_noise_xy: float = 0.002
    tracker_noise_theta: float = 0.002
    outlier_fraction: float = 0.0
    outlier_magnitude: float = 0.3
    latency_s: float = 0.0
    tracker_rate_hz: float = 0.0
    tracker_jitter_s: float = 0.004

    def __post_init__(self) -> None:
        _check(self)


@dataclass(frozen=True)
class InjectedFaults:
    """How many faults of each kind to inject (:mod:`nlp_calib.simulation.faults`): counter faults
    (of ``counter_fault_kinds``), one-record spikes and stuck readings of an absolute encoder."""

    counter_faults: int = 0
    counter_fault_kinds: tuple[str, ...] = COUNTER_FAULT_KINDS
    steering_spikes: int = 0
    steering_stuck: int = 0

    def __post_init__(self) -> None:
        _check(self)
        if not set(self.counter_fault_kinds) <= set(COUNTER_FAULT_KINDS):
            raise OptionsError(f"counter_fault_kinds must be among {', '.join(COUNTER_FAULT_KINDS)}")

    @property
    def any(self) -> bool:
        return bool(self.counter_faults or self.steering_spikes or self.steering_stuck)


_GROUPS: Mapping[str, type] = {
    "sampling": Sampling,
    "drive": DriveShape,
    "tracker": TrackerSim,
    "faults": InjectedFaults,
}
#: The options' flat names, in the order a truth file lists them.
FLAT_ORDER = (
    "records", "seed", "model", "trajectory", "truth", "guess", "encoder_ranges", "rate_hz", "jitter_s",
    "substeps", "max_speed", "max_turn", "stop_fraction", "tracker_noise_xy", "tracker_noise_theta",
    "outlier_fraction", "outlier_magnitude", "latency_s", "wrap_after_ticks", "counter_faults",
    "counter_fault_kinds", "reversals", "tracker_rate_hz", "tracker_jitter_s", "steering_spikes",
    "steering_stuck",
)  # fmt: skip


@dataclass(frozen=True)
class SimulationOptions:
    """What to simulate. Angles in rad, lengths in m, times in s.

    ``model``: a registered model (default: the first). ``truth`` and ``guess`` map parameter
    names to values (``guess`` goes into the log header as the initial guess); empty means the
    model's defaults. ``encoder_ranges`` maps encoder names to their ``#joints_max_enc_values``
    (absolute range, or counts per turn); empty means the model's defaults; counters start
    ``wrap_after_ticks`` before they wrap. The rest is grouped: :class:`Sampling`,
    :class:`DriveShape`, :class:`TrackerSim`, :class:`InjectedFaults`. Files and the command
    line name every option flat (``latency_s``, not ``tracker.latency_s``): see :meth:`of` and
    :meth:`flat`.
    """

    records: int = 1500
    seed: int = 0
    model: str = DEFAULT_MODEL
    truth: Mapping[str, float] = field(default_factory=dict)
    guess: Mapping[str, float] = field(default_factory=dict)
    encoder_ranges: Mapping[str, int] = field(default_factory=dict)
    wrap_after_ticks: int = 20000
    sampling: Sampling = Sampling()
    drive: DriveShape = DriveShape()
    tracker: TrackerSim = TrackerSim()
    faults: InjectedFaults = InjectedFaults()

    @classmethod
    def of(cls, **flat: Any) -> SimulationOptions:
        """Options from their flat names (``SimulationOptions.of(records=900, latency_s=0.05)``)."""
        grouped: dict[str, dict[str, Any]] = {g: {} for g in _GROUPS}
        own: dict[str, Any] = {}
        for key, value in flat.items():
            group = _group_of(key)
            (own if group is None else grouped[group])[key] = value
        return cls(**own, **{g: _GROUPS[g](**kw) for g, kw in grouped.items() if kw})

    def flat(self) -> dict[str, Any]:
        """Every option by its flat name, in :data:`FLAT_ORDER` (a truth file's ``options``)."""
        values = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in _GROUPS}
        for g in _GROUPS:
            values.update(asdict(getattr(self, g)))
        return {k: values[k] for k in FLAT_ORDER}

    def __post_init__(self) -> None:
        _check(self)
        if self.model not in MODELS:
            raise OptionsError(f"model must be one of {', '.join(MODELS)}, got {self.model!r}")
        drive = MODELS[self.model].drive
        # Fill in the model's defaults so the truth JSON records every value used.
        object.__setattr__(self, "truth", {**drive.default_truth, **self.truth})
        object.__setattr__(self, "guess", {**drive.default_guess, **self.guess})
        object.__setattr__(self, "encoder_ranges", {**drive.default_ranges, **self.encoder_ranges})
        _check_values(self)


def flat_hints() -> dict[str, Any]:
    """The type of every option, by its flat name (for reading a file of options)."""
    hints = {k: v for k, v in typing.get_type_hints(SimulationOptions).items() if k not in _GROUPS}
    for cls in _GROUPS.values():
        hints.update(typing.get_type_hints(cls))
    return {k: hints[k] for k in FLAT_ORDER}


def _group_of(key: str) -> str | None:
    """The group holding option ``key`` (None: the options' own); an unknown key is an error."""
    for group, cls in _GROUPS.items():
        if key in {f.name for f in fields(cls)}:
            return group
    if key in {f.name for f in fields(SimulationOptions)} and key not in _GROUPS:
        return None
    raise OptionsError(f"unknown simulation option {key!r}; the options are {', '.join(FLAT_ORDER)}")


def _check_values(opts: SimulationOptions) -> None:
    """The parameters and encoder ranges: known to the model, finite, plausible."""
    model = MODELS[opts.model]
    drive = model.drive
    unknown = sorted((set(opts.truth) | set(opts.guess)) - set(drive.default_truth))
    if unknown:
        raise OptionsError(f"unknown parameter(s) {unknown} for model {opts.model!r}")
    for name, value in opts.truth.items():
        lo, hi = model.physical_ranges[name]
        reason = Range(lo, hi).problem(value)
        if reason is not None:
            raise OptionsError(f"truth.{name} {reason} (the model's plausible range)")
    for name, value in opts.guess.items():
        if Range(-math.inf, math.inf, lo_open=True, hi_open=True).problem(value) is not None:
            raise OptionsError(f"guess.{name} must be a finite number, got {value!r}")
    unknown = sorted(set(opts.encoder_ranges) - set(drive.default_ranges))
    if unknown or not all(isinstance(v, int) and 0 < v <= 2**32 for v in opts.encoder_ranges.values()):
        raise OptionsError(
            f"encoder_ranges takes whole numbers in [1, 2^32] for {', '.join(drive.default_ranges)}, "
            f"got {dict(opts.encoder_ranges)}"
        )


class ProfileSettings(Protocol):
    """The options :func:`drive_profiles` reads."""

    @property
    def trajectory(self) -> str: ...
    @property
    def max_speed(self) -> float: ...
    @property
    def max_turn(self) -> float: ...
    @property
    def stop_fraction(self) -> float: ...
    @property
    def reversals(self) -> str: ...


def profiles_on(
    knots: tuple[np.ndarray, np.ndarray, np.ndarray], t_fine: np.ndarray, t0: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The drive's speed and turn at each sub-step's middle of the fine grid ``t_fine`` (its arc)
    and the turn at each sub-step's end (what an angle's encoder reads at that instant; the
    middle's is half a sub-step early); ``t0``: the profiles' time zero."""
    kt, kv, ks = knots
    t_mid = 0.5 * (t_fine[1:] + t_fine[:-1]) - t0
    return np.interp(t_mid, kt, kv), np.interp(t_mid, kt, ks), np.interp(t_fine[1:] - t0, kt, ks)


def circles(
    opts: ProfileSettings, n_knots: int, duration: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Knots of circles at constant speed and turn from rest, the turn reversed halfway: the speeds
    change only at the start and at the reversal (a drive that barely tells a time offset)."""
    t = np.concatenate([[0.0], np.cumsum(np.full(n_knots, 1.5))])
    speed = np.full(t.size, 0.6 * opts.max_speed)
    speed[0] = 0.0
    turn = np.where(t > duration / 2, -0.5, 0.5) * opts.max_turn
    return t, speed, turn


def drive_profiles(
    opts: ProfileSettings, rng: np.random.Generator, duration: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Knot times, speeds and turning amplitudes; linear between knots."""
    n_knots = int(duration / 1.5) + 3
    if opts.trajectory == "circles":
        return circles(opts, n_knots, duration)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(1.0, 2.5, n_knots))])
    speed = rng.uniform(0.3, 1.0, t.size) * opts.max_speed
    if opts.trajectory == "s_curves":
        # Drive in one direction for a few knots, then reverse: reversals with realistic runs.
        direction = np.where((np.arange(t.size) // 6) % 2 == 0, 1.0, -1.0)
        speed *= direction
    stops = rng.random(t.size) < opts.stop_fraction
    speed[stops] = 0.0
    speed[0] = 0.0
    # A stop is held for a while (a second knot at zero speed), not just touched.
    hold = np.flatnonzero(stops)
    t = np.insert(
        t, hold + 1, t[hold] + rng.uniform(0.5, 1.0, hold.size) * np.diff(t)[np.minimum(hold, t.size - 2)]
    )
    speed = np.insert(speed, hold + 1, 0.0)
    turn = rng.uniform(-1.0, 1.0, t.size) * opts.max_turn
    turn[hold + 1 + np.arange(hold.size)] = turn[hold + np.arange(hold.size)]
    if opts.trajectory == "straight":
        turn[:] = 0.0
    if opts.reversals == "abrupt":
        # Keep the speed until just before the next knot, then change sign within ABRUPT_S.
        flip = np.flatnonzero(speed[:-1] * speed[1:] < 0)
        at = t[flip + 1] - ABRUPT_S
        turn = np.insert(turn, flip + 1, np.interp(at, t, turn))
        t, speed = np.insert(t, flip + 1, at), np.insert(speed, flip + 1, speed[flip])
    return t, speed, turn
