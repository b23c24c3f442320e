"""A joint log as CSV: a header row ``time,<joint>,<joint>,…`` then one row per sample.

Times in seconds (read to the nanosecond), joint positions in radians as ROS publishes them
(REP 103: a wheel's angle grows without wrapping as it turns; an absolute joint's is its angle);
``#`` lines are comments. A row with another number of fields, a value that is not a finite
number and a time that does not increase are refused with the file and the line.

A wheel's column may hold another form (:data:`WHEEL_FORMS`): its speed (rad/s), a velocity of
the joints' stream integrated over the stamps by trapezoids as a bag's are
(:func:`~nlp_calib.logs.bag_joints.joint_positions`), or its increment over each cycle (the cycle
that ends at the row's stamp; counts, turned into radians by the counts per turn, or radians),
summed (:func:`wheel_positions`). An absolute joint's column (an angle it reads as it is) is
always its position.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.logs.log import frozen
from nlp_calib.logs.text_tables import Keep, Layout, first_row, read_table, seconds

TIME_COLUMN = "time"
#: What a wheel's column holds: its angle (rad), its speed (rad/s) or its increment per cycle.
WHEEL_FORMS = ("positions", "speeds", "increments")


@dataclass(frozen=True)
class JointTable:
    """Joint positions ``(n, len(names))`` (rad) at stamps ``time_ns``, with each row's line (the
    rows kept of the file's ``rows``)."""

    path: str
    time_ns: np.ndarray
    names: tuple[str, ...]
    positions: np.ndarray
    line_numbers: np.ndarray
    #: Rows the file holds (those kept are ``time_ns``'s), and the times of its first and last.
    rows: int = 0
    span_ns: tuple[int, int] = (0, 0)

    @property
    def time_s(self) -> np.ndarray:
        """The stamps in seconds (absolute: float64 keeps them to about 0.2 µs)."""
        return self.time_ns.astype(float) * 1e-9

    def column(self, name: str) -> np.ndarray:
        """The positions of joint ``name``."""
        return self.columns((name,), "joint")[:, 0]

    def columns(self, joints: Sequence[str], where: str) -> np.ndarray:
        """The positions of ``joints``, in that order; a joint the file lacks is an error naming
        ``where`` (the key that names it) and the joints it has."""
        missing = [j for j in joints if j not in self.names]
        if missing:
            raise DatasetError(
                self.path,
                None,
                f"has no joint {missing[0]!r} ({where}); its joints are {', '.join(self.names)}",
            )
        return self.positions[:, [self.names.index(j) for j in joints]]


def _names(path: str, line: int, text: str) -> tuple[str, ...]:
    names = tuple(f.strip() for f in text.split(","))
    if names[0].lower() != TIME_COLUMN or len(names) < 2:
        raise DatasetError(
            path, line, f"the first row is {text[:80]!r}; expected a header row 'time,<joint>,…'"
        )
    joints = names[1:]
    if not all(joints) or len(set(joints)) != len(joints):
        raise DatasetError(path, line, f"joint names must be non-empty and distinct, got {list(joints)}")
    return joints


def read_joint_csv(path: str | Path, keep: Keep | None = None) -> JointTable:
    """Read a CSV joint log (see the module docstring); ``keep``: which rows to keep, by their
    times (ns): a long log of which a few seconds are wanted costs those seconds."""
    p = str(path)
    header = first_row(path)
    if header is None:
        raise DatasetError(p, None, "is empty; expected a header row 'time,<joint>,…' and rows")
    names = _names(p, *header)
    words = f"{len(names) + 1} comma-separated numbers ({TIME_COLUMN},{','.join(names)})"
    table = read_table(path, Layout(len(names), b",", words, header=True), keep)
    if table.rows < 2:
        raise DatasetError(p, None, f"holds {table.rows} row(s); a joint log needs at least 2")
    return JointTable(
        p,
        frozen(table.time_ns),
        names,
        frozen(table.values),
        frozen(table.line_numbers),
        table.rows,
        (table.first_ns, table.last_ns),
    )


def format_joint_csv(time_ns: np.ndarray, names: Sequence[str], positions: np.ndarray) -> str:
    """The CSV text of joint positions ``(n, len(names))`` at stamps ``time_ns``, every value exact."""
    head = ",".join([TIME_COLUMN, *names]) + "\n"
    rows = (
        seconds(int(t)) + "," + ",".join(repr(float(v)) for v in row) + "\n"
        for t, row in zip(time_ns.tolist(), positions)
    )
    return head + "".join(rows)


#: A row whose stamp follows the one before by more than this many times the log's median cycle
#: has rows lost before it (a logger that skips cycles).
LOST_CYCLES = 1.5


def lost_rows(time_ns: np.ndarray) -> np.ndarray:
    """The rows (indices) that rows were lost before: their stamp follows the one before by more
    than :data:`LOST_CYCLES` times the median cycle. Only per-cycle increments lose motion there
    (positions are interpolated across, speeds integrated)."""
    dt = np.diff(np.asarray(time_ns, dtype=np.int64))
    if dt.size < 3:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(dt.astype(float) > LOST_CYCLES * float(np.median(dt))) + 1


def wheel_positions(
    time_ns: np.ndarray, values: np.ndarray, wheels: Sequence[bool], form: str, counts_per_turn: float | None
) -> np.ndarray:
    """Each joint's position (rad) at the stamps from its column ``values`` in ``form`` (see the
    module docstring); only the columns ``wheels`` marks take the form, the others are positions.
    A wheel's position starts at 0 where it is integrated or summed."""
    out = np.array(values, dtype=float)
    cols = np.flatnonzero(np.asarray(wheels, dtype=bool))
    if form == "positions" or cols.size == 0:
        return out
    if form == "speeds":  # a stream's velocities (see the module docstring), never positions here
        raise ValueError("speeds are integrated with the joints' stream, not read as positions")
    per_count = 2.0 * np.pi / counts_per_turn if counts_per_turn is not None else 1.0
    steps = out[1:, cols] * per_count  # the first row's increment ends at the log's first stamp
    out[:, cols] = np.vstack([np.zeros((1, cols.size)), np.cumsum(steps, axis=0)])
    return out
