"""A text log (docs/log-format.md) beside a gyro's CSV: the text log's tracker poses are the reference,
its encoders the joints both sensors read, the gyro's rates beside them::

    dataset: {text: run.log, gyro: gyro.csv, counts_per_turn: {left_wheel: 4096, right_wheel: 4096}}

with ``sensor: {mount: planar, beside: gyro}`` (:mod:`nlp_calib.sources.beside`). A gyro is read in
radians, so the text log's counts become joint angles: a wheel's unwrapped count over its counts per
turn (``counts_per_turn``, which a text log does not state), an angle encoder's reading over its
range (``#joints_max_enc_values``). The text log's records stay its own (its stamps, its line
numbers); the joints between them are interpolated as a joint log's are.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from nlp_calib.core import poses3d
from nlp_calib.core.config import coerce, fail, from_mapping
from nlp_calib.core.errors import ConfigError, DatasetError
from nlp_calib.core.numeric import wrap_angle, wrapped_difference
from nlp_calib.logs import Log
from nlp_calib.logs.bag_joints import timed_by_tracker
from nlp_calib.logs.bag_reader import DEFAULT_MAX_GAP_S, Stamped
from nlp_calib.logs.imu import integrated, read_gyro_csv
from nlp_calib.logs.log import frozen
from nlp_calib.logs.motions import timed_by_motions
from nlp_calib.models import KinematicModel, encoders
from nlp_calib.models.radians import in_units
from nlp_calib.sources.base import check_block, file_identity
from nlp_calib.sources.imu import INTERVAL
from nlp_calib.sources.robot import robot_header
from nlp_calib.sources.text import load_log

#: What a text log's block beside a gyro needs.
REQUIRED = ("text", "gyro", "counts_per_turn")
#: Counts per wheel turn: at least one, at most 2^31.
COUNTS = (1.0, 2.0**31)


def check_counts(counts_per_turn: Mapping[str, float]) -> None:
    """Each wheel's counts per turn within :data:`COUNTS`, or the error naming it."""
    for name, counts in counts_per_turn.items():
        if not COUNTS[0] <= counts <= COUNTS[1]:
            raise ConfigError(f"counts_per_turn.{name} must lie in [1, 2^31], got {counts!r}")


def _joints(log: Log, model: KinematicModel, counts_per_turn: Mapping[str, float]) -> Stamped:
    """The text log's encoders as joint angles (rad) at its records, in ``model``'s encoder order."""
    columns = []
    for name in encoders(model):
        j = log.header.encoder_index(name)
        raw = log.ticks[:, j]
        if model.encoder_kinds[name] == "absolute":
            columns.append(wrap_angle(2.0 * np.pi * raw / log.header.encoder_max[j]))
            continue
        if name not in counts_per_turn:
            raise DatasetError(
                str(log.path), None, f"counts_per_turn gives no counts per turn for the wheel {name!r}: a "
                "text log's counts are no angle; give each wheel's (dataset.counts_per_turn)",
            )  # fmt: skip
        count = np.concatenate([[0.0], np.cumsum(wrapped_difference(raw))])
        columns.append(2.0 * np.pi * count / counts_per_turn[name])
    positions = np.column_stack(columns)
    stamps = log.clock.start_ns + np.round(np.asarray(log.time_s) * 1e9).astype(np.int64)
    return Stamped(str(log.path), stamps, np.hstack([positions, np.full(positions.shape, np.nan)]))


def _tracker(log: Log, stamps_ns: np.ndarray) -> Stamped:
    """The text log's planar poses, with their level 3-D poses (height 0)."""
    T = np.asarray(log.T_world_sensor, dtype=float)
    rpy = np.column_stack([np.zeros((T.shape[0], 2)), T[:, 2]])
    quat = poses3d.matrix_to_quat(poses3d.rpy_to_matrix(rpy))
    return Stamped(str(log.path), stamps_ns, np.column_stack([T, np.zeros(T.shape[0]), quat]))


