"""Encoder counts and tracker poses from ROS 1 and ROS 2 bags (sqlite3 or MCAP), read with ``rosbags``.

``rosbags`` is pure Python but optional (``pip install 'nlp_calib[ros]'``): it is imported only
when a bag is opened. Encoders come from ``sensor_msgs/msg/JointState`` (raw counts in
``position``, or joint positions in radians, or only velocities in rad/s, integrated later), the
tracker from a pose, transform, odometry or TF topic (the planar pose, then the full 3-D pose);
each message's time is its header stamp, or the bag's record time for a topic named in
:attr:`BagTopics.receive` or whose header stamps are all zero (said in a warning). A problem
with the bag, a topic or a message is one :class:`BagError` line that lists what the bag does
hold.

Nothing but a regular file (or a folder of them) is opened as a bag: a FIFO, socket or device is
refused before it can block. Messages that are not what they claim are dropped and counted
(:class:`Drops`): a JointState whose ``position`` and ``name`` differ in length or that names a
joint twice, a tracker pose whose quaternion is not a rotation (zero, or a norm off 1 by more
than :data:`QUATERNION_TOLERANCE`; one off by less is normalised and counted). A header stamp
whose ``nanosec`` is not below 10⁹ is no time at all: the bag is refused.
"""

from __future__ import annotations

import math
import warnings
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core.errors import NlpCalibWarning, UsageError
from nlp_calib.core.ranges import Range
from nlp_calib.core.text import escaped
from nlp_calib.logs.bag_files import DAMAGED, BagError, is_bag, messages, opened, why
from nlp_calib.logs.reader import yaw_from_quaternion

__all__ = [
    "BagError",
    "BagInventory",
    "BagTopics",
    "Drops",
    "Stamped",
    "bag_inventory",
    "is_bag",
    "read_joints",
    "read_topics",
]

ENCODER_TYPE = "sensor_msgs/msg/JointState"
POSE_TYPE = "geometry_msgs/msg/PoseStamped"
TRANSFORM_TYPE = "geometry_msgs/msg/TransformStamped"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"
TRACKER_TYPES = (POSE_TYPE, TRANSFORM_TYPE, ODOMETRY_TYPE, TF_TYPE)
#: Types whose messages name the frame they follow (``child_frame_id``).
_FRAMED = (TRANSFORM_TYPE, ODOMETRY_TYPE, TF_TYPE)
#: What a tracker pose holds: the planar pose (its yaw), then the 3-D pose as published.
TRACKER_COLUMNS = ("x", "y", "yaw", "z", "qx", "qy", "qz", "qw")
#: Default of :attr:`BagTopics.max_gap`: a tracker at 10 Hz or faster brackets every encoder message.
DEFAULT_MAX_GAP_S = 0.1
#: What a JointState's positions hold (``counts``: raw encoder counts; ``radians``: REP 103).
JOINT_UNITS = ("counts", "radians")
MAX_GAP = Range(0.0, 10.0, lo_open=True)
#: A clock offset of up to a century: time since boot against the epoch.
CLOCK_OFFSET = Range(-4e9, 4e9)
#: A quaternion whose norm is off 1 by more than this is not a rotation (a lost target's zeros, a
#: publisher that scales it); closer ones are normalised. Float rounding stays below 1e-6.
QUATERNION_TOLERANCE = 1e-3
_ROUNDING = 1e-6


