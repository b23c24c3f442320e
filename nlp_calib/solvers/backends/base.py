"""The interpreted evaluation backend: maps per-residual Functions over the windows and folds the
prefix scans over the intervals, called without copies.

Two measured facts shape this module: most of a naive call's time is the numpy<->DM conversion,
which ``Function.buffer()`` removes by binding numpy memory once; and summing inside the map
(``reduce_out``) beats returning per-sample blocks to numpy (a compiled backend sums inside its
chunks and leaves the chunks' few sums to the caller). Scans fold a step over chunks of
:data:`SCAN_CHUNK` intervals, each chunk one expression, and the chunks over the data.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from nlp_calib.core.errors import OptionsError
from nlp_calib.core.numeric import PIECE_SIZES, pieces

BACKENDS = ("interpreted", "compiled")
#: Intervals one call of a scan's chunk integrates.
SCAN_CHUNK = 64
#: Sizes, in chunks, of the folds a scan of any length is evaluated with, one after the other
#: (largest first): each is built once per process, not once per evaluator and data size (a fold's
#: build grows with its size and dominated the evaluators' set-up); the pieces every fold or map
#: over columns takes (:func:`~nlp_calib.core.numeric.pieces`).
FOLD_SIZES = PIECE_SIZES
#: Sizes, in chunks, of the compiled maps a block of windows is evaluated with, one after the
#: other (largest first), for the same reason: a map of a compiled chunk takes a build time growing
#: with its size (40-80 ms at 256 chunks), and data of every size would otherwise build its own.
#: Each size at most once in a block: every piece of a block keeps its own buffer's binding.
MAP_SIZES = (256, 128, 64, 32, 16, 8, 4, 2, 1)
#: Sizes, in columns, of the interpreter's unsummed maps (each column's outputs its own: pieces of
#: any sizes give the same bits; :data:`~nlp_calib.core.numeric.PIECE_SIZES`).
UNSUMMED_SIZES = PIECE_SIZES


@dataclass(frozen=True)
class BackendOptions:
    """``kind``: ``compiled`` (generated C, cached on disk; the default) or ``interpreted`` (CasADi's VM)."""

    kind: str = "compiled"
    chunk: int = 64
    threads: int = 1

    def __post_init__(self) -> None:
        if self.kind not in BACKENDS:
            raise OptionsError(f"the backend must be one of {', '.join(BACKENDS)}, got {self.kind!r}")


@dataclass(frozen=True)
class Request:
    """A Function a backend should get ready: mapped over windows (``mapped_inputs``, summed when
    ``reduce``), or, with ``scan``, a step folded over intervals."""

    function: ca.Function
    mapped_inputs: tuple[str, ...] = ()
    reduce: bool = False
    scan: bool = False


def scan_chunk(step: ca.Function, chunk: int) -> ca.Function:
    """``step`` (state, x, x_fixed, u) → state' folded over ``chunk`` intervals:
    (state, x, x_fixed, U) → (the last state, every state ``(n_state, chunk)``)."""
    acc = step.mapaccum(f"{step.name()}_acc", chunk)
    state = ca.MX.sym("state", step.sparsity_in(0))
    x = ca.MX.sym("x", step.sparsity_in(1))
    x_fixed = ca.MX.sym("x_fixed", step.sparsity_in(2))
    U = ca.MX.sym("u", step.size1_in(3), chunk)
    states = acc(state, ca.repmat(x, 1, chunk), ca.repmat(x_fixed, 1, chunk), U)
    return ca.Function(
        f"{step.name()}_chunk{chunk}",
        [state, x, x_fixed, U],
        [states[:, -1], states],
        ["state", "x", "x_fixed", "u"],
        ["last", "states"],
    )


@functools.lru_cache(maxsize=64)
def fold_chunks(chunk_fn: ca.Function, chunks: int) -> ca.Function:
    """A scan's chunk folded over ``chunks`` chunks: (state, x, x_fixed, U) → states (built once
    per chunk Function and size)."""
    acc = chunk_fn.mapaccum(f"{chunk_fn.name()}_x{chunks}", chunks)
    state = ca.MX.sym("state", chunk_fn.sparsity_in(0))
    x = ca.MX.sym("x", chunk_fn.sparsity_in(1))
    x_fixed = ca.MX.sym("x_fixed", chunk_fn.sparsity_in(2))
    U = ca.MX.sym("u", chunk_fn.size1_in(3), chunk_fn.size2_in(3) * chunks)
    _, states = acc(state, ca.repmat(x, 1, chunks), ca.repmat(x_fixed, 1, chunks), U)
    return ca.Function(
        f"{chunk_fn.name()}_scan",
        [state, x, x_fixed, U],
        [states],
        ["state", "x", "x_fixed", "u"],
        ["states"],
    )


class Backend:
    """Maps a per-residual Function over ``n`` windows and folds scans over intervals (interpreted)."""

    name = "interpreted"
    chunk = SCAN_CHUNK

    def padded(self, n: int) -> int:
        """Number of windows the mapped Functions take for ``n`` residuals."""
        return max(n, 1)

    def padded_intervals(self, n: int) -> int:
        """Number of intervals a scan takes for ``n`` intervals (a whole number of chunks)."""
        return max(1, -(-n // self.chunk)) * self.chunk

    def prepare(self, requests: Sequence[Request]) -> None:
        """Get ready to evaluate these Functions (nothing to do here)."""

    def wait(self) -> None:
        """Wait until what :meth:`prepare` started is ready (nothing to wait for here)."""

    def map(self, f: ca.Function, n: int, mapped_inputs: Sequence[str], reduce: bool) -> ca.Function:
        """``f`` over ``n`` columns of ``mapped_inputs``. When ``reduce``, each output is
        :meth:`parts` partial sums over consecutive columns, side by side ``(rows, cols * parts)``,
        left for the caller to add in order (here one part: the map sums)."""
        reduce_in = [i for i in range(f.n_in()) if f.name_in(i) not in mapped_inputs]
        reduce_out = list(range(f.n_out())) if reduce else []
        return f.map(f"{f.name()}_map", "serial", n, reduce_in, reduce_out)

    def parts(self, n: int) -> int:
        """Partial sums a summed :meth:`map` over ``n`` columns leaves side by side."""
        return 1

    def spans(self, n: int) -> list[int]:
        """The sizes of the maps ``n`` columns are evaluated with, one after the other (here one
        map of every size: the map sums its columns itself)."""
        return [n]

    def unsummed_spans(self, n: int) -> list[int]:
        """The sizes of the maps ``n`` columns are evaluated with when not summed, one after the
        other (a size may repeat)."""
        return pieces(n, UNSUMMED_SIZES)

    def fold(self, step: ca.Function, chunks: int) -> ca.Function:
        """``step`` folded over ``chunks`` chunks of intervals: (state, x, x_fixed, U) → states."""
        return fold_chunks(self.scan_chunk(step), chunks)

    def scan_chunk(self, step: ca.Function) -> ca.Function:
        return _expanded_chunk(step, self.chunk)


#: The interpreter: it holds nothing of its own, so one instance serves every caller; mapped and
#: folded Functions are cached by backend, and a fresh instance is another key (a map rebuilt on
#: every evaluator, every analysis call).
INTERPRETED = Backend()


@functools.lru_cache(maxsize=16)
def _expanded_chunk(step: ca.Function, chunk: int) -> ca.Function:
    # One SX expression per chunk: the VM then runs it without a call per interval.
    return scan_chunk(step, chunk).expand()


class Buffered:
    """A Function with numpy arrays bound to every input and output (``Function.buffer``).

    Inputs keep their values between calls; :meth:`__call__` updates the given ones, evaluates
    and returns the outputs as arrays shaped like the Function's outputs (copies). ``bound``
    binds caller-owned arrays instead (contiguous, float64, the exact size): inputs the caller
    updates in place, or outputs written straight into the caller's memory.
    """

    def __init__(
        self,
        f: ca.Function,
        inputs: Mapping[str, np.ndarray | float] | None = None,
        bound: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        self.function = f
        self._buf, self._eval = f.buffer()
        bound = dict(bound or {})
        # Index and size by name, asked of CasADi once (each query costs microseconds; a scan
        # rebinds its buffers dozens of times per evaluation).
        self._slot_in = {f.name_in(i): (i, f.nnz_in(i)) for i in range(f.n_in())}
        self._slot_out = {f.name_out(i): (i, f.nnz_out(i)) for i in range(f.n_out())}
        self._in = {
            name: _memory(bound.pop(name), nnz) if name in bound else np.zeros(nnz)
            for name, (_, nnz) in self._slot_in.items()
        }
        self._out = [
            _memory(bound.pop(name), nnz) if name in bound else np.zeros(nnz)
            for name, (_, nnz) in self._slot_out.items()
        ]
        if bound:
            raise KeyError(f"{f.name()} has no input or output {sorted(bound)}")
        self._shapes = [f.size_out(i) for i in range(f.n_out())]
        for i in range(f.n_in()):
            self._buf.set_arg(i, self._in[f.name_in(i)].data)
        for i, arr in enumerate(self._out):
            self._buf.set_res(i, arr.data)
        if inputs:
            self.set(**inputs)

    def rebind(self, name: str, arr: np.ndarray) -> None:
        """Bind input ``name`` to another caller-owned array of the same size."""
        i, nnz = self._slot_in[name]
        self._in[name] = _memory(arr, nnz)
        self._buf.set_arg(i, self._in[name].data)

    def rebind_output(self, name: str, arr: np.ndarray) -> None:
        """Write output ``name`` into another caller-owned array of the same size."""
        i, nnz = self._slot_out[name]
        self._out[i] = _memory(arr, nnz)
        self._buf.set_res(i, self._out[i].data)

    def set(self, **inputs: np.ndarray | float) -> None:
        """Copy values into the bound input arrays (column-major, as CasADi stores them)."""
        for name, value in inputs.items():
            target = self._in[name]
            flat = np.ravel(np.asarray(value, dtype=float), order="F")
            if flat.size != target.size:
                raise ValueError(
                    f"{self.function.name()}: input {name!r} has {flat.size} values, expected {target.size}"
                )
            target[:] = flat

    def evaluate(self, **inputs: np.ndarray | float) -> None:
        """Update the given inputs and evaluate, leaving the results in the bound memory."""
        self.set(**inputs)
        self._eval()

    def outputs(self) -> list[np.ndarray]:
        """The bound output arrays, flat (valid until the next evaluation)."""
        return self._out

    def __call__(self, **inputs: np.ndarray | float) -> list[np.ndarray]:
        self.evaluate(**inputs)
        return [
            out.reshape(shape, order="F").copy() if shape[1] > 1 else out.copy()
            for out, shape in zip(self._out, self._shapes)
        ]


def _memory(arr: np.ndarray, size: int) -> np.ndarray:
    """The flat view of a caller-owned array that a buffer binds (no copy)."""
    flat = arr.reshape(-1, order="F")
    # A reshape that had to copy gives new memory, outside the array's bounds: the cheap bounds
    # check tells it (the exact overlap test costs more than the rest of a rebind).
    if flat.dtype != np.float64 or flat.size != size or not np.may_share_memory(flat, arr):
        raise ValueError(f"cannot bind an array of {arr.size} {arr.dtype} values to {size} values")
    return flat


def pad_columns(columns: np.ndarray, n_pad: int) -> np.ndarray:
    """Pad a data matrix to ``n_pad`` columns with zero-weight copies of its first column."""
    rows, n = columns.shape
    out = np.empty((rows, n_pad), order="F")
    out[:, :n] = columns
    pad_in_place(out, n)
    return out


def pad_in_place(out: np.ndarray, n: int) -> None:
    """``out``'s columns past its first ``n`` made zero-weight copies of its first column (zeros
    where ``n`` is 0), as :func:`pad_columns` pads."""
    if out.shape[1] > n:
        out[:, n:] = out[:, :1] if n else 0.0
        out[-1, n:] = 0.0
