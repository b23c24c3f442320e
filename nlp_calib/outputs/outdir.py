"""An output folder that never holds a half-written run or a mix of two runs' files.

A run writes its files into a staging folder inside the output folder (same file system) and
:meth:`StagedOutput.commit` moves them into place only when all of them are complete, one
``os.replace`` each. The folder's manifest (:data:`MANIFEST_FILE`) lists the files the last run
wrote (plain names, or names inside one subfolder); on commit, files of the previous run that
this run did not write are removed — only files the manifest lists (the tool never deletes what
it did not create), plus the names the caller owns outright (the hand-off files, which a robot
stack must never pick up stale).
An interrupted or failed run leaves the previous run's files untouched and no temporary files.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType

from nlp_calib.core.files import atomic_write_text

#: The list of files the last run wrote into the folder.
MANIFEST_FILE = ".nlp_calib_manifest.json"
_STAGING_PREFIX = ".nlp_calib_staging."


def previous_files(out_dir: Path) -> list[str]:
    """Names the folder's manifest lists; an unreadable or foreign manifest lists nothing."""
    try:
        doc = json.loads((out_dir / MANIFEST_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    files = doc.get("files") if isinstance(doc, dict) else None
    if not isinstance(files, list):
        return []
    # Plain names, or a plain name inside a plain-named subfolder: a manifest must not point the
    # clean-up outside the folder.
    return [f for f in files if isinstance(f, str) and _plain_path(f)]


def _plain_path(name: str) -> bool:
    parts = name.split("/")
    return 1 <= len(parts) <= 2 and all(p and Path(p).name == p and p not in (".", "..") for p in parts)


class StagedOutput:
    """Write into :attr:`path`, then :meth:`commit`; leaving the ``with`` block discards the rest."""

    def __init__(self, out_dir: Path, owned: Iterable[str] = ()) -> None:
        self.out_dir = Path(out_dir)
        self.owned = tuple(owned)
        self.path = Path(tempfile.mkdtemp(prefix=_STAGING_PREFIX, dir=self.out_dir))

    def __enter__(self) -> StagedOutput:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.discard()

    def discard(self) -> None:
        """Remove the staging folder and whatever is still in it."""
        shutil.rmtree(self.path, ignore_errors=True)

    def final(self, staged: Path) -> Path:
        """Where a file written into the staging folder ends up."""
        return self.out_dir / Path(staged).relative_to(self.path)

    def commit(self) -> list[Path]:
        """Move every staged file into the output folder, remove the previous run's leftovers and
        write the manifest; returns the final paths (in name order)."""
        names = sorted(
            str(p.relative_to(self.path))
            for p in [
                *self.path.iterdir(),
                *(q for d in self.path.iterdir() if d.is_dir() for q in d.iterdir()),
            ]
            if p.is_file()
        )
        stale = (set(previous_files(self.out_dir)) | set(self.owned)) - set(names) - {MANIFEST_FILE}
        for name in names:
            (self.out_dir / name).parent.mkdir(exist_ok=True)
            (self.path / name).replace(self.out_dir / name)
        for name in sorted(stale):
            old = self.out_dir / name
            if old.is_symlink() or old.is_file():  # never a folder someone put there
                old.unlink(missing_ok=True)
                if "/" in name and old.parent.is_dir() and not any(old.parent.iterdir()):
                    old.parent.rmdir()
        manifest = {"tool": "nlp_calib", "files": names}
        atomic_write_text(self.out_dir / MANIFEST_FILE, json.dumps(manifest, indent=2) + "\n")
        self.discard()
        return [self.out_dir / name for name in names]
