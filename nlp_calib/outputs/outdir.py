"""An output folder that never holds a half-written run, a mix of two runs' files, or a user's file
overwritten or deleted.

A run writes its files into a staging folder inside the output folder (same file system) and
:meth:`StagedOutput.commit` moves them into place only when all of them are complete, one
``os.replace`` each, with signals held back until the last one is in place. The folder's manifest
(:data:`MANIFEST_FILE`) lists the files nlp_calib wrote there, by group (``run`` for result and
hand-off files and reports, ``odometry``, ``codegen``): a commit removes the files its own group
wrote last time and did not write again (e.g. the report of an earlier ``--report`` run), and
nothing else. A file the manifest does not list is the user's: a run that would overwrite it
stops with an error naming it, unless ``force`` is given. The manifest also holds each file's
SHA-256: a file of ours that was changed since (an annotated ``report.md``, an edited
``example.c``) is the user's work, and a run that would replace or remove it stops the same way.
No output may be an input of the run (the log, the scenario, a bag or a file in a bag's folder,
also through a link), not even with ``force``; names starting ``.nlp_calib_`` are the tool's own
and refused as outputs; the clean-up never follows a symbolic link.

While a run stages its files it holds a lock on the output folder (``flock`` on the folder
itself, released by the kernel however the process ends), so two runs into one folder take
turns, and any staging folder found while holding the lock belongs to a run that was killed
(SIGKILL, power loss) and is removed. Without ``flock`` (not POSIX) stale folders are left alone.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import tempfile
import time
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path
from types import TracebackType

from nlp_calib.core import interrupts
from nlp_calib.core.errors import NlpCalibError, NlpCalibWarning, UsageError
from nlp_calib.core.files import (
    RESERVED_PREFIX,
    aliased_input,
    atomic_write_text,
    check_output_dir,
    kind_of,
    refuse_input_alias,
    reserved_part,
)

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None  # type: ignore[assignment]

#: The list of files nlp_calib wrote into the folder.
MANIFEST_FILE = ".nlp_calib_manifest.json"
_STAGING_PREFIX = f"{RESERVED_PREFIX}staging."
#: How long a run waits for another run that is writing into the same folder.
LOCK_WAIT_S = 120.0


def _plain_path(name: object) -> bool:
    if not isinstance(name, str):
        return False
    parts = name.split("/")
    return 1 <= len(parts) <= 2 and all(p and Path(p).name == p and p not in (".", "..") for p in parts)


def _plain(names: object) -> list[str]:
    # Plain names, or a plain name inside a plain-named subfolder: a manifest must not point the
    # clean-up outside the folder.
    return [f for f in names if _plain_path(f)] if isinstance(names, list) else []


def _manifest(out_dir: Path) -> dict[str, object]:
    try:
        doc = json.loads((Path(out_dir) / MANIFEST_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def manifest_groups(out_dir: Path) -> dict[str, list[str]]:
    """The files the folder's manifest lists, by group; an unreadable or foreign manifest lists
    nothing (a manifest without groups, from an earlier version, is the ``run`` group's)."""
    doc = _manifest(out_dir)
    groups = doc.get("groups")
    if isinstance(groups, dict):
        return {str(g): _plain(files) for g, files in groups.items()}
    return {"run": _plain(doc.get("files"))} if doc else {}


def manifest_digests(out_dir: Path) -> dict[str, str]:
    """The SHA-256 of each file as nlp_calib wrote it (none from an earlier version's manifest)."""
    digests = _manifest(out_dir).get("sha256")
    if not isinstance(digests, dict):
        return {}
    return {k: v for k, v in digests.items() if _plain_path(k) and isinstance(v, str)}


def digest(path: Path) -> str | None:
    """The SHA-256 of a regular file (None for a link, a folder or a file that cannot be read)."""
    try:
        if path.is_symlink() or not path.is_file():
            return None
        h = hashlib.sha256()
        with path.open("rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        return h.hexdigest()
    except OSError:
        return None


def previous_files(out_dir: Path) -> list[str]:
    """Every name the folder's manifest lists (files nlp_calib wrote there)."""
    return sorted({f for files in manifest_groups(out_dir).values() for f in files})


def _edited(out_dir: Path, name: str, digests: Mapping[str, str]) -> bool:
    """Whether our file ``name`` was changed since it was written (by the digest the manifest holds)."""
    target = Path(out_dir) / name
    recorded = digests.get(name)
    return recorded is not None and (target.exists() or target.is_symlink()) and digest(target) != recorded


def _edited_error(target: Path) -> UsageError:
    return UsageError(
        f"{target} was changed since nlp_calib wrote it (an annotated or edited copy); move it away "
        "to keep it, or pass --force to let the run replace or remove it"
    )


def _check_name(out_dir: Path, name: str) -> Path:
    """``out_dir / name``, after the checks no ``force`` lifts: not a name of the tool's own, not an
    input of the run, not inside a link or a file."""
    target = Path(out_dir) / name
    if (part := reserved_part(name)) is not None:
        raise UsageError(
            f"{target}: {part!r} is named like nlp_calib's own staging files ({RESERVED_PREFIX}*), "
            "which runs remove; rename the log or scenario it is named after"
        )
    refuse_input_alias(target)
    if target.parent != Path(out_dir) and (target.parent.is_symlink() or target.parent.is_file()):
        raise UsageError(f"{target.parent} is not a folder; move it away or choose another --out")
    if target.is_dir() and not target.is_symlink():
        raise UsageError(f"{target} is a folder; move it away or choose another --out")
    if target.exists() and not target.is_file():  # e.g. /dev/null: never replaced, even forced
        raise UsageError(
            f"{target} is {kind_of(target.stat().st_mode)}, not a regular file; nlp_calib replaces only "
            "regular files, even with --force: choose another path"
        )
    return target


def _link_error(target: Path) -> UsageError:
    return UsageError(
        f"{target} is a symbolic link; nlp_calib never replaces one, even with --force (it would "
        "replace the link, not write where it points): remove it or choose another path"
    )


def refuse_collisions(
    out_dir: Path, names: Iterable[str], *, tracked: bool = True, force: bool = False
) -> None:
    """Raise :class:`UsageError` if writing ``names`` into ``out_dir`` would replace something that
    is not nlp_calib's: an input of the run, a folder, or (unless ``force``) a file the manifest
    does not list or one changed since it was written (with ``tracked=False`` every existing file
    counts as the user's)."""
    ours = set(previous_files(out_dir)) if tracked else set()
    digests = manifest_digests(out_dir) if tracked else {}
    for name in names:
        target = _check_name(out_dir, name)
        if target.is_symlink() and (force or name not in ours):
            raise _link_error(target)
        if force or not (target.exists() or target.is_symlink()):
            continue
        if name not in ours:
            raise UsageError(
                f"{target} exists and was not written by nlp_calib; move it away, choose another "
                "--out, or pass --force to overwrite it"
            )
        if _edited(out_dir, name, digests):
            raise _edited_error(target)


def write_file(path: Path, text: str, *, force: bool = False) -> Path:
    """Write one file at ``path`` (``--json``, ``init --out``): never over an input of the run, a
    folder, a link, a device or a FIFO; over an existing regular file only with ``force`` (a lone
    file has no manifest to say that nlp_calib wrote it)."""
    path = Path(path)
    folder = check_output_dir(path.parent)
    refuse_collisions(folder, [path.name], tracked=False, force=force)
    atomic_write_text(path, text)
    return path


class _FolderLock:
    """An exclusive ``flock`` on a folder, waited for at most :data:`LOCK_WAIT_S`."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.fd: int | None = None

    def acquire(self) -> bool:
        """Take the lock; False where the platform has no ``flock``."""
        if fcntl is None:
            return False
        fd = os.open(self.folder, os.O_RDONLY)
        try:
            deadline = time.monotonic() + LOCK_WAIT_S
            warned = False
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if time.monotonic() > deadline:
                        raise NlpCalibError(
                            f"another nlp-calib run has been writing into {self.folder} for over "
                            f"{LOCK_WAIT_S:g} s; try again when it has finished, or choose another --out"
                        ) from None
                    if not warned:
                        warnings.warn(
                            f"waiting for another nlp-calib run that is writing into {self.folder}",
                            NlpCalibWarning,
                            stacklevel=3,
                        )
                        warned = True
                    time.sleep(0.05)
        except BaseException:
            os.close(fd)
            raise
        self.fd = fd
        return True

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)  # closing the descriptor releases the lock
            self.fd = None


def _remove_stale(out_dir: Path) -> None:
    """Staging folders and temporary manifests of runs that died (called holding the lock)."""
    for entry in out_dir.iterdir():
        if entry.name.startswith(_STAGING_PREFIX) and entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        elif entry.name.startswith(f".{MANIFEST_FILE}.") and entry.name.endswith(".tmp") and entry.is_file():
            entry.unlink(missing_ok=True)


class StagedOutput:
    """Write into :attr:`path`, then :meth:`commit`; leaving the ``with`` block discards the rest.

    ``group`` names the files' owner in the manifest (None: no manifest, e.g. a simulated log
    written into the user's own data folder, where every existing file is the user's); ``force``
    allows replacing files nlp_calib did not write.
    """

    def __init__(self, out_dir: Path, group: str | None = "run", *, force: bool = False) -> None:
        self.out_dir = Path(out_dir)
        self.group = group
        self.force = force
        self._lock = _FolderLock(self.out_dir)
        self._path: Path | None = None
        #: The SHA-256 of each file the manifest will list (set by :meth:`commit`).
        self._digests: dict[str, str] = {}

    @property
    def path(self) -> Path:
        """The staging folder (inside the ``with`` block)."""
        if self._path is None:
            raise RuntimeError("StagedOutput.path is only available inside its with block")
        return self._path

    def __enter__(self) -> StagedOutput:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        if self._lock.acquire():
            _remove_stale(self.out_dir)
        try:
            with interrupts.deferred():  # a signal between mkdir and here must not orphan the folder
                self._path = Path(tempfile.mkdtemp(prefix=_STAGING_PREFIX, dir=self.out_dir))
        except BaseException:
            self.discard()
            self._lock.release()
            raise
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        try:
            self.discard()
        finally:
            self._lock.release()

    def discard(self) -> None:
        """Remove the staging folder and whatever is still in it."""
        if self._path is not None:
            shutil.rmtree(self._path, ignore_errors=True)

    def final(self, staged: Path) -> Path:
        """Where a file written into the staging folder ends up."""
        return self.out_dir / Path(staged).relative_to(self.path)

    def _staged_names(self) -> list[str]:
        """Files in the staging folder and in its subfolders (one level), as relative names."""
        top = list(self.path.iterdir())
        files = [*top, *(q for d in top if d.is_dir() and not d.is_symlink() for q in d.iterdir())]
        return sorted(str(p.relative_to(self.path)) for p in files if p.is_file() and p.name != MANIFEST_FILE)

    def _write_manifest(self, groups: Mapping[str, list[str]]) -> None:
        files = sorted({f for names in groups.values() for f in names})
        digests = self._digests
        doc = {
            "tool": "nlp_calib",
            "files": files,
            "groups": {g: sorted(n) for g, n in groups.items()},
            "sha256": {f: digests[f] for f in files if f in digests},
        }
        atomic_write_text(self.out_dir / MANIFEST_FILE, json.dumps(doc, indent=2) + "\n")

    def _stale(
        self, names: list[str], groups: Mapping[str, list[str]], digests: Mapping[str, str]
    ) -> list[str]:
        """The files this group wrote last time and not now, that the clean-up removes: never one
        reached through a symbolic link, nor an input of the run (both are left, and no longer
        claimed); a changed one stops the run (unless ``force``)."""
        others = {f for g, files in groups.items() if g != self.group for f in files}
        stale = []
        for name in sorted(set(groups.get(str(self.group), [])) - set(names) - others - {MANIFEST_FILE}):
            parent = (self.out_dir / name).parent
            if parent != self.out_dir and (parent.is_symlink() or not parent.is_dir()):
                continue  # the user put a link (or a file) where our subfolder was: not ours to follow
            if aliased_input(self.out_dir / name) is not None or (self.out_dir / name).is_symlink():
                continue  # an input, or a link put where our file was: left, no longer claimed
            if not self.force and _edited(self.out_dir, name, digests):
                raise _edited_error(self.out_dir / name)
            stale.append(name)
        return stale

    def commit(self) -> list[Path]:
        """Move every staged file into the output folder, remove the files this group wrote last
        time and not now, and update the manifest; returns the final paths (in name order)."""
        with interrupts.deferred():
            interrupts.check()  # a signal some native code swallowed: keep the previous files
            names = self._staged_names()
            refuse_collisions(self.out_dir, names, tracked=self.group is not None, force=self.force)
            stale: list[str] = []
            if self.group is not None:
                groups = manifest_groups(self.out_dir)
                digests = manifest_digests(self.out_dir)
                stale = self._stale(names, groups, digests)
                digests.update({n: d for n in names if (d := digest(self.path / n)) is not None})
                self._digests = digests
                # Listed before they are moved (and the stale ones until they are gone): a run killed
                # half-way never leaves a file of ours that the manifest does not claim.
                self._write_manifest({**groups, self.group: sorted({*names, *stale})})
            for name in names:
                (self.out_dir / name).parent.mkdir(exist_ok=True)
                (self.path / name).replace(self.out_dir / name)
            for name in stale:
                old = self.out_dir / name
                if old.is_symlink() or old.is_file():  # never a folder someone put there
                    old.unlink(missing_ok=True)
                    if "/" in name and old.parent.is_dir() and not any(old.parent.iterdir()):
                        old.parent.rmdir()
            if self.group is not None:
                with contextlib.suppress(OSError):  # the claim above stays true enough if this fails
                    self._write_manifest({**manifest_groups(self.out_dir), self.group: names})
        self.discard()
        return [self.out_dir / name for name in names]