@dataclass(frozen=True)
class BagTopics:
    """Where a bag keeps the encoders and the tracker.

    ``joints`` names the JointState entries in the model's encoder order; ``tracker_frame`` picks
    the transforms whose child frame it is (required on a TF topic); ``max_gap`` (s) is the longest
    stretch between two messages of one topic that the other's time is interpolated across.
    ``joint_units`` says what ``JointState.position`` holds; ``receive`` names the topics timed by
    the bag's record times instead of their header stamps; ``clock_offset`` (s, or ``auto``:
    estimated from the record times) is added to the joints' stamps to put them on the tracker's
    clock.
    """

    joint_states: str
    joints: tuple[str, ...]
    tracker: str
    tracker_frame: str | None = None
    max_gap: float = DEFAULT_MAX_GAP_S
    joint_units: str = "counts"
    receive: tuple[str, ...] = ()
    clock_offset: float | str = 0.0

    def __post_init__(self) -> None:
        for key in ("joint_states", "tracker"):
            if not getattr(self, key).strip():
                raise UsageError(f"{key}: name a topic of the bag, got an empty name")
        if not self.joints or not all(j.strip() for j in self.joints):
            raise UsageError("joints: name the JointState joints, one per encoder in the model's order")
        if len(set(self.joints)) != len(self.joints):
            raise UsageError(f"joints: each joint once, got {', '.join(self.joints)}")
        if self.tracker_frame is not None and not self.tracker_frame.strip("/ "):
            raise UsageError("tracker_frame: name the tracked frame, got an empty name")
        if (reason := MAX_GAP.problem(self.max_gap)) is not None:
            raise UsageError(f"max_gap (seconds) {reason}")
        if self.joint_units not in JOINT_UNITS:
            raise UsageError(f"joint_units: one of {', '.join(JOINT_UNITS)}, got {self.joint_units!r}")
        for topic in self.receive:
            if topic not in (self.joint_states, self.tracker):
                raise UsageError(
                    f"stamps: {topic!r} is neither the joint_states nor the tracker topic "
                    f"({self.joint_states}, {self.tracker})"
                )
        offset = self.clock_offset
        if isinstance(offset, str) and offset != "auto":
            raise UsageError(f"clock_offset: seconds, or auto to estimate it, got {offset!r}")
        if not isinstance(offset, str) and (reason := CLOCK_OFFSET.problem(offset)) is not None:
            raise UsageError(f"clock_offset (seconds) {reason}")


#: Why messages were dropped, as :class:`Drops` counts them.
MALFORMED_JOINTS = "JointState messages whose position and name lists differ in length or name a joint twice"
OTHER_JOINTS = "JointState messages without the joints (another publisher on the topic?)"
PARTIAL_JOINTS = "JointState messages holding only some of the joints"
ZERO_STAMPS = "messages stamped 0 among stamped ones (a header left unset)"
REPEATED_STAMPS = "messages repeating an earlier message's stamp"
NOT_A_ROTATION = (
    f"tracker poses whose quaternion is not a rotation (zero, or norm off 1 by over {QUATERNION_TOLERANCE:g})"
)
NORMALISED = "tracker quaternions normalised (norm off 1 by less than that)"


@dataclass(frozen=True)
class Drops:
    """Messages a topic held that the import did not use as they were, by reason (the reasons
    above); ``worrying`` are those a user must hear about (all but another publisher's)."""

    counts: Mapping[str, int] = field(default_factory=dict)

    def describe(self) -> str:
        return ", ".join(f"{n} {why}" for why, n in self.counts.items() if n)

    @property
    def worrying(self) -> bool:
        return any(n for why, n in self.counts.items() if why != OTHER_JOINTS)


@dataclass(frozen=True)
class Stamped:
    """A topic's messages in bag order: stamps (ns), one row of values per message, and the bag's
    record time of each (ns); ``breaks_ns`` ``(m, 2)``: stretches of stamps over which the values'
    change is unknown (:attr:`~nlp_calib.logs.log.JointStream.breaks`)."""

    topic: str
    stamp_ns: np.ndarray
    values: np.ndarray
    drops: Drops = field(default_factory=Drops)
    recorded_ns: np.ndarray | None = None
    breaks_ns: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.stamp_ns.shape[0])


def _listing(topics: Mapping[str, str], wanted: Sequence[str]) -> str:
    """The bag's topics with their types, those of a ``wanted`` type first, at most a dozen."""
    ordered = sorted(topics.items(), key=lambda kv: (kv[1] not in wanted, kv[0]))
    shown = ", ".join(f"{name} ({msgtype})" for name, msgtype in ordered[:12])
    return (shown + (f" and {len(ordered) - 12} more" if len(ordered) > 12 else "")) or "none"


def _check_topic(path: Path, topics: Mapping[str, str], name: str, key: str, wanted: Sequence[str]) -> str:
    if name not in topics:
        raise BagError(
            path, f"{key}: the bag has no topic {name!r}; name one of its topics: {_listing(topics, wanted)}"
        )
    if topics[name] not in wanted:
        raise BagError(
            path,
            f"{key}: topic {name!r} holds {topics[name]}, expected {' or '.join(wanted)}; the bag's "
            f"topics: {_listing(topics, wanted)}",
        )
    return topics[name]


