"""Differential drive: two driven wheels with incremental (uint32) encoders.

Parameters ``(k_left, k_right, baseline)``: metres per tick of each wheel and the distance
between the wheels; inputs per interval ``(left_ticks, right_ticks)``, the unwrapped increments.
``d = k·Δticks``, ``Δθ = (d_r − d_l)/baseline``, travel ``(d_r + d_l)/2`` along an exact arc.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.core.errors import ModelError
from nlp_calib.core.numeric import wrap_angle, wrapped_difference
from nlp_calib.logs import EncoderKind, Log, LogHeader
from nlp_calib.models.base import QUANTISATION, SENSOR_TURNED, Reach, Reference, Symmetry, named, rows_by_name
from nlp_calib.models.controllers import ControllerMap, EncoderScales, wheel_radius
from nlp_calib.models.drives import (
    Pose,
    SimulationSettings,
    arcs,
    counter,
    drive_header,
    first_order,
    integrate_base,
    running,
)
from nlp_calib.models.handeye import hand_eye, robust_lstsq
from nlp_calib.models.radians import WHEEL_RADIUS, InRadians, RadiansForm, Renamed
from nlp_calib.symbolic import se2

LEFT_ENCODER = "left_wheel"
RIGHT_ENCODER = "right_wheel"
#: Curvature (1/m) per unit of the simulator's turning profile.
_SIM_CURVATURE = 1.5


#: The differential drive read from joint positions in radians: each wheel's radius (its travel is
#: radius × Δangle) and the wheel separation, as ``diff_drive_controller`` names them.
RADIANS = RadiansForm(
    params=MappingProxyType(
        {
            "k_left": Renamed("left_wheel_radius", "m", plausible=WHEEL_RADIUS),
            "k_right": Renamed("right_wheel_radius", "m", plausible=WHEEL_RADIUS),
            "baseline": Renamed("wheel_separation", "m"),
        }
    ),
    inputs=MappingProxyType(
        {
            "left_ticks": Renamed("left_angle", "rad", 1.0, LEFT_ENCODER),
            "right_ticks": Renamed("right_angle", "rad", 1.0, RIGHT_ENCODER),
        }
    ),
)


def wheel_pair(k_left: float, k_right: float, separation: float, scales: EncoderScales) -> ControllerMap:
    """``diff_drive_controller`` for two wheels travelling ``k_left``, ``k_right`` metres per count
    ``separation`` apart: the mean radius and each wheel's multiplier of it (only the multipliers
    when a wheel's counts per turn are not known and both count alike)."""
    left, why_left = wheel_radius(k_left, LEFT_ENCODER, scales)
    right, why_right = wheel_radius(k_right, RIGHT_ENCODER, scales)
    parameters = {"wheel_separation": separation, "wheel_separation_multiplier": 1.0}
    if left is not None and right is not None:
        radius = 0.5 * (left + right)
        parameters["wheel_radius"] = radius
        ratios = (left / radius, right / radius)
    else:
        ratios = (2.0 * k_left / (k_left + k_right), 2.0 * k_right / (k_left + k_right))
    parameters["left_wheel_radius_multiplier"], parameters["right_wheel_radius_multiplier"] = ratios
    omitted = {} if "wheel_radius" in parameters else {"wheel_radius": why_left or why_right}
    assumes = (
        "" if "wheel_radius" in parameters else "the multipliers assume both wheels count alike per turn"
    )
    settings = {
        "wheel_separation_multiplier": "not calibrated: 1, so that the controller drives the calibrated "
        "wheel_separation itself (a multiplier of yours would scale it)"
    }
    return ControllerMap("diff_drive_controller", parameters, {}, omitted, assumes, settings)


