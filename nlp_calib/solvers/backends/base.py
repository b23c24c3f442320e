"""The interpreted evaluation backend: maps per-residual Functions over the data, called without copies.

Two measured facts shape this module: most of a naive call's time is the numpy<->DM conversion,
which ``Function.buffer()`` removes by binding numpy memory once; and summing inside the map
(``reduce_out``) beats returning per-sample blocks to numpy.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from nlp_calib.core.errors import OptionsError

BACKENDS = ("interpreted", "compiled")


@dataclass(frozen=True)
class BackendOptions:
    """``kind``: ``interpreted`` (CasADi's VM) or ``compiled`` (generated C, cached on disk)."""

    kind: str = "interpreted"
    chunk: int = 64
    threads: int = 1

    def __post_init__(self) -> None:
        if self.kind not in BACKENDS:
            raise OptionsError(f"the backend must be one of {', '.join(BACKENDS)}, got {self.kind!r}")


class Backend:
    """Maps a per-residual Function over ``n`` data columns (interpreted)."""

    name = "interpreted"

    def padded(self, n: int) -> int:
        """Number of columns the mapped Functions take for ``n`` residuals."""
        return max(n, 1)

    def prepare(self, requests: Sequence[tuple[ca.Function, Sequence[str], bool]]) -> None:
        """Get ready to map these ``(function, mapped_inputs, reduce)`` (nothing to do here)."""

    def map(self, f: ca.Function, n: int, mapped_inputs: Sequence[str], reduce: bool) -> ca.Function:
        """``f`` over ``n`` columns of ``mapped_inputs``; outputs summed when ``reduce``."""
        reduce_in = [i for i in range(f.n_in()) if f.name_in(i) not in mapped_inputs]
        reduce_out = list(range(f.n_out())) if reduce else []
        return f.map(f"{f.name()}_map", "serial", n, reduce_in, reduce_out)


class Buffered:
    """A Function with numpy arrays bound to every input and output (``Function.buffer``).

    Inputs keep their values between calls; :meth:`__call__` updates the given ones, evaluates
    and returns the outputs as arrays shaped like the Function's outputs (copies).
    """

    def __init__(self, f: ca.Function, inputs: Mapping[str, np.ndarray | float] | None = None) -> None:
        self.function = f
        self._buf, self._eval = f.buffer()
        self._in = {f.name_in(i): np.zeros(f.nnz_in(i)) for i in range(f.n_in())}
        self._out = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
        self._shapes = [f.size_out(i) for i in range(f.n_out())]
        for i in range(f.n_in()):
            self._buf.set_arg(i, self._in[f.name_in(i)].data)
        for i, arr in enumerate(self._out):
            self._buf.set_res(i, arr.data)
        if inputs:
            self.set(**inputs)

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

    def __call__(self, **inputs: np.ndarray | float) -> list[np.ndarray]:
        self.set(**inputs)
        self._eval()
        return [
            out.reshape(shape, order="F").copy() if shape[1] > 1 else out.copy()
            for out, shape in zip(self._out, self._shapes)
        ]


def pad_columns(columns: np.ndarray, n_pad: int) -> np.ndarray:
    """Pad a data matrix to ``n_pad`` columns with zero-weight copies of its first column."""
    rows, n = columns.shape
    out = np.empty((rows, n_pad), order="F")
    out[:, :n] = columns
    if n_pad > n:
        filler = columns[:, :1] if n else np.zeros((rows, 1))
        out[:, n:] = filler
        out[-1, n:] = 0.0
    return out
