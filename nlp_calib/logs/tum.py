"""A 3-D trajectory in the TUM format: one pose per line, ``timestamp tx ty tz qx qy qz qw``.

Timestamps in seconds (read to the nanosecond), translation in the trajectory's own units (metres,
or any unit when a camera's scale is unknown), the rotation as a unit quaternion ``qx qy qz qw``,
in the trajectory's own world frame; ``#`` lines are comments. This is what ``evo``, ORB-SLAM,
VINS and most motion-capture exports write. Quaternions whose norm is within
:data:`NORM_TOLERANCE` of 1 are normalised (one warning for the file); beyond it they are
refused, as are lines with another number of columns, values that are not finite numbers and
timestamps that do not increase, each with the file and the line.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.logs.log import frozen
from nlp_calib.logs.text_tables import Layout, read_table, seconds

LAYOUT = "'timestamp tx ty tz qx qy qz qw' (8 numbers)"
#: A quaternion norm further than this from 1 is an error, not rounding.
NORM_TOLERANCE = 1e-2
#: Below this deviation from unit norm a quaternion is taken as it is.
NORM_ROUNDING = 1e-9


@dataclass(frozen=True)
class Trajectory3D:
    """Poses ``(n, 7)`` ``(x, y, z, qx, qy, qz, qw)`` at stamps ``time_ns`` (int64 ns), with the
    file's line of each."""

    path: str
    time_ns: np.ndarray
    poses: np.ndarray
    line_numbers: np.ndarray

    @property
    def n_poses(self) -> int:
        return int(self.time_ns.size)

    @property
    def time_s(self) -> np.ndarray:
        """The stamps in seconds (absolute: float64 keeps them to about 0.2 µs)."""
        return self.time_ns.astype(float) * 1e-9

    def select(self, keep: np.ndarray) -> Trajectory3D:
        """The poses ``keep`` (a mask or indices) marks, in order."""
        return Trajectory3D(
            self.path, frozen(self.time_ns[keep]), frozen(self.poses[keep]), frozen(self.line_numbers[keep])
        )

    def planar_and_3d(self) -> np.ndarray:
        """``(n, 8)``: the planar pose ``(x, y, yaw)`` of a tracker whose world is level, then
        ``z, qx, qy, qz, qw`` (the layout of a bag's tracker poses, ``TRACKER_COLUMNS``)."""
        qx, qy, qz, qw = self.poses[:, 3:].T  # yaw_from_quaternion on arrays (math's atan2: the same doubles)
        y, x = (2.0 * (qw * qz + qx * qy)).tolist(), (1.0 - 2.0 * (qy * qy + qz * qz)).tolist()
        yaw = np.fromiter(map(math.atan2, y, x), dtype=float, count=len(y))
        return np.column_stack([self.poses[:, :2], yaw, self.poses[:, 2:]])


def read_tum(path: str | Path) -> Trajectory3D:
    """Read a TUM trajectory; a malformed line raises :class:`DatasetError` naming ``file:line``."""
    p = str(path)
    table = read_table(path, Layout(7, None, LAYOUT, miscount="has {n} columns; a TUM line is {words}"))
    if table.rows < 2:
        raise DatasetError(
            p, None, f"holds {table.rows} pose(s); a trajectory needs at least 2 lines of {LAYOUT}"
        )
    poses = np.array(table.values, dtype=float)
    poses[:, 3:] = unit_quaternions(p, poses[:, 3:], table.line_numbers)
    return Trajectory3D(p, frozen(table.time_ns), frozen(poses), frozen(table.line_numbers))


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


def format_tum(time_ns: np.ndarray, poses: np.ndarray) -> str:
    """TUM text of poses ``(n, 7)`` at stamps ``time_ns`` (int ns), every value exact."""
    return "".join(
        " ".join([seconds(int(t)), *(repr(float(v)) for v in row)]) + "\n"
        for t, row in zip(np.asarray(time_ns).tolist(), np.asarray(poses, dtype=float))
    )
