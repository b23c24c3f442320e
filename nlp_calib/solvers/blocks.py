"""A per-column Function evaluated over many columns, a block at a time.

Mapping a Function over a million columns at once costs seconds to build (CasADi's map grows with
its size) and needs every output in one piece. :class:`BlockMap` maps it over blocks of
:data:`BLOCK` columns instead, each block a few maps of the fixed sizes the backend builds
(:meth:`~nlp_calib.solvers.backends.Backend.spans`, each built once per process), binds one buffer
per map size to each piece's column slices of the caller's arrays in turn (no copies) and either
sums the outputs (and, in order, the partial sums a backend's map leaves) or writes them straight
into full per-column arrays. A mapped input may also be a :class:`Columns` source (columns made on
demand, e.g. gathered from a larger array): each piece's columns are then made into one
piece-sized buffer just before it is evaluated, so the full input never exists.
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
    """``backend.map``, built once per Function and size: every evaluator evaluates the same
    wrappers of the backend's sizes instead of building its own (each call has its own buffers:
    one Function serves several threads)."""
    return backend.map(f, n, names, reduce)


class _Pieces:
    """``f`` over blocks of at most :data:`BLOCK` columns of ``mapped``, each block evaluated as the
    backend's maps of fixed sizes one after the other (:meth:`Backend.spans`: nothing is built per
    data size). One buffer per map size, bound to a piece's columns until a piece of another block
    takes it (a mapped Function's work memory holds a piece's inputs: one buffer per piece would
    hold them all again; a block has each size once, but for the interpreter's unsummed pieces,
    which repeat a size and bind again at each piece), and one piece-sized array per made input. A
    piece's outputs go to the columns of the caller's ``targets`` that :attr:`pieces` gives it: its
    columns, or, summed, its partial sums."""

    def __init__(
        self,
        backend: Backend,
        f: ca.Function,
        mapped: Mapping[str, Mapped],
        static: Mapping[str, np.ndarray | float],
        reduce: bool,
        n: int,
    ) -> None:
        total = next(iter(mapped.values())).shape[1]
        self.mapped = dict(mapped)
        self.out_names = [f.name_out(i) for i in range(f.n_out())]
        self.shapes = [f.size_out(i) for i in range(f.n_out())]
        self.blocks = [(lo, min(total, lo + BLOCK)) for lo in range(0, n, BLOCK)]
        #: Per block size: each piece's columns [a, b) in the block and output columns [o, p).
        self.pieces: dict[int, list[tuple[int, int, int, int]]] = {}
        #: Per block size: the output columns of its pieces together (its partial sums, summed).
        self.width: dict[int, int] = {}
        self.scratch: dict[tuple[str, int], np.ndarray] = {}
        self.buffers: dict[int, Buffered] = {}
        #: The first column of the piece each buffer is bound to (bound again only on a change).
        self.bound: dict[int, int] = {}
        for size in sorted({hi - lo for lo, hi in self.blocks}):
            a = o = 0
            self.pieces[size] = []
            for span in backend.spans(size) if reduce else backend.unsummed_spans(size):
                width = backend.parts(span) if reduce else span
                self.pieces[size].append((a, a + span, o, o + width))
                a, o = a + span, o + width
                if span not in self.buffers:
                    made = {k: np.zeros((v.shape[0], span), order="F") for k, v in _made(mapped).items()}
                    self.scratch.update({(k, span): v for k, v in made.items()})
                    mapped_f = _mapped(backend, f, span, tuple(mapped), reduce)
                    self.buffers[span] = Buffered(mapped_f, static, made)
            self.width[size] = o

    def set(self, **inputs: np.ndarray | float) -> None:
        for buf in self.buffers.values():
            buf.set(**inputs)

    def evaluate(self, lo: int, hi: int, targets: Sequence[np.ndarray]) -> None:
        """Evaluate the block of columns ``[lo, hi)`` into ``targets`` (one ``(rows, cols *
        width)`` array per output, column-major; the same arrays at every call for a block)."""
        for a, b, o, p in self.pieces[hi - lo]:
            buf = self.buffers[b - a]
            bind = self.bound.get(b - a) != lo + a
            for name, value in self.mapped.items():
                if not isinstance(value, np.ndarray):
                    value.fill(lo + a, lo + b, self.scratch[name, b - a])
                elif bind:
                    buf.rebind(name, value[:, lo + a : lo + b])
            if bind:
                for name, out, (_, c) in zip(self.out_names, targets, self.shapes):
                    buf.rebind_output(name, out[:, c * o : c * p])
                self.bound[b - a] = lo + a
            buf.evaluate()


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
        self.pieces = _Pieces(backend, f, mapped, static, reduce, n)
        self.shapes = self.pieces.shapes
        # Unreduced outputs: one (rows, cols * n) array each, column-major like CasADi's map;
        # summed ones: a block's partial sums, added in order once the block is evaluated.
        self.full = [] if reduce else [np.zeros((r, c * n), order="F") for r, c in self.shapes]
        self.sums = {
            size: [np.zeros((r, c * width), order="F") for r, c in self.shapes]
            for size, width in self.pieces.width.items()
            if reduce
        }

    def __call__(self, **inputs: np.ndarray | float) -> Sequence[np.ndarray]:
        """Evaluate every block; the summed outputs (shaped like ``f``'s), or the full arrays."""
        self.pieces.set(**inputs)
        totals = [np.zeros(r * c) for r, c in self.shapes] if self.reduce else []
        for lo, hi in self.pieces.blocks:
            if not self.reduce:
                self.pieces.evaluate(
                    lo, hi, [out[:, c * lo : c * hi] for out, (_, c) in zip(self.full, self.shapes)]
                )
                continue
            parts = self.sums[hi - lo]
            self.pieces.evaluate(lo, hi, parts)
            for total, part in zip(totals, parts):
                total += add_parts(part.reshape(-1, order="F"), self.pieces.width[hi - lo])
        if not self.reduce:
            return self.full
        return [s.reshape(shape, order="F") if shape[1] > 1 else s for s, shape in zip(totals, self.shapes)]


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
    n = next(iter(mapped.values())).shape[1] if n is None else n
    pieces = _Pieces(backend, f, mapped, static, False, n)
    outs = {size: [np.zeros((r, c * size), order="F") for r, c in pieces.shapes] for size in pieces.width}
    for lo, hi in pieces.blocks:
        pieces.evaluate(lo, hi, outs[hi - lo])
        yield slice(lo, min(hi, n)), outs[hi - lo]


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
