"""What a bag holds, without reading all of it: its topics and their types, counts and rates, the
joints its JointState topics name, the frames its transform topics carry and its static transforms.

``nlp-calib init`` writes a scenario from this, and the pre-flight lists it. Only the metadata and
the first :data:`SAMPLE` messages of the topics that can hold joints or poses are read.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from nlp_calib.logs.bag_files import BagError, messages, opened, why
from nlp_calib.logs.bag_reader import ENCODER_TYPE, POSE_TYPE, TF_TYPE, TRACKER_TYPES
from nlp_calib.logs.bag_tf import TF_STATIC, static_transforms

#: Messages of a topic read for the names and frames it carries.
SAMPLE = 50


@dataclass(frozen=True)
class Topic:
    """One topic: its message type and count, its mean rate over the bag (Hz), and what its first
    messages name: a JointState's joints (and whether they carry positions, velocities), a pose
    topic's frames (a transform's or odometry's child frames; a PoseStamped's world frame)."""

    name: str
    msgtype: str
    count: int
    rate_hz: float
    joints: tuple[str, ...] = ()
    positions: bool = False
    velocities: bool = False
    frames: tuple[str, ...] = ()


@dataclass(frozen=True)
class BagSurvey:
    """A bag's topics, its span (s) and its static transforms (child frame → parent frame)."""

    path: Path
    duration_s: float
    topics: tuple[Topic, ...]
    static: Mapping[str, str]

    def of_type(self, *types: str) -> list[Topic]:
        return [t for t in self.topics if t.msgtype in types]


def topic_counts(path: Path) -> dict[str, tuple[str, int]]:
    """Each topic's message type and count, from the bag's metadata."""
    with opened(path) as reader:
        try:
            return {
                name: (info.msgtype or "mixed types", int(info.msgcount))
                for name, info in reader.topics.items()
            }
        except Exception as exc:  # a damaged metadata.yaml or index gets this far in rosbags
            raise BagError(path, f"cannot read the bag's topics ({why(exc)})") from None


def _first(reader: object, path: Path, topic: str) -> list[object]:
    return [msg for _, _, msg in itertools.islice(messages(reader, path, (topic,)), SAMPLE)]


def _joint_topic(reader: object, path: Path, name: str, info: tuple[str, int, float]) -> Topic:
    joints: dict[str, None] = {}
    positions = velocities = False
    for msg in _first(reader, path, name):
        joints.update(dict.fromkeys(str(n) for n in msg.name))  # type: ignore[attr-defined]
        positions |= len(msg.position) > 0  # type: ignore[attr-defined]
        velocities |= len(msg.velocity) > 0  # type: ignore[attr-defined]
    return Topic(name, info[0], info[1], info[2], tuple(joints), positions, velocities)


def _pose_topic(reader: object, path: Path, name: str, info: tuple[str, int, float]) -> Topic:
    frames: dict[str, None] = {}
    for msg in _first(reader, path, name):
        if info[0] == TF_TYPE:
            frames.update(dict.fromkeys(tf.child_frame_id.strip().lstrip("/") for tf in msg.transforms))  # type: ignore[attr-defined]
        elif info[0] == POSE_TYPE:
            frames[msg.header.frame_id] = None  # type: ignore[attr-defined]
        else:
            frames[msg.child_frame_id.strip().lstrip("/")] = None  # type: ignore[attr-defined]
    return Topic(name, info[0], info[1], info[2], frames=tuple(frames))


def survey(path: Path) -> BagSurvey:
    """What the bag at ``path`` holds (see the module docstring)."""
    with opened(path) as reader:
        try:
            listed = {n: (i.msgtype or "mixed types", int(i.msgcount)) for n, i in reader.topics.items()}
            duration = max((reader.end_time - reader.start_time) * 1e-9, 0.0)
        except Exception as exc:
            raise BagError(path, f"cannot read the bag's topics ({why(exc)})") from None
        topics = []
        for name, (msgtype, count) in sorted(listed.items()):
            info = (msgtype, count, count / duration if duration > 0 else 0.0)
            if msgtype == ENCODER_TYPE:
                topics.append(_joint_topic(reader, path, name, info))
            elif msgtype in TRACKER_TYPES and name != TF_STATIC:
                topics.append(_pose_topic(reader, path, name, info))
            else:
                topics.append(Topic(name, *info))
    static = {child: parent for child, (parent, *_) in static_transforms(path).items()}
    return BagSurvey(path, duration, tuple(topics), static)
