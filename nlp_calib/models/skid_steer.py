"""Skid-steer (or tracked) base: each side's wheels driven together, turning by skidding.

Parameters ``(k_left, k_right, baseline, turn_slip)``: metres per tick of each side, the effective
track at a slow turn (wider than the wheels' measured track: the wheels skid sideways as the base
turns, users report 1.5 to 2 times), and how much wider it grows with the turn rate; inputs per
interval ``(left_ticks, right_ticks, left_rate, right_rate)``: the sides' unwrapped increments and
their rates over the interval (ticks/s: levels, not increments). The wheels alone would turn the
base by ``Δθ_w = (d_r − d_l)/baseline`` at the rate ``ω_w = (k_right·right_rate −
k_left·left_rate)/baseline``; skidding turns it by ``Δθ = Δθ_w / (1 + turn_slip·|ω_w|)``, as if the
track were ``baseline·(1 + turn_slip·|ω_w|)``. The base travels ``(d_r + d_l)/2`` along an exact
arc (or Euler). With ``turn_slip = 0`` it is the differential drive of :mod:`.diff_drive`, whose
controller (``diff_drive_controller``) it hands off to.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.core.errors import ModelError
from nlp_calib.logs import EncoderKind, Log, LogHeader
from nlp_calib.models.base import SENSOR_TURNED, Reference, Symmetry, named, record_rates
from nlp_calib.models.controllers import ControllerMap, EncoderScales
from nlp_calib.models.diff_drive import LEFT_ENCODER, RIGHT_ENCODER, DiffDrive, DiffDriveDrive, wheel_pair
from nlp_calib.models.diff_drive import RADIANS as DIFF_DRIVE_RADIANS
from nlp_calib.models.drives import SimulationSettings, drive_header, running
from nlp_calib.models.radians import InRadians, RadiansForm, Renamed
from nlp_calib.symbolic import se2

_PARAMS = ("k_left", "k_right", "baseline", "turn_slip")
#: Curvature (1/m) per unit of the simulator's turning profile: tighter than the differential
#: drive's, so that the turn rates span what tells the slip from the track.
_SIM_CURVATURE = 3.0

#: The differential drive's radians form, and each wheel joint's rate over the interval (rad/s).
RADIANS = RadiansForm(
    params=DIFF_DRIVE_RADIANS.params,
    inputs=MappingProxyType(
        {
            **DIFF_DRIVE_RADIANS.inputs,
            "left_rate": Renamed("left_rate", "rad/s", 1.0, LEFT_ENCODER, rate=True),
            "right_rate": Renamed("right_rate", "rad/s", 1.0, RIGHT_ENCODER, rate=True),
        }
    ),
)


#: The fast-spinning simulator's robot (:mod:`nlp_calib.simulation.vehicles`, in joint units): a
#: 0.55 m skid-steer whose effective track is 1.8 times that, rolling 10 % under its 0.15 m radius.
SPIN_TRUTH: Mapping[str, float] = MappingProxyType(
    {
        "k_left": 0.135,
        "k_right": 0.137,
        "baseline": 0.99,
        "turn_slip": 0.05,
        "sensor_x": 0.2,
        "sensor_y": 0.03,
        "sensor_theta": 0.04,
    }
)

#: How a scenario reads the fast-spinning simulator's files, after its ``joints`` and ``motions`` paths.
SPIN_SCENARIO = (
    "encoders: {left_wheel: left_wheel_joint, right_wheel: right_wheel_joint}}, with model: skid_steer "
    "and initial_guess: auto"
)


def spin_problem(truth: Mapping[str, float], spin_rate: float) -> str:
    """What keeps ``truth`` from being driven at ``spin_rate`` (rad/s) by the wheels' law ("" if
    nothing): the law's divisor must stay positive, the radii too."""
    if truth["turn_slip"] * spin_rate >= 0.9 or min(truth["k_left"], truth["k_right"]) <= 0:
        return "turn_slip × spin_rate must stay under 0.9 and the radii positive"
    return ""


def spin_wheels(truth: Mapping[str, float], speed: np.ndarray, rate: np.ndarray, dt: float) -> np.ndarray:
    """Each side's wheel angle ``(n + 1, 2)`` (left, right; rad, from 0) driving the base at
    ``speed`` (m/s) and turn rate ``rate`` (rad/s) over steps of ``dt``: the model's law
    ``ω = ω_w/(1 + turn_slip·|ω_w|)`` solved for the wheels' own turn rate ``ω_w``."""
    wheels = rate / (1.0 - truth["turn_slip"] * np.abs(rate))
    half = 0.5 * truth["baseline"] * wheels
    left = np.concatenate([[0.0], np.cumsum((speed - half) * dt)]) / truth["k_left"]
    right = np.concatenate([[0.0], np.cumsum((speed + half) * dt)]) / truth["k_right"]
    return np.stack([left, right], axis=1)


