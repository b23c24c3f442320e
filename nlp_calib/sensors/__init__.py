"""Sensor layer: the references a robot's wheels are calibrated against, one file each, and their registry.

Adding a sensor is one file implementing :class:`~nlp_calib.sensors.base.Sensor` and one entry
in :data:`SENSORS` (a name, and how to make the sensor for a scenario's ``scale``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable

from nlp_calib.core.errors import ProblemError
from nlp_calib.sensors.base import BaseMotion, Reference, Sensor, SensorStart
from nlp_calib.sensors.beside import Beside
from nlp_calib.sensors.camera import CameraPose
from nlp_calib.sensors.camera_beside import CameraBeside
from nlp_calib.sensors.gyro import Gyro
from nlp_calib.sensors.planar import PlanarPose

#: Each sensor by the name a scenario's ``sensor`` gives it, made for a ``scale`` (``fixed``, or
#: ``free`` for poses known up to scale).
SENSORS: dict[str, Callable[[str], Sensor]] = {
    "planar": lambda scale: PlanarPose(),
    "3d": lambda scale: CameraPose(scale == "free"),
    "gyro": lambda scale: Gyro(scale == "free"),
    "planar_gyro": lambda scale: Beside(scale == "free"),
    "3d_gyro": lambda scale: CameraBeside(scale == "free"),
}
#: A reference with a second sensor beside it (``sensor: {mount: planar, beside: gyro}``): the
#: registered sensor that fits both.
BESIDE: dict[tuple[str, str], str] = {("planar", "gyro"): "planar_gyro", ("3d", "gyro"): "3d_gyro"}
#: Poses are metric (``fixed``) or known up to scale (``free``: the sensor then estimates it).
SCALES = ("fixed", "free")
#: Sensors whose scale may be fitted (a camera's trajectory known up to scale, a gyro's scale factor).
SCALE_FREE = frozenset({"3d", "gyro", "planar_gyro", "3d_gyro"})


@functools.cache
def sensor_for(kind: str, scale: str = "fixed") -> Sensor:
    """The sensor registered as ``kind``, for poses of ``scale``."""
    if kind not in SENSORS:
        raise ProblemError(f"sensor must be one of {', '.join(SENSORS)}, got {kind!r}")
    if scale not in SCALES:
        raise ProblemError(f"scale must be one of {', '.join(SCALES)}, got {scale!r}")
    if scale == "free" and kind not in SCALE_FREE:
        which = ", ".join(sorted(SCALE_FREE))
        raise ProblemError(
            f"a free scale needs a 3-D sensor or a gyro (mount: {which}): {kind} poses are metric"
        )
    return SENSORS[kind](scale)


__all__ = ["BESIDE", "SCALES", "SENSORS", "BaseMotion", "Reference", "Sensor", "SensorStart", "sensor_for"]
