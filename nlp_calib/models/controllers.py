"""What a model tells its robot's controller: the ros2_control controller, the values it takes
from a calibration, where the rest belongs and why any value it takes is left out.

A model maps its parameters onto its controller's (:meth:`KinematicModel.controller`) under the
names of the newest ros2_control release; the hand-off file renames them for an older one. A
value is given only when it means what the controller takes it to mean: a wheel's radius from
encoder counts needs the counts per wheel turn, which a log's encoder range is not (it is only
the unit a gain is counted in), so without them the radius is left out and the reason said.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

#: Wheel radii a robot can have (m): a radius outside says its counts per turn are wrong.
WHEEL_RADII = (0.005, 2.0)


@dataclass(frozen=True)
class EncoderScales:
    """What the controller's values need of the encoders: each one's range in the log (readings
    per the unit its gain is counted in; 0 for joints in radians), its counts per wheel turn
    where known (given by the user; 2π for joints in radians) and whether the readings are joint
    angles after the robot's transmissions (a ROS robot's joint states) or raw encoder counts."""

    ranges: Mapping[str, float]
    per_turn: Mapping[str, float] = field(default_factory=dict)
    joint_angles: bool = False
    #: The base's turn rates (rad/s, magnitude) the drive used while turning: 10th percentile,
    #: median, 90th percentile; empty where unknown (a model whose geometry depends on the turn
    #: rate states its values for these).
    driven_turn_rates: tuple[float, ...] = ()


@dataclass(frozen=True)
class ControllerMap:
    """A ros2_control controller and its parameters (the newest release's names) from a
    calibration; ``places``: each calibrated parameter with no place among them and where it
    belongs; ``omitted``: each of the controller's parameters left out, with the reason;
    ``assumes``: what the values assume of the encoders."""

    controller: str
    parameters: Mapping[str, float]
    places: Mapping[str, str] = field(default_factory=dict)
    omitted: Mapping[str, str] = field(default_factory=dict)
    assumes: str = ""
    #: Values no calibration gives that the others' meaning needs, with why (a multiplier of 1).
    settings: Mapping[str, str] = field(default_factory=dict)


def wheel_radius(metres_per_count: float, encoder: str, scales: EncoderScales) -> tuple[float | None, str]:
    """A wheel's radius from its travel per count and its counts per turn, or None and why not."""
    per_turn = scales.per_turn.get(encoder)
    if per_turn is None:
        return None, (
            f"a radius needs the counts per wheel turn of {encoder!r} (counts_per_turn in the scenario or "
            "ROBOT.yaml); the log's encoder range is only the unit its gain is counted in"
        )
    radius = metres_per_count * per_turn / (2.0 * np.pi)
    lo, hi = WHEEL_RADII
    if not lo <= abs(radius) <= hi:
        return None, (
            f"{per_turn:g} counts per turn of {encoder!r} give a radius of {radius:.3g} m, which no wheel "
            f"has ({lo:g} to {hi:g} m): check counts_per_turn"
        )
    return float(radius), ""


def steering_places(k_steer: float, steer_offset: float, scales: EncoderScales) -> dict[str, str]:
    """Where a steering gain and offset belong: the steering joint's transmission
    (``SimpleTransmission``: ``joint = actuator / mechanical_reduction + offset``), from the one
    the logged angles came through. Raw counts are the actuator's own angle; joint angles came
    through the robot's current transmission (``R``, ``o``), which the new one replaces."""
    if not scales.joint_angles:
        where = (
            "the steering joint's transmission (SimpleTransmission, joint = actuator/mechanical_reduction"
            " + offset) with the actuator's angle 2π·count/range as the log reads it"
        )
        return {
            "k_steer": f"{where}: mechanical_reduction = 1/k_steer = {1.0 / k_steer!r}",
            "steer_offset": f"{where}: offset = steer_offset = {steer_offset!r}",
        }
    where = (
        "the steering joint's transmission (SimpleTransmission, joint = actuator/mechanical_reduction + "
        "offset); the logged angles came through its current reduction R and offset o"
    )
    return {
        "k_steer": (f"{where}: mechanical_reduction = R/k_steer (R = 1, the identity: {1.0 / k_steer!r})"),
        "steer_offset": (
            f"{where}: offset = k_steer·o + steer_offset (o = 0: {steer_offset!r}; k_steer = {k_steer!r})"
        ),
    }
