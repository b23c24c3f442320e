"""The text log: a ``#`` header and one record per line (docs/log-format.md)."""

from __future__ import annotations

import warnings
from collections.abc import Hashable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from nlp_calib.core import memory
from nlp_calib.core.config import coerce
from nlp_calib.core.errors import ModelError, NlpCalibWarning, UsageError
from nlp_calib.logs import Log, read_log
from nlp_calib.logs.bag_reader import is_bag
from nlp_calib.logs.reader import read_header
from nlp_calib.models import KinematicModel, model_for_log
from nlp_calib.sources.base import file_identity

#: A log this large is said to be so before it is read.
LARGE_LOG_BYTES = 256 << 20
#: About what a run holds in memory at its peak per byte of a log's text (the records, the windows,
#: the evaluators' buffers and the analyses: about 7.5 on simulated 1 kHz logs of 10^5 to 10^6
#: records with a scenario's defaults; the reading alone takes 2.5).
RUN_BYTES_PER_BYTE = 8


def load_log(path: str | Path, model: KinematicModel | None = None, *, strict: bool = True) -> Log:
    """Read a text log with ``model``'s encoder kinds (default: the model its header names).

    Raises :class:`ModelError` when the header names a kind of robot ``model`` does not read.
    """
    kind = read_header(path).kinematic_model
    if model is None:
        model = model_for_log(kind)
    elif kind not in model.log_names:
        raise ModelError(
            f"{path}: the log is of kind {kind!r}, but the model {model.name!r} reads "
            f"{', '.join(model.log_names)}"
        )
    _warn_size(Path(path))
    return read_log(path, model.encoder_kinds, strict=strict)


def _warn_size(path: Path) -> None:
    """Say before reading a large log what a run of it will take (:data:`RUN_BYTES_PER_BYTE`)."""
    try:
        size = path.stat().st_size
    except OSError:
        return  # the reader says what is wrong with it
    need, free = RUN_BYTES_PER_BYTE * size, memory.available_memory()
    if size < LARGE_LOG_BYTES and (free is None or need < free):
        return
    room = f", more than the {free / 1e9:.1f} GB free" if free is not None and need >= free else ""
    warnings.warn(
        f"{path}: {size / 1e6:.0f} MB of records: a run of it holds about {need / 1e9:.1f} GB in "
        f"memory{room} and takes minutes; choose the records you need with samples, or thin the log "
        "(a tracker at 1 kHz gains little over 100 Hz)",
        NlpCalibWarning,
        stacklevel=4,
    )


@dataclass(frozen=True)
class TextSource:
    """A text log at ``path`` (a scenario's ``dataset: PATH``)."""

    kind: ClassVar[str] = "text"
    record_word: ClassVar[str] = "line"
    joint_units: ClassVar[str] = "counts"
    file: Path

    @property
    def path(self) -> Path:
        return self.file

    @property
    def numbered(self) -> Path:
        return self.file

    def files(self) -> tuple[Path, ...]:
        return (self.file,)

    def clock(self) -> str:
        return "the log's own time column"

    def identity(self) -> Hashable:
        return file_identity(self.file)

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        if is_bag(self.file):
            raise UsageError(
                f"{self.file}: a ROS bag; name its topics in a dataset block (bag, joint_states, joints, "
                "tracker; docs/bags.md) or convert it with nlp-calib import-bag"
            )
        return load_log(self.file, model, strict=strict)

    def moved(self, path: Path) -> TextSource:
        return TextSource(path)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return not isinstance(raw, Mapping)

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return True

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> TextSource:
        path: Path = coerce(raw, Path, where)
        return TextSource(path if path.is_absolute() else base_dir / path)
