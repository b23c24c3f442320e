"""What the robot stack's own configuration takes from a calibration: the controller's parameters.

The model says how its parameters map onto its ros2_control controller's (under the newest
release's names) and where those with no place there belong, and why any is left out; the
analyse stage adds each value's 1σ and the odometry's noise as the controller publishes it;
``ros2_control.yaml`` only formats this record, for the release it targets.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Placement:
    """A calibrated value with no place among the controller's parameters, and where it belongs."""

    name: str
    value: float
    std: float
    unit: str
    where: str


@dataclass(frozen=True)
class NoiseRates:
    """Variances of the base's motion ``(along, across, heading)`` per metre driven (m²/m, m²/m,
    rad²/m) and per radian turned (m²/rad, m²/rad, rad²/rad); ``coverage``: the share of the drift
    segments' errors within 2σ of the covariance they grow (None: no segment to judge them by);
    ``segments``: how many; ``raised``: the largest share of the inputs' noise's rates added to a
    component to hold 95 % of them (0: they did); ``bounded``: the components whose drift the
    segments only bound (under the reference's own noise, and no joint's own noise shows it): the
    most they allow."""

    per_metre: tuple[float, float, float]
    per_radian: tuple[float, float, float]
    coverage: float | None
    segments: int
    raised: float
    bounded: tuple[str, ...] = ()
    #: The heading's variance per radian turned on the spot (rad²/rad) over the pivots the ground
    #: slipped on, beyond the rates (the fit and the rates leave those out), and how many there were.
    slip_per_radian: float = 0.0
    slipped: int = 0
    #: The heading's variance per radian turned on the spot (rad²/rad), in place of ``per_radian``'s
    #: there, over the pivots the segments hold (a skid-steer's wheels scrub on a pivot, not on an
    #: arc); None: no pivot to tell it by, ``per_radian``'s.
    on_spot: float | None = None

    @property
    def spot_rate(self) -> float:
        """The heading's variance per radian turned on the spot (rad²/rad)."""
        return self.per_radian[2] if self.on_spot is None else self.on_spot

    def words(self) -> str:
        """The rates and how they held, in one sentence."""
        per_m = ", ".join(f"{v:.3g}" for v in self.per_metre)
        per_rad = ", ".join(f"{v:.3g}" for v in self.per_radian)
        held = (
            "no drift segment to judge it by"
            if self.coverage is None
            else f"{100 * self.coverage:.0f} % of {self.segments} drift segments' errors within its 2σ"
        )
        if self.bounded:
            held += (
                f"; {' and '.join(self.bounded)} only the most the segments allow (the wheels' drift "
                "there lies under the reference's own noise, or is not told from it)"
            )
        if self.on_spot is not None:
            held += f"; on the spot the heading's grows by {self.on_spot:.3g} rad² per radian turned"
        if self.slipped:
            held += (
                f"; on the {self.slipped} pivots the ground slipped on, the heading's variance grows by "
                f"{self.slip_per_radian:.3g} rad² more per radian turned on the spot"
            )
        return (
            f"variance per metre driven {per_m} (along, across, heading: m², m², rad²), per radian "
            f"turned {per_rad}; {held}"
        )


@dataclass(frozen=True)
class OdometryNoise:
    """The odometry's covariance diagonals as a controller publishes them, from the one noise model
    (``rates``, calibrated on the log's drift against the tracker; ``input_noise``: each input's
    noise per interval that shaped them), with each reading's rounding: the twist
    ``(vx, vy, vz, wx, wy, wz)`` over one interval of the log (``interval_s``: its median), the
    pose ``(x, y, z, roll, pitch, yaw)`` after driving ``distance_m`` as the log drives, in the
    base frame at the start. What the wheels never measure (a planar base's height, roll and
    pitch, their rates and a lateral velocity) is :data:`UNMEASURED`."""

    pose: tuple[float, ...]
    twist: tuple[float, ...]
    interval_s: float
    distance_m: float
    input_noise: Mapping[str, float]
    #: The noise per metre driven and per radian turned the diagonals come from (None: not computed).
    rates: NoiseRates | None = None


#: The variance given to what planar wheel odometry does not measure: a filter then ignores it.
UNMEASURED = 1e6


@dataclass(frozen=True)
class ControllerParams:
    """A ros2_control controller's parameters (name → value, and 1σ), and the rest of the
    calibration with where each belongs."""

    controller: str
    parameters: Mapping[str, float]
    std: Mapping[str, float]
    elsewhere: tuple[Placement, ...]
    #: What the values assume of the encoders (e.g. joint angles per radian of the wheel).
    assumes: str = ""
    #: The controller's parameters left out, each with the reason (e.g. no counts per turn).
    omitted: Mapping[str, str] = field(default_factory=dict)
    #: The covariance diagonals the controller publishes with its odometry (None: not calibrated).
    noise: OdometryNoise | None = None
    #: The calibrated parameters each value rests on: a caveat on one of them holds the value back.
    rests_on: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    #: Values resting only on parameters the user gave (``known:``, ``fixed:``), with where from:
    #: written as given, never as calibrated.
    given: Mapping[str, str] = field(default_factory=dict)
    #: Values no calibration gives but that the others' meaning needs (a multiplier of 1), with why.
    settings: Mapping[str, str] = field(default_factory=dict)
    #: Each value's derivative in each calibrated parameter it rests on: what the precision each
    #: parameter needs gives the value (:meth:`CalibrationRun.waived`).
    gradient: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
