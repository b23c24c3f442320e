"""Compiling CasADi Functions into shared objects with the system C compiler, cached by content.

A shared object is cached under a hash of the generated source, the compiler, its flags and
CasADi's version: repeated runs, other data sets and other processes reuse it. Every entry ends
with a checksum of its own bytes and of its key, appended when it was compiled (the loader
ignores what follows an ELF file), and is checked before it is loaded: mapping a cut-short
shared object can kill the process with SIGBUS, and a swapped one would load the wrong code. A
damaged entry (a full disk, an interrupted copy, a cache shared over NFS, another entry's file)
is compiled again, with one warning that names the folder. Compiles write into a private
temporary folder and rename the finished, sealed file into place, so concurrent processes never
see half of one, and two processes compiling the same entry each leave a complete one.

The compiler itself is tried once per process on a tiny file before the first real compile
(:func:`check_compiler`): a ``$CC`` that hangs, fails or writes something that cannot be loaded
is found in seconds, and the caller falls back to CasADi's interpreter.

Loading a shared object runs its code, and the checksum is no seal against a person (anyone can
compute it). So, as ssh treats its keys, a cache folder that another user could write into (not
owned by this user or root, or writable by group or others) is not used: the process compiles
into a private temporary folder instead, with one warning saying how to fix the folder; and an
entry that another user could have written (a link, not owned by this user or root, or writable by
group or others) is never loaded but compiled again, with the damaged-entry warning. Entries and
the folders created here are written readable by all, writable by their owner only, whatever the
umask.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import hashlib
import os
import shutil
import signal
import stat
import tempfile
import threading
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import casadi as ca

from nlp_calib.core.errors import CodegenError, NlpCalibWarning, OptionsError, shown_path
from nlp_calib.core.files import cache_dir, writable_by_others

if TYPE_CHECKING:
    import subprocess

#: Optimisation flags for the generated code; -fno-math-errno lets sin/cos/sqrt inline.
CFLAGS = ("-O3", "-march=native", "-fno-math-errno", "-fPIC", "-shared", "-Wno-int-conversion")
#: Functions evaluated once per run (residual terms for the uncertainty and the reports) and
#: very large ones (a long horizon's exact Hessian) compile about twice as fast at -O1, for a
#: small loss at run time; the solvers' inner loops get -O3.
CFLAGS_COLD = ("-O1", "-fno-math-errno", "-fPIC", "-shared", "-Wno-int-conversion")
HOT_FUNCTIONS = frozenset({"normal_equations", "cost", "prefix_step", "prefix_value_step"})
LARGE_FUNCTION = 20_000  # instructions

#: Seconds a compiler gets for the tiny test file (a working one needs a fraction of a second).
PROBE_TIMEOUT_S = 3.0
#: Seconds a real compile gets: this much, plus :data:`COMPILE_S_PER_KB` per kB of source.
COMPILE_TIMEOUT_S = 60.0
COMPILE_S_PER_KB = 0.05
#: Part of every key: entries written in another layout are never read.
_ENTRY_FORMAT = "sealed-1"
_SEAL = b"\n#nlp_calib-cache-entry sha256:"
_SEAL_LEN = len(_SEAL) + 64 + 1
_PROBE = "int nlp_calib_probe(void) { return 42; }\n"

_lock = threading.Lock()
_probe_lock = threading.Lock()
_probed: dict[str, str | None] = {}
_warned_folders: set[Path] = set()
#: The folder each configured cache folder is used as (itself, or a private temporary folder when
#: another user could write into it).
_in_use: dict[Path, Path] = {}
_running: set[subprocess.Popen[str]] = set()


def compiler_flags(f: ca.Function) -> tuple[str, ...]:
    """-O3 for the solvers' inner loops, -O1 for the rest and for very large functions."""
    return CFLAGS if f.name() in HOT_FUNCTIONS and f.n_instructions() <= LARGE_FUNCTION else CFLAGS_COLD


def find_compiler() -> str | None:
    """The C compiler to use: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH."""
    candidates = [os.environ.get("CC"), "cc", "gcc", "clang"]
    for cc in candidates:
        if cc and shutil.which(cc):
            return shutil.which(cc)
    return None


