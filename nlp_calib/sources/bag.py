"""A ROS 1 or ROS 2 bag as a dataset: the ``dataset:`` block that names its topics, read as a log.

Joints in radians (the default, REP 103) are read as a log timed by the tracker, each stream on
its own clock (:mod:`nlp_calib.logs.bag_joints`); raw counts (``joint_units: counts``) are read and
paired on every run exactly as ``nlp-calib import-bag`` writes them
(:mod:`nlp_calib.logs.bag_records`). The header comes from ``ROBOT.yaml``, else from the bag's
``/tf_static`` for the sensor's mount, else from the model's defaults.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

from nlp_calib.core.config import coerce, from_mapping
from nlp_calib.core.errors import ConfigError, DatasetError
from nlp_calib.logs import Log, LogHeader
from nlp_calib.logs.bag_files import bag_root
from nlp_calib.logs.bag_joints import read_joint_bag
from nlp_calib.logs.bag_reader import DEFAULT_MAX_GAP_S, BagTopics, is_bag
from nlp_calib.logs.bag_records import BagRecords, read_bag, read_bag_records
from nlp_calib.logs.bag_tf import static_mount
from nlp_calib.models import KinematicModel, encoders
from nlp_calib.models.radians import in_units
from nlp_calib.sources.base import check_block, file_identity
from nlp_calib.sources.robot import load_robot, robot_header

#: The keys a ``dataset:`` bag block must have.
REQUIRED = ("bag", "joint_states", "joints", "tracker")
#: How a topic's messages are timed: their header stamps, or the bag's record (receive) times.
STAMPS = ("header", "receive")


def receive_topics(stamps: str | Mapping[str, str], topics: tuple[str, ...], where: str) -> tuple[str, ...]:
    """The topics to time by their record times: ``stamps`` is ``header`` or ``receive`` for every
    topic, or one of them per topic (``{/joint_states: receive}``)."""
    per_topic = dict.fromkeys(topics, stamps) if isinstance(stamps, str) else dict(stamps)
    for topic, how in per_topic.items():
        if how not in STAMPS:
            raise ConfigError(f"{where}.stamps: {topic}: {how!r} is not one of {', '.join(STAMPS)}")
        if topic not in topics:
            raise ConfigError(
                f"{where}.stamps: {topic!r} is neither the joint_states nor the tracker topic "
                f"({', '.join(topics)})"
            )
    return tuple(t for t, how in per_topic.items() if how == "receive")


def _resolved(path: Path, base_dir: Path) -> Path:
    return path if path.is_absolute() else base_dir / path


@dataclass(frozen=True)
class BagSource:
    """A bag (``bag``) and how to read it: the topics, the joints in the model's encoder order, the
    tracked frame, ``ROBOT.yaml``, the pairing's ``max_gap`` (s), what the joints' positions hold
    (``joint_units``), how each topic is timed (``stamps``) and the joints' ``clock_offset`` (s, or
    ``auto``); ``sensor_frame`` and ``base_frame`` name the frames ``/tf_static`` joins."""

    kind: ClassVar[str] = "bag"
    record_word: ClassVar[str] = "record"
    bag: Path
    joint_states: str
    joints: tuple[str, ...]
    tracker: str
    tracker_frame: str | None = None
    robot: Path | None = None
    max_gap: float = DEFAULT_MAX_GAP_S
    joint_units: str = "radians"
    stamps: str | Mapping[str, str] = "header"
    clock_offset: float | str = 0.0
    sensor_frame: str | None = None
    base_frame: str = "base_link"

    def __post_init__(self) -> None:
        self.topics()  # validates the topic fields

    @property
    def path(self) -> Path:
        return self.bag

    def topics(self) -> BagTopics:
        receive = receive_topics(self.stamps, (self.joint_states, self.tracker), "dataset")
        return BagTopics(
            self.joint_states,
            self.joints,
            self.tracker,
            self.tracker_frame,
            self.max_gap,
            self.joint_units,
            receive,
            self.clock_offset,
        )

    @property
    def numbered(self) -> Path:
        return self.bag

    def files(self) -> tuple[Path, ...]:
        return (self.bag,) if self.robot is None else (self.bag, self.robot)

    def clock(self) -> str:
        receive = self.topics().receive
        return " and ".join(
            f"the {'record times' if t in receive else 'header stamps'} of {t}"
            for t in (self.joint_states, self.tracker)
        )

    def identity(self) -> Hashable:
        """A ROS 2 bag's folder also when its .db3 or .mcap file is named: one bag, one log."""
        try:
            return file_identity(bag_root(self.bag))
        except DatasetError:
            return file_identity(self.bag)

    def header(self, model: KinematicModel) -> LogHeader:
        """The header the bag's records get (for ``model`` in the joints' units): ``ROBOT.yaml``'s
        values, else (joints in radians) the sensor's mount on ``/tf_static``, over the model's
        defaults. Raw counts keep the header they always had."""
        model = in_units(model, self.joint_units)
        robot = load_robot(self.robot, model) if self.robot is not None else None
        frame = (robot.sensor_frame if robot else None) or self.sensor_frame or self.tracker_frame
        mount = None
        if self.joint_units == "radians" and (robot is None or robot.sensor_pose is None) and frame:
            mount = static_mount(bag_root(self.bag), self.base_frame, frame)
        return robot_header(model, robot, frame, mount)

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        check_joints(self.joints, model, "dataset.joints")
        if self.joint_units == "radians":
            return read_joint_bag(self.bag, self.topics(), self.header(model))
        return read_bag(self.bag, self.topics(), self.header(model), model.encoder_kinds, strict=strict)

    def records(self, model: KinematicModel) -> tuple[LogHeader, BagRecords]:
        """The header and the paired records, ready to be written as a text log (``import-bag``)."""
        check_joints(self.joints, model, "joints")
        return self.header(model), read_bag_records(self.bag, self.topics())

    def moved(self, path: Path) -> BagSource:
        return replace(self, bag=path)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, Mapping) and "bag" in raw

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return is_bag(path)

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> BagSource:
        check_block(cls, raw, where, "bag", REQUIRED, "docs/bags.md", also)
        source: BagSource = from_mapping(cls, raw, where)
        robot = None if source.robot is None else _resolved(source.robot, base_dir)
        return replace(source, bag=_resolved(coerce(raw["bag"], Path, f"{where}.bag"), base_dir), robot=robot)


def check_joints(joints: tuple[str, ...], model: KinematicModel, where: str) -> None:
    """One joint per encoder of ``model``, in its order."""
    names = encoders(model)
    if len(joints) != len(names):
        raise ConfigError(
            f"{where}: {len(joints)} joint(s) ({', '.join(joints)}) for the {len(names)} encoders of "
            f"{model.name}; name one joint per encoder, in this order: {', '.join(names)}"
        )
