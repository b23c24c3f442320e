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
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core.errors import OptionsError
from nlp_calib.core.files import atomic_write_text, atomic_writer
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.core.ranges import Range
from nlp_calib.logs import LogHeader, format_header, format_log, format_records
from nlp_calib.models import DEFAULT_MODEL, MODELS
from nlp_calib.models.drives import integrate_base, running
from nlp_calib.simulation.faults import COUNTER_FAULT_KINDS, InjectedFault, inject

TRAJECTORIES = ("s_curves", "straight", "no_reversals")

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
    or counts per turn); empty means the model's defaults.
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

    def text(self) -> str:
        return format_log(self.header, self.time_ns, self.ticks, self.model_pose, self.T_world_sensor)

    def truth_dict(self) -> dict[str, Any]:
        return truth_document(self.options, self.faults)


def truth_document(opts: SimulationOptions, faults: Iterable[InjectedFault]) -> dict[str, Any]:
    """The truth JSON of a simulated log: the true parameters, every option, the injected faults."""
    return {
        "params": dict(opts.truth),
        "options": asdict(opts),
        "faults": [f.as_dict() for f in faults],
        "records": opts.records,
    }


def _profiles(
    opts: SimulationOptions, rng: np.random.Generator, duration: float
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
    return t, speed, turn


@dataclass(frozen=True)
class _Plan:
    """What the blocks need to be drawn one at a time as the whole log would be drawn at once: the
    drive's profiles (knot times, speeds, turns), the number of outliers, and where each of the
    simulation's random draws starts (the generator's state before it, in drawing order: sample
    intervals, then, after the profiles, tracker noise in x/y and in θ, which records are
    outliers, and their errors in x/y and in θ)."""

    knots: tuple[np.ndarray, np.ndarray, np.ndarray]
    n_outliers: int
    streams: tuple[Mapping[str, Any], ...]


#: Fine sub-steps simulated at once: a block's memory (about 200 bytes a sub-step) is bounded by
#: this, whatever the log's length.
BLOCK_SUBSTEPS = 2**16


def _state(rng: np.random.Generator) -> Mapping[str, Any]:
    return rng.bit_generator.state


def _generator(state: Mapping[str, Any]) -> np.random.Generator:
    rng = np.random.Generator(np.random.PCG64())
    rng.bit_generator.state = dict(state)
    return rng


def _chunks(n: int, size: int) -> Iterator[tuple[int, int]]:
    """``[a, b)`` ranges of at most ``size`` covering ``[0, n)``."""
    for a in range(0, n, size):
        yield a, min(a + size, n)


def _intervals(opts: SimulationOptions, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` jittered sample intervals (s)."""
    dt = 1.0 / opts.rate_hz + rng.normal(0.0, opts.jitter_s, n)
    return np.clip(dt, 0.25 / opts.rate_hz, None)


def _plan(opts: SimulationOptions, block: int) -> _Plan:
    """Every draw of the simulation made once, in blocks of ``block`` records, to learn where each
    starts; the records themselves are drawn again, block by block, by :func:`_blocks`."""
    rng = np.random.default_rng(opts.seed)
    n = opts.records
    streams = [_state(rng)]
    last: float | None = None
    for a, b in _chunks(n - 1, block):
        last = float(running(_intervals(opts, rng, b - a), last)[-1])
    knots = _profiles(opts, rng, (last or 0.0) + opts.latency_s + 1.0)
    streams.append(_state(rng))
    for a, b in _chunks(n, block):
        rng.normal(size=(b - a, 2))
    streams.append(_state(rng))
    for a, b in _chunks(n, block):
        rng.normal(size=b - a)
    streams.append(_state(rng))
    n_outliers = sum(int(np.sum(rng.random(b - a) < opts.outlier_fraction)) for a, b in _chunks(n, block))
    streams.append(_state(rng))
    for a, b in _chunks(n_outliers, block):
        rng.normal(size=(b - a, 2))
    streams.append(_state(rng))
    return _Plan(knots, n_outliers, tuple(streams))


def _pose_at(t_fine: np.ndarray, poses: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, t_fine, poses[:, i]) for i in range(3)], axis=1)


def _sensor_pose(base: np.ndarray, mount: tuple[float, float, float]) -> np.ndarray:
    c, s = np.cos(base[:, 2]), np.sin(base[:, 2])
    mx, my, mth = mount
    return np.stack([base[:, 0] + c * mx - s * my, base[:, 1] + s * mx + c * my, base[:, 2] + mth], axis=1)


@dataclass(frozen=True)
class _Block:
    """Records of a simulated log, before the vendor's odometry: sample times (s), encoder readings,
    tracker poses and the true base poses."""

    time_s: np.ndarray
    ticks: np.ndarray
    T_world_sensor: np.ndarray
    T_world_base_true: np.ndarray


@dataclass
class _Carry:
    """What a block continues from: the last sample time, the drive's channels and base pose at
    the last fine point, and the fine grid back as far as the tracker's latency reaches."""

    time_s: float | None = None
    channels: dict[str, float] | None = None
    pose: tuple[float, float, float] | None = None
    t_fine: np.ndarray = field(default_factory=lambda: np.empty(0))
    poses: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))


def _block_times(
    opts: SimulationOptions, rng: np.random.Generator, a: int, b: int, carry: _Carry
) -> np.ndarray:
    """Sample times of records ``[a, b)``."""
    if a == 0:
        return running(_intervals(opts, rng, b - 1))
    return running(_intervals(opts, rng, b - a), carry.time_s)[1:]


def _fine_motion(
    opts: SimulationOptions, plan: _Plan, t_s: np.ndarray, carry: _Carry
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """The fine grid from the record before ``t_s`` (from the latency's start, in the first block)
    to its last, the base poses and the drive's channels on it; ``carry`` moves on to its end."""
    t0 = -opts.latency_s
    if carry.time_s is not None:
        base_grid = np.concatenate([[carry.time_s], t_s])
    else:
        base_grid = np.concatenate([[t0], t_s]) if opts.latency_s > 0 else t_s
    frac = np.arange(opts.substeps) / opts.substeps
    t_fine = np.concatenate(
        [(base_grid[:-1, None] + np.diff(base_grid)[:, None] * frac).ravel(), base_grid[-1:]]
    )
    drive = MODELS[opts.model].drive
    kt, kv, ks = plan.knots
    t_mid = 0.5 * (t_fine[1:] + t_fine[:-1]) - t0
    ds, w, channels = drive.steps(
        opts,
        np.interp(t_mid, kt, kv),
        np.interp(t_mid, kt, ks),
        np.diff(t_fine),
        float(ks[0]),
        carry.channels,
    )
    poses = integrate_base(ds, w, carry.pose)
    carry.time_s = float(t_s[-1])
    carry.channels = {name: float(c[-1]) for name, c in channels.items()}
    carry.pose = (float(poses[-1, 0]), float(poses[-1, 1]), float(poses[-1, 2]))
    return t_fine, poses, channels


def _tracker(
    opts: SimulationOptions, t_s: np.ndarray, t_fine: np.ndarray, poses: np.ndarray, carry: _Carry
) -> np.ndarray:
    """The sensor's true pose at the times the tracker saw it (``latency`` earlier), keeping in
    ``carry`` the fine points the next block's earliest such time may fall between."""
    t_all = np.concatenate([carry.t_fine, t_fine])
    poses_all = np.concatenate([carry.poses, poses])
    t = opts.truth
    seen = _sensor_pose(
        _pose_at(t_all, poses_all, t_s - opts.latency_s), (t["sensor_x"], t["sensor_y"], t["sensor_theta"])
    )
    # The next block's fine grid starts at this block's last point: it is kept there, not here.
    keep = max(int(np.searchsorted(t_all, t_s[-1] - opts.latency_s, side="right")) - 1, 0)
    carry.t_fine, carry.poses = t_all[keep:-1], poses_all[keep:-1]
    return seen


def _noisy(opts: SimulationOptions, rngs: list[np.random.Generator], tracker: np.ndarray) -> np.ndarray:
    """``tracker`` with its noise and outliers, drawn from the streams of :class:`_Plan`."""
    n = tracker.shape[0]
    _, xy, theta, outlier, error_xy, error_theta = rngs
    tracker[:, :2] += xy.normal(0.0, opts.tracker_noise_xy, (n, 2))
    tracker[:, 2] += theta.normal(0.0, opts.tracker_noise_theta, n)
    outliers = np.asarray(outlier.random(n) < opts.outlier_fraction)
    tracker[outliers, :2] += error_xy.normal(0.0, opts.outlier_magnitude, (int(outliers.sum()), 2))
    tracker[outliers, 2] += error_theta.normal(0.0, opts.outlier_magnitude, int(outliers.sum()))
    tracker[:, 2] = wrap_angle(tracker[:, 2])
    return tracker


def _blocks(opts: SimulationOptions, block: int) -> Iterator[_Block]:
    """The log's records in blocks of ``block``, each drawn as the whole log would be drawn at once."""
    plan = _plan(opts, block)
    rngs = [_generator(s) for s in plan.streams]
    drive = MODELS[opts.model].drive
    carry = _Carry()
    for a, b in _chunks(opts.records, block):
        t_s = _block_times(opts, rngs[0], a, b, carry)
        t_fine, poses, channels = _fine_motion(opts, plan, t_s, carry)
        base = _pose_at(t_fine, poses, t_s)
        tracker = _noisy(opts, rngs, _tracker(opts, t_s, t_fine, poses, carry))
        ticks = drive.ticks(opts, {name: np.interp(t_s, t_fine, c) for name, c in channels.items()})
        yield _Block(t_s, ticks, tracker, base)


def _block_size(opts: SimulationOptions) -> int:
    return max(BLOCK_SUBSTEPS // opts.substeps, 1)


def _faulty(
    opts: SimulationOptions, header: LogHeader, blocks: Iterable[_Block]
) -> tuple[Iterable[_Block], tuple[InjectedFault, ...]]:
    """The blocks with ``opts.counter_faults`` counter faults injected: placing them needs the whole
    log, so with faults the blocks are joined into one (about 80 bytes a record)."""
    if not opts.counter_faults:
        return blocks, ()
    parts = list(blocks)
    whole = _Block(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(_Block)))
    # Their own random stream: a log without faults stays the same for a seed.
    counters = [n for n, kind in MODELS[opts.model].encoder_kinds.items() if kind == "counter"]
    fault_rng = np.random.default_rng([opts.seed, 1])
    ticks, faults = inject(
        whole.ticks, header.encoder_names, counters, opts.counter_faults, opts.counter_fault_kinds, fault_rng
    )
    return [replace(whole, ticks=ticks)], faults


def _time_ns(t_s: np.ndarray) -> np.ndarray:
    return np.round(t_s * 1e9).astype(np.int64) + 1_700_000_000_000_000_000


def _with_odometry(
    opts: SimulationOptions, header: LogHeader, blocks: Iterable[_Block]
) -> Iterator[tuple[_Block, np.ndarray]]:
    """Each block with the vendor's odometry over its records, continued from the block before."""
    drive = MODELS[opts.model].drive
    last: tuple[np.ndarray, np.ndarray] | None = None
    for blk in blocks:
        if last is None:
            odometry = drive.vendor_odometry(header, blk.ticks)
        else:
            ticks, pose = last
            start = (float(pose[0]), float(pose[1]), float(pose[2]))
            odometry = drive.vendor_odometry(header, np.concatenate([ticks[None], blk.ticks]), start)[1:]
        last = (blk.ticks[-1], odometry[-1])
        yield blk, odometry


def simulate(opts: SimulationOptions, block: int | None = None) -> SimulatedLog:
    """Simulate a drive and the log it would produce, in memory (``block``: records simulated at
    once; the log is the same whatever it is)."""
    header = MODELS[opts.model].drive.header(opts)
    blocks, faults = _faulty(opts, header, _blocks(opts, block or _block_size(opts)))
    pieces = list(_with_odometry(opts, header, blocks))
    joined = {f.name: np.concatenate([getattr(b, f.name) for b, _ in pieces]) for f in fields(_Block)}
    return SimulatedLog(
        header=header,
        time_ns=_time_ns(joined["time_s"]),
        ticks=joined["ticks"],
        model_pose=np.concatenate([odometry for _, odometry in pieces]),
        T_world_sensor=joined["T_world_sensor"],
        T_world_base_true=joined["T_world_base_true"],
        options=opts,
        faults=faults,
    )


def truth_path(log_path: Path) -> Path:
    """Where the truth JSON of a simulated log lives: beside it, ``<name>.truth.json``."""
    return log_path.with_suffix(".truth.json")


def write_simulation(sim: SimulatedLog, out: str | Path) -> tuple[Path, Path]:
    """Write the log and its truth JSON (atomically); returns both paths."""
    log_path = Path(out)
    atomic_write_text(log_path, sim.text())
    return log_path, _write_truth(log_path, sim.options, sim.faults)


def _write_truth(log_path: Path, opts: SimulationOptions, faults: Iterable[InjectedFault]) -> Path:
    tp = truth_path(log_path)
    atomic_write_text(tp, json.dumps(truth_document(opts, faults), indent=2) + "\n")
    return tp


def simulate_to_file(opts: SimulationOptions, out: str | Path, block: int | None = None) -> tuple[Path, Path]:
    """Simulate and write the log block by block, then its truth JSON (each atomically); returns
    both paths. The file holds the bytes ``simulate(opts).text()`` would; memory stays that of one
    block (``block`` records; default: :data:`BLOCK_SUBSTEPS` fine sub-steps), whatever the log's
    length, unless counter faults are injected (placing them needs the whole log)."""
    log_path = Path(out)
    header = MODELS[opts.model].drive.header(opts)
    blocks, faults = _faulty(opts, header, _blocks(opts, block or _block_size(opts)))
    with atomic_writer(log_path) as fh:
        fh.write(format_header(header).encode())
        for blk, odometry in _with_odometry(opts, header, blocks):
            fh.write(format_records(_time_ns(blk.time_s), blk.ticks, odometry, blk.T_world_sensor).encode())
    return log_path, _write_truth(log_path, opts, faults)
