"""From logs to the windows a fit is made of: which records each residual spans, and its data.

One or several logs are laid end to end: their records are numbered consecutively (log ``i``'s
record ``r`` is record ``offsets[i] + r``), and interval ``j`` joins records ``j`` and ``j + 1``.
The interval joining one log's last record to the next log's first is zero and belongs to no
window. A window is any pair of records ``start < stop`` of one log; its residual compares the
motion the model predicts over intervals ``start … stop - 1`` with the tracker's motion
``z = t2v(T(p_start)⁻¹·T(p_stop))``. The evaluator integrates the intervals once per evaluation
(see :mod:`nlp_calib.problem.motion`), so the windows are only a list of pairs: dropping some, or
adding another log's, is a matter of selecting pairs.

A log whose reference measures its own motions (``Log.motions``: a scan matcher's, visual
odometry's) has no other windows than its increments: each joins the records at its two stamps,
and its ``z`` is the increment as measured, not a motion between two poses.
"""

from __future__ import annotations

import functools
import hashlib
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.core.numeric import pieces
from nlp_calib.core.ranges import Range, check_choice, check_range
from nlp_calib.logs import Log
from nlp_calib.models.base import INTEGRATIONS, STEERING_SAMPLES, KinematicModel
from nlp_calib.problem.clock import level_rows, record_rates
from nlp_calib.problem.functions import HORIZON, ProblemFunctions

STRIDE = Range(1, 1_000_000, integer=True)
#: ``residual.horizon_s``: a window's duration (s).
HORIZON_S = Range(0.0, 3600.0, lo_open=True)


@dataclass(frozen=True)
class ResidualOptions:
    """How residuals are formed (scenario key ``residual``): windows of ``horizon`` intervals every
    ``stride`` records, the model integrated ``exact`` or ``euler``, and where in an interval an
    angle reading is taken (``steering_sample``: at its ``start``, ``end`` or ``mean``; ``mean`` the
    default, since a reading held from the start lags half an interval and biases a fitted clock
    offset by as much; over joints streamed finer than the records, the mean as the wheels
    travelled the interval).
    ``horizon_s`` gives the windows' duration in seconds instead: the horizon in records then
    follows from each log's median interval (``nlp_calib.pipeline.prepare``)."""

    horizon: int = 1
    stride: int = 1
    integration: str = "exact"
    steering_sample: str = "mean"
    horizon_s: float | None = None

    def __post_init__(self) -> None:
        check_range("horizon", self.horizon, HORIZON)
        if self.horizon_s is not None:
            check_range("horizon_s", self.horizon_s, HORIZON_S)
        check_range("stride", self.stride, STRIDE)
        check_choice("integration", self.integration, INTEGRATIONS)
        check_choice("steering_sample", self.steering_sample, STEERING_SAMPLES)


@dataclass(frozen=True)
class WindowClock:
    """What a problem's time offsets need of the data: ``lags``, the offset each log's inputs were
    re-sampled at (s), and ``rates``, each input's rate (a level: its value) at each record."""

    lags: tuple[float, ...]
    rates: np.ndarray
    #: A log of two sensors' windows (a gyro beside the reference): per log, how much later still
    #: its second sensor's records were read (its clock's offset over the reference's), and the row
    #: of ``z`` that is 1 on that sensor's windows (None: one clock).
    beside: tuple[float, ...] = ()
    beside_row: int | None = None

    def resampled(self, which: np.ndarray, z: np.ndarray) -> np.ndarray:
        """The offset each window's inputs were re-sampled at: its log's, on a second sensor's
        window that log's second clock's (``which``: each window's log; ``z``: their measurements)."""
        out = np.asarray(self.lags, dtype=float)[which]
        if self.beside_row is not None and self.beside:
            out = out + np.asarray(self.beside, dtype=float)[which] * np.asarray(z[self.beside_row])
        return out


