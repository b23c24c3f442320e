"""A CSV joint log and a tracker's TUM trajectory as a dataset: each on its own clock.

The scenario's block names both files and which joint is which of the model's encoders::

    dataset: {joints: wheels.csv, poses: tracker.tum, encoders: {left_wheel: left_wheel_joint,
              right_wheel: right_wheel_joint}}

The joints are in radians (REP 103); a wheel's column may instead hold its speed (``form:
speeds``, rad/s) or its increment per cycle (``form: increments``, with ``counts_per_turn`` when
they are counts; :func:`~nlp_calib.logs.joint_log.wheel_positions`). A record is made at each
tracker pose the joints cover, with the joints interpolated there
(:func:`nlp_calib.logs.bag_joints.timed_by_tracker`), exactly as a bag's joints in radians are
read. ``clock_offset`` (s) is added to the joints' times when the two files' clocks differ;
``robot`` is a ``ROBOT.yaml`` (initial guess, the sensor's nominal pose).
"""

from __future__ import annotations

import os
import stat
import warnings
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from nlp_calib.core.config import coerce, from_mapping
from nlp_calib.core.errors import ConfigError, DatasetError, NlpCalibWarning
from nlp_calib.core.files import kind_of
from nlp_calib.core.ranges import Range
from nlp_calib.core.text import escaped
from nlp_calib.logs import Log
from nlp_calib.logs.bag_joints import timed_by_tracker
from nlp_calib.logs.bag_reader import CLOCK_OFFSET, DEFAULT_MAX_GAP_S, MAX_GAP, Stamped
from nlp_calib.logs.joint_log import (
    LOST_CYCLES,
    WHEEL_FORMS,
    JointTable,
    lost_rows,
    read_joint_csv,
    wheel_positions,
)
from nlp_calib.logs.log import LogHeader, frozen
from nlp_calib.logs.screens import MAX_SHIFT_S, quaternion_order
from nlp_calib.logs.tum import Trajectory3D, read_tum
from nlp_calib.models import KinematicModel, encoders
from nlp_calib.models.radians import in_units
from nlp_calib.sources.base import check_block, file_identity
from nlp_calib.sources.robot import load_robot, robot_header

#: Joint rows further than this from the poses' span (s, on the poses' clock) cannot pair with them
#: (the clock check looks this far: :data:`~nlp_calib.logs.screens.MAX_SHIFT_S`).
PAIRING_MARGIN_S = MAX_SHIFT_S
#: The keys a joint-log block must have.
REQUIRED = ("joints", "poses", "encoders")
#: Counts per wheel turn a per-cycle increment may be given in.
COUNTS_PER_TURN = Range(1e-6, 1e12, lo_open=True)


