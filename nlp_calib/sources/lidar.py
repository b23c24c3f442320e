"""A bag with a 2-D lidar's scans and the wheels' joints: the lidar is the reference.

The scenario's block names the bag, the JointState topic and its joints (in the model's encoder
order) and the LaserScan topic::

    dataset: {bag: drive/, joint_states: /joint_states, joints: [left_wheel_joint, right_wheel_joint],
              scan: /scan}

Each scan is matched to the one before (:mod:`nlp_calib.logs.scans`: small_gicp, the ``lidar``
extra); the lidar's motion between two scans is one increment of the reference, compared with
the wheels over exactly those two stamps, and each match's quality is kept for the screen that
names bad ones. The joints are in radians (REP 103), read on their own clock and interpolated at
the scans' stamps. The lidar's nominal mount comes from ``ROBOT.yaml``, else ``/tf_static``
(``base_frame`` to the scans' frame), for its height, roll and pitch in the hand-off files.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

from nlp_calib.core.config import coerce, from_mapping
from nlp_calib.core.errors import ConfigError, DatasetError
from nlp_calib.logs import Log, LogHeader
from nlp_calib.logs.bag_files import BagError, bag_root
from nlp_calib.logs.bag_reader import CLOCK_OFFSET, MAX_GAP, is_bag, read_joints
from nlp_calib.logs.bag_tf import is_base_frame, static_mount
from nlp_calib.logs.motions import timed_by_motions
from nlp_calib.logs.scans import ScanMatching, match_scans, read_scans
from nlp_calib.models import KinematicModel
from nlp_calib.models.radians import in_units
from nlp_calib.sources.bag import STAMPS, check_joints
from nlp_calib.sources.base import check_block, file_identity
from nlp_calib.sources.robot import load_robot, robot_header

#: The keys a lidar block must have.
REQUIRED = ("bag", "joint_states", "joints", "scan")
#: A lidar whose scan plane tilts more than this from level (or from upside down) sweeps no plane
#: parallel to the floor: a planar match of its scans measures nothing of the base's motion.
MAX_TILT = math.radians(20.0)


@dataclass(frozen=True)
class LidarSource:
    """A bag (``bag``) with the joints (``joint_states``, ``joints`` in the model's encoder order)
    and a lidar's scans (``scan``); ``ROBOT.yaml``; the longest gap between joint messages a scan's
    stamp is interpolated across (``max_gap``, s); how both topics are timed (``stamps``: their
    header stamps or the bag's record times); the seconds added to the joints' stamps
    (``clock_offset``); the frame ``/tf_static`` places the lidar in (``base_frame``); and the
    matcher's voxel size and pairing distance (m)."""

    kind: ClassVar[str] = "lidar"
    record_word: ClassVar[str] = "scan"
    joint_units: ClassVar[str] = "radians"
    bag: Path
    joint_states: str
    joints: tuple[str, ...]
    scan: str
    robot: Path | None = None
    max_gap: float = 0.2
    stamps: str = "header"
    clock_offset: float = 0.0
    base_frame: str = "base_link"
    resolution: float = 0.05
    max_correspondence: float = 0.3

    def __post_init__(self) -> None:
        if self.stamps not in STAMPS:
            raise ConfigError(f"stamps: one of {', '.join(STAMPS)}, got {self.stamps!r}")
        for key, limit in (("max_gap", MAX_GAP), ("clock_offset", CLOCK_OFFSET)):
            if (reason := limit.problem(getattr(self, key))) is not None:
                raise ConfigError(f"{key} (seconds) {reason}")
        if not self.joints or len(set(self.joints)) != len(self.joints):
            raise ConfigError(f"joints: each joint once, got {', '.join(self.joints) or 'none'}")
        try:
            self.matching()
        except DatasetError as exc:
            raise ConfigError(exc.problem) from None

    def matching(self) -> ScanMatching:
        return ScanMatching(resolution=self.resolution, max_correspondence=self.max_correspondence)

    @property
    def path(self) -> Path:
        return self.bag

    @property
    def numbered(self) -> Path:
        return self.bag

    def files(self) -> tuple[Path, ...]:
        return (self.bag,) if self.robot is None else (self.bag, self.robot)

    def clock(self) -> str:
        how = "record times" if self.stamps == "receive" else "header stamps"
        return f"the {how} of {self.joint_states} and of {self.scan}"

    def identity(self) -> Hashable:
        try:
            return file_identity(bag_root(self.bag))
        except DatasetError:
            return file_identity(self.bag)

    def header(self, model: KinematicModel, frame: str) -> LogHeader:
        """``ROBOT.yaml``'s values, else the lidar's mount on ``/tf_static``, over the model's defaults."""
        robot = load_robot(self.robot, model) if self.robot is not None else None
        mount = None
        if robot is None or robot.sensor_pose is None:
            mount = static_mount(bag_root(self.bag), self.base_frame, frame)
        level = abs(math.cos(mount[3]) * math.cos(mount[4])) if mount is not None else 1.0
        if mount is not None and level < math.cos(MAX_TILT):
            raise BagError(
                self.bag,
                f"/tf_static tilts the lidar's frame {frame!r} {math.degrees(math.acos(level)):.0f}° from "
                f"level (roll {math.degrees(mount[3]):.0f}°, pitch {math.degrees(mount[4]):.0f}°): its scans "
                "sweep no floor-parallel plane, which a planar calibration matches; fix the transform (or "
                "give the mount in ROBOT.yaml, sensor_pose)",
            )
        return robot_header(model, robot, frame, mount)

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        model = in_units(model, "radians")
        check_joints(self.joints, model, "dataset.joints")
        receive = self.stamps == "receive"
        joints = read_joints(self.bag, self.joint_states, self.joints, receive)
        joints = replace(joints, stamp_ns=joints.stamp_ns + round(self.clock_offset * 1e9))
        scans = read_scans(self.bag, self.scan, receive)
        header = self.header(model, scans.frame)
        if is_base_frame(header.sensor_frame, self.base_frame):
            raise BagError(
                self.bag,
                f"the scans on {self.scan!r} are in the base frame {header.sensor_frame!r}: a lidar's "
                "mount is a joint from the base to a frame of its own; set the driver's frame_id, or "
                "sensor_frame in ROBOT.yaml",
            )
        motions = match_scans(scans, self.matching())
        return timed_by_motions(
            self.bag, joints, motions, self.joints, self.max_gap, header, f"{self.scan} message"
        )

    def moved(self, path: Path) -> LidarSource:
        return replace(self, bag=path)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, Mapping) and "bag" in raw and "scan" in raw

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return is_bag(path)

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> LidarSource:
        check_block(cls, raw, where, "lidar", REQUIRED, "docs/lidar.md", also)
        source: LidarSource = from_mapping(cls, raw, where)
        bag = coerce(raw["bag"], Path, f"{where}.bag")
        robot = source.robot
        return replace(
            source,
            bag=bag if bag.is_absolute() else base_dir / bag,
            robot=None if robot is None else robot if robot.is_absolute() else base_dir / robot,
        )
