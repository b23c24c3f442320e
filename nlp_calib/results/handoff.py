"""What the robot stack's own configuration takes from a calibration: the controller's parameters.

The model says how its parameters map onto a ros2_control controller's (``diff_drive_controller``,
``tricycle_controller``) and where those with no place there belong; the analyse stage adds each
value's 1σ; ``ros2_control.yaml`` only formats this record.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class Placement:
    """A calibrated value with no place among the controller's parameters, and where it belongs."""

    name: str
    value: float
    std: float
    unit: str
    where: str


@dataclass(frozen=True)
class ControllerParams:
    """A ros2_control controller's parameters (name → value, and 1σ), and the rest of the
    calibration with where each belongs."""

    controller: str
    parameters: Mapping[str, float]
    std: Mapping[str, float]
    elsewhere: tuple[Placement, ...]
    #: What the values assume of the encoders (e.g. a counter's range being one wheel turn).
    assumes: str = ""


@dataclass(frozen=True)
class MountPose:
    """The sensor's mount in a robot's terms, as its sensor plug-in says it: a URDF joint's ``xyz``
    (m) and ``rpy`` (rad, fixed axes), and what of it was calibrated and what is nominal, in words
    (the height is never calibrated: planar driving cannot see it)."""

    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    calibrated: str
    #: Whether the roll and pitch were calibrated (else they are the nominal mount's).
    tilted: bool = False


@dataclass(frozen=True)
class LogMount:
    """One log's own mount, in a fit of several logs with a mount each: the log (its name), the
    sensor's frame in it and the mount as a URDF joint."""

    log: str
    frame: str
    mount: MountPose