def _stamp_ns(p: Path, header: Any, topic: str, number: int) -> int:
    sec, nanosec = int(header.stamp.sec), int(header.stamp.nanosec)
    if not 0 <= nanosec < 1_000_000_000:
        raise BagError(
            p,
            f"message {number} on {topic!r} has header stamp sec {sec}, nanosec {nanosec}: nanosec must "
            "lie in [0, 10^9); the publisher writes invalid times (fix its stamps, or leave the topic out)",
        )
    return sec * 1_000_000_000 + nanosec


def _frame(name: str) -> str:
    return name.strip().lstrip("/")  # ROS 1 tf frames were often written with a leading '/'


def _unit(orientation: Any) -> tuple[list[float] | None, bool]:
    """The quaternion ``(x, y, z, w)`` scaled to norm 1, and whether that changed more than its
    rounding; None when it is not a rotation (see :data:`QUATERNION_TOLERANCE`)."""
    q = [float(orientation.x), float(orientation.y), float(orientation.z), float(orientation.w)]
    norm = math.hypot(*q)  # no overflow on huge components; NaN if any is NaN
    if not abs(norm - 1.0) <= QUATERNION_TOLERANCE:
        return None, False
    return [c / norm for c in q], abs(norm - 1.0) > _ROUNDING


def _tracker_poses(msg: Any, msgtype: str) -> Iterator[tuple[str, Any, Any, Any]]:
    """Each pose a tracker message holds: (child frame, header, position, orientation)."""
    if msgtype == POSE_TYPE:
        yield "", msg.header, msg.pose.position, msg.pose.orientation
    elif msgtype == ODOMETRY_TYPE:
        yield msg.child_frame_id, msg.header, msg.pose.pose.position, msg.pose.pose.orientation
    else:
        for tf in msg.transforms if msgtype == TF_TYPE else [msg]:
            yield tf.child_frame_id, tf.header, tf.transform.translation, tf.transform.rotation


class _Collector:
    """Stamps, record times and values of one topic, turned into :class:`Stamped` at the end;
    ``drops`` counts the messages not used as they were, by reason."""

    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.stamps: list[int] = []
        self.recorded: list[int] = []
        self.rows: list[Sequence[float]] = []
        self.drops: Counter[str] = Counter()
        self.stamp_drops: dict[str, int] = {}

    def add(self, stamp: int, recorded: int, row: Sequence[float]) -> None:
        self.stamps.append(stamp)
        self.recorded.append(recorded)
        self.rows.append(row)

    def result(self, path: Path, key: str, width: int, what: str, receive: bool = False) -> Stamped:
        drops = Drops({why: n for why, n in self.drops.items() if n})
        if len(self.rows) < 2:
            dropped = f"; dropped: {drops.describe()}" if drops.counts else ""
            raise BagError(
                path,
                f"{key}: topic {self.topic!r} has {len(self.rows)} usable message(s){what}{dropped}; the "
                "import needs at least 2 (is it the right topic, and does the bag cover the drive?)",
            )
        stamps = self.recorded if receive else self.stamps
        if not receive and not any(self.stamps):
            # A publisher that leaves every stamp at zero: the bag's record times are the only clock.
            warnings.warn(
                f"{path}: every header stamp on {self.topic!r} is zero; its messages are timed by the "
                f"bag's record times instead (say so with stamps: {{{self.topic}: receive}})",
                NlpCalibWarning,
                stacklevel=4,
            )
            stamps = self.recorded
        values = np.array(self.rows, dtype=float).reshape(len(self.rows), width)
        recorded = np.array(self.recorded, dtype=np.int64)
        ns = np.array(stamps, dtype=np.int64)
        keep = self._usable(path, key, ns)
        return Stamped(
            self.topic, ns[keep], values[keep], Drops({**drops.counts, **self.stamp_drops}), recorded[keep]
        )

    def _usable(self, path: Path, key: str, ns: np.ndarray) -> np.ndarray:
        """The messages whose stamps are times: a stamp of 0 among others and a stamp an earlier
        message already had are dropped (counted in :attr:`stamp_drops`); one stamp for every
        message is no clock at all."""
        if ns.size > 1 and np.all(ns == ns[0]):
            raise BagError(
                path,
                f"{key}: all {ns.size} messages on {self.topic!r} carry one header stamp "
                f"({ns[0] * 1e-9:.9f} s): no clock to time them by; time the topic by the bag's record times "
                f"(stamps: {{{self.topic}: receive}}, or --stamps {self.topic}=receive)",
            )
        zero = ns == 0
        _, first = np.unique(ns, return_index=True)
        repeated = np.ones(ns.size, dtype=bool)
        repeated[first] = False
        self.stamp_drops = {
            why: int(n)
            for why, n in ((ZERO_STAMPS, zero.sum()), (REPEATED_STAMPS, (repeated & ~zero).sum()))
            if n
        }
        keep = ~zero & ~repeated
        if int(keep.sum()) < 2:
            raise BagError(
                path,
                f"{key}: topic {self.topic!r} has {int(keep.sum())} message(s) with a usable stamp; at least "
                "2 are needed",
            )
        return keep


