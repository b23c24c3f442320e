"""What to simulate: the options of a synthetic log, validated on construction, and the drive's
speed and turning profiles they describe."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from nlp_calib.core.errors import OptionsError
from nlp_calib.core.ranges import Range
from nlp_calib.models import DEFAULT_MODEL, MODELS
from nlp_calib.simulation.faults import COUNTER_FAULT_KINDS

TRAJECTORIES = ("s_curves", "straight", "no_reversals")
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


@dataclass(frozen=True)
class SimulationOptions:
    """What to simulate. Angles in rad, lengths in m, times in s.

    ``model``: a registered model (default: the first). ``trajectory``: ``s_curves`` (turns,
    stops and reversals), ``straight`` (no turning) or ``no_reversals`` (turns and stops, always
    forward). ``truth`` and ``guess`` map parameter names to values (``guess`` goes into the log
    header as the initial guess); empty means the model's defaults. ``max_turn`` is the amplitude
    of the turning profile, which each model's drive reads in its own way (see its ``steps``).
    ``encoder_ranges`` maps encoder names to their ``#joints_max_enc_values`` (absolute range,
    or counts per turn); empty means the model's defaults. ``reversals``: ``smooth`` (the speed
    passes through zero over seconds) or ``abrupt`` (within 20 ms). ``tracker_rate_hz`` > 0 puts
    the tracker on a clock of its own (that rate, ``tracker_jitter_s``, a random phase); its poses
    are then paired with the encoders' records as a bag import pairs them (interpolated at each
    encoder stamp). ``counter_faults``, ``steering_spikes`` and ``steering_stuck`` inject that many
    faults of each kind (:mod:`nlp_calib.simulation.faults`).
    """

    records: int = 1500
    seed: int = 0
    model: str = DEFAULT_MODEL
    trajectory: str = "s_curves"
    truth: Mapping[str, float] = field(default_factory=dict)
    guess: Mapping[str, float] = field(default_factory=dict)
    encoder_ranges: Mapping[str, int] = field(default_factory=dict)
    rate_hz: float = 25.0
    jitter_s: float = 0.004
    substeps: int = 20
    max_speed: float = 0.6
    max_turn: float = 0.6
    stop_fraction: float = 0.15
    tracker_noise_xy: float = 0.002
    tracker_noise_theta: float = 0.002
    outlier_fraction: float = 0.0
    outlier_magnitude: float = 0.3
    latency_s: float = 0.0
    wrap_after_ticks: int = 20000
    counter_faults: int = 0
    counter_fault_kinds: tuple[str, ...] = COUNTER_FAULT_KINDS
    reversals: str = "smooth"
    tracker_rate_hz: float = 0.0
    tracker_jitter_s: float = 0.004
    steering_spikes: int = 0
    steering_stuck: int = 0

    def __post_init__(self) -> None:
        for name, limit in LIMITS.items():
            reason = limit.problem(getattr(self, name))
            if reason is not None:
                raise OptionsError(f"{name} {reason}")
        if self.model not in MODELS:
            raise OptionsError(f"model must be one of {', '.join(MODELS)}, got {self.model!r}")
        model = MODELS[self.model]
        drive = model.drive
        # Fill in the model's defaults so the truth JSON records every value used.
        object.__setattr__(self, "truth", {**drive.default_truth, **self.truth})
        object.__setattr__(self, "guess", {**drive.default_guess, **self.guess})
        object.__setattr__(self, "encoder_ranges", {**drive.default_ranges, **self.encoder_ranges})
        if self.trajectory not in TRAJECTORIES:
            raise OptionsError(
                f"trajectory must be one of {', '.join(TRAJECTORIES)}, got {self.trajectory!r}"
            )
        unknown = sorted((set(self.truth) | set(self.guess)) - set(drive.default_truth))
        if unknown:
            raise OptionsError(f"unknown parameter(s) {unknown} for model {self.model!r}")
        for name, value in self.truth.items():
            lo, hi = model.physical_ranges[name]
            reason = Range(lo, hi).problem(value)
            if reason is not None:
                raise OptionsError(f"truth.{name} {reason} (the model's plausible range)")
        for name, value in self.guess.items():
            if Range(-math.inf, math.inf, lo_open=True, hi_open=True).problem(value) is not None:
                raise OptionsError(f"guess.{name} must be a finite number, got {value!r}")
        unknown = sorted(set(self.encoder_ranges) - set(drive.default_ranges))
        if unknown or not all(isinstance(v, int) and 0 < v <= 2**32 for v in self.encoder_ranges.values()):
            raise OptionsError(
                f"encoder_ranges takes whole numbers in [1, 2^32] for {', '.join(drive.default_ranges)}, "
                f"got {dict(self.encoder_ranges)}"
            )
        if self.reversals not in REVERSALS:
            raise OptionsError(f"reversals must be one of {', '.join(REVERSALS)}, got {self.reversals!r}")
        if not set(self.counter_fault_kinds) <= set(COUNTER_FAULT_KINDS):
            raise OptionsError(f"counter_fault_kinds must be among {', '.join(COUNTER_FAULT_KINDS)}")


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


def drive_profiles(
    opts: ProfileSettings, rng: np.random.Generator, duration: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Knot times, speeds and turning amplitudes; linear between knots."""
    n_knots = int(duration / 1.5) + 3
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