def usable_cache_dir() -> Path:
    """The folder compiled code is kept in: :func:`cache_dir`, created if needed, or a private
    temporary folder (with one warning) when another user could write into it; an error naming it
    when it cannot hold files."""
    folder = cache_dir()
    with _lock:
        if folder in _in_use:
            return _in_use[folder]
    try:
        folder.mkdir(parents=True, exist_ok=True, mode=0o755)
        if not os.access(folder, os.W_OK | os.X_OK):
            raise PermissionError("not writable")
        unsafe = writable_by_others(folder.stat())
    except (OSError, ValueError) as exc:
        in_the_way = isinstance(exc, FileExistsError | NotADirectoryError)
        reason = "a file is in the way" if in_the_way else getattr(exc, "strerror", None) or str(exc)
        raise OptionsError(
            f"the compile cache {shown_path(folder)} is not a writable folder ({reason}); set "
            "NLP_CALIB_CACHE to a writable folder, or use the interpreted backend ('backend: interpreted')"
        ) from None
    used = folder if unsafe is None else _private_folder(folder, unsafe)
    with _lock:
        used = _in_use.setdefault(folder, used)
    if used == folder:
        _remove_leftovers(folder)
    return used


def _private_folder(folder: Path, reason: str) -> Path:
    """A temporary folder only this user can write, removed at exit, in place of ``folder``."""
    private = Path(tempfile.mkdtemp(prefix="nlp_calib-cache-"))
    atexit.register(shutil.rmtree, private, ignore_errors=True)
    warnings.warn(
        f"the compile cache {shown_path(folder)} is {reason}: a compiled file another user put there would "
        "run as you, so it is not used (compiling into a private temporary folder, slower). Give "
        "NLP_CALIB_CACHE a folder only you can write (chmod go-w FOLDER; docs/fleet.md, a shared cache)",
        NlpCalibWarning,
        stacklevel=4,
    )
    return private


def _remove_leftovers(folder: Path) -> None:
    """Remove the temporary folders of compiles that a killed process left behind (an hour old:
    a live compile takes seconds)."""
    cutoff = time.time() - 3600
    for tmp in [*folder.glob(".build-*"), *folder.glob(".probe-*")]:
        with contextlib.suppress(OSError):
            if tmp.is_dir() and not tmp.is_symlink() and tmp.stat().st_mtime < cutoff:
                shutil.rmtree(tmp, ignore_errors=True)


def entry_key(source: str, compiler: str, flags: Sequence[str]) -> str:
    """The cache key of ``source`` compiled by ``compiler`` with ``flags``."""
    text = "\n".join([source, compiler, *flags, ca.__version__, _ENTRY_FORMAT])
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _seal(key: str, body: bytes) -> bytes:
    return _SEAL + hashlib.sha256(key.encode() + b"\0" + body).hexdigest().encode() + b"\n"


def entry_problem(path: Path, key: str) -> str | None:
    """Why the cache entry at ``path`` cannot be loaded (None: it is whole and is the entry of
    ``key``; a missing file is ``"missing"``). Read, never mapped: nothing here can SIGBUS."""
    try:
        st = path.lstat()
        if not stat.S_ISREG(st.st_mode):
            return "not a regular file"
        if (unsafe := writable_by_others(st)) is not None:
            return f"{unsafe}: never loaded"
        data = path.read_bytes()
    except FileNotFoundError:
        return "missing"
    except OSError as exc:
        return f"unreadable: {exc.strerror or exc}"
    if not data:
        return "empty"
    if len(data) < _SEAL_LEN or not data[-_SEAL_LEN:].startswith(_SEAL):
        return f"cut short or not written by nlp_calib ({len(data)} bytes, no checksum at its end)"
    body = data[:-_SEAL_LEN]
    if data[-_SEAL_LEN:] != _seal(key, body):
        return "its checksum does not match (damaged, or the file of another entry)"
    return None


def compile_shared(
    source: str, name: str, compiler: str, flags: Sequence[str] = CFLAGS, *, rebuild: bool = False
) -> Path:
    """Compile C ``source`` into a cached shared object; returns its path. A whole entry is reused
    (unless ``rebuild``: it was whole but did not load); a damaged one is compiled again."""
    key = entry_key(source, compiler, flags)
    folder = usable_cache_dir()
    target = folder / f"{name}-{key}.so"
    problem = "it did not load" if rebuild else entry_problem(target, key)
    if problem is None:
        return target
    if problem != "missing":
        _warn_damaged(folder, target.name, problem)
    check_compiler(compiler)
    try:
        with tempfile.TemporaryDirectory(dir=folder, prefix=".build-") as tmp:
            src = Path(tmp) / f"{name}.c"
            src.write_text(source)
            out = Path(tmp) / f"{name}.so"
            timeout = COMPILE_TIMEOUT_S + COMPILE_S_PER_KB * len(source) / 1000
            run_compiler([compiler, *flags, str(src), "-o", str(out), "-lm"], timeout, f"compiling {name}")
            body = out.read_bytes()
            with out.open("ab") as fh:
                fh.write(_seal(key, body))
            out.chmod(0o755)  # whatever the umask: an entry writable by others is never loaded
            os.replace(out, target)  # atomic: concurrent processes never load a half-written file
    except OSError as exc:  # a full disk, a folder gone: the caller can still interpret
        raise _unwritable(folder, exc) from None
    return target


