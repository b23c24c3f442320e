"""A gyro and the wheels' joints: the gyro is the reference (``sensor: gyro``).

From a bag, the scenario's block names the bag, the JointState topic and its joints (in the
model's encoder order) and the Imu topic::

    dataset: {bag: drive/, joint_states: /joint_states, joints: [left_wheel_joint, right_wheel_joint],
              imu: /imu}

or, without a bag, a CSV joint log and a gyro's CSV ``t,wx,wy,wz`` (rad/s in the IMU's frame)::

    dataset: {joints: wheels.csv, gyro: gyro.csv,
              encoders: {left_wheel: left_wheel_joint, right_wheel: right_wheel_joint}}

The rates are integrated over intervals of about ``interval`` seconds (:mod:`nlp_calib.logs.imu`);
each interval is one increment of the reference, compared with the wheels over exactly its two
stamps (the joints interpolated there from their own stream). The IMU's nominal height comes from
``/tf_static`` (``base_frame`` to the Imu messages' frame) where the bag holds it.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

from nlp_calib.core.config import coerce, from_mapping
from nlp_calib.core.errors import ConfigError
from nlp_calib.core.ranges import Range
from nlp_calib.logs import Log
from nlp_calib.logs.bag_files import bag_root
from nlp_calib.logs.bag_reader import CLOCK_OFFSET, DEFAULT_MAX_GAP_S, MAX_GAP, is_bag, read_joints
from nlp_calib.logs.bag_tf import static_mount
from nlp_calib.logs.imu import integrated, read_gyro_csv, read_imu
from nlp_calib.logs.motions import timed_by_motions
from nlp_calib.models import KinematicModel, encoders
from nlp_calib.models.radians import in_units
from nlp_calib.sources.bag import STAMPS, check_joints
from nlp_calib.sources.base import check_block, file_identity
from nlp_calib.sources.joints import Wheels
from nlp_calib.sources.robot import load_robot, robot_header

#: The keys a gyro's bag block must have, and a gyro's CSV block.
REQUIRED = ("bag", "joint_states", "joints", "imu")
REQUIRED_CSV = ("joints", "gyro", "encoders")
#: ``interval``: an integration interval's length (s).
INTERVAL = Range(0.001, 60.0)


def _check(interval: float, max_gap: float, clock_offset: float) -> None:
    if (reason := INTERVAL.problem(interval)) is not None:
        raise ConfigError(f"interval (seconds) {reason}")
    for key, value, limit in (("max_gap", max_gap, MAX_GAP), ("clock_offset", clock_offset, CLOCK_OFFSET)):
        if (reason := limit.problem(value)) is not None:
            raise ConfigError(f"{key} (seconds) {reason}")


def _resolved(path: Path | None, base_dir: Path) -> Path | None:
    return None if path is None or path.is_absolute() else base_dir / path


@dataclass(frozen=True)
class ImuSource:
    """A bag (``bag``) with the joints (``joint_states``, ``joints`` in the model's encoder order)
    and an Imu topic (``imu``); the integration interval (``interval``, s); ``ROBOT.yaml``; the
    longest gap between joint messages a stamp is interpolated across (``max_gap``, s); how both
    topics are timed (``stamps``); the seconds added to the joints' stamps (``clock_offset``); the
    frame ``/tf_static`` places the IMU in (``base_frame``)."""

    kind: ClassVar[str] = "imu"
    record_word: ClassVar[str] = "integration interval"
    joint_units: ClassVar[str] = "radians"
    bag: Path
    joint_states: str
    joints: tuple[str, ...]
    imu: str
    interval: float = 0.1
    robot: Path | None = None
    max_gap: float = 0.2
    stamps: str = "header"
    clock_offset: float = 0.0
    base_frame: str = "base_link"

    def __post_init__(self) -> None:
        if self.stamps not in STAMPS:
            raise ConfigError(f"stamps: one of {', '.join(STAMPS)}, got {self.stamps!r}")
        _check(self.interval, self.max_gap, self.clock_offset)
        if not self.joints or len(set(self.joints)) != len(self.joints):
            raise ConfigError(f"joints: each joint once, got {', '.join(self.joints) or 'none'}")

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
        return f"the {how} of {self.joint_states} and of {self.imu}"

    def identity(self) -> Hashable:
        try:
            return file_identity(bag_root(self.bag))
        except Exception:
            return file_identity(self.bag)

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        model = in_units(model, "radians")
        check_joints(self.joints, model, "dataset.joints")
        receive = self.stamps == "receive"
        joints = read_joints(self.bag, self.joint_states, self.joints, receive)
        joints = replace(joints, stamp_ns=joints.stamp_ns + round(self.clock_offset * 1e9))
        rates = read_imu(self.bag, self.imu, receive)
        robot = load_robot(self.robot, model) if self.robot is not None else None
        mount = None
        if robot is None or robot.sensor_pose is None:
            mount = static_mount(bag_root(self.bag), self.base_frame, rates.frame)
        header = robot_header(model, robot, rates.frame, mount)
        motions = integrated(rates, self.interval)
        return timed_by_motions(
            self.bag, joints, motions, self.joints, self.max_gap, header, f"{self.imu} message"
        )

    def moved(self, path: Path) -> ImuSource:
        return replace(self, bag=path)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, Mapping) and "bag" in raw and "imu" in raw

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return is_bag(path)

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> ImuSource:
        check_block(cls, raw, where, "gyro", REQUIRED, "docs/imu.md", also)
        source: ImuSource = from_mapping(cls, raw, where)
        bag = coerce(raw["bag"], Path, f"{where}.bag")
        return replace(
            source,
            bag=_resolved(bag, base_dir) or bag,
            robot=_resolved(source.robot, base_dir) or source.robot,
        )


@dataclass(frozen=True)
class GyroCsvSource:
    """A CSV joint log (``joints``), a gyro's CSV (``gyro``), the joint that is each of the model's
    encoders, what a wheel's column holds (``form``, ``counts_per_turn``), the integration
    interval (s), the longest gap between joint rows a stamp is interpolated across (``max_gap``,
    s), the joints' ``clock_offset`` (s), ``ROBOT.yaml`` and the IMU's frame (``sensor_frame``)."""

    kind: ClassVar[str] = "gyro_csv"
    record_word: ClassVar[str] = "integration interval"
    joint_units: ClassVar[str] = "radians"
    joints: Path
    gyro: Path
    encoders: Mapping[str, str]
    interval: float = 0.1
    form: str = "positions"
    counts_per_turn: float | None = None
    max_gap: float = DEFAULT_MAX_GAP_S
    clock_offset: float = 0.0
    robot: Path | None = None
    sensor_frame: str | None = None

    def __post_init__(self) -> None:
        _check(self.interval, self.max_gap, self.clock_offset)
        self.wheels()

    def wheels(self) -> Wheels:
        return Wheels(self.encoders, self.form, self.counts_per_turn, self.clock_offset)

    @property
    def path(self) -> Path:
        return self.joints

    @property
    def numbered(self) -> Path:
        return self.gyro

    def files(self) -> tuple[Path, ...]:
        return tuple(p for p in (self.joints, self.gyro, self.robot) if p is not None)

    def clock(self) -> str:
        return f"the times of {self.joints.name} and of {self.gyro.name}, each on its own"

    def identity(self) -> Hashable:
        return (file_identity(self.joints), file_identity(self.gyro))

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        model = in_units(model, "radians")
        joints, _ = self.wheels().read(self.joints, model, "dataset.encoders")
        robot = load_robot(self.robot, model) if self.robot is not None else None
        header = robot_header(model, robot, self.sensor_frame or "imu_link")
        motions = integrated(read_gyro_csv(self.gyro), self.interval)
        return timed_by_motions(self.joints, joints, motions, encoders(model), self.max_gap, header)

    def moved(self, path: Path) -> GyroCsvSource:
        return replace(self, joints=path)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, Mapping) and "gyro" in raw and "bag" not in raw

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return path.suffix.lower() == ".csv"

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> GyroCsvSource:
        check_block(cls, raw, where, "gyro CSV", REQUIRED_CSV, "docs/imu.md", also)
        source: GyroCsvSource = from_mapping(cls, raw, where)
        joints, gyro = (coerce(raw[k], Path, f"{where}.{k}") for k in ("joints", "gyro"))
        return replace(
            source,
            joints=_resolved(joints, base_dir) or joints,
            gyro=_resolved(gyro, base_dir) or gyro,
            robot=_resolved(source.robot, base_dir) or source.robot,
        )
