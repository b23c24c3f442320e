"""The simulation drawn block by block: a log of any length in the memory of one block.

Every random draw is made once up front to learn where each of its streams starts
(:class:`_Plan`); each block then draws its own share of every stream and continues the motion
from the block before (:class:`_Carry`), so a log made in blocks holds the very numbers of a log
made at once, whatever the block size. What needs the whole log at once (a tracker on a clock
of its own, paired with the encoders as a bag import pairs them; injected faults, placed over
the whole log) is made as one block.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from nlp_calib.core.numeric import wrap_angle
from nlp_calib.logs import LogHeader
from nlp_calib.logs.bag_reader import DEFAULT_MAX_GAP_S, Stamped
from nlp_calib.logs.bag_records import pair
from nlp_calib.models import MODELS
from nlp_calib.models.drives import integrate_base, running
from nlp_calib.simulation.faults import InjectedFault, inject, inject_glitches
from nlp_calib.simulation.options import SimulationOptions, drive_profiles, profiles_on

#: Fine sub-steps simulated at once: a block's memory (about 200 bytes a sub-step) is bounded by
#: this, whatever the log's length.
BLOCK_SUBSTEPS = 2**16


@dataclass(frozen=True)
class Block:
    """Records of a simulated log, before the vendor's odometry: sample times (s), encoder
    readings, tracker poses, the true base poses and which tracker poses took in an outlier."""

    time_s: np.ndarray
    ticks: np.ndarray
    T_world_sensor: np.ndarray
    T_world_base_true: np.ndarray
    outliers: np.ndarray


@dataclass(frozen=True)
class _Plan:
    """What the blocks need to be drawn one at a time as the whole log would be drawn at once: the
    drive's profiles (knot times, speeds, turns) and where each of the simulation's random draws
    starts (the generator's state before it, in drawing order: sample intervals, then, after the
    profiles, tracker noise in x/y and in θ, which records are outliers, and their errors in x/y
    and in θ)."""

    knots: tuple[np.ndarray, np.ndarray, np.ndarray]
    streams: tuple[Mapping[str, Any], ...]


@dataclass
class _Carry:
    """What a block continues from: the last sample time, the drive's channels and base pose at
    the last fine point, and the fine grid back as far as the tracker's latency reaches."""

    time_s: float | None = None
    channels: dict[str, float] | None = None
    pose: tuple[float, float, float] | None = None
    t_fine: np.ndarray = field(default_factory=lambda: np.empty(0))
    poses: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))


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


