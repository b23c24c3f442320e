"""A bag's joints in radians and its tracker, each on its own clock, as a log timed by the tracker.

Joint positions (REP 103: radians, a wheel's angle growing without wrapping) come fast and smooth;
tracker poses do not. So a record is made at each tracker pose, at its own stamp, with every
joint's position interpolated there from the joints' own messages; no pose is ever made up
between two tracker poses. A tracker pose before the first joint message, after the last, or
inside a gap of the joints over ``max_gap`` is left out. The joints' messages are kept as they
are (:class:`~nlp_calib.logs.log.JointStream`), so a tracker lag re-samples them at their own
stamps. A joint that publishes only its velocity is integrated over the stamps (trapezoids), said
in a warning.

Each topic is timed by its header stamps unless told otherwise (:class:`BagTopics`): the bag's
record times, or a constant offset added to the joints' stamps, given or estimated from the record
times (the tracker lag then refines what remains). Streams that do not overlap in time are one
error saying which clock to change.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.logs.bag_reader import BagError, BagTopics, Drops, Stamped, read_topics
from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.logs.log import JointStream, Log, LogClock, LogHeader, ReferenceData, frozen
from nlp_calib.logs.screens import clock_shift
from nlp_calib.logs.tum import format_tum

#: A joint's positions are quantised when at least this share of its steps are whole multiples
#: of its smallest step (to 1 %).
QUANTISED_SHARE = 0.9
#: A joint whose readings change every this many messages or more (the median) has a driver that
#: updates slower than it publishes; fewer, and a repeated reading is the joint at rest (or within
#: one step of its resolution), as published.
SLOW_DRIVER_MESSAGES = 2.0
#: A reading held this many times longer than the joint's usual time between updates is a joint
#: that stood still (the last message of the hold is its position then), not a slow driver's.
STANDSTILL_UPDATES = 2.0


@dataclass(frozen=True)
class Timing:
    """How the tracker's poses were timed against the joints: poses kept, before the first joint
    message, after the last, inside a gap of the joints over ``max_gap_s``; the joints integrated
    from velocities; the messages not used as they were."""

    tracker_poses: int
    kept: int
    before: int
    after: int
    in_gaps: int
    max_gap_s: float
    integrated: tuple[str, ...] = ()
    drops: Drops = field(default_factory=Drops)

    def describe(self) -> str:
        left = (
            f"{self.before} before the first joint message, {self.after} after the last, {self.in_gaps} "
            f"in joint gaps over {self.max_gap_s:g} s"
        )
        velocity = (
            f"; joints integrated from their velocities: {', '.join(self.integrated)}"
            if self.integrated
            else ""
        )
        dropped = f"; not used as they were: {self.drops.describe()}" if self.drops.counts else ""
        return (
            f"{self.kept} of {self.tracker_poses} tracker poses timed inside the joints' stream "
            f"({left}){velocity}{dropped}"
        )


def clock_shift_ns(path: Path, joints: Stamped, tracker: Stamped, offset: float | str) -> int:
    """What to add to the joints' stamps to put them on the tracker's clock (ns): ``offset`` (s),
    or, for ``auto``, the difference of the two topics' median delay from stamp to record time."""
    if offset != "auto":
        return round(float(offset) * 1e9)
    assert joints.recorded_ns is not None and tracker.recorded_ns is not None
    delay_joints = float(np.median(joints.recorded_ns - joints.stamp_ns))
    delay_tracker = float(np.median(tracker.recorded_ns - tracker.stamp_ns))
    shift = round(delay_joints - delay_tracker)
    warnings.warn(
        f"{path}: clock_offset auto: the stamps of {joints.topic!r} lie {shift * 1e-9:+.6f} s off those of "
        f"{tracker.topic!r} (from the bag's record times); they are shifted by it, and the tracker lag "
        "refines what remains",
        NlpCalibWarning,
        stacklevel=3,
    )
    return shift


def check_overlap(path: Path, joints: Stamped, tracker: Stamped) -> None:
    """Refuse streams that do not overlap in time, saying which clock to change."""
    j, t = joints.stamp_ns, tracker.stamp_ns
    if j.max() >= t.min() and t.max() >= j.min():
        return
    raise BagError(
        path,
        f"the stamps of {joints.topic!r} ({_span(j)}) and of {tracker.topic!r} ({_span(t)}) do not overlap: "
        "the topics' header clocks differ (time since boot?); set stamps: {TOPIC: receive} for the "
        "topic whose clock is unusable, or clock_offset: auto (docs/bags.md)",
    )


