"""Compiling CasADi Functions into shared objects with the system C compiler, cached by content.

A shared object is cached under a hash of the generated source, the compiler, its flags and
CasADi's version: repeated runs, other data sets and other processes reuse it, and concurrent
processes never load a half-written file.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

import casadi as ca

from nlp_calib.core.errors import CodegenError, OptionsError

#: Optimisation flags for the generated code; -fno-math-errno lets sin/cos/sqrt inline.
CFLAGS = ("-O3", "-march=native", "-fno-math-errno", "-fPIC", "-shared", "-Wno-int-conversion")
#: Functions evaluated once per run (residual terms for the uncertainty and the reports) and
#: very large ones (a long horizon's exact Hessian) compile about twice as fast at -O1, for a
#: small loss at run time; the solvers' inner loops get -O3.
CFLAGS_COLD = ("-O1", "-fno-math-errno", "-fPIC", "-shared", "-Wno-int-conversion")
HOT_FUNCTIONS = frozenset({"normal_equations", "cost", "prefix_step", "prefix_value_step"})
LARGE_FUNCTION = 20_000  # instructions


def compiler_flags(f: ca.Function) -> tuple[str, ...]:
    """-O3 for the solvers' inner loops, -O1 for the rest and for very large functions."""
    return CFLAGS if f.name() in HOT_FUNCTIONS and f.n_instructions() <= LARGE_FUNCTION else CFLAGS_COLD


_COMPILE_TIMEOUT_S = 600


def find_compiler() -> str | None:
    """The C compiler to use: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH."""
    candidates = [os.environ.get("CC"), "cc", "gcc", "clang"]
    for cc in candidates:
        if cc and shutil.which(cc):
            return shutil.which(cc)
    return None


def cache_dir() -> Path:
    """Where compiled shared objects are kept: ``$NLP_CALIB_CACHE`` or the user cache folder."""
    env = os.environ.get("NLP_CALIB_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "nlp_calib"


def usable_cache_dir() -> Path:
    """:func:`cache_dir`, created if needed; an error naming it when it cannot hold files."""
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not os.access(folder, os.W_OK | os.X_OK):
            raise PermissionError("not writable")
    except (OSError, ValueError) as exc:
        reason = "a file is in the way" if folder.is_file() else getattr(exc, "strerror", None) or str(exc)
        raise OptionsError(
            f"the compile cache {folder} is not a writable folder ({reason}); set NLP_CALIB_CACHE to "
            "a writable folder, or use the interpreted backend ('backend: interpreted')"
        ) from None
    return folder


def compile_shared(source: str, name: str, compiler: str, flags: Sequence[str] = CFLAGS) -> Path:
    """Compile C ``source`` into a cached shared object; returns its path (compiles at most once)."""
    key = hashlib.sha256("\n".join([source, compiler, *flags, ca.__version__]).encode()).hexdigest()[:24]
    folder = cache_dir()
    target = folder / f"{name}-{key}.so"
    if target.exists():
        return target
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder, prefix=".build-") as tmp:
        src = Path(tmp) / f"{name}.c"
        src.write_text(source)
        out = Path(tmp) / f"{name}.so"
        try:
            subprocess.run(
                [compiler, *flags, str(src), "-o", str(out), "-lm"],
                check=True,
                capture_output=True,
                text=True,
                timeout=_COMPILE_TIMEOUT_S,
            )
        except (subprocess.CalledProcessError, subprocess.TimeoutExpired, OSError) as exc:
            detail = getattr(exc, "stderr", "") or str(exc)
            raise CodegenError(f"compiling {name} with {compiler} failed: {detail.strip()[:500]}") from None
        os.replace(out, target)  # atomic: concurrent processes never load a half-written file
    return target


def generate_source(f: ca.Function) -> str:
    """CasADi's generated C for ``f`` (and its dependencies), as one translation unit."""
    cg = ca.CodeGenerator(f"{f.name()}.c", {"with_header": False})
    cg.add(f)
    source: str = cg.dump()
    return source
