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
from nlp_calib.logs.text_tables import check_increasing, data_lines, numbers, seconds, stamp_ns

LAYOUT = "'t x y theta' (4 numbers)"


@dataclass(frozen=True)
class Odometry:
    """Base poses ``(n, 3)`` at stamps ``time_ns``, with each one's line (or message number)."""

    path: str
    time_ns: np.ndarray
    poses: np.ndarray
    line_numbers: np.ndarray


def read_odometry(path: str | Path) -> Odometry:
    """Read a ``t x y θ`` file (see the module docstring)."""
    p = str(path)
    stamps, rows, lines = [], [], []
    for number, text in data_lines(path):
        fields = text.replace(",", " ").split()
        if len(fields) != 4:
            raise DatasetError(p, number, f"has {len(fields)} columns; an odometry line is {LAYOUT}")
        rows.append(numbers(p, number, fields[1:], LAYOUT))
        stamps.append(stamp_ns(fields[0], p, number))
        lines.append(number)
    if len(rows) < 2:
        raise DatasetError(p, None, f"holds {len(rows)} pose(s); odometry needs at least 2 lines of {LAYOUT}")
    time_ns, line_numbers = np.array(stamps, dtype=np.int64), np.array(lines, dtype=np.int64)
    check_increasing(p, time_ns, line_numbers)
    return Odometry(p, frozen(time_ns), frozen(np.array(rows, dtype=float)), frozen(line_numbers))


def format_odometry(time_ns: np.ndarray, base: np.ndarray) -> str:
    """``t x y θ`` text of base poses ``(n, 3)`` at stamps ``time_ns``, every value exact."""
    return "".join(
        " ".join([seconds(int(t)), *(repr(float(v)) for v in row)]) + "\n"
        for t, row in zip(np.asarray(time_ns).tolist(), np.asarray(base, dtype=float))
    )
