"""A gyro beside a planar reference (its own motions, or a tracker's poses): one dataset block naming both.

From one bag, a lidar's scans (``scan:``) or a tracker's poses (``tracker:``) and an Imu topic
beside the joints::

    dataset: {bag: drive/, joint_states: /joint_states, joints: [left_wheel_joint, right_wheel_joint],
              scan: /scan, imu: /imu}

or, without a bag, a CSV joint log, a motions file (or a TUM file of poses, ``poses:``) and a
gyro's CSV::

    dataset: {joints: wheels.csv, motions: lidar.csv, gyro: gyro.csv,
              encoders: {left_wheel: left_wheel_joint, right_wheel: right_wheel_joint}}

with ``sensor: {mount: planar, beside: gyro}`` (a camera's 3-D poses: ``{mount: 3d, beside: gyro}``,
which sets ``in_3d`` on load). Each key goes to the source that has it (the
joints' keys to both); each reads its log, and :func:`~nlp_calib.logs.beside.beside_gyro` lays
them on one time axis.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

from nlp_calib.core.config import fail, key_name
from nlp_calib.logs import Log
from nlp_calib.logs.beside import beside_gyro
from nlp_calib.models import KinematicModel
from nlp_calib.sources.bag import BagSource
from nlp_calib.sources.base import DatasetSource
from nlp_calib.sources.imu import GyroCsvSource, ImuSource
from nlp_calib.sources.joints import JointLogSource
from nlp_calib.sources.lidar import LidarSource
from nlp_calib.sources.motions import MotionsSource
from nlp_calib.sources.text_gyro import TextGyroSource, TextPosesSource

#: Each pair: the reference's source, the gyro's, the key only the reference's block has and the
#: gyro's.
PAIRS: tuple[tuple[type[DatasetSource], type[DatasetSource], str, str], ...] = (
    (LidarSource, ImuSource, "scan", "imu"),
    (BagSource, ImuSource, "tracker", "imu"),
    (MotionsSource, GyroCsvSource, "motions", "gyro"),
    (JointLogSource, GyroCsvSource, "poses", "gyro"),
    (TextPosesSource, TextGyroSource, "text", "gyro"),
)


def _fields(cls: type) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


def _pair(raw: Any) -> tuple[type[DatasetSource], type[DatasetSource], str, str] | None:
    if not isinstance(raw, Mapping):
        return None
    return next((p for p in PAIRS if p[2] in raw and p[3] in raw), None)


@dataclass(frozen=True)
class BesideSource:
    """A reference's own motions (``reference``) and a gyro's increments (``gyro``), read from the
    same joints."""

    kind: ClassVar[str] = "beside_gyro"
    record_word: ClassVar[str] = "increment"
    joint_units: ClassVar[str] = "radians"
    reference: DatasetSource
    gyro: DatasetSource
    #: The reference's motions between its 3-D poses (a camera's), not its planar track.
    in_3d: bool = False

    @property
    def path(self) -> Path:
        return self.reference.path

    @property
    def numbered(self) -> Path:
        return self.reference.numbered

    def files(self) -> tuple[Path, ...]:
        return tuple(dict.fromkeys((*self.reference.files(), *self.gyro.files())))

    def clock(self) -> str:
        return f"{self.reference.clock()}; the gyro's: {self.gyro.clock()}"

    def identity(self) -> Hashable:
        return (self.reference.identity(), self.gyro.identity(), self.in_3d)

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        reference, gyro = self.reference.read(model, strict=strict), self.gyro.read(model, strict=strict)
        return beside_gyro(reference, gyro, self.in_3d)

    def moved(self, path: Path) -> BesideSource:
        return replace(self, reference=self.reference.moved(path), gyro=self.gyro.moved(path))

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return _pair(raw) is not None

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return any(ref.accepts(path) for ref, *_ in PAIRS)

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> BesideSource:
        pair = _pair(raw)
        assert pair is not None  # claims() said so
        ref_cls, gyro_cls, _, _ = pair
        ref_keys, gyro_keys = _fields(ref_cls), _fields(gyro_cls)
        for key in raw:
            if key not in ref_keys | gyro_keys:
                valid = ", ".join(sorted(ref_keys | gyro_keys | set(also)))
                fail(f"{where}.{key_name(key)}", f"unknown key; a reference beside a gyro has {valid}")
        ref_raw = {k: v for k, v in raw.items() if k in ref_keys}
        gyro_raw = {k: v for k, v in raw.items() if k in gyro_keys}
        return cls(
            ref_cls.parse(ref_raw, where, base_dir, also), gyro_cls.parse(gyro_raw, where, base_dir, also)
        )
