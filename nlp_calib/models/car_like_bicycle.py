"""The car-like base with one traction joint: a drive motor through the rear differential.

Parameters ``(k_steer, steer_offset, k_traction, wheelbase)``; inputs per interval
``(traction_ticks, steering_angle)``. The motor's counter measures the rear-axle midpoint's travel
(the differential averages the two rear wheels), ``d = k_traction·Δticks``; the steering is the
car's (:mod:`.car_like`): ``φ = k_steer·angle + steer_offset``, the base turns by
``d·tan φ / wheelbase``. ros2_control's ``bicycle_steering_controller`` takes it.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.logs import EncoderKind
from nlp_calib.models.base import SENSOR_TURNED, Symmetry, named
from nlp_calib.models.car_like import STEERING_ENCODER, CarLike, CarLikeDrive
from nlp_calib.models.drives import SimulationSettings, counter, running
from nlp_calib.models.radians import WHEEL_RADIUS, InRadians, RadiansForm, Renamed

TRACTION_ENCODER = "traction_motor"
_PARAMS = ("k_steer", "steer_offset", "k_traction", "wheelbase")

RADIANS = RadiansForm(
    params=MappingProxyType({"k_traction": Renamed("traction_wheel_radius", "m", plausible=WHEEL_RADIUS)}),
    inputs=MappingProxyType(
        {
            "traction_ticks": Renamed("traction_angle", "rad", 1.0, TRACTION_ENCODER),
            "steering_angle": Renamed("steering_angle", "rad", 1.0, STEERING_ENCODER),
        }
    ),
)


class CarLikeBicycleDrive(CarLikeDrive):
    """The car's drive with one counter on the differential (the rear-axle midpoint's travel)."""

    default_truth: Mapping[str, float] = MappingProxyType(
        {n: v for n, v in CarLikeDrive.default_truth.items() if n != "rear_track"}
    )
    default_guess: Mapping[str, float] = MappingProxyType(
        {n: v for n, v in CarLikeDrive.default_guess.items() if n != "rear_track"}
    )
    default_ranges: Mapping[str, int] = MappingProxyType({STEERING_ENCODER: 8192, TRACTION_ENCODER: 4096})
    log_kind: ClassVar[str] = "car_like_bicycle"

    def steps(
        self,
        opts: SimulationSettings,
        speed: np.ndarray,
        turn: np.ndarray,
        turn_end: np.ndarray,
        dt: np.ndarray,
        turn_start: float,
        carry: Mapping[str, float] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        ds = speed * dt
        first: Mapping[str, float | None] = carry or {"travel": None, "phi": turn_start}
        channels = {"travel": running(ds, first["travel"]), "phi": np.concatenate([[first["phi"]], turn_end])}
        return ds, ds * np.tan(turn) / opts.truth["wheelbase"], channels

    def ticks(self, opts: SimulationSettings, channels: Mapping[str, np.ndarray]) -> np.ndarray:
        steer = self.steering_ticks(opts, channels["phi"], STEERING_ENCODER).astype(np.int64)
        return np.stack(
            [steer, counter(channels["travel"], opts.truth["k_traction"], opts.wrap_after_ticks)], 1
        )


class CarLikeBicycle(CarLike):
    """The car with one traction joint, parameters ``(k_steer, steer_offset, k_traction,
    wheelbase)`` then the sensor pose."""

    name: ClassVar[str] = "car_like_bicycle"
    log_names: ClassVar[tuple[str, ...]] = ("car_like_bicycle",)
    kinematic_params: ClassVar[tuple[str, ...]] = _PARAMS
    units: ClassVar[Mapping[str, str]] = MappingProxyType({n: CarLike.units[n] for n in _PARAMS})
    header_names: ClassVar[Mapping[str, str]] = MappingProxyType({n: n for n in _PARAMS})
    header_aliases: ClassVar[Mapping[str, str]] = MappingProxyType({n: n for n in _PARAMS})
    encoder_kinds: ClassVar[Mapping[str, EncoderKind]] = MappingProxyType(
        {STEERING_ENCODER: "absolute", TRACTION_ENCODER: "counter"}
    )
    input_names: ClassVar[tuple[str, ...]] = ("traction_ticks", "steering_angle")
    input_units: ClassVar[Mapping[str, str]] = MappingProxyType(
        {"traction_ticks": "ticks", "steering_angle": "rad"}
    )
    turning_params: ClassVar[tuple[str, ...]] = ("wheelbase",)
    headline: ClassVar[tuple[str, ...]] = ("k_traction", "wheelbase")
    symmetries: ClassVar[tuple[Symmetry, ...]] = (
        Symmetry(
            "the base frame turned round",
            "wheelbase",
            ("k_traction", "wheelbase", *SENSOR_TURNED[0]),
            SENSOR_TURNED[1],
        ),
    )
    drive: ClassVar[CarLikeBicycleDrive] = CarLikeBicycleDrive()
    physical_ranges: ClassVar[Mapping[str, tuple[float, float]]] = MappingProxyType(
        {n: r for n, r in CarLike.physical_ranges.items() if n != "rear_track"}
    )
    controller_name: ClassVar[str] = "bicycle_steering_controller"
    radius_name: ClassVar[str] = "traction_wheel_radius"

    def travel(self, k: ca.SX, u: ca.SX, curvature: ca.SX) -> ca.SX:
        """The differential's counter measures the rear-axle midpoint's travel."""
        p, inputs = named(self.kinematic_params, k), named(self.input_names, u)
        return p["k_traction"] * inputs["traction_ticks"]

    def undetermined(self, inputs: np.ndarray) -> dict[str, str]:
        """None: every parameter can be determined (the observability analysis judges how well)."""
        return {}

    def tracks(self, params: Mapping[str, float]) -> dict[str, float]:
        """None: one traction joint has no track."""
        return {}

    def in_radians(self) -> InRadians:
        return InRadians(self, RADIANS)

    def mean_travel(self, rows: Mapping[str, np.ndarray]) -> np.ndarray:
        return rows["traction_ticks"]

    def start_lengths(
        self, rows: Mapping[str, np.ndarray], steering: tuple[float, float], wheelbase: float
    ) -> dict[str, float]:
        """None besides the wheelbase."""
        return {}