@dataclass(frozen=True)
class Wheels:
    """How a joint CSV is read: which joint is each of the model's encoders, what a wheel's column
    holds (``form``, :data:`~nlp_calib.logs.joint_log.WHEEL_FORMS`) and, for increments in counts,
    the counts per turn; ``clock_offset`` (s) is added to its times."""

    encoders: Mapping[str, str]
    form: str = "positions"
    counts_per_turn: float | None = None
    clock_offset: float = 0.0

    def __post_init__(self) -> None:
        if self.form not in WHEEL_FORMS:
            raise ConfigError(f"form: one of {', '.join(WHEEL_FORMS)}, got {self.form!r}")
        if self.counts_per_turn is not None:
            if self.form != "increments":
                raise ConfigError("counts_per_turn: only increments per cycle are counted (form: increments)")
            if (reason := COUNTS_PER_TURN.problem(self.counts_per_turn)) is not None:
                raise ConfigError(f"counts_per_turn {reason}")
        if (reason := CLOCK_OFFSET.problem(self.clock_offset)) is not None:
            raise ConfigError(f"clock_offset (seconds) {reason}")

    def read(
        self, path: Path, model: KinematicModel, where: str, table: JointTable | None = None
    ) -> tuple[Stamped, tuple[str, ...]]:
        """The joints of ``path`` for ``model`` (in radians) as a stream (each joint's position,
        then its velocity, NaN) on the other file's clock, and the joints' names in encoder order
        (``table``: its rows, when already read)."""
        check_encoders(self.encoders, model, where)
        names = encoders(model)
        table = read_joint_csv(path) if table is None else table
        joint_names = tuple(self.encoders[e] for e in names)
        wheels = [model.encoder_kinds[e] == "counter" for e in names]
        values = table.columns(joint_names, where)
        if self.form == "speeds":
            # Speeds are a stream's velocities, integrated as a bag's are: the log knows which joints
            # came from speeds (their units are checked against the tracker: rpm, deg/s).
            speeds = np.zeros(values.shape, dtype=bool)
            speeds[:, wheels] = True
            positions, velocities = np.where(speeds, np.nan, values), np.where(speeds, values, np.nan)
        else:
            positions = wheel_positions(table.time_ns, values, wheels, self.form, self.counts_per_turn)
            velocities = np.full(positions.shape, np.nan)
        shift = round(self.clock_offset * 1e9)
        breaks = self._lost(table) if self.form == "increments" and any(wheels) else None
        stamped = Stamped(table.path, table.time_ns + shift, np.hstack([positions, velocities]))
        return replace(stamped, breaks_ns=None if breaks is None else breaks + shift), joint_names

    def _lost(self, table: JointTable) -> np.ndarray | None:
        """The stretches ``(from, to)`` (ns) over which increments per cycle were lost with their
        rows (:func:`~nlp_calib.logs.joint_log.lost_rows`), said; None when none was."""
        lost = lost_rows(table.time_ns)
        if not lost.size:
            return None
        t = table.time_ns
        cycle = float(np.median(np.diff(t))) * 1e-9
        warnings.warn(
            f"{table.path}: {lost.size} of {t.size} rows follow the row before by more than "
            f"{LOST_CYCLES:g} cycles of {1e3 * cycle:.3g} ms (first on line "
            f"{int(table.line_numbers[lost[0]])}, "
            f"{(t[lost[0]] - t[lost[0] - 1]) * 1e-6:.3g} ms after the row before): rows lost by the "
            "logger, and the wheels' increments over their cycles with them; no residual window crosses them",
            NlpCalibWarning,
            stacklevel=4,
        )
        return np.stack([t[lost - 1], t[lost]], axis=1)


