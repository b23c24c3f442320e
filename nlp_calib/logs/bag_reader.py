"""Encoder counts and tracker poses from ROS 1 and ROS 2 bags (sqlite3 or MCAP), read with ``rosbags``.

``rosbags`` is pure Python but optional (``pip install 'nlp_calib[ros]'``): it is imported only
when a bag is opened. Encoders come from ``sensor_msgs/msg/JointState`` (raw counts in
``position``), the tracker from a pose, transform, odometry or TF topic; each message's time is
its header stamp. A problem with the bag, a topic or a message is one :class:`BagError` line that
lists what the bag does hold.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core.errors import DatasetError, UsageError
from nlp_calib.core.ranges import Range
from nlp_calib.logs.reader import yaw_from_quaternion

ENCODER_TYPE = "sensor_msgs/msg/JointState"
POSE_TYPE = "geometry_msgs/msg/PoseStamped"
TRANSFORM_TYPE = "geometry_msgs/msg/TransformStamped"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"
TRACKER_TYPES = (POSE_TYPE, TRANSFORM_TYPE, ODOMETRY_TYPE, TF_TYPE)
#: Types whose messages name the frame they follow (``child_frame_id``).
_FRAMED = (TRANSFORM_TYPE, ODOMETRY_TYPE, TF_TYPE)
#: Files that belong to a ROS 2 bag folder (the folder holds ``metadata.yaml`` beside them).
_ROS2_FILES = (".db3", ".mcap")
#: Default of :attr:`BagTopics.max_gap`: a tracker at 10 Hz or faster brackets every encoder message.
DEFAULT_MAX_GAP_S = 0.1
MAX_GAP = Range(0.0, 10.0, lo_open=True)
_HOW_TO_OPEN = "a ROS 1 bag is a .bag file, a ROS 2 bag a folder with metadata.yaml or its .db3 or .mcap file"
_INSTALL = "reading bags needs rosbags: install the ros extra: pip install 'nlp_calib[ros]'"


class BagError(DatasetError):
    """A bag that cannot be opened or lacks what the import needs; the message lists what it has."""

    def __init__(self, path: Path | str, problem: str) -> None:
        super().__init__(str(path), None, problem)


@dataclass(frozen=True)
class BagTopics:
    """Where a bag keeps the encoders and the tracker.

    ``joints`` names the JointState entries in the model's encoder order; ``tracker_frame`` picks
    the transforms whose child frame it is (required on a TF topic); ``max_gap`` (s) is the longest
    stretch between two tracker poses an encoder message is interpolated across.
    """

    joint_states: str
    joints: tuple[str, ...]
    tracker: str
    tracker_frame: str | None = None
    max_gap: float = DEFAULT_MAX_GAP_S

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


@dataclass(frozen=True)
class Stamped:
    """A topic's messages in bag order: stamps (ns) and one row of values per message."""

    topic: str
    stamp_ns: np.ndarray
    values: np.ndarray

    @property
    def n(self) -> int:
        return int(self.stamp_ns.shape[0])


def is_bag(path: Path) -> bool:
    """Whether ``path`` names a bag rather than a text log (by its name, or a ROS 2 bag folder)."""
    return path.suffix in (".bag", *_ROS2_FILES) or (path / "metadata.yaml").is_file()


def _rosbags(path: Path) -> tuple[Any, Any]:
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise BagError(path, _INSTALL) from None
    # Old ROS 2 bags carry no message definitions; the standard messages read them.
    return AnyReader, get_typestore(Stores.LATEST)


def _bag_root(path: Path) -> Path:
    """The path rosbags opens: a ROS 2 bag's folder also when its .db3 or .mcap file is named."""
    if not (path.exists() or path.is_symlink()):
        raise BagError(path, "no such file")
    if path.suffix in _ROS2_FILES and (path.parent / "metadata.yaml").is_file():
        return path.parent
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise BagError(path, f"a folder without metadata.yaml is not a ROS 2 bag ({_HOW_TO_OPEN})")
    return path


@contextmanager
def opened(path: Path) -> Iterator[Any]:
    """An open ``rosbags`` reader of the bag at ``path``; any failure to open it is a :class:`BagError`."""
    reader_type, typestore = _rosbags(path)
    root = _bag_root(path)
    try:
        reader = reader_type([root], default_typestore=typestore)
        reader.open()
    except Exception as exc:  # rosbags raises many kinds on a file that is not a bag
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise BagError(path, f"cannot open the bag ({why}); {_HOW_TO_OPEN}") from None
    try:
        yield reader
    finally:
        reader.close()


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


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _frame(name: str) -> str:
    return name.strip().lstrip("/")  # ROS 1 tf frames were often written with a leading '/'


def _pose(position: Any, orientation: Any) -> tuple[float, float, float]:
    """SE(2) of a 3-D pose: x, y and the heading about the vertical axis."""
    q = orientation
    return float(position.x), float(position.y), yaw_from_quaternion(q.x, q.y, q.z, q.w)