class SkidSteerDrive(DiffDriveDrive):
    """The base turns at ``w`` (curvature ``3·turn`` per metre); the sides' wheels turn it by
    ``w·(1 + turn_slip·|ω_w|)`` of their own, ``ω_w`` their turn rate."""

    default_truth: Mapping[str, float] = MappingProxyType(
        {
            "k_left": 4.9e-4,
            "k_right": 5.1e-4,
            "baseline": 0.95,
            "turn_slip": 0.3,
            "sensor_x": 0.3,
            "sensor_y": -0.05,
            "sensor_theta": 0.08,
        }
    )
    default_guess: Mapping[str, float] = MappingProxyType(
        {
            "k_left": 5e-4,
            "k_right": 5e-4,
            "baseline": 0.8,
            "turn_slip": 0.0,
            "sensor_x": 0.25,
            "sensor_y": 0.0,
            "sensor_theta": 0.0,
        }
    )

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
        t = opts.truth
        ds = speed * dt
        w = ds * _SIM_CURVATURE * turn
        # Δθ_w = Δθ·(1 + turn_slip·|Δθ_w|/Δt) solved for Δθ_w: the wheels turn faster than the base.
        wheels = w / np.maximum(1.0 - t["turn_slip"] * np.abs(w) / dt, 0.05)
        half = 0.5 * t["baseline"] * wheels
        first: Mapping[str, float | None] = carry or {"left": None, "right": None}
        return ds, w, {"left": running(ds - half, first["left"]), "right": running(ds + half, first["right"])}

    def header(self, opts: SimulationSettings) -> LogHeader:
        return drive_header(opts, "skid_steer", SkidSteer.header_names)


