"""A batch's jobs: which logs and scenarios, each with its own, recognisable result folder.

Inputs are folders (their logs), quoted globs, YAML lists of paths (relative to the list) or files;
a ``.yaml``/``.yml`` file is a scenario (or, holding a list, a list of inputs), anything else a
log. Each log's folder is named after its file; logs whose names would collide (two
``drive.txt`` in different folders) are told apart by as many of their parent folders as it takes
(``robot1_drive``, ``robot2_drive``).
"""

from __future__ import annotations

import glob
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from nlp_calib.core.config import read_yaml
from nlp_calib.core.errors import ConfigError, UsageError

#: Files a folder contributes: text logs and ROS 1 bags (a ROS 2 bag is a folder with this file).
LOG_SUFFIXES = (".txt", ".bag")
ROS2_METADATA = "metadata.yaml"
SCENARIO_SUFFIXES = (".yaml", ".yml")


@dataclass(frozen=True)
class BatchOptions:
    """What every job of a batch shares: the top output folder, the scenario logs are calibrated
    with (or, without one, the ``model``'s defaults), the calibration to ``check`` each log against
    instead, the ``solver``, whether to draw the ``report``, and ``force`` (replace files nlp_calib
    did not write)."""

    out: Path
    scenario: Path | None = None
    model: str | None = None
    check: Path | None = None
    solver: str | None = None
    report: bool = False
    force: bool = False


@dataclass(frozen=True)
class Job:
    """One log (or scenario) of a batch: its unique ``name`` (its folder's), its ``path`` and the
    batch's shared options. Plain and picklable: a job can be sent to any worker process."""

    name: str
    path: Path
    options: BatchOptions

    @property
    def folder(self) -> Path:
        return self.options.out / self.name

    @property
    def is_scenario(self) -> bool:
        return self.path.suffix in SCENARIO_SUFFIXES


def _in_folder(folder: Path) -> list[Path]:
    """A folder's logs: text logs, ROS 1 bags and ROS 2 bag folders, by name."""
    found = [p for p in folder.iterdir() if p.is_file() and p.suffix in LOG_SUFFIXES]
    found += [p for p in folder.iterdir() if p.is_dir() and (p / ROS2_METADATA).is_file()]
    return sorted(found)


def _listed(path: Path) -> list[str] | None:
    """The entries of a YAML list of inputs (relative to its folder); None for a scenario file."""
    try:
        doc = read_yaml(path, "batch list")
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    if not isinstance(doc, list):
        return None
    if not all(isinstance(e, str) and e for e in doc):
        raise UsageError(f"{path}: a batch list holds paths (strings), one per entry")
    return [e if Path(e).is_absolute() else str(path.parent / e) for e in doc]


def expand(inputs: Iterable[str]) -> list[Path]:
    """Every log and scenario the inputs name, each once, in the order given."""
    found: list[Path] = []
    for text in inputs:
        path = Path(text)
        if path.is_dir() and not (path / ROS2_METADATA).is_file():
            found += _in_folder(path)
        elif path.exists():
            entries = _listed(path) if path.suffix in SCENARIO_SUFFIXES else None
            found += [path] if entries is None else expand(entries)
        else:
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                raise UsageError(f"{text}: no such file or folder, and no file matches it as a pattern")
            found += [Path(m) for m in matches]
    unique = {p.resolve(): p for p in reversed(found)}
    return [unique[r] for r in dict.fromkeys(p.resolve() for p in found)]


def _plain(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).lstrip(".") or "log"


def job_names(paths: Sequence[Path]) -> list[str]:
    """A unique folder name for each path: its file's stem, with as many parent folders before it
    as it takes to tell it from the others (and its suffix, for files that differ only by it)."""
    bare = [p.resolve().with_suffix("") for p in paths]
    # Files that differ only by their suffix keep it: their other parts cannot tell them apart.
    parts = [
        list(reversed((b.parent / p.name if bare.count(b) > 1 else b).parts)) for b, p in zip(bare, paths)
    ]
    depth = [1] * len(paths)
    for _ in range(max((len(p) for p in parts), default=0)):
        names = ["_".join(reversed(p[:d])) for p, d in zip(parts, depth)]
        clash = {n for n in names if names.count(n) > 1}
        if not clash:
            break
        depth = [d + 1 if n in clash and d < len(p) else d for n, d, p in zip(names, depth, parts)]
    return [_plain("_".join(reversed(p[:d]))) for p, d in zip(parts, depth)]


def batch_jobs(inputs: Iterable[str], options: BatchOptions) -> list[Job]:
    """The jobs of a batch over ``inputs`` (folders, globs, YAML lists, files)."""
    paths = expand(inputs)
    if not paths:
        raise UsageError("the inputs name no log or scenario (a folder contributes its *.txt and *.bag)")
    return [Job(name, path, options) for name, path in zip(job_names(paths), paths)]
