"""A 3-D trajectory in the TUM format: one pose per line, ``timestamp tx ty tz qx qy qz qw``.

Timestamps in seconds, translation in the trajectory's own units (metres, or any unit when the
scale is unknown), the rotation as a unit quaternion ``qx qy qz qw``, in the trajectory's own
world frame; ``#`` lines are comments. This is what ORB-SLAM, VINS and ``evo`` write. Quaternions
whose norm is within :data:`NORM_TOLERANCE` of 1 are normalised (one warning for the file);
beyond it they are refused, as are lines with another number of columns, values that are not
finite numbers and timestamps that do not increase.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.logs.log import frozen
from nlp_calib.logs.tables import check_time_order, data_lines, numbers

LAYOUT = "'timestamp tx ty tz qx qy qz qw' (8 numbers)"
#: A quaternion norm further than this from 1 is an error, not rounding.
NORM_TOLERANCE = 1e-2
#: Below this deviation from unit norm a quaternion is taken as it is.
NORM_ROUNDING = 1e-9


@dataclass(frozen=True)
class Trajectory3D:
    """Poses ``(n, 7)`` ``(x, y, z, qx, qy, qz, qw)`` at absolute stamps ``time_s`` (s), with the
    file's line of each."""

    path: str
    time_s: np.ndarray
    poses: np.ndarray
    line_numbers: np.ndarray

    @property
    def n_poses(self) -> int:
        return int(self.time_s.size)

    def select(self, keep: np.ndarray) -> Trajectory3D:
        """The poses ``keep`` (a mask or indices) marks, in order."""
        return Trajectory3D(
            self.path, frozen(self.time_s[keep]), frozen(self.poses[keep]), frozen(self.line_numbers[keep])
        )


def read_tum(path: str | Path) -> Trajectory3D:
    """Read a TUM trajectory; a malformed line raises :class:`DatasetError` naming ``file:line``."""
    p = str(path)
    rows, lines = [], []
    for number, text in data_lines(path):
        fields = text.split()
        if len(fields) != 8:
            raise DatasetError(p, number, f"has {len(fields)} columns; a TUM line is {LAYOUT}")
        rows.append(numbers(p, number, fields, LAYOUT))
        lines.append(number)
    if len(rows) < 2:
        raise DatasetError(
            p, None, f"holds {len(rows)} pose(s); a trajectory needs at least 2 lines of {LAYOUT}"
        )
    table = np.array(rows)
    line_numbers = np.array(lines, dtype=np.int64)
    check_time_order(p, table[:, 0], line_numbers)
    poses = table[:, 1:]
    poses[:, 3:] = unit_quaternions(p, poses[:, 3:], line_numbers)
    return Trajectory3D(p, frozen(table[:, 0]), frozen(poses), frozen(line_numbers))


def unit_quaternions(path: str, q: np.ndarray, line_numbers: np.ndarray) -> np.ndarray:
    """``q`` normalised; a norm far from 1 is refused, a small deviation warned about once."""
    norm = np.linalg.norm(q, axis=1)
    deviation = np.abs(norm - 1.0)
    far = np.flatnonzero(deviation > NORM_TOLERANCE)
    if far.size:
        k = int(far[0])
        raise DatasetError(
            path,
            int(line_numbers[k]),
            f"the quaternion has norm {norm[k]:.6g}, not 1; write unit quaternions as 'qx qy qz qw'",
        )
    off = deviation > NORM_ROUNDING
    if off.any():
        k = int(np.argmax(deviation))
        warnings.warn(
            f"{path}: {int(off.sum())} quaternion(s) are not of unit norm (largest deviation "
            f"{deviation[k]:.2g} on line {int(line_numbers[k])}); normalised",
            NlpCalibWarning,
            stacklevel=3,
        )
    return q / norm[:, None]


def format_tum(time_s: np.ndarray, poses: np.ndarray) -> str:
    """TUM text of poses ``(n, 7)`` at stamps ``time_s``."""
    table = np.column_stack([time_s, poses])
    return "".join(
        " ".join(f"{v:.9f}" if i == 0 else f"{v:.15g}" for i, v in enumerate(row)) + "\n" for row in table
    )