@dataclass(frozen=True)
class JointLogSource:
    """A CSV joint log (``joints``), a TUM trajectory of the sensor (``poses``), the joint that is
    each of the model's encoders (``encoders``), the longest gap between joint rows a pose's time
    is interpolated across (``max_gap``, s), the joints' ``clock_offset`` (s), ``ROBOT.yaml``, and
    what a wheel's column holds (``form``; ``counts_per_turn``: see :class:`Wheels`)."""

    kind: ClassVar[str] = "joints"
    record_word: ClassVar[str] = "pose"
    joint_units: ClassVar[str] = "radians"
    joints: Path
    poses: Path
    encoders: Mapping[str, str]
    max_gap: float = DEFAULT_MAX_GAP_S
    clock_offset: float = 0.0
    robot: Path | None = None
    form: str = "positions"
    counts_per_turn: float | None = None

    def __post_init__(self) -> None:
        if (reason := MAX_GAP.problem(self.max_gap)) is not None:
            raise ConfigError(f"max_gap (seconds) {reason}")
        self.wheels()  # validates the wheels' fields

    def wheels(self) -> Wheels:
        return Wheels(self.encoders, self.form, self.counts_per_turn, self.clock_offset)

    @property
    def path(self) -> Path:
        return self.joints

    @property
    def numbered(self) -> Path:
        return self.poses  # a record is made at each pose

    def files(self) -> tuple[Path, ...]:
        return tuple(p for p in (self.joints, self.poses, self.robot) if p is not None)

    def clock(self) -> str:
        return f"the times of {self.joints.name} and of {self.poses.name}, each on its own"

    def identity(self) -> Hashable:
        return (file_identity(self.joints), file_identity(self.poses))

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        model = in_units(model, "radians")
        poses = read_tum(self.poses)
        self._check_order(poses)
        table = self._paired(poses, round(self.clock_offset * 1e9))
        joints, _ = self.wheels().read(self.joints, model, "dataset.encoders", table)
        tracker = Stamped(str(self.poses), poses.time_ns, poses.planar_and_3d())
        header = self.header(model)
        log = timed_by_tracker(self.joints, joints, tracker, encoders(model), self.max_gap, header)
        return replace(log, line_numbers=frozen(poses.line_numbers[log.line_numbers - 1]))

    def header(self, model: KinematicModel, frame: str | None = None) -> LogHeader:
        """``ROBOT.yaml``'s header (the model's defaults without one), for ``model`` in radians."""
        robot = load_robot(self.robot, model) if self.robot is not None else None
        return robot_header(model, robot, frame)

    def _check_order(self, poses: Trajectory3D) -> None:
        """Refuse quaternions written ``w`` first (:func:`~nlp_calib.logs.screens.quaternion_order`)."""
        found = quaternion_order(poses.time_s, poses.poses)
        if found is not None:
            read, w_first = found
            raise DatasetError(
                str(self.poses),
                None,
                "its quaternions look written 'qw qx qy qz': read as TUM's 'qx qy qz qw', "
                f"{100 * read:.0f} % of the sensor's rotation is about the normal of the plane its positions "
                f"lie in, read w first {100 * w_first:.0f} %; a TUM line is "
                "'timestamp tx ty tz qx qy qz qw': move each line's w to the end",
            )

    def _paired(self, poses: Trajectory3D, shift: int) -> JointTable:
        """The joint rows within :data:`PAIRING_MARGIN_S` of the poses (on the poses' clock): what
        can pair with them, the lag search and the clock check included; the rest of a long joint
        log is skipped as it is read, and said."""
        margin = round(PAIRING_MARGIN_S * 1e9)
        lo, hi = int(poses.time_ns[0]) - shift - margin, int(poses.time_ns[-1]) - shift + margin
        table = read_joint_csv(self.joints, keep=lambda t: (t >= lo) & (t <= hi))
        self._check_overlap(np.array(table.span_ns) + shift, poses.time_ns)
        kept = int(table.time_ns.size)
        if kept < 2:
            raise DatasetError(
                str(self.joints),
                None,
                f"holds {kept} row(s) within {PAIRING_MARGIN_S:g} s of the poses; at least 2 are needed",
            )
        if kept < table.rows:
            span = (table.span_ns[1] - table.span_ns[0]) * 1e-9
            warnings.warn(
                f"{self.joints}: {table.rows} rows over {span:.0f} s, of which the {kept} within "
                f"{PAIRING_MARGIN_S:g} s of the poses' {poses.time_s[-1] - poses.time_s[0]:.0f} s "
                f"({self.poses.name}) were kept; the rest cannot pair with them",
                NlpCalibWarning,
                stacklevel=4,
            )
        return table

    def _check_overlap(self, joint_ns: np.ndarray, pose_ns: np.ndarray) -> None:
        """Refuse files whose times do not overlap, in this block's words (a bag's are the topics')."""
        if joint_ns.max() >= pose_ns.min() and pose_ns.max() >= joint_ns.min():
            return
        spans = [f"{ns.min() * 1e-9:.3f}-{ns.max() * 1e-9:.3f} s" for ns in (joint_ns, pose_ns)]
        raise DatasetError(
            str(self.joints),
            None,
            f"its times ({spans[0]}) and those of {self.poses} ({spans[1]}) do not overlap: the two "
            "files' clocks differ; give the seconds to add to the joints' times as clock_offset in the "
            "dataset block",
        )

    def moved(self, path: Path) -> JointLogSource:
        """The same block on another recording: ``path`` names either file of a pair lying side by
        side with one stem, and both files move (the joints and the poses of one recording)."""
        joints, poses = paired_files(path)
        return replace(self, joints=joints, poses=poses)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, Mapping) and "joints" in raw and "bag" not in raw and "motions" not in raw

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return path.suffix.lower() in (".csv", ".tum")

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> JointLogSource:
        check_block(cls, raw, where, "joint-log", REQUIRED, "docs/bags.md", also)
        source: JointLogSource = from_mapping(cls, raw, where)
        joints, poses = (
            _resolved(coerce(raw[k], Path, f"{where}.{k}"), base_dir) for k in ("joints", "poses")
        )
        robot = None if source.robot is None else _resolved(source.robot, base_dir)
        return replace(source, joints=joints, poses=poses, robot=robot)


