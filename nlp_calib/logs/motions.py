"""A file of the sensor's own motions between pairs of stamps, and a log timed by them.

The file is CSV: a header row ``t_start,t_end,x,y,theta`` (more named columns may follow: what the
tool that measured each motion said of it, e.g. ``converged``, ``inliers``, ``rmse``), then one
row per increment: its two stamps (s, read to the nanosecond) and the sensor's motion from its
pose at ``t_start`` to its pose at ``t_end`` in its own frame at ``t_start`` (m, m, rad). ``#``
lines are comments. RelativeMotions may leave gaps between them, share stamps (a chain of scan
matches) or overlap (matches against a key frame).

A log timed by the motions has a record at each stamp the wheels' stream covers, the joints
interpolated there exactly as at a tracker's poses (:mod:`nlp_calib.logs.bag_joints`); an
increment whose stamps are not both covered is left out and counted.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.logs.bag_joints import at_tracker, breaks_s, check_overlap, joint_positions, joint_stream
from nlp_calib.logs.bag_reader import Stamped
from nlp_calib.logs.log import Log, LogClock, LogHeader, ReferenceData, frozen
from nlp_calib.logs.reference import Motions
from nlp_calib.logs.relative import RelativeMotions
from nlp_calib.logs.text_tables import data_lines, joined, numbers, seconds, stamp_ns

#: The columns every motions file starts with.
COLUMNS = ("t_start", "t_end", "x", "y", "theta")


@dataclass(frozen=True)
class MotionTable:
    """The increments of a motions file: stamps (ns), motions ``(n, 3)``, the file's line of
    each and the further columns by name."""

    path: str
    start_ns: np.ndarray
    end_ns: np.ndarray
    z: np.ndarray
    line_numbers: np.ndarray
    quality: Mapping[str, np.ndarray] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.start_ns.size)


def _names(path: str, line: int, text: str) -> tuple[str, ...]:
    names = tuple(f.strip() for f in text.split(","))
    if names[: len(COLUMNS)] != COLUMNS:
        raise DatasetError(
            path,
            line,
            f"the first row is {text[:80]!r}; expected a header row '{','.join(COLUMNS)}' (further "
            "named columns may follow)",
        )
    extra = names[len(COLUMNS) :]
    if not all(extra) or len(set(names)) != len(names):
        raise DatasetError(path, line, f"column names must be non-empty and distinct, got {list(names)}")
    return names


#: Rows converted to arrays at a time: a large file costs its arrays, not a Python object per value.
ROWS_PER_BLOCK = 1 << 16


def _block(
    rows: list[list[float]], starts: list[int], ends: list[int], at: list[int]
) -> tuple[np.ndarray, ...]:
    out = (
        np.array(starts, dtype=np.int64),
        np.array(ends, dtype=np.int64),
        np.array(rows, dtype=float),
        np.array(at, dtype=np.int64),
    )
    for part in (rows, starts, ends, at):
        part.clear()
    return out


def _rows(p: str, lines: Iterator[tuple[int, str]], names: tuple[str, ...]) -> list[tuple[np.ndarray, ...]]:
    """The rows after the header, as arrays a block at a time: stamps, values, lines."""
    layout = f"{len(names)} comma-separated numbers ({','.join(names)})"
    starts: list[int] = []
    ends: list[int] = []
    rows: list[list[float]] = []
    at: list[int] = []
    blocks = []
    for number, text in lines:
        fields = text.split(",")
        if len(fields) != len(names):
            raise DatasetError(p, number, f"has {len(fields)} fields; expected {layout}")
        a, b = stamp_ns(fields[0], p, number), stamp_ns(fields[1], p, number)
        if b <= a:
            raise DatasetError(
                p,
                number,
                f"t_end {seconds(b)} is not after t_start {seconds(a)}; an increment runs forward over "
                "an interval of its own",
            )
        starts.append(a)
        ends.append(b)
        rows.append(numbers(p, number, fields[2:], layout))
        at.append(number)
        if len(at) == ROWS_PER_BLOCK:
            blocks.append(_block(rows, starts, ends, at))
    if at:
        blocks.append(_block(rows, starts, ends, at))
    return blocks


def _once_each(p: str, table: MotionTable) -> MotionTable:
    """Each interval once: a row whose stamps repeat an earlier row's is dropped (a row written
    twice would count its motion twice, and the σ come out too small), and said; increments that
    chain (each starting where one ended) with some missing between them are said too."""
    order = np.lexsort((table.end_ns, table.start_ns))
    start, end = table.start_ns[order], table.end_ns[order]
    again = (start[1:] == start[:-1]) & (end[1:] == end[:-1])
    del start, end
    if not again.any():
        _say_lost(p, table)
        return table
    keep = np.ones(table.n, dtype=bool)
    keep[order[1:][again]] = False
    del order, again
    if keep.sum() < table.n:
        lines = table.line_numbers[~keep]
        warnings.warn(
            f"{p}: {table.n - int(keep.sum())} of {table.n} rows repeat the interval of an earlier row "
            f"(first on line {int(lines[0])}); each interval is kept once, from its first row",
            NlpCalibWarning,
            stacklevel=3,
        )
    kept = MotionTable(
        table.path,
        frozen(table.start_ns[keep]),
        frozen(table.end_ns[keep]),
        frozen(table.z[keep]),
        frozen(table.line_numbers[keep]),
        {k: frozen(v[keep]) for k, v in table.quality.items()},
    )
    _say_lost(p, kept)
    return kept


def _say_lost(p: str, table: MotionTable) -> None:
    """A chain of increments (most starting where the one before ended) with links missing: the rows
    a logger lost leave a wheel stretch with no reference, said with its count."""
    if table.n < 3:
        return
    in_order = bool(np.all(table.start_ns[1:] >= table.start_ns[:-1]))
    order = slice(None) if in_order else np.argsort(table.start_ns, kind="stable")
    start, end = table.start_ns[order], table.end_ns[order]
    chained = start[1:] == end[:-1]
    gaps = start[1:] > end[:-1]
    if chained.mean() >= 0.5 and gaps.any():
        k = int(np.flatnonzero(gaps)[0]) + 1
        warnings.warn(
            f"{p}: the increments chain (each starts where one ends) but {int(gaps.sum())} links are "
            f"missing (first before line {int(table.line_numbers[order][k])}, {seconds(int(end[k - 1]))} to "
            f"{seconds(int(start[k]))}): rows lost by the logger? The stretches without a row have no "
            "reference",
            NlpCalibWarning,
            stacklevel=4,
        )


def read_motions(path: str | Path) -> MotionTable:
    """Read a motions file (see the module docstring); a malformed row is an error naming its line.
    Rows are read into arrays a block at a time (memory: the arrays)."""
    p = str(path)
    lines = data_lines(path)
    first = next(lines, None)
    if first is None:
        raise DatasetError(p, None, f"is empty; expected a header row '{','.join(COLUMNS)}' and rows")
    names = _names(p, *first)
    blocks = _rows(p, lines, names)
    if not blocks:
        raise DatasetError(p, None, "holds no increment")
    starts, ends, values, at = joined(blocks, 4)
    quality = {n: frozen(values[:, 3 + i].copy()) for i, n in enumerate(names[len(COLUMNS) :])}
    z = values if values.shape[1] == 3 else values[:, :3].copy()
    del values
    return _once_each(p, MotionTable(p, frozen(starts), frozen(ends), frozen(z), frozen(at), quality))


def format_motions(
    start_ns: np.ndarray, end_ns: np.ndarray, z: np.ndarray, quality: Mapping[str, np.ndarray] | None = None
) -> str:
    """The CSV text of increments (see the module docstring), every value exact."""
    extra = dict(quality or {})
    head = ",".join([*COLUMNS, *extra]) + "\n"
    rows = (
        ",".join([seconds(int(a)), seconds(int(b)), *(repr(float(v)) for v in (*row, *more))]) + "\n"
        for a, b, row, *more in zip(start_ns.tolist(), end_ns.tolist(), np.asarray(z, float), *extra.values())
    )
    return head + "".join(rows)


def _records(
    p: Path, joint_ns: np.ndarray, motions: MotionTable, max_gap_s: float
) -> tuple[np.ndarray, np.ndarray, str]:
    """The records' stamps (those of the increments the joints cover), which increments they keep,
    and what was left out, in words."""
    stamps = np.unique(np.concatenate([motions.start_ns, motions.end_ns]))
    ok_index, timing = at_tracker(
        joint_ns, Stamped(motions.path, stamps, np.zeros((stamps.size, 0))), max_gap_s
    )
    records = stamps[np.sort(ok_index)]
    keep = np.isin(motions.start_ns, records) & np.isin(motions.end_ns, records)
    left = motions.n - int(keep.sum())
    said = (
        f"{left} of {motions.n} increments left out: their stamps lie outside the joints' stream or in "
        f"its gaps over {max_gap_s:g} s ({timing.before} stamps before the first joint message, "
        f"{timing.after} after the last, {timing.in_gaps} in gaps)"
        if left
        else ""
    )
    return records, keep, said


def timed_by_motions(
    p: Path,
    joints: Stamped,
    motions: MotionTable,
    names: Sequence[str],
    max_gap_s: float,
    header: LogHeader,
    numbered: str = "line",
) -> Log:
    """The log of ``joints`` (each joint's position, then its velocity; NaN where absent) with a
    record at each stamp of the ``motions`` the joints cover, and the increments between them;
    ``numbered``: what the motions' line numbers count (a bag topic's ``/topic message``)."""
    check_overlap(p, joints, Stamped(motions.path, motions.start_ns, np.zeros((motions.n, 0))))
    joint_ns, positions, integrated, quadrature = joint_positions(p, joints, tuple(names))
    stamps, keep, left = _records(p, joint_ns, motions, max_gap_s)
    if keep.sum() < 1:
        raise DatasetError(str(p), None, f"no increment lies inside the joints' stream ({left})")
    if left:
        warnings.warn(f"{motions.path}: {left}", NlpCalibWarning, stacklevel=3)
    start_ns = int(stamps[0])
    increments = RelativeMotions(
        frozen(np.searchsorted(stamps, motions.start_ns[keep]).astype(np.int64)),
        frozen(np.searchsorted(stamps, motions.end_ns[keep]).astype(np.int64)),
        frozen(motions.z[keep]),
        frozen(motions.line_numbers[keep]),
        {k: frozen(v[keep]) for k, v in motions.quality.items()},
    )
    stream_s = frozen((joint_ns - start_ns).astype(float) * 1e-9)
    breaks = breaks_s(joints, start_ns)
    stream = joint_stream(stream_s, positions, tuple(names), integrated, header, breaks, quadrature)
    time_s = frozen((stamps - start_ns).astype(float) * 1e-9)
    n = int(stamps.size)
    # A record's "line" is that of the first increment that starts or ends there.
    line = np.zeros(n, dtype=np.int64)
    for idx in (increments.last, increments.first):
        line[idx[::-1]] = increments.line_numbers[::-1]
    return Log(
        path=str(p),
        header=header,
        time_s=time_s,
        ticks=frozen(np.zeros((n, 0), dtype=np.int64)),
        model_pose=frozen(np.zeros((n, 3))),
        T_world_sensor=frozen(increments.chain(n)),
        line_numbers=frozen(line),
        clock=LogClock(start_ns=start_ns),
        joint_positions=stream.at(time_s),
        joint_stream=stream,
        reference=ReferenceData(motions=increments, measures=Motions.name, numbered=numbered),
    )
