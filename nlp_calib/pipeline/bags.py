"""Bags as a scenario's data: the ``dataset:`` block that names one, and reading it as a :class:`Log`.

A scenario's ``dataset`` is either a text log's path or a block with the fields of ``nlp-calib
import-bag``; the bag is then read and paired on every run exactly as ``import-bag`` would write it
(:mod:`nlp_calib.logs.bag_records`), with a header from ``ROBOT.yaml`` or the model's defaults.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from nlp_calib.core.errors import ConfigError, UsageError
from nlp_calib.logs import Log, LogHeader
from nlp_calib.logs.bag_reader import DEFAULT_MAX_GAP_S, BagTopics, is_bag
from nlp_calib.logs.bag_records import BagRecords, read_bag, read_bag_records
from nlp_calib.models import KinematicModel, encoders, load_log
from nlp_calib.pipeline.config import coerce, fail, from_mapping, key_name
from nlp_calib.pipeline.robot import load_robot, robot_header

#: The keys a ``dataset:`` bag block must have.
REQUIRED = ("bag", "joint_states", "joints", "tracker")


@dataclass(frozen=True)
class BagSource:
    """How to read a bag (the ``dataset:`` block but its ``bag`` path): the topics, the joints in the
    model's encoder order, the tracked frame, ``ROBOT.yaml`` and the pairing's ``max_gap`` (s)."""

    joint_states: str
    joints: tuple[str, ...]
    tracker: str
    tracker_frame: str | None = None
    robot: Path | None = None
    max_gap: float = DEFAULT_MAX_GAP_S

    def __post_init__(self) -> None:
        self.topics()  # validates the topic fields

    def topics(self) -> BagTopics:
        return BagTopics(self.joint_states, self.joints, self.tracker, self.tracker_frame, self.max_gap)


def _resolved(path: Path, base_dir: Path) -> Path:
    return path if path.is_absolute() else base_dir / path


def dataset_block(
    raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()
) -> tuple[Path, BagSource | None]:
    """A scenario's ``dataset``: a log's path, or a bag block; paths resolve against ``base_dir``.
    ``also``: keys the caller takes out of the block first, named among the valid ones."""
    if not isinstance(raw, Mapping):
        return _resolved(coerce(raw, Path, where), base_dir), None
    valid = ("bag", *BagSource.__dataclass_fields__)
    for key in raw:
        if key not in valid:
            fail(f"{where}.{key_name(key)}", f"unknown key; a bag block has {', '.join((*valid, *also))}")
    missing = [k for k in REQUIRED if k not in raw]
    if missing:
        fail(where, f"a bag block needs {', '.join(REQUIRED)}; missing {', '.join(missing)} (docs/bags.md)")
    bag = coerce(raw["bag"], Path, f"{where}.bag")
    source: BagSource = from_mapping(BagSource, {k: v for k, v in raw.items() if k != "bag"}, where)
    if source.robot is not None:
        source = replace(source, robot=_resolved(source.robot, base_dir))
    return _resolved(bag, base_dir), source


def check_joints(joints: tuple[str, ...], model: KinematicModel, where: str) -> None:
    """One joint per encoder of ``model``, in its order."""
    names = encoders(model)
    if len(joints) != len(names):
        raise ConfigError(
            f"{where}: {len(joints)} joint(s) ({', '.join(joints)}) for the {len(names)} encoders of "
            f"{model.name}; name one joint per encoder, in this order: {', '.join(names)}"
        )


def bag_header(source: BagSource, model: KinematicModel) -> LogHeader:
    """The header a bag's records get: ``ROBOT.yaml``'s values over the model's defaults."""
    robot = load_robot(source.robot, model) if source.robot is not None else None
    return robot_header(model, robot, source.tracker_frame)


def import_bag(bag: Path, source: BagSource, model: KinematicModel) -> tuple[LogHeader, BagRecords]:
    """A bag's header and paired records, ready to be written as a text log (``import-bag``)."""
    check_joints(source.joints, model, "joints")
    header = bag_header(source, model)
    return header, read_bag_records(bag, source.topics())


def load_dataset(path: Path, bag: BagSource | None, model: KinematicModel, *, strict: bool) -> Log:
    """The scenario's data as a :class:`Log`: a text log, or the bag ``bag`` describes."""
    if bag is None:
        if is_bag(path):
            raise UsageError(
                f"{path}: a ROS bag; name its topics in a dataset block (bag, joint_states, joints, "
                "tracker; docs/bags.md) or convert it with nlp-calib import-bag"
            )
        return load_log(path, model, strict=strict)
    check_joints(bag.joints, model, "dataset.joints")
    return read_bag(path, bag.topics(), bag_header(bag, model), model.encoder_kinds, strict=strict)