def _tracker_poses(msg: Any, msgtype: str) -> Iterator[tuple[str, Any, tuple[float, float, float]]]:
    """Each pose a tracker message holds: (child frame, header, pose)."""
    if msgtype == POSE_TYPE:
        yield "", msg.header, _pose(msg.pose.position, msg.pose.orientation)
    elif msgtype == ODOMETRY_TYPE:
        yield msg.child_frame_id, msg.header, _pose(msg.pose.pose.position, msg.pose.pose.orientation)
    else:
        for tf in msg.transforms if msgtype == TF_TYPE else [msg]:
            yield tf.child_frame_id, tf.header, _pose(tf.transform.translation, tf.transform.rotation)


class _Collector:
    """Stamps, record times and values of one topic, turned into :class:`Stamped` at the end."""

    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.stamps: list[int] = []
        self.recorded: list[int] = []
        self.rows: list[Sequence[float]] = []

    def add(self, stamp: int, recorded: int, row: Sequence[float]) -> None:
        self.stamps.append(stamp)
        self.recorded.append(recorded)
        self.rows.append(row)

    def result(self, path: Path, key: str, width: int, what: str) -> Stamped:
        if len(self.rows) < 2:
            raise BagError(
                path,
                f"{key}: topic {self.topic!r} has {len(self.rows)} usable message(s){what}; the import "
                "needs at least 2 (is it the right topic, and does the bag cover the drive?)",
            )
        # A publisher that leaves every stamp at zero: the bag's record times are the only clock.
        stamps = self.stamps if any(self.stamps) else self.recorded
        values = np.array(self.rows, dtype=float).reshape(len(self.rows), width)
        return Stamped(self.topic, np.array(stamps, dtype=np.int64), values)


def read_topics(path: str | Path, topics: BagTopics) -> tuple[Stamped, Stamped]:
    """The encoder counts (columns in ``topics.joints`` order) and the tracker's ``(x, y, θ)``."""
    p = Path(path)
    with opened(p) as reader:
        available = {name: info.msgtype or "mixed types" for name, info in reader.topics.items()}
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


def _decoded(reader: Any, p: Path, conn: Any, raw: bytes) -> Any:
    try:
        return reader.deserialize(raw, conn.msgtype)
    except Exception as exc:  # rosbags' own error, or a struct error on a truncated message
        why = f"a message on {conn.topic!r} cannot be decoded ({exc})"
        raise BagError(p, f"{why}; is the bag damaged?") from None


def _child_frames(reader: Any, p: Path, topic: str) -> set[str]:
    conns = [c for c in reader.connections if c.topic == topic]
    frames: set[str] = set()
    for conn, _, raw in reader.messages(connections=conns):
        frames.update(_frame(f) for f, _, _ in _tracker_poses(_decoded(reader, p, conn, raw), conn.msgtype))
    return frames


def _collect(reader: Any, p: Path, topics: BagTopics, tracker_type: str) -> tuple[Stamped, Stamped]:
    want = None if topics.tracker_frame is None else _frame(topics.tracker_frame)
    enc, trk = _Collector(topics.joint_states), _Collector(topics.tracker)
    names_seen: set[str] = set()
    frames_seen: set[str] = set()
    n_joint_states = 0
    conns = [c for c in reader.connections if c.topic in (topics.joint_states, topics.tracker)]
    for conn, recorded, raw in reader.messages(connections=conns):
        msg = _decoded(reader, p, conn, raw)
        if conn.topic == topics.joint_states:
            n_joint_states += 1
            row = _counts(p, msg, topics, n_joint_states, names_seen)
            if row is not None:
                enc.add(_stamp_ns(msg.header), recorded, row)
            continue
        for frame, header, pose in _tracker_poses(msg, tracker_type):
            frames_seen.add(_frame(frame))
            if want is None or _frame(frame) == want:
                trk.add(_stamp_ns(header), recorded, pose)
    if not enc.rows and not set(topics.joints) <= names_seen:
        raise BagError(
            p,
            f"joints: no message on {topics.joint_states!r} holds {', '.join(topics.joints)}; the joint "
            f"names present: {', '.join(sorted(names_seen)) or 'none'} (give them in the model's "
            "encoder order)",
        )
    if want is not None and not trk.rows and frames_seen:
        raise BagError(
            p,
            f"tracker_frame: no pose on {topics.tracker!r} has child frame {want!r}; the child frames "
            f"present: {', '.join(sorted(frames_seen))}",
        )
    frame = f" with child frame {want!r}" if want is not None else ""
    return (
        enc.result(p, "joint_states", len(topics.joints), f" holding {', '.join(topics.joints)}"),
        trk.result(p, "tracker", 3, frame),
    )


def _counts(p: Path, msg: Any, topics: BagTopics, number: int, names_seen: set[str]) -> list[float] | None:
    """The raw counts of ``topics.joints`` in one JointState message (None if it lacks them: another
    publisher on the same topic)."""
    names = list(msg.name)
    names_seen.update(names)
    position = np.asarray(msg.position, dtype=float)
    if position.shape[0] != len(names) or not set(topics.joints) <= set(names):
        return None
    row = [float(position[names.index(j)]) for j in topics.joints]
    for joint, value in zip(topics.joints, row):
        # Counts beyond 2^53 are no longer whole numbers in a float64: none can be trusted.
        if not (math.isfinite(value) and abs(value) < 2**53 and value == round(value)):
            raise BagError(
                p,
                f"joint {joint!r} reads {value!r} in message {number} on {topics.joint_states!r}; the "
                "import needs raw encoder counts (whole numbers) in JointState.position, not angles",
            )
    return row
