"""What a dataset source is: the records of one log, from wherever they are kept.

A source is a frozen dataclass parsed from a scenario's ``dataset:`` entry (validated once, on
load) that reads its records into a :class:`~nlp_calib.logs.Log` for a model. Adding a source is
one module with such a class and one entry in :data:`nlp_calib.sources.SOURCES`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Hashable, Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar, Protocol

from nlp_calib.core import files
from nlp_calib.core.config import fail, key_name
from nlp_calib.logs import Log
from nlp_calib.models import KinematicModel


class DatasetSource(Protocol):
    """One log's records: where they are, what their stamps are, how to read them."""

    #: The registry name (``text``, ``bag``...).
    kind: ClassVar[str]
    #: What one record is called in messages (a text log's ``line``, a bag's ``message``).
    record_word: ClassVar[str]

    @property
    def path(self) -> Path:
        """The file or folder that names the log (in messages and output folder names)."""
        ...

    @property
    def joint_units(self) -> str:
        """What its encoder readings are: ``counts`` or ``radians`` (the model's form follows)."""
        ...

    @property
    def numbered(self) -> Path:
        """The file whose line numbers a record's ``line`` counts (a joint log's are its poses')."""
        ...

    def files(self) -> tuple[Path, ...]:
        """Every file or folder the source reads (to tell logs apart and to never overwrite one)."""
        ...

    def clock(self) -> str:
        """Which clock the records' times come from, in words."""
        ...

    def identity(self) -> Hashable:
        """What tells this log from every other whatever it is called: the device and inode of
        the file it reads (links and ``..`` are one file), or its resolved path when missing."""
        ...

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        """The records, read for ``model`` (``strict``: refuse a bad record instead of dropping it)."""
        ...

    def moved(self, path: Path) -> DatasetSource:
        """The same reading of another file (``--data``)."""
        ...

    @classmethod
    def claims(cls, raw: Any) -> bool:
        """Whether the scenario's ``dataset`` entry ``raw`` (YAML) describes this kind of source."""
        ...

    @classmethod
    def accepts(cls, path: Path) -> bool:
        """Whether a path alone (``--data PATH``) can be read by this kind of source."""
        ...

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> DatasetSource:
        """The source ``raw`` describes; paths resolve against ``base_dir``, errors name ``where``;
        ``also``: keys the caller took out of the entry first, named among the valid ones."""
        ...


def file_identity(path: Path) -> Hashable:
    """The device and inode of ``path``, or its resolved path when it cannot be read (the read
    that follows says why)."""
    try:
        return files.identity(path)
    except (OSError, ValueError):
        pass
    try:
        return path.resolve()
    except (OSError, ValueError):  # a NUL in the path: no file has it; the read says so
        return str(path)


def check_block(
    cls: type, raw: Any, where: str, what: str, required: Sequence[str], doc: str, also: tuple[str, ...] = ()
) -> None:
    """Refuse a dataset block ``raw`` (a ``what`` block, read as the dataclass ``cls``) with a key
    ``cls`` does not have or without a ``required`` one; ``doc``: the page that describes it."""
    valid = [f.name for f in dataclasses.fields(cls)]
    for key in raw:
        if key not in valid:
            fail(f"{where}.{key_name(key)}", f"unknown key; a {what} block has {', '.join((*valid, *also))}")
    missing = [k for k in required if k not in raw]
    if missing:
        fail(where, f"a {what} block needs {', '.join(required)}; missing {', '.join(missing)} ({doc})")


def encoder_joints(source: object, model: KinematicModel) -> dict[str, str]:
    """The joint each of ``model``'s encoders reads where ``source`` names them (a bag's ``joints``
    in the model's encoder order, a CSV's ``encoders``); empty for a source that names none (a
    text log's columns are the encoders themselves)."""
    named = getattr(source, "encoders", None)
    if isinstance(named, Mapping):
        return {str(k): str(v) for k, v in named.items()}
    joints = getattr(source, "joints", None)
    if isinstance(joints, tuple):
        return dict(zip(model.encoder_kinds, map(str, joints)))
    return {}
