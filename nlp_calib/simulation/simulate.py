"""Synthetic logs with known truth, in the log text format, for any registered model.

The robot is simulated in continuous time (exact arcs on a fine sub-step grid, with smoothly
varying speed and turning), then sampled at jittered ~25 Hz: quantised encoders (wheel counters
start near 2³² so they wrap), and a tracker that sees the sensor pose with noise, gross outliers
and latency. What differs between robots (how speed and turning move the wheels, and which
encoders read them) is each model's ``drive``. Independent of the symbolic model on purpose: it
is the yardstick the model is checked against. Deterministic for a given seed.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from nlp_calib.core.errors import OptionsError
from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.core.ranges import Range
from nlp_calib.logs import LogHeader, format_log
from nlp_calib.logs.bag_reader import DEFAULT_MAX_GAP_S, Stamped
from nlp_calib.logs.bag_records import pair
from nlp_calib.models import DEFAULT_MODEL, MODELS
from nlp_calib.models.drives import integrate_base
from nlp_calib.simulation.faults import COUNTER_FAULT_KINDS, InjectedFault, inject, inject_glitches

TRAJECTORIES = ("s_curves", "straight", "no_reversals")
#: How the speed changes sign: through zero over seconds, or within :data:`ABRUPT_S`.
REVERSALS = ("smooth", "abrupt")
ABRUPT_S = 0.02

#: Accepted values of the numeric options (the command line checks its options against the same).
#: Memory grows with ``records × substeps`` (about 200 bytes each).
LIMITS: Mapping[str, Range] = {
    "records": Range(3, 10**7, integer=True),
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


@dataclass(frozen=True)
class SimulatedLog:
    """A simulated log: record arrays plus the header that describes them."""

    header: LogHeader
    time_ns: np.ndarray
    ticks: np.ndarray
    model_pose: np.ndarray
    T_world_sensor: np.ndarray
    T_world_base_true: np.ndarray
    options: SimulationOptions
    faults: tuple[InjectedFault, ...] = ()
    #: Per record, whether its tracker pose took in a gross outlier (paired: either bracket).
    tracker_outliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def text(self) -> str:
        return format_log(self.header, self.time_ns, self.ticks, self.model_pose, self.T_world_sensor)

    def truth_dict(self) -> dict[str, Any]:
        opts = asdict(self.options)
        return {
            "params": dict(self.options.truth),
            "options": opts,
            "faults": [f.as_dict() for f in self.faults],
            "tracker_outliers": np.flatnonzero(self.tracker_outliers).tolist(),
            "records": int(self.time_ns.size),
        }


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


def _sample_times(n: int, rate_hz: float, jitter_s: float, rng: np.random.Generator) -> np.ndarray:
    dt = 1.0 / rate_hz + rng.normal(0.0, jitter_s, n - 1)
    dt = np.clip(dt, 0.25 / rate_hz, None)
    return np.concatenate([[0.0], np.cumsum(dt)])


def _pose_at(t_fine: np.ndarray, poses: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, t_fine, poses[:, i]) for i in range(3)], axis=1)


def _sensor_pose(base: np.ndarray, mount: tuple[float, float, float]) -> np.ndarray:
    c, s = np.cos(base[:, 2]), np.sin(base[:, 2])
    mx, my, mth = mount
    return np.stack([base[:, 0] + c * mx - s * my, base[:, 1] + s * mx + c * my, base[:, 2] + mth], axis=1)


@dataclass(frozen=True)
class _Motion:
    """The robot's continuous motion: base poses and encoder channels on a fine time grid."""

    t: np.ndarray
    poses: np.ndarray
    channels: dict[str, np.ndarray]

    def base_at(self, t: np.ndarray) -> np.ndarray:
        return _pose_at(self.t, self.poses, t)


def _motion(opts: SimulationOptions, knots: tuple[np.ndarray, ...], grid: np.ndarray) -> _Motion:
    """The drive over sub-steps between the times ``grid``, starting early enough for the latency."""
    t0 = -opts.latency_s
    base_grid = np.concatenate([[t0], grid]) if opts.latency_s > 0 else grid
    frac = np.arange(opts.substeps) / opts.substeps
    t_fine = np.concatenate(
        [(base_grid[:-1, None] + np.diff(base_grid)[:, None] * frac).ravel(), base_grid[-1:]]
    )
    kt, kv, ks = knots
    t_mid = 0.5 * (t_fine[1:] + t_fine[:-1]) - t0
    drive = MODELS[opts.model].drive
    ds, w, channels = drive.steps(
        opts, np.interp(t_mid, kt, kv), np.interp(t_mid, kt, ks), np.diff(t_fine), float(ks[0])
    )
    return _Motion(t_fine, integrate_base(ds, w), channels)


