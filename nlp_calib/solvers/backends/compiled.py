"""Compiled evaluation backend: generated C for each per-residual Function and scan, cached on disk.

Each per-residual Function is mapped over a fixed chunk of windows (sums taken inside the map),
each scan step folded over a fixed chunk of intervals; the chunk is generated as C by CasADi's
code generator, compiled once with the system C compiler and loaded with ``casadi.external``
(:mod:`nlp_calib.codegen.compiler`, cached by content). Data of any size is then a map (or, for
scans, a fold) of that compiled chunk over the number of chunks it needs (padded), so nothing is
compiled per data size. The chunk map can run on several threads.

:meth:`CompiledBackend.prepare` starts the compilers in the background, one per core, in the
order asked (what the first steps need first) and returns at once: the run goes on while the
rest compiles, and waits only for a Function it needs that is not ready yet.

Nothing the compiler or the cache does can end a run: a cached file that does not load is
compiled again, and a compiler that fails, hangs past its timeout or writes something that does
not load leaves that Function (and, once it has hung, every later one) to CasADi's interpreter,
with one warning.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import queue
import threading
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import casadi as ca

from nlp_calib.codegen.compiler import (
    cache_dir,
    compile_shared,
    compiler_flags,
    find_compiler,
    generate_source,
    stop_compilers,
    usable_cache_dir,
)
from nlp_calib.core import interrupts, threads
from nlp_calib.core.errors import CodegenError, NlpCalibWarning
from nlp_calib.core.numeric import pieces
from nlp_calib.solvers.backends.base import (
    INTERPRETED,
    MAP_SIZES,
    Backend,
    BackendOptions,
    Request,
    scan_chunk,
)


class CompiledBackend(Backend):
    """Maps and folds compiled chunks (see the module docstring)."""

    name = "compiled"

    def __init__(self, options: BackendOptions, compiler: str) -> None:
        self.chunk = options.chunk
        self.threads = options.threads
        self.compiler = compiler

    def padded(self, n: int) -> int:
        return max(1, -(-n // self.chunk)) * self.chunk

    def _key(self, request: Request) -> tuple[object, ...]:
        # The Function itself (problems are built once per model and spec), how it is chunked,
        # compiled and where it is cached: every backend of the process shares what is loaded.
        f = request.function
        how = ("scan",) if request.scan else (str(request.reduce), *request.mapped_inputs)
        return (id(f), *how, self.chunk, self.compiler, str(cache_dir()))

    def _chunk(self, request: Request) -> ca.Function:
        """The chunk Function of a request."""
        f = request.function
        if request.scan:
            return scan_chunk(f, self.chunk)
        reduce_in = [i for i in range(f.n_in()) if f.name_in(i) not in request.mapped_inputs]
        reduce_out = list(range(f.n_out())) if request.reduce else []
        name = f"{f.name()}_chunk{self.chunk}{'_sum' if request.reduce else ''}"
        return f.map(name, "serial", self.chunk, reduce_in, reduce_out)

    def _build(self, request: Request, rebuild: bool = False) -> tuple[str, Path]:
        """Generate and compile (or find in the cache) a request's chunk: its name and shared object."""
        if self.compiler in _BROKEN:
            raise CodegenError(_BROKEN[self.compiler])
        fc = self._chunk(request)
        flags = compiler_flags(request.function)
        so = compile_shared(generate_source(fc), fc.name(), self.compiler, flags, rebuild=rebuild)
        return fc.name(), so

    def _compile(self, request: Request) -> ca.Function:
        """The compiled chunk of a request, loaded (compiled at most once per content)."""
        key = self._key(request)
        with _LOCK:
            if key in _LOADED:
                return _LOADED[key][1]
            pending = _PENDING.get(key)
        loaded = self._load(request, pending)
        with _LOCK:
            _PENDING.pop(key, None)
            return _LOADED.setdefault(key, (request.function, loaded))[1]

    def _load(self, request: Request, pending: Future[tuple[str, Path]] | None) -> ca.Function:
        """The request's chunk from its shared object; compiled again once if that does not load,
        then interpreted (with a warning) if the compiler cannot make one that does."""
        try:
            name, so = pending.result() if pending is not None else self._build(request)
            try:
                return ca.external(name, str(so))
            except RuntimeError:  # checked whole, yet not loadable: compile it once more
                name, so = self._build(request, rebuild=True)
                try:
                    return ca.external(name, str(so))
                except RuntimeError as exc:
                    raise CodegenError(
                        f"the C compiler {self.compiler} wrote {so.name}, which does not load "
                        f"({str(exc).strip().splitlines()[-1][:200]})"
                    ) from None
        except CodegenError as exc:
            _fall_back(self.compiler, str(exc))
            fc = self._chunk(request)
            return fc.expand() if request.scan else fc

    def prepare(self, requests: Sequence[Request]) -> None:
        """Start compiling the requests' chunks in the background, in this order."""
        for request in requests:
            key = self._key(request)
            with _LOCK:
                if key not in _LOADED and key not in _PENDING:
                    _PENDING[key] = _pool().submit(self._build, request)

    def wait(self) -> None:
        """Wait until everything :meth:`prepare` started has compiled (or failed to: a failure is
        dealt with when the Function is loaded)."""
        with _LOCK:
            pending = list(_PENDING.values())
        for future in pending:
            with contextlib.suppress(CodegenError):
                future.result()

    def scan_chunk(self, step: ca.Function) -> ca.Function:
        return self._compile(Request(step, scan=True))

    def map(self, f: ca.Function, n: int, mapped_inputs: Sequence[str], reduce: bool) -> ca.Function:
        # The chunks' sums are left side by side: a map that adds them itself takes a build time
        # growing with their number (an addition per chunk), paid again for every window count.
        chunks = n // self.chunk
        fc = self._compile(Request(f, tuple(mapped_inputs), reduce))
        reduce_in = [i for i in range(f.n_in()) if f.name_in(i) not in mapped_inputs]
        if self.threads <= 1 or chunks <= 1:
            return fc.map(f"{f.name()}_x{chunks}", "serial", chunks, reduce_in, [])
        return self._threaded(fc, chunks, reduce_in)

    def parts(self, n: int) -> int:
        return n // self.chunk

    def spans(self, n: int) -> list[int]:
        return [size * self.chunk for size in pieces(n // self.chunk, MAP_SIZES)]

    def unsummed_spans(self, n: int) -> list[int]:
        return self.spans(n)

    def _threaded(self, fc: ca.Function, chunks: int, reduce_in: list[int]) -> ca.Function:
        """The chunk map on ``threads`` threads, broadcast inputs tiled."""
        # map(n, 'thread', t) maps every input: a thin MX wrapper tiles the broadcast ones (the
        # 5-argument form would start a thread per chunk).
        par = fc.map(chunks, "thread", min(self.threads, chunks))
        ins = [
            ca.MX.sym(
                fc.name_in(i),
                fc.sparsity_in(i).size1(),
                fc.sparsity_in(i).size2() * (1 if i in reduce_in else chunks),
            )
            for i in range(fc.n_in())
        ]
        args = [ca.repmat(s, 1, chunks) if i in reduce_in else s for i, s in enumerate(ins)]
        outs = par(*args)
        return ca.Function(
            f"{fc.name()}_t{chunks}",
            ins,
            [outs] if isinstance(outs, ca.MX) else list(outs),
            [fc.name_in(i) for i in range(fc.n_in())],
            [fc.name_out(i) for i in range(fc.n_out())],
        )


_warned_no_compiler = False
#: Compilers found unable to make a loadable shared object in time, with the reason.
_BROKEN: dict[str, str] = {}
_warned_fallback: set[str] = set()
_POOL: _Compilers | None = None
_LOCK = threading.Lock()
#: Loaded chunks (with the Function they came from, which keeps its id valid) and compiles under way.
_LOADED: dict[tuple[object, ...], tuple[ca.Function, ca.Function]] = {}
_PENDING: dict[tuple[object, ...], Future[tuple[str, Path]]] = {}


class _Compilers:
    """Compile jobs on daemon threads, one per core. When the process ends (an error, or a run that
    did not need everything it started), jobs not yet started are dropped and those under way are
    let finish, so that exiting never waits for a compile nobody needs nor leaves one half done."""

    def __init__(self, workers: int) -> None:
        self._queue: queue.SimpleQueue[tuple[Future[Any], Callable[[], Any]]] = queue.SimpleQueue()
        self._busy = 0
        self._closing = False
        self._cond = threading.Condition()
        for k in range(workers):
            threading.Thread(target=self._work, name=f"nlp_calib-cc-{k}", daemon=True).start()
        atexit.register(self.close)

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future[Any]:
        future: Future[Any] = Future()
        self._queue.put((future, lambda: fn(*args)))
        return future

    def _work(self) -> None:
        while True:
            future, job = self._queue.get()
            with self._cond:
                if self._closing or not future.set_running_or_notify_cancel():
                    continue
                self._busy += 1
            try:
                future.set_result(job())
            except BaseException as exc:
                future.set_exception(exc)
            finally:
                with self._cond:
                    self._busy -= 1
                    self._cond.notify_all()

    def close(self) -> None:
        with self._cond:
            self._closing = True
        if interrupts.pending() is not None:  # the run was interrupted: nobody needs these compiles
            stop_compilers()
        with self._cond:
            self._cond.wait_for(lambda: self._busy == 0, timeout=60)


def _pool() -> _Compilers:
    """The compiler threads every backend of the process shares."""
    global _POOL
    if _POOL is None:
        _POOL = _Compilers(threads.allowed(os.cpu_count() or 1))
    return _POOL


def _fall_back(compiler: str, reason: str) -> None:
    """Warn once per compiler that Functions are evaluated by the interpreter; a compiler that
    hung is not asked again (each compile would take as long)."""
    with _LOCK:
        if "did not finish within" in reason:
            _BROKEN.setdefault(compiler, reason)
        if compiler in _warned_fallback:
            return
        _warned_fallback.add(compiler)
    warnings.warn(
        f"{reason.rstrip('.')}: evaluating with CasADi's interpreter instead, several times slower; "
        "fix the compiler ($CC) or what it needs, or set 'backend: interpreted' to silence this",
        NlpCalibWarning,
        stacklevel=4,
    )


def make_compiled_backend(options: BackendOptions) -> Backend:
    """The compiled backend, or the interpreted one with a warning (once) when no C compiler exists."""
    global _warned_no_compiler
    compiler = find_compiler()
    if compiler is None:
        if not _warned_no_compiler:
            _warned_no_compiler = True
            warnings.warn(
                "no C compiler found (set $CC or install gcc or clang): evaluating with CasADi's "
                "interpreter, several times slower; set 'backend: interpreted' to silence this",
                NlpCalibWarning,
                stacklevel=2,
            )
        return INTERPRETED
    usable_cache_dir()  # a cache that cannot be written is named now, before any work
    return CompiledBackend(options, compiler)
