"""A robot's own (vendor's) wheel odometry, turned back into the wheels' angles it was made from.

Many robots publish only their odometry: a base pose ``(x, y, θ)`` per cycle, integrated by the
vendor's controller from the wheels with its own model (a differential drive's wheel radius and
separation). Between two poses the base moved along an arc of length ``s`` turning by ``Δθ``; the
vendor's model says the wheels turned ``(s ∓ b₀Δθ/2)/r₀``. Those angles are what the wheels' joints
would have published had the vendor's model been right: calibrating from them gives the true
radii and separation, and their ratios to ``r₀`` and ``b₀`` are the corrections the vendor's
controller takes (``left_wheel_radius_multiplier``, ``right_wheel_radius_multiplier``,
``wheel_separation_multiplier``). The file format is text, one pose per line, ``t x y θ``
(seconds, m, m, rad; ``#`` lines are comments), as ``nav_msgs/Odometry`` reduced to the plane.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.core import poses
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


def wheel_angles(base: np.ndarray, wheel_radius: float, wheel_separation: float) -> np.ndarray:
    """The left and right wheels' angles ``(n, 2)`` (rad, from 0) that a differential drive of the
    vendor's ``wheel_radius`` and ``wheel_separation`` turns to drive the base poses ``base``
    ``(n, 3)``: each step an arc (its length signed by its direction of travel)."""
    step = poses.between(base[:-1], base[1:])
    turn = step[:, 2]
    chord = np.hypot(step[:, 0], step[:, 1]) * np.sign(step[:, 0])
    half = 0.5 * turn
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(np.abs(half) > 1e-9, half / np.sin(half), 1.0 + half**2 / 6.0)
    arc = chord * factor
    left = (arc - 0.5 * wheel_separation * turn) / wheel_radius
    right = (arc + 0.5 * wheel_separation * turn) / wheel_radius
    return np.vstack([np.zeros((1, 2)), np.cumsum(np.column_stack([left, right]), axis=0)])


def format_odometry(time_ns: np.ndarray, base: np.ndarray) -> str:
    """``t x y θ`` text of base poses ``(n, 3)`` at stamps ``time_ns``, every value exact."""
    return "".join(
        " ".join([seconds(int(t)), *(repr(float(v)) for v in row)]) + "\n"
        for t, row in zip(np.asarray(time_ns).tolist(), np.asarray(base, dtype=float))
    )