class DiffDriveDrive:
    """Base moves at ``speed``, curvature ``1.5·turn`` per metre; encoders: left and right wheel."""

    default_truth: Mapping[str, float] = MappingProxyType(
        {
            "k_left": 4.9e-4,
            "k_right": 5.1e-4,
            "baseline": 0.55,
            "sensor_x": 0.3,
            "sensor_y": -0.05,
            "sensor_theta": 0.08,
        }
    )
    default_guess: Mapping[str, float] = MappingProxyType(
        {
            "k_left": 5e-4,
            "k_right": 5e-4,
            "baseline": 0.5,
            "sensor_x": 0.25,
            "sensor_y": 0.0,
            "sensor_theta": 0.0,
        }
    )
    #: Counts per wheel turn: written to the header for information, not used by the model.
    default_ranges: Mapping[str, int] = MappingProxyType({LEFT_ENCODER: 4096, RIGHT_ENCODER: 4096})
    #: A robot whose controller integrates its odometry with a wrong model (joint units: the radii
    #: in m per rad), and that model: the vendor odometry simulator's defaults.
    vendor_truth: Mapping[str, float] = MappingProxyType(
        {"k_left": 0.1012, "k_right": 0.0994, "baseline": 0.462}
    )
    vendor_model: Mapping[str, float] = MappingProxyType({"k_left": 0.1, "k_right": 0.1, "baseline": 0.45})

    def odometry(self, joints: Mapping[str, np.ndarray], params: Mapping[str, float]) -> np.ndarray:
        """The base poses ``(n, 3)`` a controller integrates (exact arcs) from the wheels' angles
        with its own model ``params`` (m per rad, m)."""
        d_l = np.diff(joints["left_wheel_joint"]) * params["k_left"]
        d_r = np.diff(joints["right_wheel_joint"]) * params["k_right"]
        return integrate_base(0.5 * (d_l + d_r), (d_r - d_l) / params["baseline"])

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
        w = ds * _SIM_CURVATURE * turn
        half = 0.5 * opts.truth["baseline"] * w
        first: Mapping[str, float | None] = carry or {"left": None, "right": None}
        return ds, w, {"left": running(ds - half, first["left"]), "right": running(ds + half, first["right"])}

    def ticks(self, opts: SimulationSettings, channels: Mapping[str, np.ndarray]) -> np.ndarray:
        t = opts.truth
        left = counter(channels["left"], t["k_left"], opts.wrap_after_ticks)
        right = counter(channels["right"], t["k_right"], 2 * opts.wrap_after_ticks)
        return np.stack([left, right], axis=1)

    def header(self, opts: SimulationSettings) -> LogHeader:
        return drive_header(opts, "differential_drive", DiffDrive.header_names)

    def vendor_odometry(self, header: LogHeader, ticks: np.ndarray, start: Pose | None = None) -> np.ndarray:
        # The vendor's odometry knows the plain differential drive only (a skid-steer's slip too).
        aliases = DiffDrive.header_aliases
        p = {aliases[n.lower()]: v for n, v in header.parameters.items() if n.lower() in aliases}
        d_l = p["k_left"] * wrapped_difference(ticks[:, 0])
        d_r = p["k_right"] * wrapped_difference(ticks[:, 1])
        return first_order(0.5 * (d_l + d_r), (d_r - d_l) / p["baseline"], start)


