"""Compiled evaluation backend: generated C for each per-residual Function, cached on disk.

Each per-residual Function is mapped over a fixed chunk of columns (sums taken inside the map),
generated as C by CasADi's code generator, compiled once with the system C compiler and loaded
with ``casadi.external`` (:mod:`nlp_calib.codegen.compiler`, cached by content). Data of any size
is then a map of that compiled chunk over the number of chunks it needs (padded with zero-weight
columns), so nothing is compiled per data size. The chunk map can run on several threads.
"""

from __future__ import annotations

import os
import threading
import warnings
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import casadi as ca

from nlp_calib.codegen.compiler import compile_shared, compiler_flags, find_compiler, generate_source
from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.solvers.backends.base import Backend, BackendOptions


class CompiledBackend(Backend):
    """Maps per-residual Functions through compiled chunks (see the module docstring)."""

    name = "compiled"

    def __init__(self, options: BackendOptions, compiler: str) -> None:
        self.chunk = options.chunk
        self.threads = options.threads
        self.compiler = compiler
        self._loaded: dict[tuple[str, bool, tuple[str, ...]], ca.Function] = {}
        self._lock = threading.Lock()

    def padded(self, n: int) -> int:
        return max(1, -(-n // self.chunk)) * self.chunk

    def _chunk_map(
        self, f: ca.Function, mapped_inputs: Sequence[str], reduce: bool
    ) -> tuple[ca.Function, tuple[str, ...]]:
        """``f`` mapped over one chunk (sums inside when ``reduce``) and the flags to compile it with."""
        reduce_in = [i for i in range(f.n_in()) if f.name_in(i) not in mapped_inputs]
        reduce_out = list(range(f.n_out())) if reduce else []
        name = f"{f.name()}_chunk{self.chunk}{'_sum' if reduce else ''}"
        return f.map(name, "serial", self.chunk, reduce_in, reduce_out), compiler_flags(f)

    def chunk_function(self, f: ca.Function, mapped_inputs: Sequence[str], reduce: bool) -> ca.Function:
        """``f`` mapped over one chunk of columns, compiled and loaded (cached per Function)."""
        key = (f.name(), reduce, tuple(mapped_inputs))
        with self._lock:
            if key not in self._loaded:
                fc, flags = self._chunk_map(f, mapped_inputs, reduce)
                so = compile_shared(generate_source(fc), fc.name(), self.compiler, flags)
                self._loaded[key] = ca.external(fc.name(), str(so))
            return self._loaded[key]

    def prepare(self, requests: Sequence[tuple[ca.Function, Sequence[str], bool]]) -> None:
        """Compile several chunk functions at once, one compiler process per core."""

        def compile_one(f: ca.Function, mapped_inputs: Sequence[str], reduce: bool) -> None:
            fc, flags = self._chunk_map(f, mapped_inputs, reduce)
            compile_shared(generate_source(fc), fc.name(), self.compiler, flags)

        with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
            for future in [pool.submit(compile_one, *r) for r in requests]:
                future.result()

    def map(self, f: ca.Function, n: int, mapped_inputs: Sequence[str], reduce: bool) -> ca.Function:
        chunks = n // self.chunk
        fc = self.chunk_function(f, mapped_inputs, reduce)
        reduce_in = [i for i in range(f.n_in()) if f.name_in(i) not in mapped_inputs]
        reduce_out = list(range(f.n_out())) if reduce else []
        if self.threads <= 1 or chunks <= 1:
            return fc.map(f"{f.name()}_x{chunks}", "serial", chunks, reduce_in, reduce_out)
        return self._threaded(fc, chunks, reduce_in, reduce_out)

    def _threaded(
        self, fc: ca.Function, chunks: int, reduce_in: list[int], reduce_out: list[int]
    ) -> ca.Function:
        """The chunk map on ``threads`` threads; broadcast inputs tiled, sums taken after."""
        # map(n, 'thread', t) maps every input: a thin MX wrapper tiles the broadcast ones and
        # sums the per-chunk partial sums (the 5-argument form would start a thread per chunk).
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
        outs = [outs] if isinstance(outs, ca.MX) else list(outs)
        summed = []
        for i, o in enumerate(outs):
            if i in reduce_out:
                cols = fc.sparsity_out(i).size2()
                o = ca.mtimes(o, ca.repmat(ca.DM.eye(cols), chunks, 1))
            summed.append(o)
        return ca.Function(
            f"{fc.name()}_t{chunks}",
            ins,
            summed,
            [fc.name_in(i) for i in range(fc.n_in())],
            [fc.name_out(i) for i in range(fc.n_out())],
        )


def make_compiled_backend(options: BackendOptions) -> Backend:
    """The compiled backend, or the interpreted one with a warning when no C compiler exists."""
    compiler = find_compiler()
    if compiler is None:
        warnings.warn(
            "backend 'compiled' needs a C compiler (set $CC or install gcc/clang); "
            "falling back to the interpreted backend",
            NlpCalibWarning,
            stacklevel=2,
        )
        return Backend()
    return CompiledBackend(options, compiler)
