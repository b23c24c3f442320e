"""A robot's own (vendor's) odometry: a base pose ``(x, y, θ)`` per cycle, integrated by the
vendor's controller from the wheels with its own model.

The model turns it back into the readings it was made from (a differential drive: each step an
arc, the wheels' travel ``s ∓ b₀Δθ/2`` over their radii): what the joints would have published had
the vendor's model been right, so that calibrating from them gives the true parameters and their
ratios to the vendor's are the corrections its controller takes. The file format is text, one pose
per line, ``t x y θ`` (seconds, m, m, rad; ``#`` lines are comments), as ``nav_msgs/Odometry``
reduced to the plane.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.logs.log import frozen
from nlp_calib.logs.text_tables import Layout, first_row, read_table, seconds

LAYOUT = "'t x y theta' (4 numbers)"


@dataclass(frozen=True)
class Odometry:
    """Base poses ``(n, 3)`` at stamps ``time_ns``, with each one's line (or message number)."""

    path: str
    time_ns: np.ndarray
    poses: np.ndarray
    line_numbers: np.ndarray


def read_odometry(path: str | Path) -> Odometry:
    """Read a ``t x y θ`` file (see the module docstring), spaces or commas between the numbers: a
    block at a time, into arrays (memory: the arrays, not a Python object per value)."""
    p = str(path)
    first = first_row(path)
    sep = b"," if first is not None and "," in first[1] else None
    layout = Layout(3, sep, LAYOUT, miscount="has {n} columns; an odometry line is {words}")
    table = read_table(path, layout)
    if table.rows < 2:
        raise DatasetError(
            p, None, f"holds {table.rows} pose(s); odometry needs at least 2 lines of {LAYOUT}"
        )
    return Odometry(p, frozen(table.time_ns), frozen(table.values), frozen(table.line_numbers))


def format_odometry(time_ns: np.ndarray, base: np.ndarray) -> str:
    """``t x y θ`` text of base poses ``(n, 3)`` at stamps ``time_ns``, every value exact."""
    return "".join(
        " ".join([seconds(int(t)), *(repr(float(v)) for v in row)]) + "\n"
        for t, row in zip(np.asarray(time_ns).tolist(), np.asarray(base, dtype=float))
    )
