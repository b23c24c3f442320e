"""The tricycle with a steering gain of its own while the base drives backwards.

Parameters ``(k_steer, k_traction, axis_length, steer_offset, k_steer_reverse)`` then the sensor
pose. The steering angle is ``φ = k_steer·(1 + k_steer_reverse·r)·angle + steer_offset`` with
``r = 1`` while the base drives backwards and 0 otherwise; the rest is the tricycle's. On the
real robot's log, fits on forward-only and reverse-only driving disagree by 3–5 white-noise σ;
of the one-parameter features tried (a traction gain, a steering offset or a steering gain per
direction, a steering delay, a steering backlash), blocked cross-validation on the fault-robust
figures prefers this one (``docs/accuracy.md``). A drive without reversing cannot
determine ``k_steer_reverse``; it is then held at its initial value (0 unless given).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.models.base import Reference, Symmetry, named
from nlp_calib.models.controllers import ControllerMap, EncoderScales
from nlp_calib.models.tricycle import Tricycle, TricycleDrive

#: With fewer reversing intervals than this, ``k_steer_reverse`` is held (about 2 s of driving).
MIN_REVERSING = 50


def _in_state_order(tricycle: Mapping[str, float], reverse: float) -> dict[str, float]:
    """The tricycle's values with ``k_steer_reverse`` after its kinematic parameters."""
    values = dict(tricycle)
    kinematic = {n: values.pop(n) for n in Tricycle.kinematic_params}
    return {**kinematic, "k_steer_reverse": reverse, **values}


class TricycleReverseDrive(TricycleDrive):
    """The tricycle's drive, its steering gain ``k_steer·(1 + k_steer_reverse)`` while reversing."""

    default_truth: Mapping[str, float] = MappingProxyType(_in_state_order(TricycleDrive.default_truth, 0.04))
    default_guess: Mapping[str, float] = MappingProxyType(_in_state_order(TricycleDrive.default_guess, 0.0))

    def steering_gain(self, truth: Mapping[str, float], direction: np.ndarray) -> np.ndarray:
        return truth["k_steer"] * (1.0 + truth["k_steer_reverse"] * (direction < 0))


class TricycleReverse(Tricycle):
    """Tricycle, parameters ``(k_steer, k_traction, axis_length, steer_offset, k_steer_reverse)``
    then the sensor pose ``(sensor_x, sensor_y, sensor_theta)``."""

    name: ClassVar[str] = "tricycle_reverse"
    kinematic_params: ClassVar[tuple[str, ...]] = (*Tricycle.kinematic_params, "k_steer_reverse")
    units: ClassVar[Mapping[str, str]] = MappingProxyType({**Tricycle.units, "k_steer_reverse": "1"})
    header_names: ClassVar[Mapping[str, str]] = MappingProxyType(
        {**Tricycle.header_names, "k_steer_reverse": "k_steer_reverse"}
    )
    header_aliases: ClassVar[Mapping[str, str]] = MappingProxyType(
        {**Tricycle.header_aliases, "k_steer_reverse": "k_steer_reverse"}
    )
    physical_ranges: ClassVar[Mapping[str, tuple[float, float]]] = MappingProxyType(
        {**Tricycle.physical_ranges, "k_steer_reverse": (-0.5, 0.5)}
    )
    reference: ClassVar[Mapping[str, Reference]] = MappingProxyType(
        {**Tricycle.reference, "k_steer_reverse": ("absolute", 0.005)}
    )
    headline: ClassVar[tuple[str, ...]] = ("k_traction", "axis_length", "k_steer_reverse")
    defaults: ClassVar[Mapping[str, float]] = MappingProxyType({"k_steer_reverse": 0.0})
    # Turning the base frame round swaps forward and backward driving: no longer a symmetry.
    symmetries: ClassVar[tuple[Symmetry, ...]] = Tricycle.symmetries[1:]
    drive: ClassVar[TricycleReverseDrive] = TricycleReverseDrive()

    def steering_angle(self, k: ca.SX, u: ca.SX) -> ca.SX:
        """``φ = k_steer·(1 + k_steer_reverse·r)·angle + steer_offset``, ``r`` = the base reverses.

        The base reverses when ``d·cos φ₀ < 0`` (``d`` the wheel's travel, ``φ₀`` the angle
        without the reverse term): unchanged by turning the wheel round.
        """
        p, inputs = named(self.kinematic_params, k), named(self.input_names, u)
        angle = inputs["steering_angle"]
        phi0 = p["k_steer"] * angle + p["steer_offset"]
        reversing = ca.if_else(p["k_traction"] * inputs["traction_revolutions"] * ca.cos(phi0) < 0, 1.0, 0.0)
        return p["k_steer"] * (1.0 + p["k_steer_reverse"] * reversing) * angle + p["steer_offset"]

    def controller(self, params: Mapping[str, float], scales: EncoderScales) -> ControllerMap:
        """The tricycle's, with the reverse gain, which no ros2_control component models."""
        base = super().controller(params, scales)
        reverse = (
            "no ros2_control parameter: the steering gain is k_steer·(1 + k_steer_reverse) while the base "
            "reverses; apply it in the hardware interface where the direction is known"
        )
        return dataclasses.replace(base, places={**base.places, "k_steer_reverse": reverse})

    def undetermined(self, inputs: np.ndarray) -> dict[str, str]:
        """``k_steer_reverse`` without enough driving in either direction (it compares the two)."""
        direction = self.travel_direction(inputs)
        counts = {"reversing": int(np.sum(direction < 0)), "forward driving": int(np.sum(direction > 0))}
        short = [f"only {n} intervals of {what}" for what, n in counts.items() if n < MIN_REVERSING]
        if not short:
            return {}
        return {"k_steer_reverse": f"{' and '.join(short)} (at least {MIN_REVERSING} are needed)"}

    def initial_guess(
        self,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: Callable[[Mapping[str, float]], np.ndarray],
    ) -> dict[str, float]:
        """The tricycle's closed-form start, with no difference between directions."""

        def with_reverse(params: Mapping[str, float]) -> np.ndarray:
            return base_motion({**params, "k_steer_reverse": 0.0})

        return {**super().initial_guess(U, z, with_reverse), "k_steer_reverse": 0.0}