def check_clocks(path: Path, joint_ns: np.ndarray, positions: np.ndarray, tracker: Stamped) -> None:
    """Refuse streams whose motion agrees only with one shifted seconds against the other: one
    clock is off by that much, which pairs poses with the wrong joints (:func:`~nlp_calib.logs.
    screens.clock_shift`)."""
    order = np.argsort(tracker.stamp_ns, kind="stable")
    ts = tracker.stamp_ns[order]
    first = np.concatenate([[True], np.diff(ts) > 0])
    found = clock_shift(joint_ns, positions, ts[first], tracker.values[order][first])
    if found is None:
        return
    shift, best, stamped = found.shift, found.best, found.stamped
    agree = (
        f"the joints' speed and the tracker's motion agree when the joints' times are shifted by "
        f"{shift:+.2f} s (correlation {best:.2f}, against {stamped:.2f} as stamped)"
    )
    if found.ambiguous:
        warnings.warn(
            f"{path}: {agree}, and as well at {found.rival_s:+.2f} s ({found.rival:.2f}): the drive "
            "repeats, so the recording cannot tell a clock shift from none; its stamps are used as "
            "they are (if a clock is off, add the seconds to clock_offset in the dataset block)",
            NlpCalibWarning,
            stacklevel=3,
        )
        return
    late = "the tracker's stamps lie" if shift > 0 else "the joints' stamps lie"
    raise BagError(
        path,
        f"{agree}: {late} {abs(shift):.2f} s late, which pairs poses with the wrong joints; add "
        f"{shift:+.2f} s to clock_offset in the dataset block (the seconds added to the joints' "
        "times; the tracker lag refines what remains), or fix the recording's stamps",
    )


def _span(ns: np.ndarray) -> str:
    return f"{ns.min() * 1e-9:.3f}-{ns.max() * 1e-9:.3f} s"


def resolution(positions: np.ndarray) -> float:
    """A joint's smallest step when its positions are quantised (most steps are whole multiples
    of it), else 0."""
    steps = np.abs(np.diff(positions))
    steps = steps[steps > 0]
    if steps.size == 0:
        return 0.0
    q = float(steps.min())
    ratio = steps / q
    return q if np.mean(np.abs(ratio - np.round(ratio)) < 0.01) >= QUANTISED_SHARE else 0.0