def read_topics(path: str | Path, topics: BagTopics) -> tuple[Stamped, Stamped]:
    """The encoder readings (columns in ``topics.joints`` order: counts; or, for radians, each
    joint's position then each joint's velocity, NaN where a message has none) and the tracker's
    poses, :data:`TRACKER_COLUMNS`."""
    p = Path(path)
    with opened(p) as reader:
        try:
            available = {name: info.msgtype or "mixed types" for name, info in reader.topics.items()}
        except Exception as exc:  # a damaged metadata.yaml or index gets this far in rosbags
            raise BagError(p, f"cannot read the bag's topics ({why(exc)}); {DAMAGED}") from None
        _check_topic(p, available, topics.joint_states, "joint_states", (ENCODER_TYPE,))
        tracker_type = _check_topic(p, available, topics.tracker, "tracker", TRACKER_TYPES)
        if topics.tracker_frame is not None and tracker_type not in _FRAMED:
            raise BagError(
                p,
                f"tracker_frame: topic {topics.tracker!r} holds {tracker_type}, which names no child "
                "frame to pick; leave tracker_frame out",
            )
        if tracker_type == TF_TYPE and topics.tracker_frame is None:
            frames = _child_frames(reader, p, topics.tracker)
            raise BagError(
                p,
                f"tracker_frame: topic {topics.tracker!r} holds {TF_TYPE}; name the tracked frame "
                f"(child frames on it: {', '.join(sorted(frames)) or 'none'})",
            )
        return _collect(reader, p, topics, tracker_type)


def _child_frames(reader: Any, p: Path, topic: str) -> set[str]:
    frames: set[str] = set()
    for conn, _, msg in messages(reader, p, (topic,)):
        frames.update(_frame(pose[0]) for pose in _tracker_poses(msg, conn.msgtype))
    return frames


def _collect(reader: Any, p: Path, topics: BagTopics, tracker_type: str) -> tuple[Stamped, Stamped]:
    want = None if topics.tracker_frame is None else _frame(topics.tracker_frame)
    enc, trk = _Collector(topics.joint_states), _Collector(topics.tracker)
    names_seen: set[str] = set()
    frames_seen: set[str] = set()
    number: Counter[str] = Counter()
    for conn, recorded, msg in messages(reader, p, (topics.joint_states, topics.tracker)):
        number[conn.topic] += 1
        if conn.topic == topics.joint_states:
            _add_joints(p, msg, topics, number[conn.topic], recorded, enc, names_seen)
        else:
            _add_poses(p, msg, tracker_type, want, number[conn.topic], recorded, trk, frames_seen)
    if not enc.rows and not set(topics.joints) <= names_seen:
        raise BagError(
            p,
            f"joints: no message on {topics.joint_states!r} holds {', '.join(topics.joints)}; the joint "
            f"names present: {', '.join(sorted(names_seen)) or 'none'} (give them in the model's "
            "encoder order)",
        )
    _one_frame(p, topics.tracker, want, frames_seen)
    if want is not None and not trk.rows and frames_seen and not trk.drops:
        raise BagError(
            p,
            f"tracker_frame: no pose on {topics.tracker!r} has child frame {want!r}; the child frames "
            f"present: {', '.join(sorted(frames_seen))}",
        )
    frame = f" with child frame {want!r}" if want is not None else ""
    width = len(topics.joints) * (1 if topics.joint_units == "counts" else 2)
    holding = f" holding {', '.join(topics.joints)}"
    return (
        enc.result(p, "joint_states", width, holding, topics.joint_states in topics.receive),
        trk.result(p, "tracker", len(TRACKER_COLUMNS), frame, topics.tracker in topics.receive),
    )


