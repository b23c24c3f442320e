"""Atomic file writing, inputs opened by kind, and output-folder checks.

Files are written to a temporary name in the target folder and renamed into place, so an
interrupted run never leaves a half-written file. Inputs are opened only when they are regular
files (a FIFO, a socket or a device is refused before it can block), and each input a run reads
is noted (by device and inode, so also through links), so that no output can replace one.
"""

from __future__ import annotations

import contextlib
import os
import stat
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from nlp_calib.core.errors import UsageError

#: Names beginning so are the tool's own in an output folder (staging folders, the manifest): a
#: user's file or folder named so would be taken for one of them.
RESERVED_PREFIX = ".nlp_calib_"

#: The inputs read so far: (device, inode) -> the path it was read under.
_inputs: dict[tuple[int, int], Path] = {}


def kind_of(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words ("a regular file", "a FIFO", ...)."""
    if stat.S_ISREG(mode):
        return "a regular file"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a device"


class SpecialFileError(OSError):
    """An input that is not a regular file (:attr:`kind` says what it is)."""

    def __init__(self, path: Path, kind: str) -> None:
        super().__init__(f"{path} is {kind}, not a regular file")
        self.kind = kind


def open_regular(path: Path) -> BinaryIO:
    """``path`` opened for reading in binary, and noted as an input; anything but a regular file
    raises :class:`SpecialFileError` without blocking (a FIFO is opened non-blocking, then
    checked)."""
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except UnicodeEncodeError:
        raise OSError(unencodable(path)) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise SpecialFileError(path, kind_of(st.st_mode))
        os.set_blocking(fd, True)
        _inputs[(st.st_dev, st.st_ino)] = Path(os.path.abspath(path))
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def unencodable(path: Path | str) -> str:
    """Why a path whose name the file system's encoding cannot write cannot be opened, and the fix."""
    encoding = sys.getfilesystemencoding()
    locale = os.environ.get("LC_ALL") or os.environ.get("LC_CTYPE") or os.environ.get("LANG") or "unset"
    return (
        f"its name holds characters the file system encoding ({encoding}, from the locale {locale}) cannot "
        "write; run with a UTF-8 locale (LC_ALL=C.UTF-8) or PYTHONUTF8=1, or rename it in ASCII"
    )


def forget_inputs() -> None:
    """Start a new run: the inputs noted so far are no longer this run's."""
    _inputs.clear()


def identity(path: Path) -> tuple[int, int]:
    """``(device, inode)`` of what ``path`` names, through links: one key for every name of a file
    (a hard link, a symbolic link, ``..``), where its path would give several."""
    st = os.stat(path)
    return st.st_dev, st.st_ino


def note_input(path: Path) -> None:
    """Note ``path`` (a file or a folder, e.g. a bag's) as an input of this run."""
    _inputs[identity(path)] = Path(os.path.abspath(path))


def _noted(st: os.stat_result) -> Path | None:
    """The input noted under ``st``'s inode, if its path still names that inode (a file read and
    since deleted may have its inode reused)."""
    path = _inputs.get((st.st_dev, st.st_ino))
    if path is None:
        return None
    try:
        now = os.stat(path)
    except OSError:
        return None
    return path if (now.st_dev, now.st_ino) == (st.st_dev, st.st_ino) else None


def aliased_input(target: Path) -> Path | None:
    """The input that writing ``target`` would replace or write into: the same file (by inode,
    so also through a symbolic or hard link), or a folder noted as an input (a ROS 2 bag) that
    holds it; None when it touches no input."""
    for look in (os.lstat, os.stat):
        try:
            found = _noted(look(target))
        except (OSError, ValueError):
            continue
        if found is not None:
            return found
    folder = Path(os.path.realpath(Path(target).parent))
    for parent in (folder, *folder.parents):
        try:
            st = os.stat(parent)
        except (OSError, ValueError):
            continue
        found = _noted(st)
        if found is not None and stat.S_ISDIR(st.st_mode):
            return found
    return None


def refuse_input_alias(target: Path) -> None:
    """Raise :class:`UsageError` if writing ``target`` would replace an input or write into one."""
    found = aliased_input(target)
    if found is None:
        return
    if stat.S_ISDIR(os.stat(found).st_mode):
        how = f"is inside {found}, a folder this run reads (a bag's)"
    elif found == Path(os.path.abspath(target)):
        how = "is an input of this run"
    else:
        how = f"is another name of {found}, an input of this run"
    raise UsageError(f"{target} {how}; choose an output path that is none of the run's inputs")


def reserved_part(path: str | Path) -> str | None:
    """The first part of ``path`` that is named like the tool's own files (:data:`RESERVED_PREFIX`)."""
    return next((p for p in Path(path).parts if p.startswith(RESERVED_PREFIX)), None)


def cache_dir() -> Path:
    """Where compiled code is kept: ``$NLP_CALIB_CACHE`` or the user cache folder."""
    env = os.environ.get("NLP_CALIB_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "nlp_calib"


def writable_by_others(st: os.stat_result) -> str | None:
    """Why another user could change what ``st`` describes (None: only its owner, this user or
    root, can)."""
    if st.st_uid not in (os.getuid(), 0):
        return f"owned by user id {st.st_uid}, not by you"
    who = [w for w, bit in (("its group", stat.S_IWGRP), ("others", stat.S_IWOTH)) if st.st_mode & bit]
    return f"writable by {' and '.join(who)} (mode {stat.S_IMODE(st.st_mode):04o})" if who else None


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_writer(path: Path) -> Iterator[BinaryIO]:
    """A binary file to write ``path`` through, piece by piece: it is written under a temporary
    name and moved into place by ``os.replace`` when the block ends without an exception."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; give the file normal permissions
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: Path, payload: bytes) -> None:
    """Write ``payload`` to ``path`` via a temporary file and ``os.replace``."""
    with atomic_writer(path) as fh:
        fh.write(payload)


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def truth_path(log_path: Path) -> Path:
    """Where the truth JSON of a simulated log lives: beside it, ``<name>.truth.json`` (here, not
    with the simulator: a run reads it without loading the simulator)."""
    return log_path.with_suffix(".truth.json")


def check_output_dir(out: str | Path) -> Path:
    """Check that ``out`` is, or can be created as, a writable folder, without creating it: a run
    that stops on bad input leaves no empty folders behind. (A probe file is created and removed
    in the nearest folder that exists.)"""
    p = Path(out)
    if (part := reserved_part(p)) is not None:
        raise UsageError(
            f"cannot write to the output folder {p}: {part!r} is named like nlp_calib's own staging "
            f"files ({RESERVED_PREFIX}*), which runs remove; choose another --out"
        )
    existing = p
    while not (existing.exists() or existing.is_symlink()) and existing.parent != existing:
        existing = existing.parent
    try:
        if not existing.is_dir():
            raise NotADirectoryError(20, "not a folder", str(existing))
        with tempfile.NamedTemporaryFile(dir=existing, prefix=".probe."):
            pass
    except OSError as exc:
        where = f"{existing}: " if existing != p else ""
        raise UsageError(
            f"cannot write to the output folder {p} ({where}{exc.strerror or exc}); choose another --out"
        ) from None
    return p