class DiffDrive:
    """Differential-drive base, parameters ``(k_left, k_right, baseline)`` then the sensor pose
    ``(sensor_x, sensor_y, sensor_theta)``; base link midway between the wheels, x forward."""

    name: ClassVar[str] = "diff_drive"
    log_names: ClassVar[tuple[str, ...]] = ("differential_drive", "diff_drive")
    kinematic_params: ClassVar[tuple[str, ...]] = ("k_left", "k_right", "baseline")
    units: ClassVar[Mapping[str, str]] = MappingProxyType(
        {"k_left": "m per tick", "k_right": "m per tick", "baseline": "m"}
    )
    header_names: ClassVar[Mapping[str, str]] = MappingProxyType(
        {"k_left": "Kleft", "k_right": "Kright", "baseline": "baseline"}
    )
    header_aliases: ClassVar[Mapping[str, str]] = MappingProxyType(
        {
            "kleft": "k_left",
            "k_left": "k_left",
            "kright": "k_right",
            "k_right": "k_right",
            "baseline": "baseline",
            "base_line": "baseline",
        }
    )
    input_names: ClassVar[tuple[str, ...]] = ("left_ticks", "right_ticks")
    input_units: ClassVar[Mapping[str, str]] = MappingProxyType(
        {"left_ticks": "ticks", "right_ticks": "ticks"}
    )
    level_inputs: ClassVar[tuple[str, ...]] = ()
    encoder_kinds: ClassVar[Mapping[str, EncoderKind]] = MappingProxyType(
        {LEFT_ENCODER: "counter", RIGHT_ENCODER: "counter"}
    )
    turning_params: ClassVar[tuple[str, ...]] = ("baseline",)
    turning_note: ClassVar[str] = ""
    reference: ClassVar[Mapping[str, Reference]] = MappingProxyType({})
    headline: ClassVar[tuple[str, ...]] = ("k_left", "baseline")
    defaults: ClassVar[Mapping[str, float]] = MappingProxyType({})
    symmetries: ClassVar[tuple[Symmetry, ...]] = (
        Symmetry(
            "the base frame turned round",
            "baseline",
            ("k_left", "k_right", "baseline", *SENSOR_TURNED[0]),
            SENSOR_TURNED[1],
        ),
    )
    angle_params: ClassVar[tuple[str, ...]] = ("sensor_theta",)
    steer_max: ClassVar[float | None] = None
    drive: ClassVar[DiffDriveDrive] = DiffDriveDrive()
    physical_ranges: ClassVar[Mapping[str, tuple[float, float]]] = MappingProxyType(
        {
            "k_left": (1e-7, 1.0),
            "k_right": (1e-7, 1.0),
            "baseline": (0.05, 5.0),
            "sensor_x": (-5.0, 5.0),
            "sensor_y": (-5.0, 5.0),
            "sensor_theta": (-np.pi, np.pi),
        }
    )

    def reach(self, params: Mapping[str, float], steer_max: float | None = None) -> Reach:
        """Wheels on a common axis, none steered: the base turns on the spot (a skid-steer too)."""
        return Reach(0.0)

    def increment(self, k: ca.SX, u: ca.SX, integration: str) -> ca.SX:
        """Travel ``(d_r + d_l)/2`` turning by ``(d_r − d_l)/baseline``; exact arc or Euler."""
        p, ticks = named(self.kinematic_params, k), named(self.input_names, u)
        d_left, d_right = p["k_left"] * ticks["left_ticks"], p["k_right"] * ticks["right_ticks"]
        travel = 0.5 * (d_left + d_right)
        dtheta = (d_right - d_left) / p["baseline"]
        if integration == "euler":
            return ca.vertcat(travel, 0.0, dtheta)
        return se2.arc(travel, dtheta)

    def inputs(self, log: Log, steering_sample: str) -> np.ndarray:
        """Rows: left and right wheel tick increments (``steering_sample`` does not apply)."""
        missing = [e for e in self.encoder_kinds if e not in log.header.encoder_names]
        if missing:
            raise ModelError(
                f"{log.path}: the differential-drive model needs encoders {list(self.encoder_kinds)}; "
                f"the log has {list(log.header.encoder_names)}"
            )
        return np.vstack([log.increments(LEFT_ENCODER), log.increments(RIGHT_ENCODER)]).astype(float)

    def moving(self, inputs: np.ndarray) -> np.ndarray:
        return np.asarray((inputs[0] != 0.0) | (inputs[1] != 0.0))

    def travel_direction(self, inputs: np.ndarray) -> np.ndarray:
        """The sign of the wheels' mean increment (0 when turning on the spot)."""
        return np.sign(inputs[0] + inputs[1])

    def undetermined(self, inputs: np.ndarray) -> dict[str, str]:
        """None: every parameter can be determined (the observability analysis judges how well)."""
        return {}

    def controller(self, params: Mapping[str, float], scales: EncoderScales) -> ControllerMap:
        """``diff_drive_controller``: the wheel separation, and each wheel's radius (its travel per
        tick times the ticks per turn over 2π) as their mean and each wheel's multiplier of it when
        the ticks per turn are known; else only the multipliers, which need none when both wheels
        count alike."""
        return wheel_pair(params["k_left"], params["k_right"], params["baseline"], scales)

    def input_rates(self, log: Log) -> np.ndarray | None:
        """None: counts are re-sampled on whole ticks, so the intervals give the rates."""
        return None

    def in_radians(self) -> InRadians:
        """The differential drive read from joint positions in radians (:data:`RADIANS`)."""
        return InRadians(self, RADIANS)

    def implausible(self, params: Mapping[str, float]) -> str:
        """Both wheel gains negative: the mirror image of the robot, which fits a log whose left and
        right encoders are swapped exactly (the sensor then faces backwards). One negative: that
        wheel's encoder counts backwards (a joint whose axis is mirrored, as URDFs often have it)."""
        negative = [n for n in ("k_left", "k_right") if params[n] < 0]
        if len(negative) == 1:
            name = negative[0]
            side = name.removeprefix("k_")
            return (
                f"{name} came out negative ({params[name]:.3g}) and the other wheel's positive: the "
                f"{side} wheel's encoder counts backwards (its joint's axis mirrored, as URDFs often give "
                f"one side's wheel, or the motor wired the other way); negate its readings ({side} wheel)"
            )
        if len(negative) < 2:
            return ""
        # A planar mount's heading says where the sensor faces; a 3-D mount's takes all three angles.
        theta = params.get("sensor_theta")
        facing = "" if theta is None else "backwards" if abs(wrap_angle(theta)) > np.pi / 2 else "forwards"
        return (
            f"k_left and k_right came out negative ({params['k_left']:.3g}, {params['k_right']:.3g})"
            f"{f' and the sensor faces {facing}' if facing else ''}: the mirror image of the robot, "
            "which the wheels and the reference give when they disagree on which way the robot turns: "
            "either the reference's sign convention is mirrored (REP 103: x forward, y left, angles "
            "counter-clockwise seen from above; a lidar mounted upside down whose scans are not flipped, "
            "a motions file or tracker whose y and θ have the opposite sign), or the left and right wheel "
            "joints are swapped (or both count backwards). Drive a left turn: if the reference's heading "
            "falls, negate its y and θ (flip the scans); if it grows, give the joints in the order "
            f"{LEFT_ENCODER}, {RIGHT_ENCODER}"
        )

    def counter_rows(self, log: Log) -> dict[str, tuple[int, float]]:
        """Both counters drive their own row, in ticks."""
        return {LEFT_ENCODER: (0, 1.0), RIGHT_ENCODER: (1, 1.0)}

    def input_noise_std(self, log: Log, encoder_noise: Mapping[str, float] | None = None) -> np.ndarray:
        """1σ of each increment in ticks (default: quantisation, ``1/√12``)."""
        ticks = {**dict.fromkeys(self.encoder_kinds, QUANTISATION), **(encoder_noise or {})}
        return np.array([ticks[LEFT_ENCODER], ticks[RIGHT_ENCODER]])

    def readings_from_odometry(self, base: np.ndarray, params: Mapping[str, float]) -> dict[str, np.ndarray]:
        """The wheels' readings (from 0) a controller of model ``params`` turned to drive the base
        poses ``base`` ``(n, 3)``: each step an arc, the wheels' travel ``s ∓ baseline·Δθ/2``."""
        arc, turn = arcs(base)
        left = (arc - 0.5 * params["baseline"] * turn) / params["k_left"]
        right = (arc + 0.5 * params["baseline"] * turn) / params["k_right"]
        return {LEFT_ENCODER: running(left), RIGHT_ENCODER: running(right)}

    def initial_guess(
        self,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: Callable[[Mapping[str, float]], np.ndarray],
    ) -> dict[str, float]:
        """Closed form: ``Δθ = (k_right/b)·ΣΔr − (k_left/b)·ΣΔl`` is linear; hand-eye gives ``b``."""
        rows = rows_by_name(self.input_names, U)
        left, right = rows["left_ticks"].sum(0), rows["right_ticks"].sum(0)
        alpha, beta = robust_lstsq(np.stack([right, -left], 1), z[2])
        unit = {"k_left": float(beta), "k_right": float(alpha), "baseline": 1.0}
        unit.update({"sensor_x": 0.0, "sensor_y": 0.0, "sensor_theta": 0.0})
        base = base_motion(unit)
        he = hand_eye(base[2], base[:2], z)
        x, y, theta = he.T_base_sensor
        b = he.scale
        return {
            "k_left": float(beta) * b,
            "k_right": float(alpha) * b,
            "baseline": b,
            "sensor_x": x,
            "sensor_y": y,
            "sensor_theta": theta,
        }