def paired_files(path: Path) -> tuple[Path, Path]:
    """The joint CSV and the TUM file of one recording from either one's path: ``NAME.tum`` beside
    ``NAME.csv`` (as ``import-bag`` writes them) or ``NAME.joints.csv`` (as ``simulate`` does)."""
    is_tum = path.suffix.lower() == ".tum"
    stem = path.name[: -len(path.suffix)]
    if is_tum:
        partners = [path.with_name(f"{stem}.csv"), path.with_name(f"{stem}.joints.csv")]
    else:
        partners = [path.with_name(f"{stem.removesuffix('.joints')}.tum")]
    found = [p for p in partners if p.is_file()]
    fix = (
        "--data names one file of a joint-log pair and reads its partner beside it; give the pair "
        "one stem (NAME.tum with NAME.csv or NAME.joints.csv) or edit the scenario's dataset block "
        "(joints, poses)"
    )
    if not path.is_file():
        raise DatasetError(str(path), None, f"no such file ({fix})")
    special = [(p, kind) for p in partners if (kind := _not_regular(p)) is not None]
    if not found and special:
        partner, kind = special[0]
        raise DatasetError(
            str(path), None, f"its partner {partner.name} beside it is {kind}, not a regular file ({fix})"
        )
    if len(found) != 1:
        what = "no" if not found else "two candidate partners"
        listed = " or ".join(p.name for p in (found or partners))
        raise DatasetError(str(path), None, f"{what} {listed} beside it ({fix})")
    return (found[0], path) if is_tum else (path, found[0])


def _not_regular(path: Path) -> str | None:
    """What ``path`` is when it exists but is not a regular file (a folder, a FIFO...), else None."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    return None if stat.S_ISREG(mode) else kind_of(mode)


def check_encoders(given: Mapping[str, str], model: KinematicModel, where: str) -> None:
    """One joint for each of the model's encoders, by the encoder's name, each its own: one joint
    read twice (a single steer column for both front wheels of a pair) tells the model nothing
    the second encoder stands for (the pair's split), so it is refused."""
    names = encoders(model)
    if set(given) != set(names):
        raise ConfigError(
            f"{where}: name the joint of each of {model.name}'s encoders, {', '.join(names)} (got "
            f"{', '.join(given) or 'none'}), as {{{names[0]}: <joint name>, ...}}"
        )
    readers: dict[str, list[str]] = {}
    for encoder, joint in given.items():
        readers.setdefault(joint, []).append(encoder)
    for joint, shared in readers.items():
        if len(shared) < 2:
            continue
        steered = all(model.encoder_kinds[e] == "absolute" for e in shared)
        hint = (
            "one steer joint for both front wheels is a model's with one steer encoder, which "
            "holds no Ackermann split: choose it, or log each wheel's own steer joint"
            if steered
            else "give each encoder its own joint"
        )
        raise ConfigError(f"{where}: {' and '.join(shared)} both read the joint '{escaped(joint)}': {hint}")


def _resolved(path: Path, base_dir: Path) -> Path:
    return path if path.is_absolute() else base_dir / path