def _intervals(rate_hz: float, jitter_s: float, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` jittered sample intervals (s)."""
    dt = 1.0 / rate_hz + rng.normal(0.0, jitter_s, n)
    return np.clip(dt, 0.25 / rate_hz, None)


def _plan(opts: SimulationOptions, block: int) -> _Plan:
    """Every draw of the simulation made once, in blocks of ``block`` records, to learn where each
    starts; the records themselves are drawn again, block by block, by :func:`blocks`."""
    rng = np.random.default_rng(opts.seed)
    n = opts.records
    streams = [_state(rng)]
    last: float | None = None
    for a, b in _chunks(n - 1, block):
        last = float(running(_intervals(opts.sampling.rate_hz, opts.sampling.jitter_s, rng, b - a), last)[-1])
    knots = drive_profiles(opts.drive, rng, (last or 0.0) + opts.tracker.latency_s + 1.0)
    streams.append(_state(rng))
    for a, b in _chunks(n, block):
        rng.normal(size=(b - a, 2))
    streams.append(_state(rng))
    for a, b in _chunks(n, block):
        rng.normal(size=b - a)
    streams.append(_state(rng))
    n_outliers = sum(
        int(np.sum(rng.random(b - a) < opts.tracker.outlier_fraction)) for a, b in _chunks(n, block)
    )
    streams.append(_state(rng))
    for a, b in _chunks(n_outliers, block):
        rng.normal(size=(b - a, 2))
    streams.append(_state(rng))
    return _Plan(knots, tuple(streams))


def _pose_at(t_fine: np.ndarray, poses: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, t_fine, poses[:, i]) for i in range(3)], axis=1)


def _sensor_pose(base: np.ndarray, mount: tuple[float, float, float]) -> np.ndarray:
    c, s = np.cos(base[:, 2]), np.sin(base[:, 2])
    mx, my, mth = mount
    return np.stack([base[:, 0] + c * mx - s * my, base[:, 1] + s * mx + c * my, base[:, 2] + mth], axis=1)


def _block_times(
    opts: SimulationOptions, rng: np.random.Generator, a: int, b: int, carry: _Carry
) -> np.ndarray:
    """Sample times of records ``[a, b)``."""
    if a == 0:
        return running(_intervals(opts.sampling.rate_hz, opts.sampling.jitter_s, rng, b - 1))
    return running(_intervals(opts.sampling.rate_hz, opts.sampling.jitter_s, rng, b - a), carry.time_s)[1:]


def _fine_motion(
    opts: SimulationOptions, plan: _Plan, t_s: np.ndarray, carry: _Carry
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """The fine grid from the record before ``t_s`` (from the latency's start, in the first block)
    to its last, the base poses and the drive's channels on it; ``carry`` moves on to its end."""
    t0 = -opts.tracker.latency_s
    if carry.time_s is not None:
        base_grid = np.concatenate([[carry.time_s], t_s])
    else:
        base_grid = np.concatenate([[t0], t_s]) if opts.tracker.latency_s > 0 else t_s
    frac = np.arange(opts.sampling.substeps) / opts.sampling.substeps
    t_fine = np.concatenate(
        [(base_grid[:-1, None] + np.diff(base_grid)[:, None] * frac).ravel(), base_grid[-1:]]
    )
    speed, turn, turn_end = profiles_on(plan.knots, t_fine, t0)
    drive = MODELS[opts.model].drive
    turn_start = float(plan.knots[2][0])
    ds, w, channels = drive.steps(opts, speed, turn, turn_end, np.diff(t_fine), turn_start, carry.channels)
    poses = integrate_base(ds, w, carry.pose)
    carry.time_s = float(t_s[-1])
    carry.channels = {name: float(c[-1]) for name, c in channels.items()}
    carry.pose = (float(poses[-1, 0]), float(poses[-1, 1]), float(poses[-1, 2]))
    return t_fine, poses, channels


def _seen(
    opts: SimulationOptions, t_s: np.ndarray, t_fine: np.ndarray, poses: np.ndarray, carry: _Carry
) -> np.ndarray:
    """The sensor's true pose at the times the tracker saw it (``latency`` earlier), keeping in
    ``carry`` the fine points the next block's earliest such time may fall between."""
    t_all = np.concatenate([carry.t_fine, t_fine])
    poses_all = np.concatenate([carry.poses, poses])
    t = opts.truth
    mount = (t["sensor_x"], t["sensor_y"], t["sensor_theta"])
    seen = _sensor_pose(_pose_at(t_all, poses_all, t_s - opts.tracker.latency_s), mount)
    # The next block's fine grid starts at this block's last point: it is kept there, not here.
    keep = max(int(np.searchsorted(t_all, t_s[-1] - opts.tracker.latency_s, side="right")) - 1, 0)
    carry.t_fine, carry.poses = t_all[keep:-1], poses_all[keep:-1]
    return seen


def _noisy(
    opts: SimulationOptions, rngs: list[np.random.Generator], tracker: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``tracker`` with its noise and gross outliers (drawn from the streams of :class:`_Plan`),
    and which poses took in an outlier."""
    n = tracker.shape[0]
    xy, theta, outlier, error_xy, error_theta = rngs
    tracker[:, :2] += xy.normal(0.0, opts.tracker.tracker_noise_xy, (n, 2))
    tracker[:, 2] += theta.normal(0.0, opts.tracker.tracker_noise_theta, n)
    outliers = np.asarray(outlier.random(n) < opts.tracker.outlier_fraction)
    tracker[outliers, :2] += error_xy.normal(0.0, opts.tracker.outlier_magnitude, (int(outliers.sum()), 2))
    tracker[outliers, 2] += error_theta.normal(0.0, opts.tracker.outlier_magnitude, int(outliers.sum()))
    tracker[:, 2] = wrap_angle(tracker[:, 2])
    return tracker, outliers


def _same_clock(opts: SimulationOptions, block: int) -> Iterator[Block]:
    """The records in blocks of ``block``, the tracker sampled with each encoder sample."""
    plan = _plan(opts, block)
    rngs = [_generator(s) for s in plan.streams]
    drive = MODELS[opts.model].drive
    carry = _Carry()
    for a, b in _chunks(opts.records, block):
        t_s = _block_times(opts, rngs[0], a, b, carry)
        t_fine, poses, channels = _fine_motion(opts, plan, t_s, carry)
        base = _pose_at(t_fine, poses, t_s)
        tracker, outliers = _noisy(opts, rngs[1:], _seen(opts, t_s, t_fine, poses, carry))
        ticks = drive.ticks(opts, {name: np.interp(t_s, t_fine, c) for name, c in channels.items()})
        yield Block(t_s, ticks, tracker, base, outliers)


def _own_clock(opts: SimulationOptions) -> Block:
    """The whole log with the tracker on a clock of its own (its rate and jitter, a random phase,
    its noise from a stream of its own), paired with the encoder samples as a bag import pairs
    them: a record at each encoder sample the tracker brackets."""
    plan = _plan(opts, opts.records)
    t_enc = running(
        _intervals(
            opts.sampling.rate_hz, opts.sampling.jitter_s, _generator(plan.streams[0]), opts.records - 1
        )
    )
    clock = np.random.default_rng([opts.seed, 2])
    n = int(np.ceil(t_enc[-1] * opts.tracker.tracker_rate_hz)) + 2
    phase = clock.uniform(0.0, 1.0 / opts.tracker.tracker_rate_hz)
    t_trk = phase + running(
        _intervals(opts.tracker.tracker_rate_hz, opts.tracker.tracker_jitter_s, clock, n - 1)
    )
    t_fine, poses, channels = _fine_motion(opts, plan, np.union1d(t_enc, t_trk[t_trk > t_enc[-1]]), _Carry())
    own = np.random.default_rng([opts.seed, 3])
    tracker, outliers = _noisy(opts, [own] * 5, _seen(opts, t_trk, t_fine, poses, _Carry()))
    ns = lambda t: np.round(t * 1e9).astype(np.int64)  # noqa: E731
    joints = Stamped("joints", ns(t_enc), np.zeros((t_enc.size, 0)))
    index, paired, _ = pair(joints, Stamped("tracker", ns(t_trk), tracker), DEFAULT_MAX_GAP_S)
    t_s = t_enc[index]
    ticks = MODELS[opts.model].drive.ticks(opts, {k: np.interp(t_s, t_fine, c) for k, c in channels.items()})
    bad = np.interp(t_s, t_trk, outliers.astype(float)) > 0
    return Block(t_s, ticks, paired, _pose_at(t_fine, poses, t_s), bad)


def blocks(opts: SimulationOptions, block: int | None = None) -> Iterator[Block]:
    """The log's records in blocks of ``block`` (default: :data:`BLOCK_SUBSTEPS` fine sub-steps),
    each drawn as the whole log would be drawn at once."""
    if opts.tracker.tracker_rate_hz:
        yield _own_clock(opts)
        return
    yield from _same_clock(opts, block or max(BLOCK_SUBSTEPS // opts.sampling.substeps, 1))


def with_faults(
    opts: SimulationOptions, header: LogHeader, parts: Iterable[Block]
) -> tuple[Iterable[Block], tuple[InjectedFault, ...]]:
    """The blocks with the options' faults injected: placing them needs the whole log, so with
    faults the blocks are joined into one (about 80 bytes a record)."""
    if not opts.faults.any:
        return parts, ()
    listed = list(parts)
    whole = Block(*(np.concatenate([getattr(p, f.name) for p in listed]) for f in fields(Block)))
    ticks, faults = inject_faults(opts, header, whole.ticks)
    return [replace(whole, ticks=ticks)], faults


def inject_faults(
    opts: SimulationOptions, header: LogHeader, ticks: np.ndarray
) -> tuple[np.ndarray, tuple[InjectedFault, ...]]:
    """``ticks`` with the options' counter faults, spikes and stuck readings of an absolute encoder,
    each kind from a random stream of its own (a log without faults stays the same for a seed)."""
    kinds = MODELS[opts.model].encoder_kinds
    faults: tuple[InjectedFault, ...] = ()
    if opts.faults.counter_faults:
        counters = [n for n, kind in kinds.items() if kind == "counter"]
        fault_rng = np.random.default_rng([opts.seed, 1])
        ticks, faults = inject(
            ticks,
            header.encoder_names,
            counters,
            opts.faults.counter_faults,
            opts.faults.counter_fault_kinds,
            fault_rng,
        )
    absolute = [n for n, kind in kinds.items() if kind == "absolute"]
    if absolute and (opts.faults.steering_spikes or opts.faults.steering_stuck):
        glitch_rng = np.random.default_rng([opts.seed, 4])
        counts = (opts.faults.steering_spikes, opts.faults.steering_stuck)
        ticks, glitches = inject_glitches(ticks, header, absolute[0], counts, faults, glitch_rng)
        faults = tuple(sorted(faults + glitches, key=lambda f: f.record))
    return ticks, faults


def with_odometry(
    opts: SimulationOptions, header: LogHeader, parts: Iterable[Block]
) -> Iterator[tuple[Block, np.ndarray]]:
    """Each block with the vendor's odometry over its records, continued from the block before."""
    drive = MODELS[opts.model].drive
    last: tuple[np.ndarray, np.ndarray] | None = None
    for blk in parts:
        if last is None:
            odometry = drive.vendor_odometry(header, blk.ticks)
        else:
            ticks, pose = last
            start = (float(pose[0]), float(pose[1]), float(pose[2]))
            odometry = drive.vendor_odometry(header, np.concatenate([ticks[None], blk.ticks]), start)[1:]
        last = (blk.ticks[-1], odometry[-1])
        yield blk, odometry
