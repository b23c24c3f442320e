"""A tracker's poses as a TUM trajectory: one pose per line, ``timestamp tx ty tz qx qy qz qw``.

Timestamps in seconds (read to the nanosecond), the position in metres and the orientation as a
unit quaternion, in the tracker's own world frame; ``#`` lines are comments. This is what ``evo``
and most SLAM and motion-capture exports write. A planar robot's pose is read from it as
``(x, y, yaw)`` with ``z`` kept beside it. A line with another number of columns, a value that is
not a finite number, a quaternion that is not a rotation and a time that does not increase are
refused with the file and the line.
"""

from __future__ import annotations

import math

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.logs.log import frozen
from nlp_calib.logs.reader import yaw_from_quaternion
from nlp_calib.logs.text_tables import check_increasing, data_lines, numbers, seconds, stamp_ns

LAYOUT = "'timestamp tx ty tz qx qy qz qw' (8 numbers)"
#: A quaternion whose norm is off 1 by more than this is not a rotation.
QUATERNION_TOLERANCE = 1e-3


def read_tum_poses(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The stamps (ns), the poses ``(n, 4)`` as ``(x, y, yaw, z)`` and each pose's line."""
    stamps, rows, at = [], [], []
    for number, text in data_lines(path):
        fields = text.split()
        if len(fields) != 8:
            raise DatasetError(path, number, f"has {len(fields)} columns; a TUM line is {LAYOUT}")
        x, y, z, qx, qy, qz, qw = numbers(path, number, fields[1:], LAYOUT)
        norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        if not abs(norm - 1.0) <= QUATERNION_TOLERANCE:
            raise DatasetError(
                path, number, f"the quaternion's norm is {norm:.6g}, not 1; write unit quaternions"
            )
        rows.append((x, y, yaw_from_quaternion(qx / norm, qy / norm, qz / norm, qw / norm), z))
        stamps.append(stamp_ns(fields[0], path, number))
        at.append(number)
    if len(rows) < 2:
        raise DatasetError(
            path, None, f"holds {len(rows)} pose(s); a trajectory needs at least 2 lines of {LAYOUT}"
        )
    time_ns, line_numbers = np.array(stamps, dtype=np.int64), np.array(at, dtype=np.int64)
    check_increasing(path, time_ns, line_numbers)
    return frozen(time_ns), frozen(np.array(rows, dtype=float)), frozen(line_numbers)


def format_tum_poses(time_ns: np.ndarray, poses: np.ndarray) -> str:
    """TUM text of planar poses ``(n, 4)`` ``(x, y, yaw, z)`` at stamps ``time_ns``, every value exact."""
    lines = []
    for t, (x, y, yaw, z) in zip(time_ns.tolist(), poses.tolist()):
        q = (0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw))
        lines.append(" ".join([seconds(int(t)), *(repr(float(v)) for v in (x, y, z, *q))]) + "\n")
    return "".join(lines)