def _add_poses(
    p: Path,
    msg: Any,
    msgtype: str,
    want: str | None,
    number: int,
    recorded: int,
    trk: _Collector,
    frames_seen: set[str],
) -> None:
    """The poses of one tracker message of the tracked frame (all of them: ``want`` None)."""
    for frame, header, position, orientation in _tracker_poses(msg, msgtype):
        frames_seen.add(_frame(frame))
        if want is not None and _frame(frame) != want:
            continue
        q, normalised = _unit(orientation)
        if q is None:
            trk.drops[NOT_A_ROTATION] += 1
            continue
        trk.drops[NORMALISED] += normalised
        pose = (float(position.x), float(position.y), yaw_from_quaternion(*q), float(position.z), *q)
        trk.add(_stamp_ns(p, header, trk.topic, number), recorded, pose)


def _add_joints(
    p: Path, msg: Any, topics: BagTopics, number: int, recorded: int, enc: _Collector, names_seen: set[str]
) -> None:
    """The readings of ``topics.joints`` in one JointState message; a message without them
    (another publisher on the same topic) or malformed is counted, not used. Joints in radians
    may come as positions, velocities or both (either list may be empty)."""
    names = list(msg.name)
    names_seen.update(names)
    position = np.asarray(msg.position, dtype=float)
    if not set(topics.joints) <= set(names):
        enc.drops[PARTIAL_JOINTS if set(topics.joints) & set(names) else OTHER_JOINTS] += 1
        return
    if topics.joint_units == "radians":
        _add_angles(p, msg, topics, number, recorded, enc, names)
        return
    if position.shape != (len(names),) or len(set(names)) != len(names):
        enc.drops[MALFORMED_JOINTS] += 1
        return
    row = [float(position[names.index(j)]) for j in topics.joints]
    for joint, value in zip(topics.joints, row):
        # Counts beyond 2^53 are no longer whole numbers in a float64: none can be trusted.
        if not (math.isfinite(value) and abs(value) < 2**53 and value == round(value)):
            raise BagError(
                p,
                f"joint {joint!r} reads {value!r} in message {number} on {topics.joint_states!r}; the "
                "import needs raw encoder counts (whole numbers) in JointState.position, not angles, with "
                "joint_units: counts (leave joint_units out to read joint positions in radians)",
            )
    enc.add(_stamp_ns(p, msg.header, topics.joint_states, number), recorded, row)


def _add_angles(
    p: Path, msg: Any, topics: BagTopics, number: int, recorded: int, enc: _Collector, names: list[str]
) -> None:
    """Each joint's position and velocity (NaN where the message has none) in one JointState."""
    position = np.asarray(msg.position, dtype=float)
    velocity = np.asarray(msg.velocity, dtype=float)
    sizes_ok = position.shape[0] in (0, len(names)) and velocity.shape[0] in (0, len(names))
    if not sizes_ok or len(set(names)) != len(names) or position.size + velocity.size == 0:
        enc.drops[MALFORMED_JOINTS] += 1
        return
    index = [names.index(j) for j in topics.joints]
    pos = [float(position[i]) if position.size else math.nan for i in index]
    vel = [float(velocity[i]) if velocity.size else math.nan for i in index]
    enc.add(_stamp_ns(p, msg.header, topics.joint_states, number), recorded, pos + vel)


def read_joints(
    path: str | Path, joint_states: str, joints: tuple[str, ...], receive: bool = False
) -> Stamped:
    """The joints in radians on ``joint_states`` alone (each joint's position, then its velocity;
    NaN where a message has none), timed by their header stamps or, with ``receive``, the bag's
    record times (a reference other than a pose topic: a lidar's scans)."""
    p = Path(path)
    topics = BagTopics(joint_states, joints, joint_states, joint_units="radians")
    enc, names_seen, number = _Collector(joint_states), set[str](), 0
    with opened(p) as reader:
        available = {name: info.msgtype or "mixed types" for name, info in reader.topics.items()}
        _check_topic(p, available, joint_states, "joint_states", (ENCODER_TYPE,))
        for _, recorded, msg in messages(reader, p, (joint_states,)):
            number += 1
            _add_joints(p, msg, topics, number, recorded, enc, names_seen)
    if not enc.rows and not set(joints) <= names_seen:
        raise BagError(
            p,
            f"joints: no message on {joint_states!r} holds {', '.join(joints)}; the joint names present: "
            f"{', '.join(sorted(names_seen)) or 'none'} (give them in the model's encoder order)",
        )
    return enc.result(p, "joint_states", 2 * len(joints), f" holding {', '.join(joints)}", receive)


#: Messages of a topic looked at for its joint names or frames (the first ones).
INVENTORY_MESSAGES = 50