#: Windows :meth:`ResidualData.write_data` writes at a time: their columns of the column-major data
#: stay in the processor's cache while each row is written (a row over every window went through
#: the whole matrix's memory, a dozen times a write).
WRITE_BLOCK = 4096


@dataclass(frozen=True)
class ResidualData:
    """The windows of one fit and the data they are evaluated on (records numbered as above).

    ``inputs`` ``(n_inputs, n_records - 1)`` holds every interval's model inputs; ``T_world_sensor``
    ``(n_records, pose rows)`` the tracker's poses (in the sensor's layout: ``(x, y, theta)``, or
    ``(x, y, z, qx, qy, qz, qw)`` for a 3-D sensor); ``starts`` / ``stops`` the first and last
    record of each window; ``z`` ``(z rows, n_residuals)`` the tracker's motion over each window.
    ``offsets`` is the first record of each of ``logs``.
    """

    logs: tuple[Log, ...]
    offsets: tuple[int, ...]
    inputs: np.ndarray
    T_world_sensor: np.ndarray
    starts: np.ndarray
    stops: np.ndarray
    z: np.ndarray
    horizon: int
    dropped_stationary: int
    dropped_faulty: int = 0
    #: The windows the sensor's start left out, by reason (:func:`nlp_calib.problem.start.fit_windows`).
    dropped_selection: Mapping[str, int] | None = None
    #: Problems with a time offset: the offset each log's inputs were re-sampled at and each input's
    #: rate at each record (:mod:`nlp_calib.problem.clock`); None: no clock data.
    clock: WindowClock | None = None

    @property
    def increment(self) -> np.ndarray | None:
        """Per window, whether its ``z`` is an increment the reference measured itself (its noise
        its own, not two poses'; a log with ``motions``, a gyro's beside a tracker's poses); None:
        no log's reference gives increments."""
        kinds = [lg.reference.kind for lg in self.logs]
        if not any(k.own_increments for k in kinds):
            return None
        own, of = np.zeros(self.n_residuals, dtype=bool), self.log_of(self.starts)
        for i, kind in enumerate(kinds):
            own[of == i] = kind.own_windows(self.z[:, of == i])
        return own

    def with_selector(self) -> ResidualData:
        """These windows saying which log each belongs to (a problem with a mount per log and no
        time offset: a clock of no offsets)."""
        if self.clock is not None:
            return self
        return replace(self, clock=WindowClock((), np.zeros((0, self.n_records))))

    @property
    def log(self) -> Log:
        """The log of a single-log fit."""
        if len(self.logs) != 1:
            raise ProblemError(f"these windows come from {len(self.logs)} logs, not one")
        return self.logs[0]

    @property
    def n_residuals(self) -> int:
        return int(self.starts.size)

    @property
    def n_records(self) -> int:
        return int(self.T_world_sensor.shape[0])

    @property
    def data_rows(self) -> int:
        """The rows of :meth:`data`."""
        return self.z.shape[0] + self._n_clock_rows() + 1

    def data(self) -> np.ndarray:
        """The per-window ``data = [z, clock, w]`` matrix, column-major (see
        :attr:`ProblemFunctions.clock_rows`)."""
        out = np.empty((self.data_rows, self.n_residuals), order="F")
        self.write_data(out)
        return out

    def write_data(self, out: np.ndarray, *, clock_only: bool = False) -> None:
        """:meth:`data` written into the first :attr:`n_residuals` columns of ``out`` (column-major),
        :data:`WRITE_BLOCK` windows at a time, each row straight from its source; ``clock_only``:
        the clock rows alone, where ``out`` holds these windows' ``z`` and weights already (the
        same windows on re-sampled inputs)."""
        n, rows = self.n_residuals, self.z.shape[0]
        clock = slice(rows, rows + self._n_clock_rows())
        for lo in range(0, n, WRITE_BLOCK):
            cols = slice(lo, min(n, lo + WRITE_BLOCK))
            if not clock_only:
                out[:rows, cols] = self.z[:, cols]
                out[-1, cols] = 1.0
            self._write_clock(out[clock, cols], cols)

    def log_of(self, records: np.ndarray) -> np.ndarray:
        """The index of the log each of ``records`` belongs to."""
        return np.searchsorted(np.asarray(self.offsets), records, side="right") - 1

    def _n_clock_rows(self) -> int:
        if self.clock is None:
            return 0
        return len(self.logs) + (2 * self.clock.rates.shape[0] + 1 if self.clock.lags else 0)

    def clock_rows(self) -> np.ndarray:
        """Each window's clock data (``(0, n)`` without a time offset): the rates at its first and
        last record, its log's re-sampled offset and which log it belongs to."""
        out = np.empty((self._n_clock_rows(), self.n_residuals))
        self._write_clock(out, slice(None))
        return out

    def _write_clock(self, out: np.ndarray, cols: slice) -> None:
        """:meth:`clock_rows`' columns ``cols`` written into ``out``, row by row."""
        if self.clock is None:
            return
        starts = self.starts[cols]
        which = self.log_of(starts)
        select = out[out.shape[0] - len(self.logs) :]
        select[:] = 0.0
        select[which, np.arange(starts.size)] = 1.0
        if not self.clock.lags:
            return  # a mount per log: which log alone
        rates, stops = self.clock.rates, self.stops[cols]
        k = rates.shape[0]
        for i in range(k):
            out[i] = rates[i, starts]
            out[k + i] = rates[i, stops]
        out[2 * k] = self.clock.resampled(which, self.z[:, cols])

    def interval_counts(self, flagged: np.ndarray) -> np.ndarray:
        """How many of each window's intervals ``flagged`` (a mask over the intervals) marks."""
        c = np.concatenate([[0], np.cumsum(np.asarray(flagged, dtype=np.int64))])
        return c[self.stops] - c[self.starts]

    def select(self, keep: np.ndarray) -> ResidualData:
        """The windows ``keep`` (a mask or indices) marks, in order."""
        return replace(self, starts=self.starts[keep], stops=self.stops[keep], z=self.z[:, keep])

    def intervals_of(self, windows: np.ndarray) -> np.ndarray:
        """The intervals the windows of the indices ``windows`` cover, in order (each once)."""
        inside = np.zeros(self.inputs.shape[1] + 1, dtype=np.int64)
        np.add.at(inside, self.starts[windows], 1)
        np.add.at(inside, self.stops[windows], -1)
        return np.flatnonzero(np.cumsum(inside[:-1]) > 0)

    def spanned(self) -> ResidualData:
        """The same windows on the records they span alone, renumbered from the first: an evaluator
        bound to them integrates those intervals only, not the whole log's (a window's motion,
        ``P_a⁻¹·P_b``, does not depend on where the prefix poses start)."""
        if not self.n_residuals:
            return self
        lo, hi = int(self.starts.min()), int(self.stops.max()) + 1
        clock = self.clock
        if clock is not None:
            clock = replace(clock, rates=clock.rates[:, lo:hi])
        return replace(
            self,
            offsets=tuple(o - lo for o in self.offsets),
            inputs=self.inputs[:, lo : hi - 1],
            T_world_sensor=self.T_world_sensor[lo:hi],
            starts=self.starts - lo,
            stops=self.stops - lo,
            clock=clock,
        )

    def with_inputs(
        self, inputs: np.ndarray, lags: Sequence[float] | None = None, rates: np.ndarray | None = None
    ) -> ResidualData:
        """The same windows and tracker motions on other interval inputs (e.g. encoders re-sampled
        at the offsets ``lags``, one per log, with their ``rates`` at the records, when the problem
        has them)."""
        if inputs.shape != self.inputs.shape:
            raise ProblemError(f"inputs of shape {inputs.shape} do not fit {self.inputs.shape}")
        if lags is None or rates is None or self.clock is None:
            return replace(self, inputs=inputs)
        return replace(
            self, inputs=inputs, clock=replace(self.clock, lags=tuple(float(v) for v in lags), rates=rates)
        )

    def columns_of(self, windows: np.ndarray | slice) -> np.ndarray:
        """One column ``[u_0 … u_{H-1}, z, w]`` per window, as the defining ``residual`` takes it."""
        starts, lengths = self.starts[windows], self.stops[windows] - self.starts[windows]
        if np.any(lengths != self.horizon):
            raise ProblemError(f"only windows of {self.horizon} intervals have a column layout")
        n_in, H = self.inputs.shape[0], self.horizon
        data = self.data()[:, windows]
        out = np.empty((n_in * H + data.shape[0], starts.size), order="F")
        for j in range(H):
            out[j * n_in : (j + 1) * n_in] = self.inputs[:, starts + j]
        out[n_in * H :] = data
        return out

    @functools.cached_property
    def columns(self) -> np.ndarray:
        """:meth:`columns_of` every window (``H`` times the size of the data: tests and export only)."""
        return self.columns_of(slice(None))