@dataclass(frozen=True)
class TextPosesSource:
    """A text log's tracker poses as the reference beside a gyro, its encoders as joint angles (see
    the module docstring); ``gyro`` and ``interval`` are the gyro's (:class:`TextGyroSource`)."""

    kind: ClassVar[str] = "text_poses"
    record_word: ClassVar[str] = "line"
    joint_units: ClassVar[str] = "radians"
    text: Path
    counts_per_turn: Mapping[str, float] = field(default_factory=dict)
    max_gap: float = DEFAULT_MAX_GAP_S

    def __post_init__(self) -> None:
        check_counts(self.counts_per_turn)

    @property
    def path(self) -> Path:
        return self.text

    @property
    def numbered(self) -> Path:
        return self.text

    def files(self) -> tuple[Path, ...]:
        return (self.text,)

    def clock(self) -> str:
        return f"the times of {self.text.name}"

    def identity(self) -> Hashable:
        return file_identity(self.text)

    def joints(self, model: KinematicModel, *, strict: bool) -> tuple[Log, Stamped]:
        """The text log as read, and its encoders as joint angles."""
        log = load_log(self.text, strict=strict)
        return log, _joints(log, in_units(model, "radians"), self.counts_per_turn)

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        text, joints = self.joints(model, strict=strict)
        radians = in_units(model, "radians")
        header = robot_header(radians)
        log = timed_by_tracker(
            self.text, joints, _tracker(text, joints.stamp_ns), encoders(radians), self.max_gap, header
        )
        return replace(log, line_numbers=frozen(text.line_numbers[log.line_numbers - 1]))

    def moved(self, path: Path) -> TextPosesSource:
        return replace(self, text=path)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, Mapping) and "text" in raw

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return False

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> TextPosesSource:
        check_block(cls, raw, where, "text log beside a gyro", ("text",), "docs/imu.md", also)
        source: TextPosesSource = from_mapping(cls, raw, where)
        text = coerce(raw["text"], Path, f"{where}.text")
        return replace(source, text=text if text.is_absolute() else base_dir / text)


@dataclass(frozen=True)
class TextGyroSource:
    """A gyro's CSV (``gyro``) beside a text log (``text``), its increments over intervals of about
    ``interval`` s compared with the text log's encoders as joint angles."""

    kind: ClassVar[str] = "text_gyro"
    record_word: ClassVar[str] = "integration interval"
    joint_units: ClassVar[str] = "radians"
    text: Path
    gyro: Path
    counts_per_turn: Mapping[str, float] = field(default_factory=dict)
    interval: float = 0.1
    max_gap: float = DEFAULT_MAX_GAP_S
    sensor_frame: str | None = None

    def __post_init__(self) -> None:
        check_counts(self.counts_per_turn)
        if (reason := INTERVAL.problem(self.interval)) is not None:
            raise ConfigError(f"interval {reason}")

    @property
    def path(self) -> Path:
        return self.text

    @property
    def numbered(self) -> Path:
        return self.gyro

    def files(self) -> tuple[Path, ...]:
        return (self.text, self.gyro)

    def clock(self) -> str:
        return f"the times of {self.text.name} and of {self.gyro.name}, each on its own"

    def identity(self) -> Hashable:
        return (file_identity(self.text), file_identity(self.gyro))

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        _, joints = TextPosesSource(self.text, self.counts_per_turn).joints(model, strict=strict)
        radians = in_units(model, "radians")
        header = robot_header(radians, None, self.sensor_frame or "imu_link")
        motions = integrated(read_gyro_csv(self.gyro), self.interval)
        return timed_by_motions(self.text, joints, motions, encoders(radians), self.max_gap, header)

    def moved(self, path: Path) -> TextGyroSource:
        return replace(self, text=path)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, Mapping) and "text" in raw and "gyro" in raw

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return False

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> TextGyroSource:
        check_block(cls, raw, where, "gyro beside a text log", REQUIRED, "docs/imu.md", also)
        source: TextGyroSource = from_mapping(cls, raw, where)
        text, gyro = (coerce(raw[k], Path, f"{where}.{k}") for k in ("text", "gyro"))
        if not source.counts_per_turn:
            fail(
                f"{where}.counts_per_turn",
                "give each wheel's counts per turn (a text log's counts are no angle)",
            )
        return replace(
            source,
            text=text if text.is_absolute() else base_dir / text,
            gyro=gyro if gyro.is_absolute() else base_dir / gyro,
        )