def _unwritable(folder: Path, exc: OSError) -> CodegenError:
    return CodegenError(
        f"writing into the compile cache {shown_path(folder)} failed ({exc.strerror or exc}; NLP_CALIB_CACHE "
        "names the folder)"
    )


def _warn_damaged(folder: Path, name: str, problem: str) -> None:
    with _lock:
        if folder in _warned_folders:
            return
        _warned_folders.add(folder)
    warnings.warn(
        f"the compile cache {folder} held a damaged file ({name}: {problem}); compiling it again. "
        f"If this comes back, delete the folder {folder} (it only holds compiled code)",
        NlpCalibWarning,
        stacklevel=3,
    )


def check_compiler(compiler: str) -> None:
    """Raise :class:`CodegenError` if ``compiler`` cannot turn a tiny C file into a shared object
    this process can load, within :data:`PROBE_TIMEOUT_S` (tried once per process)."""
    with _probe_lock:  # one test compile per compiler, whichever thread asks first
        if compiler not in _probed:
            try:
                _probed[compiler] = _probe(compiler)
            except OSError as exc:  # not remembered: a full disk may have room again
                raise _unwritable(usable_cache_dir(), exc) from None
        problem = _probed[compiler]
    if problem is not None:
        raise CodegenError(problem)


def _probe(compiler: str) -> str | None:
    """What is wrong with ``compiler`` (None: nothing). The test file is loaded from the cache
    folder, where the real ones will be (a folder mounted noexec fails here, not later)."""
    folder = usable_cache_dir()
    with tempfile.TemporaryDirectory(dir=folder, prefix=".probe-") as tmp:
        src, out = Path(tmp) / "probe.c", Path(tmp) / "probe.so"
        src.write_text(_PROBE)
        try:
            command = [compiler, *CFLAGS_COLD, str(src), "-o", str(out)]
            run_compiler(command, PROBE_TIMEOUT_S, "a test compile")
        except CodegenError as exc:
            return str(exc)
        what = f"the C compiler {compiler} wrote"
        if not out.is_file() or out.stat().st_size == 0:
            return f"{what} no shared object for a test file"
        try:
            if ctypes.CDLL(str(out)).nlp_calib_probe() == 42:
                return None
        except (OSError, AttributeError) as exc:
            return f"{what} a shared object that cannot be loaded ({str(exc).strip()[:200]})"
        return f"{what} a shared object that computes the wrong value"


def run_compiler(command: list[str], timeout: float, what: str) -> None:
    """Run a compiler in its own process group: a compile past ``timeout`` seconds, or cut short
    by :func:`stop_compilers`, ends with its children (a wrapper script and what it started)."""
    import subprocess  # here: a command whose compiled code is cached never starts a compiler

    try:
        proc = subprocess.Popen(
            command,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
            errors="replace",
            start_new_session=True,  # a Ctrl-C on the terminal is ours to handle, not the compiler's
        )
    except OSError as exc:
        raise CodegenError(f"{what} with {command[0]} failed: {exc.strerror or exc}") from None
    with _lock:
        _running.add(proc)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        _stop(proc)
        raise CodegenError(f"{what} with {command[0]} did not finish within {timeout:.0f} s") from None
    finally:
        with _lock:
            _running.discard(proc)
    if proc.returncode != 0:
        lines = [ln.strip() for ln in (err or "").splitlines() if ln.strip()]
        # One line: the compiler's first error, else its last word, else its exit status.
        detail = next((ln for ln in lines if "error" in ln), lines[-1] if lines else "")[:300]
        raise CodegenError(f"{what} with {command[0]} failed: {detail or f'exit status {proc.returncode}'}")


def _stop(proc: subprocess.Popen[str]) -> None:
    import subprocess  # loaded by run_compiler, which started ``proc``

    with contextlib.suppress(OSError):
        os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired, OSError, ValueError):
        proc.communicate(timeout=5)  # a grandchild that left the group may hold the pipes: bounded


def stop_compilers() -> None:
    """End every compiler this process is running (the process is about to exit)."""
    with _lock:
        running = list(_running)
    for proc in running:
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGKILL)


def generate_source(f: ca.Function) -> str:
    """CasADi's generated C for ``f`` (and its dependencies), as one translation unit."""
    cg = ca.CodeGenerator(f"{f.name()}.c", {"with_header": False})
    cg.add(f)
    source: str = cg.dump()
    return source