def window_starts(n_intervals: int, horizon: int, stride: int) -> np.ndarray:
    """First interval of every full window of ``horizon`` intervals, ``stride`` apart."""
    if n_intervals < horizon:
        return np.zeros(0, dtype=np.int64)
    return np.arange(0, n_intervals - horizon + 1, stride, dtype=np.int64)


def interval_inputs(model: KinematicModel, logs: Sequence[Log], steering_sample: str) -> np.ndarray:
    """Every interval's inputs of ``logs`` laid end to end (zeros between two logs)."""
    parts = []
    for i, log in enumerate(logs):
        if i:
            parts.append(np.zeros((len(model.input_names), 1)))
        parts.append(model.inputs(log, steering_sample))
    return np.ascontiguousarray(np.concatenate(parts, axis=1))


#: Columns a helper Function is mapped over at a time (a map over a million columns is slow to build).
BLOCK = 1 << 14
#: Records from which a run maps :func:`over_columns`' calls with compiled chunks (:func:`compile_columns`):
#: each helper is evaluated a few times per run over every interval, and the interpreter took a
#: tenth of a run of 10^6 records doing it; below, it is quick enough.
COMPILED_FROM = 50_000

#: ``(f, n, mapped inputs) -> pieces``: ``f`` over the first columns of ``n`` (the other inputs the
#: same for every column) as a compiled backend's maps, one after the other, each with the number
#: of columns it takes; the rest (fewer than a chunk) is left to CasADi's map.
ColumnMap = Callable[[ca.Function, int, tuple[str, ...]], list[tuple[ca.Function, int]]]
_column_map: list[ColumnMap] = []


