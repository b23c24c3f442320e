"""A joint log as CSV: a header row ``time,<joint>,<joint>,…`` then one row per sample.

Times in seconds, joint positions in radians (a wheel's angle grows without wrapping as it
turns; a joint that steers gives its angle); ``#`` lines are comments. Rows with another number of
fields, values that are not finite numbers and times that do not increase are refused with the
file and the line.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.logs.log import frozen
from nlp_calib.logs.tables import check_time_order, data_lines, numbers

TIME_COLUMN = "time"


@dataclass(frozen=True)
class JointLog:
    """Joint positions ``(n, len(names))`` (rad) at absolute times ``time_s`` (s)."""

    path: str
    time_s: np.ndarray
    names: tuple[str, ...]
    positions: np.ndarray
    line_numbers: np.ndarray

    def column(self, name: str) -> np.ndarray:
        """The positions of joint ``name``."""
        if name not in self.names:
            raise DatasetError(self.path, None, f"has no joint {name!r}; its joints are {list(self.names)}")
        return self.positions[:, self.names.index(name)]


def _header(path: str, line: int, text: str) -> tuple[str, ...]:
    names = tuple(f.strip() for f in text.split(","))
    layout = f"a header row '{TIME_COLUMN},<joint>,<joint>,…'"
    if names[0].lower() != TIME_COLUMN or len(names) < 2:
        raise DatasetError(path, line, f"the first row is {text!r}; expected {layout}")
    joints = names[1:]
    if any(not n for n in joints) or len(set(joints)) != len(joints):
        raise DatasetError(path, line, f"joint names must be non-empty and distinct, got {list(joints)}")
    return joints


def read_joints_csv(path: str | Path) -> JointLog:
    """Read a joint CSV; a malformed row raises :class:`DatasetError` naming ``file:line``."""
    p = str(path)
    lines = data_lines(path)
    first = next(lines, None)
    if first is None:
        raise DatasetError(p, None, f"is empty; expected a header row '{TIME_COLUMN},<joint>,…' and rows")
    names = _header(p, *first)
    layout = f"{len(names) + 1} comma-separated numbers ({TIME_COLUMN},{','.join(names)})"
    rows, numbers_at = [], []
    for number, text in lines:
        fields = text.split(",")
        if len(fields) != len(names) + 1:
            raise DatasetError(p, number, f"has {len(fields)} fields; expected {layout}")
        rows.append(numbers(p, number, fields, layout))
        numbers_at.append(number)
    if len(rows) < 2:
        raise DatasetError(p, None, f"holds {len(rows)} row(s); a joint log needs at least 2")
    table = np.array(rows)
    line_numbers = np.array(numbers_at, dtype=np.int64)
    check_time_order(p, table[:, 0], line_numbers)
    return JointLog(p, frozen(table[:, 0]), names, frozen(table[:, 1:]), frozen(line_numbers))


def format_joints_csv(time_s: np.ndarray, names: Sequence[str], positions: np.ndarray) -> str:
    """CSV text of joint positions ``(n, len(names))`` at times ``time_s``."""
    head = ",".join([TIME_COLUMN, *names]) + "\n"
    body = "".join(
        f"{t:.9f}," + ",".join(f"{v:.15g}" for v in row) + "\n" for t, row in zip(time_s, positions)
    )
    return head + body
