"""A gyro beside a camera's 3-D poses (``sensor: {mount: 3d, beside: gyro}``): :class:`.Beside`
with the camera (:class:`.CameraPose`) as the reference.

A window's ``z`` is the camera's motion between two consecutive poses ``(x, y, z, qx, qy, qz, qw)``
or the gyro's integrated rates ``(∫ω, Δt)``, then the gyro row; the residual has the camera's six
rows (translation, rotation) and the gyro's three, the other sensor's zero, so Ω's diagonal is
``(translation ×3, rotation ×3, gyro ×3)``. The mount block holds the camera's six (its height
held, as the camera alone holds it) and the gyro's biases and tilt; the clock block each sensor's
offset (``tracker_lag``: the camera's, ``gyro_lag``: the gyro's). The camera's poses, figures and
hand-off joint are its own; the IMU's joint is stated beside them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from nlp_calib.logs import Log
from nlp_calib.sensors.base import Sensor, SensorStart
from nlp_calib.sensors.beside import GYRO_ROWS, Beside
from nlp_calib.sensors.camera import HELD_WHY, CameraPose
from nlp_calib.sensors.gyro import Gyro
from nlp_calib.sensors.mount import HELD_PARAMS, MOUNT_ANGLES

#: The camera's motion's rows in a window's ``z``, and its residual's.
CAMERA_ROWS, CAMERA_ERRORS = 7, 6


class CameraBeside(Beside):
    """A camera's 3-D poses and a gyro's integrated rates in one problem (see the module docstring)."""

    kind: ClassVar[str] = "3d_gyro"
    label: ClassVar[str] = "3-D poses beside a gyro"
    group: ClassVar[str] = "SE(3)"
    pose_rows: ClassVar[int] = CAMERA_ROWS
    z_rows: ClassVar[int] = CAMERA_ROWS + GYRO_ROWS + 1
    error_rows: ClassVar[int] = CAMERA_ERRORS + 3
    noise_groups: ClassVar[tuple[tuple[int, ...], ...]] = ((0, 1, 2), (3, 4, 5), (6, 7, 8))
    noise_names: ClassVar[tuple[str, ...]] = ("tracker_xyz", "tracker_rotation", "gyro_angle")
    weights: ClassVar[tuple[str, ...]] = ("translation",) * 3 + ("rotation",) * 3 + ("gyro",) * 3
    turning: ClassVar[tuple[str, ...]] = (*CameraPose.turning, *Gyro.turning)
    angles: ClassVar[tuple[str, ...]] = (*MOUNT_ANGLES, *Gyro.angles)
    held: ClassVar[tuple[str, ...]] = HELD_PARAMS
    held_why: ClassVar[str] = HELD_WHY
    planar_base: ClassVar[bool] = False
    #: The camera's start on seconds of driving (its windows the poses', the gyro starting level).
    start_span_s: ClassVar[float | None] = CameraPose.start_span_s

    @staticmethod
    def _reference() -> Sensor:
        return CameraPose(False)

    def poses(self, log: Log) -> np.ndarray:
        """The camera's 3-D poses (interpolated at the gyro's stamps, for figures)."""
        return log.poses_3d()

    def given(self, initial: Mapping[str, float]) -> SensorStart | None:
        return self.reference_sensor.given(initial)