def compile_columns(column_map: ColumnMap | None) -> None:
    """Map :func:`over_columns` calls with ``column_map`` from now on (None: CasADi's map,
    interpreted). Set with each run's backend: the process's runs share the helper Functions."""
    _column_map[:] = [] if column_map is None else [column_map]


@functools.lru_cache(maxsize=32)
def _mapped(f: ca.Function, n: int) -> ca.Function:
    """``f`` mapped over ``n`` columns, built once per Function and size."""
    return f.map(n)


#: A piece of a block bound to numpy memory: its buffer, its call, its inputs and its columns.
_Bound = tuple[ca.FunctionBuffer, Callable[[], None], list[np.ndarray], int]


def _bound(f: ca.Function, n: int, mapped: tuple[str, ...]) -> list[_Bound]:
    """Buffers that evaluate ``f`` over a block of ``n`` columns, one piece after the other: its
    whole chunks compiled (where a run set a column map), the rest interpreted. A block of a few
    thousand columns interpreted cost more than a run's whole compiled blocks (the lag search's
    windows, the folds' blocks, a start's windows)."""
    fms = _column_map[0](f, n, mapped) if _column_map else []
    rest = n - sum(cols for _, cols in fms)
    # The rest interpreted by maps of fixed sizes (each column's outputs its own: the same bits):
    # a map's build grows with its size, and every number of columns built its own.
    fms += [(_mapped(f, cols), cols) for cols in pieces(rest)]
    # Pieces of one size share a buffer: each is filled and bound to its outputs just before its call.
    made: dict[int, _Bound] = {}
    for fm, cols in fms:
        if id(fm) not in made:
            buf, call = fm.buffer()
            ins = [np.empty(fm.nnz_in(i)) for i in range(fm.n_in())]
            for i, arr in enumerate(ins):
                buf.set_arg(i, arr.data)
            made[id(fm)] = (buf, call, ins, cols)
    return [made[id(fm)] for fm, _ in fms]


