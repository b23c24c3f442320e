"""A CSV joint log and a file of the sensor's own motions (a scan matcher's, visual odometry's):
the reference is each increment, compared with the wheels over exactly its two stamps.

The scenario's block names both files and which joint is which of the model's encoders::

    dataset: {joints: wheels.csv, motions: scan_matches.csv,
              encoders: {left_wheel: left_wheel_joint, right_wheel: right_wheel_joint}}

The joints' CSV is read as a joint log's (:class:`~nlp_calib.sources.joints.Wheels`: positions,
speeds or increments per cycle); the motions file as :mod:`nlp_calib.logs.motions` says. A
record is made at each increment's stamps the joints cover; the windows of the fit are the
increments themselves, whatever ``residual.horizon`` says.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

from nlp_calib.core.config import coerce, from_mapping
from nlp_calib.core.errors import ConfigError, DatasetError
from nlp_calib.logs import Log
from nlp_calib.logs.bag_reader import DEFAULT_MAX_GAP_S, MAX_GAP
from nlp_calib.logs.motions import read_motions, timed_by_motions
from nlp_calib.models import KinematicModel, encoders
from nlp_calib.models.radians import in_units
from nlp_calib.sources.base import check_block, file_identity
from nlp_calib.sources.joints import Wheels
from nlp_calib.sources.robot import load_robot, robot_header

#: The keys a motions block must have.
REQUIRED = ("joints", "motions", "encoders")
#: How ``--data`` names a recording: ``NAME.motions.csv`` beside ``NAME.csv``.
MOTIONS_SUFFIX = ".motions.csv"


def motions_pair(path: Path) -> tuple[Path, Path]:
    """The joints' CSV and the motions file of one recording, named by either: ``NAME.csv`` and
    ``NAME.motions.csv`` side by side (as ``simulate --vehicle skid_spins`` writes them)."""
    name = path.name
    if name.endswith(MOTIONS_SUFFIX):
        return path.with_name(name[: -len(MOTIONS_SUFFIX)] + ".csv"), path
    return path, path.with_name(name[: -len(path.suffix)] + MOTIONS_SUFFIX)


@dataclass(frozen=True)
class MotionsSource:
    """A CSV joint log (``joints``), a motions file (``motions``), the joint that is each of the
    model's encoders, what a wheel's column holds (``form``, ``counts_per_turn``), the longest gap
    between joint rows a stamp is interpolated across (``max_gap``, s), the joints' ``clock_offset``
    (s), ``ROBOT.yaml`` and the sensor's frame (``sensor_frame``: its URDF link)."""

    kind: ClassVar[str] = "motions"
    record_word: ClassVar[str] = "increment"
    joint_units: ClassVar[str] = "radians"
    joints: Path
    motions: Path
    encoders: Mapping[str, str]
    form: str = "positions"
    counts_per_turn: float | None = None
    max_gap: float = DEFAULT_MAX_GAP_S
    clock_offset: float = 0.0
    robot: Path | None = None
    sensor_frame: str | None = None

    def __post_init__(self) -> None:
        if (reason := MAX_GAP.problem(self.max_gap)) is not None:
            raise ConfigError(f"max_gap (seconds) {reason}")
        self.wheels()

    def wheels(self) -> Wheels:
        return Wheels(self.encoders, self.form, self.counts_per_turn, self.clock_offset)

    @property
    def path(self) -> Path:
        return self.joints

    @property
    def numbered(self) -> Path:
        return self.motions  # a record's line is that of an increment at its stamp

    def files(self) -> tuple[Path, ...]:
        return tuple(p for p in (self.joints, self.motions, self.robot) if p is not None)

    def clock(self) -> str:
        return f"the times of {self.joints.name} and the stamps of {self.motions.name}, each on its own"

    def identity(self) -> Hashable:
        return (file_identity(self.joints), file_identity(self.motions))

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        model = in_units(model, "radians")
        joints, _ = self.wheels().read(self.joints, model, "dataset.encoders")
        robot = load_robot(self.robot, model) if self.robot is not None else None
        header = robot_header(model, robot, self.sensor_frame)
        return timed_by_motions(
            self.joints, joints, read_motions(self.motions), encoders(model), self.max_gap, header
        )

    def moved(self, path: Path) -> MotionsSource:
        """The same block on another recording: ``NAME.motions.csv`` and ``NAME.csv`` side by side,
        named by either."""
        joints, motions = motions_pair(path)
        missing = [p for p in (joints, motions) if not p.is_file()]
        if missing:
            raise DatasetError(
                str(path),
                None,
                f"no {missing[0].name} beside it (--data names one file of a NAME.csv, NAME{MOTIONS_SUFFIX} "
                "pair; or edit the scenario's dataset block: joints, motions)",
            )
        return replace(self, joints=joints, motions=motions)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, Mapping) and "motions" in raw and "bag" not in raw

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return path.suffix.lower() == ".csv"

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> MotionsSource:
        check_block(cls, raw, where, "motions", REQUIRED, "docs/motions.md", also)
        source: MotionsSource = from_mapping(cls, raw, where)
        joints, motions = (
            _resolved(coerce(raw[k], Path, f"{where}.{k}"), base_dir) for k in ("joints", "motions")
        )
        robot = None if source.robot is None else _resolved(source.robot, base_dir)
        return replace(source, joints=joints, motions=motions, robot=robot)


def _resolved(path: Path, base_dir: Path) -> Path:
    return path if path.is_absolute() else base_dir / path