def _tracker(
    opts: SimulationOptions, motion: _Motion, t: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """The tracker's poses reported at times ``t``: the sensor ``latency_s`` earlier, with noise and
    gross outliers (and which poses are outliers)."""
    truth, n = opts.truth, t.size
    mount = (truth["sensor_x"], truth["sensor_y"], truth["sensor_theta"])
    tracker = _sensor_pose(motion.base_at(t - opts.latency_s), mount)
    tracker[:, :2] += rng.normal(0.0, opts.tracker_noise_xy, (n, 2))
    tracker[:, 2] += rng.normal(0.0, opts.tracker_noise_theta, n)
    outliers = rng.random(n) < opts.outlier_fraction
    tracker[outliers, :2] += rng.normal(0.0, opts.outlier_magnitude, (int(outliers.sum()), 2))
    tracker[outliers, 2] += rng.normal(0.0, opts.outlier_magnitude, int(outliers.sum()))
    tracker[:, 2] = wrap_angle(tracker[:, 2])
    return tracker, outliers


def _own_clock(opts: SimulationOptions, t_enc: np.ndarray) -> np.ndarray:
    """The tracker's own sample times over the encoders' span: its rate and jitter, a random phase."""
    rng = np.random.default_rng([opts.seed, 2])
    n = int(np.ceil(t_enc[-1] * opts.tracker_rate_hz)) + 2
    return rng.uniform(0.0, 1.0 / opts.tracker_rate_hz) + _sample_times(
        n, opts.tracker_rate_hz, opts.tracker_jitter_s, rng
    )


def _records(
    opts: SimulationOptions, rng: np.random.Generator, t_enc: np.ndarray, knots: tuple[np.ndarray, ...]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, _Motion]:
    """Record times, the tracker's pose at each, which took in an outlier, and the motion: one
    record per encoder sample with the tracker sampled alongside, or, on its own clock, paired
    as a bag import pairs them."""
    if not opts.tracker_rate_hz:
        motion = _motion(opts, knots, t_enc)
        return (t_enc, *_tracker(opts, motion, t_enc, rng), motion)
    t_trk = _own_clock(opts, t_enc)
    motion = _motion(opts, knots, np.union1d(t_enc, t_trk[t_trk > t_enc[-1]]))
    poses, outliers = _tracker(opts, motion, t_trk, np.random.default_rng([opts.seed, 3]))
    ns = lambda t: np.round(t * 1e9).astype(np.int64)  # noqa: E731
    joints = Stamped("joints", ns(t_enc), np.zeros((t_enc.size, 0)))
    index, paired, _ = pair(joints, Stamped("tracker", ns(t_trk), poses), DEFAULT_MAX_GAP_S)
    t_s = t_enc[index]
    return t_s, paired, np.interp(t_s, t_trk, outliers.astype(float)) > 0, motion


def simulate(opts: SimulationOptions) -> SimulatedLog:
    """Simulate a drive and the log it would produce."""
    rng = np.random.default_rng(opts.seed)
    t_enc = _sample_times(opts.records, opts.rate_hz, opts.jitter_s, rng)
    knots = drive_profiles(opts, rng, float(t_enc[-1]) + opts.latency_s + 1.0)
    t_s, tracker, outliers, motion = _records(opts, rng, t_enc, knots)
    drive = MODELS[opts.model].drive
    ticks = drive.ticks(opts, {name: np.interp(t_s, motion.t, c) for name, c in motion.channels.items()})
    header = drive.header(opts)
    ticks, faults = inject_faults(opts, header, ticks)
    return SimulatedLog(
        header=header,
        time_ns=np.round(t_s * 1e9).astype(np.int64) + 1_700_000_000_000_000_000,
        ticks=ticks,
        model_pose=drive.vendor_odometry(header, ticks),
        T_world_sensor=tracker,
        T_world_base_true=motion.base_at(t_s),
        options=opts,
        faults=faults,
        tracker_outliers=outliers,
    )


def inject_faults(
    opts: SimulationOptions, header: LogHeader, ticks: np.ndarray
) -> tuple[np.ndarray, tuple[InjectedFault, ...]]:
    """``ticks`` with the options' counter faults, spikes and stuck readings of an absolute encoder,
    each kind from a random stream of its own (a log without faults stays the same for a seed)."""
    kinds = MODELS[opts.model].encoder_kinds
    faults: tuple[InjectedFault, ...] = ()
    if opts.counter_faults:
        counters = [n for n, kind in kinds.items() if kind == "counter"]
        fault_rng = np.random.default_rng([opts.seed, 1])
        ticks, faults = inject(
            ticks, header.encoder_names, counters, opts.counter_faults, opts.counter_fault_kinds, fault_rng
        )
    absolute = [n for n, kind in kinds.items() if kind == "absolute"]
    if absolute and (opts.steering_spikes or opts.steering_stuck):
        glitch_rng = np.random.default_rng([opts.seed, 4])
        counts = (opts.steering_spikes, opts.steering_stuck)
        ticks, glitches = inject_glitches(ticks, header, absolute[0], counts, faults, glitch_rng)
        faults = tuple(sorted(faults + glitches, key=lambda f: f.record))
    return ticks, faults


def truth_path(log_path: Path) -> Path:
    """Where the truth JSON of a simulated log lives: beside it, ``<name>.truth.json``."""
    return log_path.with_suffix(".truth.json")


def write_simulation(sim: SimulatedLog, out: str | Path) -> tuple[Path, Path]:
    """Write the log and its truth JSON (atomically); returns both paths."""
    log_path = Path(out)
    atomic_write_text(log_path, sim.text())
    tp = truth_path(log_path)
    atomic_write_text(tp, json.dumps(sim.truth_dict(), indent=2) + "\n")
    return log_path, tp
