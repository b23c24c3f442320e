"""A batch's jobs: which logs and scenarios, each with its own, recognisable result folder.

Inputs are folders (their logs), quoted globs, YAML lists of paths (relative to the list) or files;
a ``.yaml``/``.yml`` file is a scenario (or, holding a list, a list of inputs), anything else a
log. A pattern's matches are read as the inputs they are (a folder gives its logs); what nlp_calib
wrote (anything inside the batch's output folder or another run's, which holds its manifest) and,
among a pattern's matches, files that are neither logs nor scenarios are left out with one warning
each. A list that names itself, directly or through another list, is refused.

Each log's folder is named after its file, in plain characters (``a b.txt`` and ``a_b.txt`` both
read ``a_b``); logs whose folder names would collide, as written or on a file system that ignores
case (two ``drive.txt`` in different folders, ``a b`` and ``a_b``, ``ä`` and ``ö``, ``..x`` and
``x``) are told apart by as many of their parent folders as it takes (``robot1_drive``,
``robot2_drive``), and then by a number (``a_b``, ``a_b-2``); no folder takes the name of the
summary's files.
"""

from __future__ import annotations

import glob
import re
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from nlp_calib.core.config import read_yaml
from nlp_calib.core.errors import ConfigError, NlpCalibWarning, UsageError
from nlp_calib.outputs.batch import SUMMARY_FILES
from nlp_calib.outputs.outdir import MANIFEST_FILE

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


def _listed(path: Path, lists: tuple[Path, ...]) -> list[str] | None:
    """The entries of a YAML list of inputs (relative to its folder); None for a scenario file.
    ``lists``: the lists that named this one (a list among them names itself)."""
    try:
        doc = read_yaml(path, "batch list")
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    if not isinstance(doc, list):
        return None
    if not all(isinstance(e, str) and e for e in doc):
        raise UsageError(f"{path}: a batch list holds paths (strings), one per entry")
    entries = [e if Path(e).is_absolute() else str(path.parent / e) for e in doc]
    for k, entry in enumerate(entries):
        if Path(entry).exists() and Path(entry).resolve() in {*lists, path.resolve()}:
            named = "itself" if Path(entry).resolve() == path.resolve() else f"the list {entry} that names it"
            raise UsageError(
                f"{path}: entry {k + 1} ({doc[k]}) names {named}; a batch list names logs, scenarios, "
                "folders or other lists, never one that leads back to it"
            )
    return entries


def _written_by_us(path: Path, out: Path | None) -> bool:
    """Whether ``path`` lies inside the batch's output folder or another folder nlp_calib wrote."""
    resolved = path.resolve()
    if out is not None and resolved.is_relative_to(out.resolve()):
        return True
    return any((folder / MANIFEST_FILE).is_file() for folder in (resolved, *resolved.parents))


def _is_input(path: Path) -> bool:
    """What a pattern may match: a log, a scenario (or list), a bag or a folder of logs."""
    return path.is_dir() or path.suffix in (*LOG_SUFFIXES, *SCENARIO_SUFFIXES)


def expand(inputs: Iterable[str], out: Path | None = None, lists: tuple[Path, ...] = ()) -> list[Path]:
    """Every log and scenario the inputs name, each once, in the order given; nothing inside
    ``out`` (the batch's output folder) or another folder nlp_calib wrote."""
    found: list[Path] = []
    left_out: dict[str, list[str]] = {"written by nlp_calib": [], "neither logs nor scenarios": []}
    for text in inputs:
        path = Path(text)
        if path.exists() and _written_by_us(path, out):
            left_out["written by nlp_calib"].append(text)
        elif path.is_dir() and not (path / ROS2_METADATA).is_file():
            found += [p for p in _in_folder(path) if not _written_by_us(p, out)]
        elif path.exists():
            entries = _listed(path, lists) if path.suffix in SCENARIO_SUFFIXES else None
            found += [path] if entries is None else expand(entries, out, (*lists, path.resolve()))
        else:
            matches = [Path(m) for m in sorted(glob.glob(text, recursive=True))]
            if not matches:
                raise UsageError(f"{text}: no such file or folder, and no file matches it as a pattern")
            ours = [m for m in matches if _written_by_us(m, out)]
            other = [m for m in matches if m not in ours and not _is_input(m)]
            left_out["written by nlp_calib"] += map(str, ours)
            left_out["neither logs nor scenarios"] += map(str, other)
            found += expand([str(m) for m in matches if m not in ours and m not in other], out, lists)
    _warn_left_out(left_out)
    unique = {p.resolve(): p for p in reversed(found)}
    return [unique[r] for r in dict.fromkeys(p.resolve() for p in found)]


def _warn_left_out(left_out: dict[str, list[str]]) -> None:
    for why, paths in left_out.items():
        if paths:
            shown = ", ".join(paths[:5]) + (f" and {len(paths) - 5} more" if len(paths) > 5 else "")
            warnings.warn(f"left out {len(paths)} input(s) {why}: {shown}", NlpCalibWarning, stacklevel=3)


def _plain(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).lstrip(".") or "log"


def job_names(paths: Sequence[Path]) -> list[str]:
    """A unique folder name for each path: its file's stem, with as many parent folders before it
    as it takes to tell it from the others (and its suffix, for files that differ only by it), in
    plain characters; a name that still collides (whatever the case) or is a summary file's takes
    a number."""
    bare = [p.resolve().with_suffix("") for p in paths]
    # Files that differ only by their suffix keep it: their other parts cannot tell them apart.
    parts = [
        list(reversed((b.parent / p.name if bare.count(b) > 1 else b).parts)) for b, p in zip(bare, paths)
    ]
    depth = [1] * len(paths)
    for _ in range(max((len(p) for p in parts), default=0)):
        keys = ["/".join(reversed(p[:d])) for p, d in zip(parts, depth)]
        clash = {k for k in keys if keys.count(k) > 1}
        if not clash:
            break
        depth = [d + 1 if k in clash and d < len(p) else d for k, d, p in zip(keys, depth, parts)]
    taken = {n.lower() for n in SUMMARY_FILES}
    out = []
    for p, d in zip(parts, depth):
        base = candidate = _plain("_".join(reversed(p[:d])))
        k = 1
        while candidate.lower() in taken:
            k += 1
            candidate = f"{base}-{k}"
        taken.add(candidate.lower())
        out.append(candidate)
    return out


def batch_jobs(inputs: Iterable[str], options: BatchOptions) -> list[Job]:
    """The jobs of a batch over ``inputs`` (folders, globs, YAML lists, files)."""
    paths = expand(inputs, options.out)
    if not paths:
        raise UsageError("the inputs name no log or scenario (a folder contributes its *.txt and *.bag)")
    return [Job(name, path, options) for name, path in zip(job_names(paths), paths)]