class SkidSteer(DiffDrive):
    """Skid-steer base, parameters ``(k_left, k_right, baseline, turn_slip)`` then the sensor pose."""

    name: ClassVar[str] = "skid_steer"
    log_names: ClassVar[tuple[str, ...]] = ("skid_steer",)
    kinematic_params: ClassVar[tuple[str, ...]] = _PARAMS
    units: ClassVar[Mapping[str, str]] = MappingProxyType({**DiffDrive.units, "turn_slip": "s/rad"})
    header_names: ClassVar[Mapping[str, str]] = MappingProxyType(
        {**DiffDrive.header_names, "turn_slip": "turn_slip"}
    )
    header_aliases: ClassVar[Mapping[str, str]] = MappingProxyType(
        {**DiffDrive.header_aliases, "turn_slip": "turn_slip"}
    )
    input_names: ClassVar[tuple[str, ...]] = ("left_ticks", "right_ticks", "left_rate", "right_rate")
    input_units: ClassVar[Mapping[str, str]] = MappingProxyType(
        {**DiffDrive.input_units, "left_rate": "ticks/s", "right_rate": "ticks/s"}
    )
    level_inputs: ClassVar[tuple[str, ...]] = ("left_rate", "right_rate")
    encoder_kinds: ClassVar[Mapping[str, EncoderKind]] = DiffDrive.encoder_kinds
    turning_params: ClassVar[tuple[str, ...]] = ("baseline", "turn_slip")
    turning_note: ClassVar[str] = "the split between the track and the slip (turns at several rates)"
    reference: ClassVar[Mapping[str, Reference]] = MappingProxyType({"turn_slip": ("absolute", 0.01)})
    headline: ClassVar[tuple[str, ...]] = ("k_left", "baseline", "turn_slip")
    defaults: ClassVar[Mapping[str, float]] = MappingProxyType({"turn_slip": 0.0})
    symmetries: ClassVar[tuple[Symmetry, ...]] = (
        Symmetry(
            "the base frame turned round",
            "baseline",
            ("k_left", "k_right", "baseline", *SENSOR_TURNED[0]),
            SENSOR_TURNED[1],
        ),
    )
    drive: ClassVar[SkidSteerDrive] = SkidSteerDrive()
    physical_ranges: ClassVar[Mapping[str, tuple[float, float]]] = MappingProxyType(
        {**DiffDrive.physical_ranges, "baseline": (0.05, 10.0), "turn_slip": (-0.5, 5.0)}
    )

    def increment(self, k: ca.SX, u: ca.SX, integration: str) -> ca.SX:
        """Travel ``(d_r + d_l)/2`` turning by ``Δθ_w/(1 + turn_slip·|ω_w|)``; exact arc or Euler."""
        p, inputs = named(self.kinematic_params, k), named(self.input_names, u)
        d_left, d_right = p["k_left"] * inputs["left_ticks"], p["k_right"] * inputs["right_ticks"]
        wheels = (d_right - d_left) / p["baseline"]
        rate = (p["k_right"] * inputs["right_rate"] - p["k_left"] * inputs["left_rate"]) / p["baseline"]
        dtheta = wheels / (1.0 + p["turn_slip"] * ca.fabs(rate))
        travel = 0.5 * (d_left + d_right)
        if integration == "euler":
            return ca.vertcat(travel, 0.0, dtheta)
        return se2.arc(travel, dtheta)

    def inputs(self, log: Log, steering_sample: str) -> np.ndarray:
        """Rows: the sides' tick increments, then their rates over each interval (ticks/s)."""
        ticks = super().inputs(log, steering_sample)
        return np.vstack([ticks, ticks / np.diff(log.time_s)])

    def input_rates(self, log: Log) -> np.ndarray:
        """Each side's rate (ticks/s) at each record, for its increment and for its rate alike: the
        ticks of the two intervals around the record over their duration."""
        rates = record_rates(super().inputs(log, "start"), np.asarray(log.time_s))
        return np.vstack([rates, rates])

    def input_noise_std(self, log: Log, encoder_noise: Mapping[str, float] | None = None) -> np.ndarray:
        """1σ of each increment in ticks (default: quantisation, ``1/√12``); a rate's noise is its
        increment's, counted there."""
        return np.append(super().input_noise_std(log, encoder_noise), [0.0, 0.0])

    def controller(self, params: Mapping[str, float], scales: EncoderScales) -> ControllerMap:
        """``diff_drive_controller`` with the effective track at the median turn rate the drive
        used (the zero-rate track where unknown); the slip has no place there, so the rule and the
        track over the driven rates are said with it."""
        baseline, slip = params["baseline"], params["turn_slip"]
        rates = scales.driven_turn_rates
        chosen = rates[len(rates) // 2] if rates else 0.0
        separation = effective_track(baseline, slip, chosen)
        base = wheel_pair(params["k_left"], params["k_right"], separation, scales)
        rule = (
            "no ros2_control parameter: diff_drive_controller's wheel_separation is a fixed track, but a "
            f"skid-steer's effective track {_track_change(slip)} the base's turn rate ω (rad/s) as "
            f"T0/(1 − turn_slip·|ω|), T0 = {baseline!r} m the zero-rate track (calibration.yaml's)"
        )
        if rates:
            low, high = (effective_track(baseline, slip, r) for r in (rates[0], rates[-1]))
            rule += (
                f"; wheel_separation is it at the drive's median |ω| while turning, {chosen:.3g} rad/s; "
                f"over the driven rates ({rates[0]:.3g} to {rates[-1]:.3g} rad/s, 10th to 90th "
                f"percentile) it runs from {low:.4g} to {high:.4g} m, and the controller's yaw rate is "
                "off by that ratio elsewhere"
            )
        else:
            unknown = "the drive's turn rates are unknown: wheel_separation is the zero-rate track"
            rule += f"; {unknown} T0"
        return ControllerMap(
            base.controller, base.parameters, {"turn_slip": rule}, base.omitted, base.assumes, base.settings
        )

    def readings_from_odometry(self, base: np.ndarray, params: Mapping[str, float]) -> dict[str, np.ndarray]:
        """Refused: the slip needs the turn rate, which poses alone do not give, and the skid-steer's
        controller (``diff_drive_controller``) integrates as a differential drive whose separation
        is the effective track: that model turns its odometry back."""
        raise ModelError(
            "the skid_steer model cannot turn a robot's odometry back into its joints: its "
            "controller integrates as a differential drive with the effective track; calibrate "
            "the vendor's odometry with model: diff_drive"
        )

    def in_radians(self) -> InRadians:
        return InRadians(self, RADIANS)

    def initial_guess(
        self,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: Callable[[Mapping[str, float]], np.ndarray],
    ) -> dict[str, float]:
        """The differential drive's closed form with no slip (its track is the effective one at
        the log's turn rates); the fit finds the slip."""
        start = super().initial_guess(U, z, lambda p: base_motion({**p, "turn_slip": 0.0}))
        return {**{n: start[n] for n in DiffDrive.kinematic_params}, "turn_slip": 0.0, **_sensor(start)}


def effective_track(baseline: float, turn_slip: float, rate: float) -> float:
    """The track (m) a differential drive turning the base at ``rate`` (rad/s) from the same wheel
    travel has: the wheels' own rate ``ω_w = ω/(1 − turn_slip·|ω|)`` (the law solved for it) over
    the base's, times ``baseline``. A rate beyond the law's reach keeps the zero-rate track."""
    divisor = 1.0 - turn_slip * abs(rate)
    return baseline / divisor if divisor > 0.1 else baseline


def _track_change(turn_slip: float) -> str:
    """How the effective track follows the turn rate, by the fitted slip's sign: a negative slip
    narrows it (the base turns more than its wheels' difference over the zero-rate track would)."""
    if turn_slip > 0:
        return "grows with"
    return "shrinks with" if turn_slip < 0 else "does not change with"


def _sensor(params: Mapping[str, float]) -> dict[str, float]:
    return {n: params[n] for n in ("sensor_x", "sensor_y", "sensor_theta")}