def over_columns(f: ca.Function, *args: np.ndarray) -> list[np.ndarray]:
    """``f`` over the columns of its 2-D arguments (one column of each per call), a block at a
    time; a 1-D argument is the same for every column. Each output as CasADi's map gives it,
    ``(rows, cols * n)``. Blocks are evaluated in buffers bound to numpy memory: no conversion to
    and from CasADi's matrices (a third of the time of a call)."""
    n = next(a.shape[1] for a in args if a.ndim == 2)
    shapes = [f.size_out(i) for i in range(f.n_out())]
    outs = [np.empty((r, c * n), order="F") for r, c in shapes]
    dense = [f.sparsity_in(i).is_dense() for i in range(f.n_in())]
    if not all(dense + [f.sparsity_out(i).is_dense() for i in range(f.n_out())]):
        # A buffer holds the nonzeros only: sparse Functions go through CasADi's matrices.
        for lo in range(0, n, BLOCK):
            hi = min(n, lo + BLOCK)
            res = _mapped(f, hi - lo)(*[a[:, lo:hi] if a.ndim == 2 else a for a in args])
            for out, r, (_, c) in zip(outs, [res] if f.n_out() == 1 else res, shapes):
                out[:, c * lo : c * hi] = np.asarray(r)
        return outs
    blocks: dict[int, list[_Bound]] = {}
    mapped = tuple(f.name_in(i) for i, a in enumerate(args) if a.ndim == 2)
    for lo in range(0, n, BLOCK):
        size = min(n, lo + BLOCK) - lo
        if size not in blocks:
            blocks[size] = _bound(f, size, mapped)
        at = lo
        for buf, call, ins, cols in blocks[size]:
            for target, a in zip(ins, args):
                if a.ndim == 2:
                    # Column by column, straight from ``a`` (a ravelled copy of a row-major
                    # argument's columns was a second copy of every block).
                    target.reshape(cols, a.shape[0])[:] = a[:, at : at + cols].T
                elif a.size:  # the same column for every column of the piece (once, where compiled)
                    target.reshape(-1, a.size)[:] = np.ravel(a)
            for i, (out, (_, c)) in enumerate(zip(outs, shapes)):
                # A piece's columns of a column-major array are one contiguous run: written in place.
                buf.set_res(i, out[:, c * at : c * (at + cols)].reshape(-1, order="F").data)
            call()
            at += cols
    return outs


