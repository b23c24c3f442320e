"""Atomic file writing and output-folder checks.

Files are written to a temporary name in the target folder and renamed into place, so an
interrupted run never leaves a half-written file.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from nlp_calib.core.errors import UsageError


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


def check_output_dir(out: str | Path) -> Path:
    """Check that ``out`` is, or can be created as, a writable folder, without creating it: a run
    that stops on bad input leaves no empty folders behind. (A probe file is created and removed
    in the nearest folder that exists.)"""
    p = Path(out)
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
