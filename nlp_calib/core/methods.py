"""The methods Python writes for dataclasses, compiled once and kept for the next command.

When a class is made, ``dataclasses`` writes the source of its ``__init__``, ``__repr__``,
``__eq__``, ``__hash__`` (a frozen class's ``__setattr__`` and ``__delattr__`` too) and compiles
each with ``exec``: about 1,200 compiles for the classes a run imports, more CPU than every other
part of importing the package after numpy and CasADi. While the command runs (:func:`kept`), the
code of each source text comes from a file in the compile cache folder, written by the previous
command that compiled it; a text not found there is compiled as ``exec`` compiles it (no flags of
the caller inherited), so the classes are the ones Python makes, code object for code object.

A loaded code object runs as this user, as a compiled shared object does: the file is only read
where no other user could have written it or its folder (owned by this user or root, not writable
by group or others); it ends with a checksum of its bytes, and a file cut short, damaged or
written by another Python is not read but written again. Nothing here ever stops a command: a
folder that cannot hold the file only leaves each command compiling its own.
"""

from __future__ import annotations

import builtins
import contextlib
import dataclasses
import hashlib
import importlib.util
import marshal
import os
import sys
import tempfile
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

from nlp_calib.core.files import writable_by_others

#: Past this many kept texts (classes edited over many versions) the file keeps only one command's.
MAX_KEPT = 20_000
_SEAL = b"nlp_calib-methods sha256:"


def file_name() -> str:
    """The file's name for this interpreter: code objects are read only by the Python that wrote them."""
    tag = f"{sys.version}\0{importlib.util.MAGIC_NUMBER.hex()}\0{marshal.version}"
    return f"dataclass-methods-{hashlib.sha256(tag.encode()).hexdigest()[:16]}.marshal"


def _seal(body: bytes) -> bytes:
    return _SEAL + hashlib.sha256(file_name().encode() + b"\0" + body).hexdigest().encode()


def _trusted(path: Path) -> bool:
    """Whether ``path`` is a regular file in a folder no other user could have written."""
    try:
        st = path.lstat()
        return (
            path.is_file()
            and not path.is_symlink()
            and writable_by_others(st) is None
            and writable_by_others(path.parent.stat()) is None
        )
    except OSError:
        return False


def read(path: Path) -> dict[str, types.CodeType]:
    """The code kept at ``path`` by source text (empty: none, or not to be read)."""
    if not _trusted(path):
        return {}
    try:
        data = path.read_bytes()
    except OSError:
        return {}
    end = len(data) - len(_seal(b""))
    if end < 0 or data[end:] != _seal(data[:end]):
        return {}
    try:
        kept = marshal.loads(data[:end])
    except (EOFError, ValueError, TypeError):
        return {}
    if not isinstance(kept, dict):
        return {}
    return {k: v for k, v in kept.items() if isinstance(k, str) and isinstance(v, types.CodeType)}


def write(path: Path, kept: dict[str, types.CodeType]) -> None:
    """``kept`` into ``path``, readable by all and writable by this user only, moved into place
    whole; nothing where the folder cannot hold it or another user could write into it."""
    with contextlib.suppress(OSError):
        path.parent.mkdir(parents=True, exist_ok=True, mode=0o755)
        if writable_by_others(path.parent.stat()) is not None:
            return
        body = marshal.dumps(kept)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            os.fchmod(fd, 0o644)
            with os.fdopen(fd, "wb") as fh:
                fh.write(body + _seal(body))
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise


class _Methods:
    """``exec`` for ``dataclasses``: a source text's code from the kept file, else compiled."""

    def __init__(self, known: dict[str, types.CodeType]) -> None:
        self.known = known
        self.used: dict[str, types.CodeType] = {}
        self.compiled = 0

    def __call__(self, source: Any, globals: Any = None, locals: Any = None, /, **kw: Any) -> None:
        if isinstance(source, str):
            code = self.known.get(source)
            if code is None:
                # As ``exec`` compiles a text: the flags of dataclasses' own code (none), not ours.
                code = compile(source, "<string>", "exec", dont_inherit=True)
                self.known[source] = code
                self.compiled += 1
            self.used[source] = code
            source = code
        builtins.exec(source, globals, locals, **kw)


def kept(folder: Path) -> Callable[..., None]:
    """Make dataclasses with the methods kept in ``folder``, until the returned function is
    called; it writes the file again for the next command where texts were compiled meanwhile
    (``save=False``: not, e.g. in a command a signal ends)."""
    path = folder / file_name()
    methods = _Methods(read(path))
    dataclasses.exec = methods  # type: ignore[attr-defined]  # found before the built-in

    def done(save: bool = True) -> None:
        if getattr(dataclasses, "exec", None) is not methods:
            return  # done already
        del dataclasses.exec  # type: ignore[attr-defined]
        if save and methods.compiled:
            write(path, methods.known if len(methods.known) <= MAX_KEPT else methods.used)

    return done