def tracker_motions(
    fns: ProblemFunctions, T_world_sensor: np.ndarray, a: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """The tracker's motion ``T(p_a)⁻¹·T(p_b)`` for each pair of records, ``(z rows, len(a))``."""
    if a.size == 0:
        return np.zeros((fns.sensor.z_rows, 0))
    # The lag's fits and profile build the same windows of the same poses once per lag (only the
    # encoders are re-sampled): their motions are computed once, keyed by the arrays' contents.
    key = (fns.between, *(_digest(v) for v in (T_world_sensor, a, b)))
    with _MOTIONS_LOCK:
        found = _MOTIONS.pop(key, None)
    if found is None:
        found = over_columns(fns.between, T_world_sensor[a].T, T_world_sensor[b].T)[0]
        found.flags.writeable = False
    with _MOTIONS_LOCK:
        _MOTIONS[key] = found
        while len(_MOTIONS) > _MOTIONS_KEPT:
            del _MOTIONS[next(iter(_MOTIONS))]
    return found.copy()


#: The last few :func:`tracker_motions` (most recent last): a log's, and a fold's or a part's.
_MOTIONS: dict[tuple[object, ...], np.ndarray] = {}
_MOTIONS_KEPT = 4
_MOTIONS_LOCK = threading.Lock()


def _digest(values: np.ndarray) -> tuple[object, ...]:
    """What identifies an array's contents: its type, shape and a hash of its bytes."""
    v = np.ascontiguousarray(values)
    return (v.dtype.str, v.shape, hashlib.blake2b(v.tobytes(), digest_size=16).digest())


def joined(parts: Sequence[ResidualData]) -> ResidualData:
    """The windows of several fits' data laid end to end, as :func:`build_residual_data` lays
    logs: each part's records after the previous part's, a zero interval between them."""
    if len({p.horizon for p in parts}) != 1:
        raise ProblemError(f"parts of horizons {sorted({p.horizon for p in parts})} cannot be joined")
    offsets = np.cumsum([0, *(p.n_records for p in parts)])[:-1]
    gap = np.zeros((parts[0].inputs.shape[0], 1))
    inputs = [x for i, p in enumerate(parts) for x in ([gap, p.inputs] if i else [p.inputs])]
    return ResidualData(
        logs=tuple(log for p in parts for log in p.logs),
        offsets=tuple(int(o + q) for o, p in zip(offsets, parts) for q in p.offsets),
        inputs=np.ascontiguousarray(np.concatenate(inputs, axis=1)),
        T_world_sensor=np.ascontiguousarray(np.concatenate([p.T_world_sensor for p in parts])),
        starts=np.concatenate([p.starts + o for p, o in zip(parts, offsets)]),
        stops=np.concatenate([p.stops + o for p, o in zip(parts, offsets)]),
        z=np.concatenate([p.z for p in parts], axis=1),
        horizon=parts[0].horizon,
        dropped_stationary=sum(p.dropped_stationary for p in parts),
        dropped_faulty=sum(p.dropped_faulty for p in parts),
        dropped_selection=_summed([p.dropped_selection for p in parts]),
        clock=_joined_clock([p.clock for p in parts]),
    )


def appended(
    fns: ProblemFunctions,
    data: ResidualData,
    stretch: tuple[np.ndarray, np.ndarray, np.ndarray],
    options: ResidualOptions,
) -> ResidualData:
    """``data`` with a stretch of driving appended to its last log: ``stretch`` is the stretch's
    record times (s), its interval inputs ``(n_inputs, n - 1)`` and its tracker poses (in the
    sensor's layout), laid after the last record as another log would be (a zero interval between,
    no window across) but on the last log's clock (its time offset). The new windows are the last
    ones; a manoeuvre a plan proposes is judged on them."""
    time_s, inputs, poses = stretch
    H, n0 = options.horizon, data.n_records
    starts = n0 + window_starts(inputs.shape[1], H, options.stride)
    all_poses = np.ascontiguousarray(np.concatenate([data.T_world_sensor, poses]))
    clock = data.clock
    if clock is not None:
        # A clock of no offsets (a mount per log) says only which log a window belongs to.
        rates = (
            record_rates(inputs, time_s, level_rows(fns.model)) if clock.lags else np.zeros((0, time_s.size))
        )
        clock = replace(clock, rates=np.concatenate([clock.rates, rates], axis=1))
    return replace(
        data,
        inputs=np.ascontiguousarray(
            np.concatenate([data.inputs, np.zeros((inputs.shape[0], 1)), inputs], axis=1)
        ),
        T_world_sensor=all_poses,
        starts=np.concatenate([data.starts, starts]),
        stops=np.concatenate([data.stops, starts + H]),
        z=np.concatenate([data.z, tracker_motions(fns, all_poses, starts, starts + H)], axis=1),
        clock=clock,
    )


def _joined_clock(clocks: Sequence[WindowClock | None]) -> WindowClock | None:
    """Parts' clock data end to end (None when a part has none)."""
    given = [c for c in clocks if c is not None]
    if len(given) < len(clocks):
        return None
    return WindowClock(
        tuple(v for c in given for v in c.lags),
        np.concatenate([c.rates for c in given], axis=1),
        tuple(v for c in given for v in (c.beside or (0.0,) * len(c.lags))),
        given[0].beside_row,
    )


def log_rates(model: KinematicModel, logs: Sequence[Log], inputs: np.ndarray) -> np.ndarray:
    """Each input's rate at every record of ``logs`` laid end to end (``inputs`` as
    :func:`interval_inputs` lays them): the model's own where it has them, else the intervals'."""
    parts, first = [], 0
    for log in logs:
        exact = model.input_rates(log)
        u = inputs[:, first : first + log.n_records - 1]
        parts.append(exact if exact is not None else record_rates(u, log.time_s, level_rows(model)))
        first += log.n_records
    return np.concatenate(parts, axis=1)


def _summed(counts: Sequence[Mapping[str, int] | None]) -> dict[str, int] | None:
    """Counts by reason added up (None when no part has any)."""
    given = [c for c in counts if c is not None]
    if not given:
        return None
    return {r: sum(c.get(r, 0) for c in given) for r in given[0]}


def tracker_poses(fns: ProblemFunctions, log: Log) -> np.ndarray:
    """The log's tracker poses in the layout of the problem's sensor."""
    return fns.sensor.poses(log)


def build_residual_data(
    fns: ProblemFunctions,
    log: Log | Sequence[Log],
    options: ResidualOptions,
    *,
    drop_stationary: bool = False,
    bad_intervals: np.ndarray | None = None,
    bad_records: np.ndarray | None = None,
    inputs: np.ndarray | None = None,
    gaps: np.ndarray | None = None,
) -> ResidualData:
    """The windows of ``options`` over ``log`` (or several logs, end to end, no window crossing
    from one into the next).

    Windows in which no encoder moves are dropped when ``drop_stationary``; windows that cross an
    interval of ``bad_intervals`` (a mask over the intervals) or start or end at a record of
    ``bad_records`` (over the records) are always dropped, and so are those that cross an interval of
    ``gaps`` (the streams' gaps: not counted as left out for faults). ``inputs`` gives the intervals' model
    inputs (laid out as :func:`interval_inputs` lays them) when they do not come from the logs'
    encoders, e.g. joint positions paired with a camera's images.
    """
    if options.horizon != fns.spec.horizon:
        raise ProblemError(
            f"data horizon {options.horizon} does not match the built problem's {fns.spec.horizon}"
        )
    logs = (log,) if isinstance(log, Log) else tuple(log)
    H = options.horizon
    offsets = tuple(int(v) for v in np.cumsum([0, *(lg.n_records for lg in logs)])[:-1])
    if inputs is None:
        inputs = interval_inputs(fns.model, logs, options.steering_sample)
    elif inputs.shape != (fns.n_inputs, sum(lg.n_records for lg in logs) - 1):
        raise ProblemError(f"inputs of shape {inputs.shape} do not fit the logs' intervals")
    parts = [_log_windows(fns, lg, o, H, options.stride) for o, lg in zip(offsets, logs)]
    starts = np.concatenate([p[0] for p in parts]).astype(np.int64)
    stops = np.concatenate([p[1] for p in parts]).astype(np.int64)
    poses = np.ascontiguousarray(np.concatenate([tracker_poses(fns, lg) for lg in logs]))
    z = tracker_motions(fns, poses, starts, stops)
    if any(p[2] is not None for p in parts):
        measured = np.concatenate([np.full(p[0].size, p[2] is not None) for p in parts])
        z[:, measured] = np.concatenate([p[2] for p in parts if p[2] is not None], axis=1)
    data = ResidualData(
        logs=logs,
        offsets=offsets,
        inputs=inputs,
        T_world_sensor=poses,
        starts=starts,
        stops=stops,
        z=z,
        horizon=H,
        dropped_stationary=0,
        clock=_window_clock(fns, logs, inputs) if fns.spec.lags else None,
    )
    if fns.select_rows and data.clock is None:
        data = data.with_selector()
    if drop_stationary and starts.size:
        keep = data.interval_counts(fns.model.moving(inputs)) > 0
        data = replace(data.select(keep), dropped_stationary=int((~keep).sum()))
    return _without_faults(data, bad_intervals, bad_records, gaps)


def resampled_data(
    fns: ProblemFunctions, data: ResidualData, logs: Sequence[Log], steering_sample: str
) -> ResidualData:
    """``data``'s windows on ``logs``: the logs ``data`` was built from with their encoders re-sampled
    at other offsets. The inputs and clock data are computed again; the windows, the tracker's poses
    and motions are kept, for they do not depend on the encoders (the caller's to know: windows
    dropped as stationary, or chosen from the inputs, do)."""
    inputs = interval_inputs(fns.model, logs, steering_sample)
    if inputs.shape != data.inputs.shape:
        raise ProblemError(f"inputs of shape {inputs.shape} do not fit {data.inputs.shape}")
    clock = _window_clock(fns, logs, inputs) if fns.spec.lags else data.clock
    return replace(data, logs=tuple(logs), inputs=inputs, clock=clock)


def _window_clock(fns: ProblemFunctions, logs: Sequence[Log], inputs: np.ndarray) -> WindowClock:
    """The offsets ``logs``' inputs were re-sampled at (each clock's) and the inputs' rates."""
    lags = tuple(lg.encoder_lag_s for lg in logs)
    beside = tuple(lg.clock.beside_lag_s for lg in logs)
    return WindowClock(lags, log_rates(fns.model, logs, inputs), beside, fns.sensor.beside_row)


def _log_windows(
    fns: ProblemFunctions, log: Log, offset: int, horizon: int, stride: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The first and last records of one log's windows (numbered from ``offset``), and their
    measured motions when the log's reference gives its own increments (None: from its poses)."""
    inc = log.motions
    if inc is None:
        first = offset + window_starts(log.n_records - 1, horizon, stride)
        return first, first + horizon, None
    if inc.z.shape[1] != fns.sensor.z_rows:
        what, needs = ("planar motions", "a planar sensor (sensor: planar)")
        if inc.z.shape[1] != 3:
            what, needs = ("a gyro's integrated rates", "a gyro (sensor: gyro)")
        raise ProblemError(
            f"{log.path}: its reference gives {what} (increments); they need {needs}, not {fns.sensor.kind}"
        )
    k = np.arange(0, inc.n, stride)
    if not fns.prefix and np.any(inc.last[k] - inc.first[k] != 1):
        raise ProblemError(
            f"{log.path}: some increments span several records (they overlap): a problem of horizon 1 "
            "compares one interval; set residual.horizon to 2 or more"
        )
    return offset + inc.first[k], offset + inc.last[k], np.ascontiguousarray(inc.z[k].T)


def _without_faults(
    data: ResidualData,
    bad_intervals: np.ndarray | None,
    bad_records: np.ndarray | None,
    gaps: np.ndarray | None = None,
) -> ResidualData:
    """``data`` without the windows that cross a bad interval or a gap or start or end at a bad
    record; ``dropped_faulty`` counts those the faults alone leave out (a window across a gap goes
    whatever the faults)."""
    faulty = np.zeros(data.n_residuals, dtype=bool)
    if bad_intervals is not None and np.any(bad_intervals):
        faulty |= data.interval_counts(bad_intervals) > 0
    if bad_records is not None and np.any(bad_records):
        bad = np.asarray(bad_records, dtype=bool)
        faulty |= bad[data.starts] | bad[data.stops]
    gapped = data.interval_counts(gaps) > 0 if gaps is not None and np.any(gaps) else np.zeros_like(faulty)
    if (faulty | gapped).any():
        data = replace(data.select(~(faulty | gapped)), dropped_faulty=int((faulty & ~gapped).sum()))
    return data