def fresh_positions(time_s: np.ndarray, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's positions at its messages, the readings a slow driver held filled in between
    its updates, and which messages are readings of their own (fresh). A driver that updates at
    4 Hz under 20 Hz messages repeats its last reading, up to one update period (0.25 s) old, so
    the stream read between its messages is a staircase whose steps land late (a pivot's start or
    stop then disagrees with the reference as slip would). A reading is fresh at the message where
    it changed. The driver's update period is its busiest joint's median time between changes (a
    wheel while the robot moves): a joint that rests (a steered wheel's angle held on a circle) says
    nothing of its driver. Where that period spans :data:`SLOW_DRIVER_MESSAGES` messages or more,
    each joint's held messages are interpolated from its fresh ones, except a hold
    :data:`STANDSTILL_UPDATES` update periods long or longer, where the joint stood still (its last
    message is kept); otherwise every joint is returned as published."""
    out = np.array(positions, dtype=float)
    changes = [np.flatnonzero(np.r_[True, out[1:, j] != out[:-1, j]]) for j in range(out.shape[1])]
    fresh = np.zeros(out.shape, dtype=bool)
    for j, changed in enumerate(changes):
        fresh[changed, j] = True
    busy = [float(np.median(np.diff(time_s[c]))) for c in changes if c.size >= 3]
    if not busy or min(busy) < SLOW_DRIVER_MESSAGES * float(np.median(np.diff(time_s))):
        return out, fresh
    update = min(busy)
    for j, changed in enumerate(changes):
        if changed.size < 2:
            continue
        gaps = np.diff(time_s[changed])
        still = changed[1:][gaps >= STANDSTILL_UPDATES * update] - 1
        keep = np.unique(np.r_[changed, still, out.shape[0] - 1])
        out[:, j] = np.interp(time_s, time_s[keep], out[keep, j])
    return out, fresh


def joint_stream(
    time_s: np.ndarray,
    positions: np.ndarray,
    names: tuple[str, ...],
    integrated: list[str],
    header: LogHeader,
    breaks: np.ndarray | None,
    quadrature: np.ndarray | None = None,
) -> JointStream:
    """The joints' own stream (:class:`JointStream`) of ``positions`` at ``time_s`` (``names``: the
    joints', in the header's encoder order), each joint's resolution read off its readings as
    published, the readings a slow driver held filled in between its updates
    (:func:`fresh_positions`); ``quadrature``: the integrated joints' (:attr:`JointStream.quadrature`)."""
    steps = [0.0 if n in integrated else resolution(positions[:, j]) for j, n in enumerate(names)]
    by_velocity = tuple(e for e, n in zip(header.encoder_names, names) if n in integrated)
    filled, fresh = fresh_positions(time_s, positions)
    held = None if quadrature is None else frozen(quadrature)
    return JointStream(time_s, frozen(filled), tuple(steps), by_velocity, breaks, frozen(fresh), held)


def joint_positions(
    path: Path, joints: Stamped, names: tuple[str, ...]
) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray | None]:
    """The joints' messages in stamp order (one per stamp), their positions (rad; a joint with
    only velocities integrated over the stamps from 0), the joints so integrated, and their
    :attr:`~nlp_calib.logs.log.JointStream.quadrature` (None: none integrated)."""
    order = np.argsort(joints.stamp_ns, kind="stable")
    ns = joints.stamp_ns[order]
    first = np.concatenate([[True], np.diff(ns) > 0])
    ns, values = ns[first], joints.values[order][first]
    n = len(names)
    columns, integrated = [], []
    quadrature = np.zeros((ns.size, n))
    for j, name in enumerate(names):
        position, velocity = values[:, j], values[:, n + j]
        if np.all(np.isfinite(position)):
            columns.append(position)
            continue
        if not np.all(np.isfinite(velocity)):
            bad = int(np.sum(~np.isfinite(position) & ~np.isfinite(velocity)))
            raise BagError(
                path,
                f"joint {name!r} on {joints.topic!r}: {bad} of {ns.size} messages give it neither a finite "
                "position nor a finite velocity; a joint needs one or the other in every message",
            )
        dt = np.diff(ns).astype(float) * 1e-9
        columns.append(np.concatenate([[0.0], np.cumsum(0.5 * (velocity[1:] + velocity[:-1]) * dt)]))
        # Each speed held over the interval after its stamp: v_i·dt_i, the trapezoid's less half
        # the jump to the next (the mean over the interval before: v_(i+1)·dt_i, plus it).
        quadrature[:, j] = np.concatenate([[0.0], np.cumsum(0.5 * (velocity[:-1] - velocity[1:]) * dt)])
        integrated.append(name)
    return ns, np.stack(columns, axis=1), integrated, (quadrature if integrated else None)


def breaks_s(joints: Stamped, start_ns: int) -> np.ndarray | None:
    """The joints' breaks (:attr:`Stamped.breaks_ns`) on a log's time axis, which starts at ``start_ns``."""
    return None if joints.breaks_ns is None else frozen((joints.breaks_ns - start_ns).astype(float) * 1e-9)


def at_tracker(joint_ns: np.ndarray, tracker: Stamped, max_gap_s: float) -> tuple[np.ndarray, Timing]:
    """The tracker poses (indices into its messages, in stamp order) the joints can be interpolated
    at, and how the others fell."""
    order = np.argsort(tracker.stamp_ns, kind="stable")
    ts = tracker.stamp_ns[order]
    first = np.concatenate([[True], np.diff(ts) > 0])
    order, ts = order[first], ts[first]
    before, after = ts < joint_ns[0], ts > joint_ns[-1]
    hi = np.clip(np.searchsorted(joint_ns, ts, side="left"), 1, joint_ns.size - 1)
    exact = joint_ns[np.minimum(np.searchsorted(joint_ns, ts, side="left"), joint_ns.size - 1)] == ts
    bridged = joint_ns[hi] - joint_ns[hi - 1] <= round(max_gap_s * 1e9)
    ok = ~before & ~after & (exact | bridged)
    gaps = int(np.sum(~ok)) - int(before.sum()) - int(after.sum())
    timing = Timing(ts.size, int(ok.sum()), int(before.sum()), int(after.sum()), gaps, max_gap_s)
    return order[ok], timing


