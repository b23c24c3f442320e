"""The car-like base with both front wheels' steering joints logged (Ackermann steering).

Parameters ``(k_steer, steer_offset, k_traction, wheelbase, rear_track, steering_track)``; inputs
per interval ``(rear_left_ticks, rear_right_ticks, steering_left_angle, steering_right_angle)``.
Each front wheel's angle is ``k_steer·angle + steer_offset``; with Ackermann geometry the inner
wheel turns more than the outer one, each on its own circle about the turn's centre, so each
gives the bicycle-equivalent angle ``atan(L·tan φ_w / (L ∓ W/2·tan φ_w))`` (``L`` the wheelbase,
``W`` the steering track: the distance between the steering pivots), and the car steers by their
mean, as ros2_control's ``ackermann_steering_controller`` does; the rest is the car's
(:mod:`.car_like`). The motion cannot tell ``W``: a wrong one moves the two wheels' estimates
equally and oppositely, and their mean only at second order. It is held at its initial value: a
measured one, or (``initial_guess: auto``) the one the joints' own Ackermann split gives.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.logs import EncoderKind
from nlp_calib.models.base import CAR_STEER_MAX, SENSOR_TURNED, Reach, Symmetry, named, steered_reach
from nlp_calib.models.car_like import LEFT_ENCODER, RIGHT_ENCODER, CarLike, CarLikeDrive
from nlp_calib.models.drives import SimulationSettings, counter
from nlp_calib.models.radians import WHEEL_RADIUS, InRadians, RadiansForm, Renamed

LEFT_STEERING = "steering_left"
RIGHT_STEERING = "steering_right"
_PARAMS = ("k_steer", "steer_offset", "k_traction", "wheelbase", "rear_track", "steering_track")
#: Below this bicycle angle (rad) a turn says little of the steering track (cotangents blow up).
_MIN_TURN = 0.1

RADIANS = RadiansForm(
    params=MappingProxyType(
        {
            "k_traction": Renamed("traction_wheels_radius", "m", plausible=WHEEL_RADIUS),
            "rear_track": Renamed("traction_track_width", "m"),
            "steering_track": Renamed("steering_track_width", "m"),
        }
    ),
    inputs=MappingProxyType(
        {
            "rear_left_ticks": Renamed("rear_left_angle", "rad", 1.0, LEFT_ENCODER),
            "rear_right_ticks": Renamed("rear_right_angle", "rad", 1.0, RIGHT_ENCODER),
            "steering_left_angle": Renamed("steering_left_angle", "rad", 1.0, LEFT_STEERING),
            "steering_right_angle": Renamed("steering_right_angle", "rad", 1.0, RIGHT_STEERING),
        }
    ),
)


def _in_state_order(car: Mapping[str, float], steering_track: float) -> dict[str, float]:
    """The car's values with the steering track after its kinematic parameters."""
    values = dict(car)
    kinematic = {n: values.pop(n) for n in CarLike.kinematic_params}
    return {**kinematic, "steering_track": steering_track, **values}


def wheel_angles(phi: np.ndarray, wheelbase: float, steering_track: float) -> tuple[np.ndarray, np.ndarray]:
    """Each front wheel's angle (left, right) on its own circle about the turn's centre of the
    bicycle angle ``phi``."""
    t = np.tan(phi)
    half = 0.5 * steering_track * t
    return np.arctan(wheelbase * t / (wheelbase - half)), np.arctan(wheelbase * t / (wheelbase + half))


class CarLikeAckermannDrive(CarLikeDrive):
    """The car's drive with each front wheel's joint at its own Ackermann angle."""

    default_truth: Mapping[str, float] = MappingProxyType(_in_state_order(CarLikeDrive.default_truth, 0.55))
    default_guess: Mapping[str, float] = MappingProxyType(_in_state_order(CarLikeDrive.default_guess, 0.55))
    default_ranges: Mapping[str, int] = MappingProxyType(
        {LEFT_STEERING: 8192, RIGHT_STEERING: 8192, LEFT_ENCODER: 4096, RIGHT_ENCODER: 4096}
    )
    log_kind: ClassVar[str] = "car_like_ackermann"
    steering_encoders: ClassVar[tuple[str, ...]] = (LEFT_STEERING, RIGHT_STEERING)

    def ticks(self, opts: SimulationSettings, channels: Mapping[str, np.ndarray]) -> np.ndarray:
        t, wrap = opts.truth, opts.wrap_after_ticks
        left, right = wheel_angles(channels["phi"], t["wheelbase"], t["steering_track"])
        steering = [
            self.steering_ticks(opts, a, e).astype(np.int64)
            for a, e in ((left, LEFT_STEERING), (right, RIGHT_STEERING))
        ]
        wheels = [counter(channels[c], t["k_traction"], wrap) for c in ("left", "right")]
        return np.stack([*steering, *wheels], 1)


