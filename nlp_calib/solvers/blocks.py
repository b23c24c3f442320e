"""A per-column Function evaluated over many columns, a block at a time.

Mapping a Function over a million columns at once costs seconds to build (CasADi's map grows with
its size) and needs every output in one piece. :class:`BlockMap` maps it over blocks of
:data:`BLOCK` columns instead (at most two map sizes, built once), binds one buffer per block
size to each block's column slices of the caller's arrays in turn (no copies) and either sums the
blocks' outputs (and the partial sums a backend's map leaves, in order) or writes them straight
into full per-column arrays. A mapped input may also be
a :class:`Columns` source (columns made on demand, e.g. gathered from a larger array): each
block's columns are then made into one block-sized buffer just before the block is evaluated, so
the full input never exists.
:class:`Scan` folds a step over many intervals the same way: folds of a few fixed sizes (built
once), chained through the caller's array of states.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping, Sequence
from typing import Protocol, TypeAlias

import casadi as ca
import numpy as np

from nlp_calib.solvers.backends import Backend, Buffered
from nlp_calib.solvers.backends.base import fold_sizes

#: Columns per block: a multiple of every backend's chunk.
BLOCK = 1 << 14


class Columns(Protocol):
    """Columns of a mapped input made on demand: ``shape`` ``(rows, n)``; :meth:`fill` writes columns
    ``lo:hi`` into ``out`` ``(rows, hi - lo)``, column-major."""

    @property
    def shape(self) -> tuple[int, int]: ...

    def fill(self, lo: int, hi: int, out: np.ndarray) -> None: ...


#: A mapped input: an array, or columns made on demand.
Mapped: TypeAlias = "np.ndarray | Columns"


def _made(mapped: Mapping[str, Mapped]) -> dict[str, Columns]:
    return {k: v for k, v in mapped.items() if not isinstance(v, np.ndarray)}


@functools.lru_cache(maxsize=64)
def _mapped(backend: Backend, f: ca.Function, n: int, names: tuple[str, ...], reduce: bool) -> ca.Function:
    """``backend.map``, built once per Function and size: every evaluator on windows of about the
    same number (the refits, the lag search's) evaluates the same wrapper instead of building
    its own (each call has its own buffers: one Function serves several threads)."""
    return backend.map(f, n, names, reduce)


class BlockMap:
    """``f`` over the ``n`` columns of ``mapped`` (arrays ``(rows, n)``, column-major), with the
    other inputs in ``static``; outputs summed over the columns when ``reduce``."""

    def __init__(
        self,
        backend: Backend,
        f: ca.Function,
        mapped: Mapping[str, Mapped],
        static: Mapping[str, np.ndarray | float],
        reduce: bool,
    ) -> None:
        self.reduce = reduce
        n = next(iter(mapped.values())).shape[1]
        names = tuple(mapped)
        self.out_names = [f.name_out(i) for i in range(f.n_out())]
        self.shapes = [f.size_out(i) for i in range(f.n_out())]
        # Unreduced outputs: one (rows, cols * n) array each, column-major like CasADi's map.
        self.full = [] if reduce else [np.zeros((r, c * n), order="F") for r, c in self.shapes]
        self.mapped = dict(mapped)
        self.made = _made(mapped)
        self.spans = [(lo, min(n, lo + BLOCK)) for lo in range(0, n, BLOCK)]
        # One buffer per block size, bound to each block's columns in turn (a mapped Function's
        # work memory holds a block's inputs: one buffer per block would hold them all again), and
        # one block-sized array per made input.
        self.scratch: dict[tuple[str, int], np.ndarray] = {}
        self.buffers: dict[int, Buffered] = {}
        self.parts = {size: backend.parts(size) for size in {hi - lo for lo, hi in self.spans}}
        for size in sorted(self.parts):
            made = {k: np.zeros((v.shape[0], size), order="F") for k, v in self.made.items()}
            self.scratch.update({(k, size): v for k, v in made.items()})
            self.buffers[size] = Buffered(_mapped(backend, f, size, names, reduce), static, made)

    def __call__(self, **inputs: np.ndarray | float) -> Sequence[np.ndarray]:
        """Evaluate every block; the summed outputs (shaped like ``f``'s), or the full arrays."""
        for buf in self.buffers.values():
            buf.set(**inputs)
        sums = [np.zeros(r * c) for r, c in self.shapes] if self.reduce else []
        for lo, hi in self.spans:
            buf = self.buffers[hi - lo]
            for name, value in self.mapped.items():
                if isinstance(value, np.ndarray):
                    buf.rebind(name, value[:, lo:hi])
                else:
                    value.fill(lo, hi, self.scratch[name, hi - lo])
            for name, out, (_, c) in zip(self.out_names, self.full, self.shapes):
                buf.rebind_output(name, out[:, c * lo : c * hi])
            buf.evaluate()
            for total, out in zip(sums, buf.outputs()):
                total += add_parts(out, self.parts[hi - lo])
        if not self.reduce:
            return self.full
        return [s.reshape(shape, order="F") if shape[1] > 1 else s for s, shape in zip(sums, self.shapes)]


def add_parts(out: np.ndarray, parts: int) -> np.ndarray:
    """The sum of ``parts`` partial sums stored one after the other in ``out``, added in order from
    the first, as a map's own sum adds them (the same bits)."""
    if parts == 1:
        return out
    # accumulate, unlike sum, never reorders the additions (no pairwise summation).
    return np.add.accumulate(out.reshape(parts, -1), axis=0)[-1]


def stream(
    backend: Backend,
    f: ca.Function,
    mapped: Mapping[str, Mapped],
    static: Mapping[str, np.ndarray | float],
    n: int | None = None,
) -> Iterator[tuple[slice, list[np.ndarray]]]:
    """``f`` over the columns of ``mapped``, one block at a time: each block's columns and its
    outputs ``(rows, cols * block)`` (reused for the next block: copy what must outlive it). Only
    the first ``n`` columns' blocks are evaluated. Memory stays one block's, however many columns."""
    total = next(iter(mapped.values())).shape[1]
    n = total if n is None else n
    buffers: dict[int, tuple[Buffered, dict[str, np.ndarray]]] = {}
    for lo in range(0, n, BLOCK):
        hi = min(total, lo + BLOCK)
        size = hi - lo
        if size not in buffers:
            scratch = {k: np.zeros((v.shape[0], size), order="F") for k, v in _made(mapped).items()}
            mapped_f = _mapped(backend, f, size, tuple(mapped), False)
            buffers[size] = (Buffered(mapped_f, static, scratch), scratch)
        buf, scratch = buffers[size]
        for name, arr in mapped.items():
            if isinstance(arr, np.ndarray):
                buf.rebind(name, arr[:, lo:hi])
            else:
                arr.fill(lo, hi, scratch[name])
        buf.evaluate()
        shapes = [f.size_out(i) for i in range(f.n_out())]
        yield (
            slice(lo, min(hi, n)),
            [out.reshape(r, c * size, order="F") for out, (r, c) in zip(buf.outputs(), shapes)],
        )


class Scan:
    """``step`` (state, x, x_fixed, u) → state' folded over the columns of ``inputs`` (a whole number
    of the backend's chunks) from the state in ``states[:, 0]``, every state written into
    ``states[:, 1:]`` (``(rows, n + 1)``, column-major). Each fold of the chain reads its first state
    from the column the previous one wrote last: no copies, and the same arithmetic as one fold.
    One buffer per fold size, bound to each span in turn (a fold's work memory is as large as its
    states: one per span would hold the states twice)."""

    def __init__(self, backend: Backend, step: ca.Function, inputs: np.ndarray, states: np.ndarray) -> None:
        self.inputs, self.states = inputs, states
        self.spans: list[tuple[Buffered, int, int]] = []
        by_size: dict[int, Buffered] = {}
        lo = 0
        for size in fold_sizes(inputs.shape[1] // backend.chunk):
            if size not in by_size:
                by_size[size] = Buffered(backend.fold(step, size))
            hi = lo + size * backend.chunk
            self.spans.append((by_size[size], lo, hi))
            lo = hi
        self.buffers = list(by_size.values())

    def evaluate(self, **inputs: np.ndarray | float) -> None:
        """Fold over every interval with these inputs (``x``, ``x_fixed``)."""
        for buf in self.buffers:
            buf.set(**inputs)
        for buf, lo, hi in self.spans:
            buf.rebind("state", self.states[:, lo])
            buf.rebind("u", self.inputs[:, lo:hi])
            buf.rebind_output("states", self.states[:, lo + 1 : hi + 1])
            buf.evaluate()