@dataclass(frozen=True)
class BagInventory:
    """What a bag holds, for a user to choose from: each topic's type and message count, the
    joint names on each JointState topic and the frames each framed topic names (a TF topic's and
    an odometry's child frames, a scan's or an Imu's own frame), from their first messages."""

    path: str
    topics: Mapping[str, tuple[str, int]]
    joints: Mapping[str, tuple[str, ...]]
    frames: Mapping[str, tuple[str, ...]]

    def lines(self) -> list[str]:
        """The inventory in words, a topic a line."""
        out = []
        for name, (msgtype, count) in sorted(self.topics.items()):
            more = ""
            if name in self.joints:
                more = f": joints {', '.join(self.joints[name]) or 'none'}"
            elif name in self.frames:
                more = f": frames {', '.join(self.frames[name]) or 'none'}"
            out.append(f"{name} ({msgtype}, {count} messages){more}")
        return out

    def of_type(self, *msgtypes: str) -> list[str]:
        """The topics holding any of ``msgtypes``."""
        return sorted(n for n, (t, _) in self.topics.items() if t in msgtypes)


def bag_inventory(path: str | Path) -> BagInventory:
    """What the bag at ``path`` holds (see :class:`BagInventory`)."""
    p = Path(path)
    joints: dict[str, set[str]] = {}
    frames: dict[str, set[str]] = {}
    with opened(p) as reader:
        try:
            topics = {n: (i.msgtype or "mixed types", int(i.msgcount)) for n, i in reader.topics.items()}
        except Exception as exc:  # a damaged metadata.yaml or index gets this far in rosbags
            raise BagError(p, f"cannot read the bag's topics ({why(exc)}); {DAMAGED}") from None
        # A scan and an Imu message name their own frame (a lidar's, an IMU's: a reference's).
        looked = (ENCODER_TYPE, *_FRAMED, "sensor_msgs/msg/LaserScan", "sensor_msgs/msg/Imu")
        wanted = [n for n, (t, _) in topics.items() if t in looked]
        seen: Counter[str] = Counter()
        for conn, _, msg in messages(reader, p, wanted):
            if seen[conn.topic] >= INVENTORY_MESSAGES:
                continue
            seen[conn.topic] += 1
            if conn.msgtype == ENCODER_TYPE:
                joints.setdefault(conn.topic, set()).update(msg.name)
            elif conn.msgtype in _FRAMED:
                frames.setdefault(conn.topic, set()).update(
                    _frame(f[0]) for f in _tracker_poses(msg, conn.msgtype)
                )
            else:
                frames.setdefault(conn.topic, set()).add(_frame(msg.header.frame_id))
    return BagInventory(
        str(p),
        topics,
        {k: tuple(sorted(v)) for k, v in joints.items()},
        {k: tuple(sorted(v)) for k, v in frames.items()},
    )


def read_pose_topic(path: str | Path, topic: str, frame: str | None = None, receive: bool = False) -> Stamped:
    """A pose topic alone (a robot's own ``nav_msgs/Odometry``, a tracker): its planar and 3-D
    poses, :data:`TRACKER_COLUMNS`, of child frame ``frame`` where the type names one."""
    p = Path(path)
    trk = _Collector(topic)
    with opened(p) as reader:
        available = {name: info.msgtype or "mixed types" for name, info in reader.topics.items()}
        msgtype = _check_topic(p, available, topic, "odometry", TRACKER_TYPES)
        want = None if frame is None else _frame(frame)
        seen: set[str] = set()
        for number, (_, recorded, msg) in enumerate(messages(reader, p, (topic,)), start=1):
            _add_poses(p, msg, msgtype, want, number, recorded, trk, seen)
    _one_frame(p, topic, want, seen)
    return trk.result(p, "odometry", len(TRACKER_COLUMNS), "", receive)


def _one_frame(p: Path, topic: str, want: str | None, seen: set[str]) -> None:
    """Refuse a topic whose poses follow several child frames when none was named: their poses
    interleaved are no one frame's path."""
    frames = sorted(f for f in seen if f)
    if want is None and len(frames) > 1:
        shown = ", ".join(escaped(f) for f in frames[:5])
        raise BagError(
            p,
            f"topic {topic!r} holds the poses of {len(frames)} child frames ({shown}); they are no one "
            "frame's path: name the one to read (a tracker's tracker_frame) or record each on a topic "
            "of its own",
        )