class CarLikeAckermann(CarLike):
    """The car with both front wheels' steering joints, parameters ``(k_steer, steer_offset,
    k_traction, wheelbase, rear_track, steering_track)`` then the sensor pose."""

    name: ClassVar[str] = "car_like_ackermann"
    log_names: ClassVar[tuple[str, ...]] = ("car_like_ackermann",)
    kinematic_params: ClassVar[tuple[str, ...]] = _PARAMS
    units: ClassVar[Mapping[str, str]] = MappingProxyType({**CarLike.units, "steering_track": "m"})
    header_names: ClassVar[Mapping[str, str]] = MappingProxyType({n: n for n in _PARAMS})
    header_aliases: ClassVar[Mapping[str, str]] = MappingProxyType({n: n for n in _PARAMS})
    encoder_kinds: ClassVar[Mapping[str, EncoderKind]] = MappingProxyType(
        {
            LEFT_STEERING: "absolute",
            RIGHT_STEERING: "absolute",
            LEFT_ENCODER: "counter",
            RIGHT_ENCODER: "counter",
        }
    )
    input_names: ClassVar[tuple[str, ...]] = (
        "rear_left_ticks",
        "rear_right_ticks",
        "steering_left_angle",
        "steering_right_angle",
    )
    input_units: ClassVar[Mapping[str, str]] = MappingProxyType(
        {
            "rear_left_ticks": "ticks",
            "rear_right_ticks": "ticks",
            "steering_left_angle": "rad",
            "steering_right_angle": "rad",
        }
    )
    level_inputs: ClassVar[tuple[str, ...]] = ("steering_left_angle", "steering_right_angle")
    symmetries: ClassVar[tuple[Symmetry, ...]] = (
        Symmetry(
            "the base frame turned round",
            "wheelbase",
            ("k_traction", "wheelbase", "rear_track", "steering_track", *SENSOR_TURNED[0]),
            SENSOR_TURNED[1],
        ),
    )
    drive: ClassVar[CarLikeAckermannDrive] = CarLikeAckermannDrive()
    physical_ranges: ClassVar[Mapping[str, tuple[float, float]]] = MappingProxyType(
        {**CarLike.physical_ranges, "steering_track": (0.0, 5.0)}
    )
    controller_name: ClassVar[str] = "ackermann_steering_controller"

    def reach(self, params: Mapping[str, float], steer_max: float | None = None) -> Reach:
        """The inner front wheel reaches its limit first: the rear-axle midpoint then turns on
        ``wheelbase / tan φ_max`` plus half the steering track."""
        limit = CAR_STEER_MAX if steer_max is None else steer_max
        return steered_reach(params["wheelbase"], limit, 0.5 * params["steering_track"])

    def steering_angle(self, k: ca.SX, u: ca.SX) -> ca.SX:
        """The mean of each front wheel's bicycle-equivalent angle."""
        p, inputs = named(self.kinematic_params, k), named(self.input_names, u)
        L, half = p["wheelbase"], 0.5 * p["steering_track"]
        t_left = ca.tan(p["k_steer"] * inputs["steering_left_angle"] + p["steer_offset"])
        t_right = ca.tan(p["k_steer"] * inputs["steering_right_angle"] + p["steer_offset"])
        return 0.5 * (ca.atan(L * t_left / (L + half * t_left)) + ca.atan(L * t_right / (L - half * t_right)))

    def undetermined(self, inputs: np.ndarray) -> dict[str, str]:
        """The car's, and the steering track, always: the motion tells it only at second order."""
        return {
            **super().undetermined(inputs),
            "steering_track": (
                "a wrong one moves the mean steering angle only at second order (give the measured distance "
                "between the steering pivots): no turn tells it"
            ),
        }

    def in_radians(self) -> InRadians:
        return InRadians(self, RADIANS)

    def mean_travel(self, rows: Mapping[str, np.ndarray]) -> np.ndarray:
        return 0.5 * (rows["rear_left_ticks"] + rows["rear_right_ticks"])

    def bicycle_angle(self, rows: Mapping[str, np.ndarray], k_steer: float, offset: float) -> np.ndarray:
        """The mean of both wheels' angles: the bicycle angle to within second order."""
        return k_steer * 0.5 * (rows["steering_left_angle"] + rows["steering_right_angle"]) + offset

    def start_lengths(
        self, rows: Mapping[str, np.ndarray], steering: tuple[float, float], wheelbase: float
    ) -> dict[str, float]:
        """The car's, and the steering track the joints' own Ackermann split gives:
        ``W/L = cot φ_right − cot φ_left`` in the turns."""
        k_steer, offset = steering
        left = k_steer * rows["steering_left_angle"] + offset
        right = k_steer * rows["steering_right_angle"] + offset
        turning = np.abs(0.5 * (left + right)) > _MIN_TURN
        ratio = (
            float(np.median(1.0 / np.tan(right[turning]) - 1.0 / np.tan(left[turning])))
            if turning.any()
            else 0.0
        )
        return {
            **super().start_lengths(rows, steering, wheelbase),
            "steering_track": max(ratio, 0.0) * wheelbase,
        }
