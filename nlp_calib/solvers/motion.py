"""The windows' motion data at a parameter vector: what the per-residual Functions are mapped over.

Direct problems (``H = 1``) take each window's interval inputs, fixed once the data are bound.
Prefix problems integrate every interval once per parameter vector with the problem's scan of
the order asked for (values, first or second derivatives; see :mod:`nlp_calib.problem.motion`)
and gather each window's prefix jets at its first and last record, a block of windows at a time
as the Functions are evaluated; each order keeps its prefix jets for the last ``x`` it was asked
for.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from nlp_calib.problem import ProblemFunctions, ResidualData
from nlp_calib.solvers.backends import Backend
from nlp_calib.solvers.blocks import Mapped, Scan


def padded_index(index: np.ndarray, n: int) -> np.ndarray:
    """``index`` padded to ``n`` entries with copies of its first (padding windows weigh 0)."""
    out = np.full(n, index[0] if index.size else 0, dtype=np.intp)
    out[: index.size] = index
    return out


@functools.lru_cache(maxsize=32)
def reads(step: ca.Function) -> np.ndarray:
    """The free coordinates ``step`` reads (the kinematic ones): points equal in them have its
    prefix jets to the bit (a step of the mount's or the clock's integrates nothing). Once per
    step: CasADi walks the step's graph to tell (milliseconds, at every evaluator bound)."""
    out = np.flatnonzero(step.which_depends("x", [step.name_out(0)], 1, False))
    out.setflags(write=False)
    return out


class _Scan:
    """One order's prefix scan and its prefix jets; the windows' motion data are gathered from
    them a block of windows at a time (:meth:`fill`), never held whole."""

    def __init__(
        self, fns: ProblemFunctions, backend: Backend, order: int, inputs: np.ndarray, ends: np.ndarray
    ):
        step = fns.step(order)
        self.rows = step.nnz_in(0)
        n_pad = inputs.shape[1]
        # Column r: the jet after r intervals; column 0 the identity (zeros).
        self.poses = np.zeros((self.rows, n_pad + 1), order="F")
        self._ends = ends
        self._scan = Scan(backend, step, inputs, self.poses)
        self._reads = reads(step)
        self.at: bytes | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return 2 * self.rows, self._ends.size // 2

    def update(self, x: np.ndarray, x_fixed: np.ndarray) -> _Scan:
        key = np.asarray(x, dtype=float)[self._reads].tobytes()
        if self.at != key:
            self._scan.evaluate(x=x, x_fixed=x_fixed)
            self.at = key
        return self

    def fill(self, lo: int, hi: int, out: np.ndarray) -> None:
        """Windows ``lo:hi``'s motion data into ``out`` ``(2 rows, hi - lo)``: their prefix jets at
        their first and last record, side by side."""
        _gather(self.poses, self.rows, self._ends[2 * lo : 2 * hi], out)

    def picked(self, windows: np.ndarray) -> _Picked:
        """The motion data of ``windows`` alone (gathered from these prefix jets)."""
        ends = np.empty(2 * windows.size, dtype=np.intp)
        ends[0::2], ends[1::2] = self._ends[2 * windows], self._ends[2 * windows + 1]
        return _Picked(self.poses, self.rows, ends)


class _Picked:
    """Some windows' motion data, gathered from prefix jets ``poses`` at their records ``ends``
    (first and last of each, interleaved) a block at a time."""

    def __init__(self, poses: np.ndarray, rows: int, ends: np.ndarray) -> None:
        self.poses, self.rows, self._ends = poses, rows, ends

    @property
    def shape(self) -> tuple[int, int]:
        return 2 * self.rows, self._ends.size // 2

    def fill(self, lo: int, hi: int, out: np.ndarray) -> None:
        _gather(self.poses, self.rows, self._ends[2 * lo : 2 * hi], out)


def _gather(poses: np.ndarray, rows: int, ends: np.ndarray, out: np.ndarray) -> None:
    """The prefix jets at the records ``ends`` into ``out`` ``(2 rows, ends / 2)``, a window's two
    side by side."""
    # Row gathers on the transposed (C-contiguous) views: one copy of each jet, no temporaries
    # (a column gather of column-major arrays goes through a strided copy of everything).
    gathered = out.reshape(rows, -1, order="F").T
    np.take(poses.T, ends, axis=0, out=gathered, mode="clip")


class WindowMotion:
    """Motion data of the windows of ``data`` (padded to ``n_padded``) at any derivative order."""

    def __init__(self, fns: ProblemFunctions, backend: Backend, data: ResidualData, n_padded: int) -> None:
        self.fns = fns
        self.backend = backend
        self.prefix = fns.prefix
        self.starts = padded_index(data.starts, n_padded)
        self.stops = padded_index(data.stops, n_padded)
        self.n_intervals = data.inputs.shape[1]
        if not self.prefix:
            self.direct = np.zeros((fns.motion_rows(1), n_padded), order="F")
            self.set_inputs(data.inputs)
            return
        self.inputs = np.zeros((fns.n_inputs, backend.padded_intervals(self.n_intervals)), order="F")
        # A window's motion is its prefix jets at its first and last record, side by side.
        self._ends = np.empty(2 * n_padded, dtype=np.intp)
        self._ends[0::2], self._ends[1::2] = self.starts, self.stops
        self._scans: dict[int, _Scan] = {}
        self.set_inputs(data.inputs)

    def buffer(self, order: int) -> Mapped:
        """Where the motion data of ``order`` come from (what a Function maps over): an array, or
        the prefix jets they are gathered from a block at a time."""
        if not self.prefix:
            return self.direct
        if order not in self._scans:
            self._scans[order] = _Scan(self.fns, self.backend, order, self.inputs, self._ends)
        return self._scans[order]

    def set_inputs(self, inputs: np.ndarray) -> None:
        """New interval inputs for the same windows (e.g. encoders re-sampled on another clock)."""
        if not self.prefix:
            self.direct[:] = inputs[:, self.starts]
            return
        self.inputs[:, : self.n_intervals] = inputs
        for scan in self._scans.values():
            scan.at = None

    def update(
        self, order: int, x: np.ndarray, x_fixed: np.ndarray, windows: np.ndarray | None = None
    ) -> Mapped:
        """The windows' motion data of ``order`` at ``x`` (see :meth:`buffer`); only those of the
        window indices ``windows`` when given."""
        if not self.prefix:
            return self.direct if windows is None else np.asfortranarray(self.direct[:, windows])
        self.buffer(order)
        scan = self._scans[order].update(x, x_fixed)
        return scan if windows is None else scan.picked(windows)

    def poses(self, x: np.ndarray, x_fixed: np.ndarray) -> np.ndarray:
        """Prefix poses at ``x``, ``(3, padded intervals + 1)`` (prefix problems)."""
        self.update(0, x, x_fixed)
        return self._scans[0].poses
