"""The facts of a 3-D sensor mount on a planar base, whatever the model.

A 3-D sensor (a camera) sits on the base at ``T_base_sensor = (x, y, z, roll, pitch, yaw)``
(URDF: fixed axes, ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``). Planar driving determines the rotation
fully and the translation in the floor plane; ``sensor_z`` never enters the prediction (the base
turns about z, so ``(R_Δ − I)·t`` has no z component) and is held at a given value. A trajectory
known only up to scale (monocular visual odometry) adds ``scale``: the factor that turns its
translations into metres.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Literal, Protocol

import numpy as np

from nlp_calib.core import poses3d


class _Units(Protocol):
    """What :func:`length_params` reads of a model (no import of the model protocol: base imports us)."""

    @property
    def kinematic_params(self) -> tuple[str, ...]: ...

    @property
    def units(self) -> Mapping[str, str]: ...


#: The 3-D mount closes a 3-D sensor's parameter vector, in this order.
MOUNT_PARAMS: tuple[str, ...] = (
    "sensor_x",
    "sensor_y",
    "sensor_z",
    "sensor_roll",
    "sensor_pitch",
    "sensor_yaw",
)
#: The mount's rotation angles (perturbed together on SO(3) when all three are free).
MOUNT_ANGLES: tuple[str, str, str] = ("sensor_roll", "sensor_pitch", "sensor_yaw")
#: Not observable from planar driving: always held at its given value.
HELD_PARAMS: tuple[str, ...] = ("sensor_z",)
#: The trajectory's scale, last parameter when the scale is free.
SCALE_PARAM = "scale"
MOUNT_UNITS: Mapping[str, str] = MappingProxyType(
    {
        "sensor_x": "m",
        "sensor_y": "m",
        "sensor_z": "m",
        "sensor_roll": "rad",
        "sensor_pitch": "rad",
        "sensor_yaw": "rad",
        SCALE_PARAM: "m per trajectory unit",
    }
)
#: What a useful calibration must resolve of the mount: 1 cm, 5 mrad, 0.5 % of the scale.
MOUNT_REFERENCE: Mapping[str, tuple[Literal["relative", "absolute"], float]] = MappingProxyType(
    {
        "sensor_x": ("absolute", 0.01),
        "sensor_y": ("absolute", 0.01),
        "sensor_z": ("absolute", 0.01),
        "sensor_roll": ("absolute", 0.005),
        "sensor_pitch": ("absolute", 0.005),
        "sensor_yaw": ("absolute", 0.005),
        SCALE_PARAM: ("relative", 0.005),
    }
)


def length_params(model: _Units) -> tuple[str, ...]:
    """The model's kinematic parameters that are lengths (their unit starts with ``m``): with the
    trajectory's scale free, all of them scale with it, so one must be known."""
    return tuple(n for n in model.kinematic_params if model.units[n].split()[0] == "m")


def mount_rotation(params: Mapping[str, float]) -> np.ndarray:
    """``R = Rz(yaw)·Ry(pitch)·Rx(roll)`` of a 3-D mount given by its named angles."""
    return poses3d.rpy_to_matrix(np.array([params[n] for n in MOUNT_ANGLES]))


def image_up(params: Mapping[str, float]) -> str | None:
    """Which way the mount turns the camera's image, from the base's forward and up axes seen in the
    sensor's frame: ``"up"``/``"down"`` for a camera looking along the base's forward axis (x right,
    y down in the image: REP 103's optical frame) or a body frame (x forward, z up), None when the
    sensor looks neither way (straight down, say): no convention tells."""
    R = mount_rotation(params)
    forward, up = R.T @ np.array([1.0, 0.0, 0.0]), R.T @ np.array([0.0, 0.0, 1.0])
    axis = int(np.argmax(np.abs(forward)))
    if abs(forward[axis]) < 0.7:
        return None
    if axis == 2:  # optical: looking along the base's forward (or backward) axis, y down
        return "down" if up[1] > 0.5 else "up" if up[1] < -0.5 else None
    if axis == 0:  # a body frame, x along the base's forward axis, z up
        return "down" if up[2] < -0.5 else "up" if up[2] > 0.5 else None
    return None


def mirrored_mount(params: Mapping[str, float], given: Mapping[str, float] | None) -> str:
    """Why a 3-D mount is likely the mirror image a camera's motion cannot tell from the robot (its
    image upside down), when no mount ``given`` by the user says the camera is so; "" when not."""
    if image_up(params) != "down" or (given is not None and image_up(given) == "down"):
        return ""
    return (
        "the camera came out mounted upside down (its image's down axis pointing up): the mirror image "
        "that both wheel joints turning the other way, or the left and right joints swapped, give a "
        "camera's motion; check the joints' signs and order in the scenario, or, if the camera is "
        "mounted upside down, give its mount as the initial guess (sensor_roll, sensor_pitch, sensor_yaw)"
    )