def read_joint_bag(path: str | Path, topics: BagTopics, header: LogHeader) -> Log:
    """A bag's joints in radians and its tracker as a :class:`Log` timed by the tracker (see the
    module docstring)."""
    p = Path(path)
    joints, tracker = read_topics(p, topics)
    shift = clock_shift_ns(p, joints, tracker, topics.clock_offset)
    joints = replace(joints, stamp_ns=joints.stamp_ns + shift)
    return timed_by_tracker(
        p, joints, tracker, topics.joints, topics.max_gap, header, f"{tracker.topic} message"
    )


def timed_by_tracker(
    p: Path,
    joints: Stamped,
    tracker: Stamped,
    names: tuple[str, ...],
    max_gap_s: float,
    header: LogHeader,
    numbered: str = "line",
) -> Log:
    """The log of ``joints`` (each joint's position, then its velocity; NaN where absent) and of
    ``tracker`` (its planar and its 3-D pose), a record at each tracker pose the joints cover; a
    warning says when poses fell in joint gaps, joints were integrated or messages were dropped;
    ``numbered``: what the tracker's line numbers count (a bag topic's ``/topic message``)."""
    check_overlap(p, joints, tracker)
    joint_ns, positions, integrated, quadrature = joint_positions(p, joints, names)
    check_clocks(p, joint_ns, positions, tracker)
    index, timing = at_tracker(joint_ns, tracker, max_gap_s)
    drops = Drops({**joints.drops.counts, **tracker.drops.counts})
    timing = replace(timing, integrated=tuple(integrated), drops=drops)
    if timing.kept < 2:
        raise BagError(p, f"{timing.describe()}; at least 2 are needed")
    if timing.in_gaps or drops.worrying or integrated:
        warnings.warn(f"{p}: {timing.describe()}", NlpCalibWarning, stacklevel=3)
    stamps = tracker.stamp_ns[index]
    start_ns = int(stamps[0])
    stream_s = frozen((joint_ns - start_ns).astype(float) * 1e-9)
    stream = joint_stream(
        stream_s, positions, names, integrated, header, breaks_s(joints, start_ns), quadrature
    )
    time_s = frozen((stamps - start_ns).astype(float) * 1e-9)
    poses = np.array(tracker.values[index, :3], dtype=float)
    poses[:, 2] = wrap_angle(poses[:, 2])
    n = int(index.size)
    return Log(
        path=str(p),
        header=header,
        time_s=time_s,
        ticks=frozen(np.zeros((n, 0), dtype=np.int64)),
        model_pose=frozen(np.zeros((n, 3))),
        T_world_sensor=frozen(poses),
        line_numbers=frozen(index.astype(np.int64) + 1),
        clock=LogClock(start_ns=start_ns),
        joint_positions=stream.at(time_s),
        joint_stream=stream,
        reference=ReferenceData(
            frozen(np.array(tracker.values[index][:, [0, 1, 3, 4, 5, 6, 7]], dtype=float)),
            numbered=numbered,
        ),
    )


def joint_files(path: str | Path, topics: BagTopics) -> tuple[str, str, str]:
    """A bag's joints in radians as a CSV joint log and its tracker's poses as a TUM trajectory, on
    the tracker's clock (the joints' stamps shifted by the clock offset), and what was written."""
    p = Path(path)
    joints, tracker = read_topics(p, topics)
    joints = replace(
        joints, stamp_ns=joints.stamp_ns + clock_shift_ns(p, joints, tracker, topics.clock_offset)
    )
    joint_ns, positions, integrated, _ = joint_positions(p, joints, topics.joints)
    order = np.argsort(tracker.stamp_ns, kind="stable")
    ts = tracker.stamp_ns[order]
    first = np.concatenate([[True], np.diff(ts) > 0])
    poses = tracker.values[order][first]
    velocity = f" ({', '.join(integrated)} integrated from velocities)" if integrated else ""
    summary = (
        f"{joint_ns.size} joint messages{velocity} and {int(first.sum())} tracker poses, each on its clock"
    )
    drops = Drops({**joints.drops.counts, **tracker.drops.counts})
    if drops.counts:
        summary += f"; not used as they were: {drops.describe()}"
    if drops.worrying:
        warnings.warn(f"{p}: {drops.describe()}", NlpCalibWarning, stacklevel=2)
    return (
        format_joint_csv(joint_ns, topics.joints, positions),
        format_tum(ts[first], poses[:, [0, 1, 3, 4, 5, 6, 7]]),
        summary,
    )
