"""Real vehicles' drives, with known truth: a skid-steer spinning fast on rough ground, a car on a
highway.

:func:`simulate_skid_spins` drives a skid-steer base (the skid-steer model in joint units: each side's
rolling radius in m per rad, the effective track at a slow turn and its growth with the turn
rate) through straight stretches, arcs and pivot turns at ``spin_rate`` (several radians per
motion: more than π per increment at the default rate). The wheels are the model's own law, but
on a pivot the ground lets the base turn a random share up to ``pivot_slip`` less than that law
says, or more (slip the model does not hold). The joints are logged at ``joint_rate_hz`` while their
positions update only at ``encoder_update_hz`` (a slow wheel driver: each message repeats the
last update); a lidar matcher reports the sensor's motion over each ``motion_span_s`` with white
noise, its heading wrapped to (−π, π] as a matcher gives it. The simulator integrates the base on
a fine grid, independently of the symbolic model. Deterministic for a given seed.

:func:`simulate_highway` drives a car (the car-like model in joint units) at 8 to 20 m/s for a
minute, about a kilometre, its road wheels steered within ±``steer_max`` by a driver's small
corrections and its heading changing by ``road.heading_change`` in all; the four wheels' speeds
(rad/s) and the steer joint's angle are logged at ``wheel_rate_hz`` (a car's CAN bus), the pose of
a windshield device (GNSS/vision) at ``pose_rate_hz`` with white noise. Its ``road``
(:class:`RoadOptions`) can add bends, a rear axle sliding out of them and a device error that
wanders in time: what a real car has at speed that the kinematic model lacks. What such a drive cannot
determine (the axle distance, the steer gain, the track, the device's position) is the class it
stands for.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from nlp_calib.core import poses
from nlp_calib.core.errors import OptionsError
from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.poses3d import from_planar
from nlp_calib.core.ranges import Range
from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.logs.motions import format_motions
from nlp_calib.logs.tum import format_tum
from nlp_calib.models.car_like import (
    HIGHWAY_JOINTS,
    HIGHWAY_TRUTH,
    highway_curvature,
    highway_steer,
    highway_wheels,
)
from nlp_calib.models.drives import integrate_base
from nlp_calib.models.skid_steer import SPIN_TRUTH as SKID_TRUTH
from nlp_calib.models.skid_steer import spin_problem, spin_wheels

JOINTS = ("left_wheel_joint", "right_wheel_joint")
#: The fine grid the base is integrated on (s).
FINE_S = 0.002
EPOCH_NS = 1_700_000_000_000_000_000

LIMITS: Mapping[str, Range] = {
    "duration_s": Range(10.0, 36_000.0),
    "seed": Range(0, 2**32 - 1, integer=True),
    "joint_rate_hz": Range(1.0, 1000.0),
    "encoder_update_hz": Range(0.5, 1000.0),
    "motion_span_s": Range(0.05, 10.0),
    "spin_rate": Range(0.0, 6.0),
    "max_speed": Range(0.0, 5.0, lo_open=True),
    "pivot_fraction": Range(0.0, 1.0),
    "pivot_slip": Range(0.0, 0.9),
    "motion_noise_xy": Range(0.0, 1.0),
    "motion_noise_theta": Range(0.0, 1.0),
}


@dataclass(frozen=True)
class SkidSpinOptions:
    """What to simulate (angles in rad, lengths in m, times in s); ``truth`` overrides
    :data:`SKID_TRUTH` by name."""

    duration_s: float = 240.0
    seed: int = 0
    joint_rate_hz: float = 20.0
    encoder_update_hz: float = 4.0
    motion_span_s: float = 2.0
    spin_rate: float = 2.5
    max_speed: float = 0.8
    pivot_fraction: float = 0.4
    pivot_slip: float = 0.1
    motion_noise_xy: float = 0.005
    motion_noise_theta: float = 0.003
    truth: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        truth = _checked(self, LIMITS, SKID_TRUTH, "skid-steer")
        if problem := spin_problem(truth, self.spin_rate):
            raise OptionsError(problem)


def _limited(opts: Any, limits: Mapping[str, Range], what: str = "") -> None:
    """Check ``opts``' fields against ``limits`` (``what``: how the error names their group)."""
    for name, limit in limits.items():
        if (reason := limit.problem(getattr(opts, name))) is not None:
            raise OptionsError(f"{what}{name} {reason}")


def _checked(
    opts: Any, limits: Mapping[str, Range], defaults: Mapping[str, float], robot: str
) -> Mapping[str, float]:
    """Check ``opts``' fields against ``limits`` and its truth's names against ``defaults`` (the
    ``robot``'s); set its truth to ``defaults`` overridden by it, and return that."""
    _limited(opts, limits)
    unknown = sorted(set(opts.truth) - set(defaults))
    if unknown:
        raise OptionsError(f"unknown parameter(s) {unknown}; the {robot}'s are {', '.join(defaults)}")
    truth = MappingProxyType({**defaults, **opts.truth})
    object.__setattr__(opts, "truth", truth)
    return truth


@dataclass(frozen=True)
class VehicleSimulation:
    """A simulated drive: the joints' stamps, names and positions (rad), the reference's motions
    (``motion_stamps_s`` ``(m, 2)``, ``motions`` ``(m, 3)``), which motions a pivot's slip spoiled,
    the true base poses at the joints' stamps and the options."""

    joint_time_s: np.ndarray
    joint_names: tuple[str, ...]
    joint_positions: np.ndarray
    motion_stamps_s: np.ndarray
    motions: np.ndarray
    slipped: np.ndarray
    base_poses: np.ndarray
    options: Any

    def joints_csv(self) -> str:
        return format_joint_csv(_ns(self.joint_time_s), self.joint_names, self.joint_positions)

    def motions_csv(self) -> str:
        ns = _ns(self.motion_stamps_s)
        return format_motions(ns[:, 0], ns[:, 1], self.motions)

    def truth_dict(self) -> dict[str, Any]:
        return {
            "params": dict(self.options.truth),
            "slipped_motions": np.flatnonzero(self.slipped).tolist(),
            "distance_m": float(np.sum(np.hypot(*np.diff(self.base_poses[:, :2], axis=0).T))),
        }

    def write(self, stem: str | Path) -> tuple[Path, Path, Path]:
        """``<stem>.csv`` (joints), ``<stem>.motions.csv`` and ``<stem>.truth.json``."""
        import json

        paths = vehicle_paths(stem, "skid_spins")
        atomic_write_text(paths[0], self.joints_csv())
        atomic_write_text(paths[1], self.motions_csv())
        atomic_write_text(paths[2], json.dumps(self.truth_dict(), indent=2) + "\n")
        return paths


#: The vehicles ``nlp-calib simulate --vehicle`` drives: each one's reference file beside its joints.
VEHICLES: Mapping[str, str] = MappingProxyType({"highway_car": ".tum", "skid_spins": ".motions.csv"})


def vehicle_paths(stem: str | Path, vehicle: str) -> tuple[Path, Path, Path]:
    """The files a ``vehicle``'s drive is written to beside ``stem``: its joints (``.csv``), its
    reference (:data:`VEHICLES`) and its truth (``.truth.json``)."""
    stem = Path(stem)
    return stem.with_suffix(".csv"), stem.with_suffix(VEHICLES[vehicle]), stem.with_suffix(".truth.json")


def _ns(t_s: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(t_s) * 1e9).astype(np.int64) + EPOCH_NS


def _segments(
    opts: SkidSpinOptions, rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per fine step: the base's speed (m/s), turn rate (rad/s) and whether it pivots, in segments
    of 2 to 6 s (a pivot's turn rate, a drive's speed and curvature drawn per segment)."""
    speed, rate, pivot = np.zeros(n), np.zeros(n), np.zeros(n, dtype=bool)
    i = 0
    while i < n:
        j = min(n, i + int(rng.uniform(2.0, 6.0) / FINE_S))
        if rng.random() < opts.pivot_fraction:
            rate[i:j] = rng.choice([-1.0, 1.0]) * opts.spin_rate * rng.uniform(0.6, 1.0)
            pivot[i:j] = True
        else:
            speed[i:j] = rng.choice([-1.0, 1.0], p=[0.2, 0.8]) * opts.max_speed * rng.uniform(0.3, 1.0)
            rate[i:j] = speed[i:j] * rng.uniform(-0.8, 0.8)
        i = j
    # Smooth the steps over 0.2 s, as a base's inertia does.
    kernel = np.ones(int(0.2 / FINE_S)) / int(0.2 / FINE_S)
    return np.convolve(speed, kernel, "same"), np.convolve(rate, kernel, "same"), pivot


def simulate_skid_spins(opts: SkidSpinOptions) -> VehicleSimulation:
    """The drive of the module docstring."""
    rng = np.random.default_rng(opts.seed)
    t = opts.truth
    n = int(opts.duration_s / FINE_S)
    speed, rate, pivot = _segments(opts, rng, n)
    # The wheels' own turn rate: the model's law ω = ω_w/(1 + turn_slip·|ω_w|) solved for ω_w; on a
    # pivot the ground turns the base a random share off that (one share per pivot, either way:
    # a share of one sign on every pivot would be the law's own slip, and the truth no longer its).
    angles = spin_wheels(t, speed, rate, FINE_S)  # before the pivots' slip: the wheels' own
    starts = np.flatnonzero(np.diff(np.concatenate([[0], pivot.astype(int)])) == 1)
    share = np.zeros(n)
    for a in starts:
        b = a + int(np.argmin(pivot[a:])) if not pivot[a:].all() else n
        share[a:b] = rng.uniform(-opts.pivot_slip, opts.pivot_slip)
    rate = rate * (1.0 - share)
    base = integrate_base(speed * FINE_S, rate * FINE_S)
    time_s = np.arange(n + 1) * FINE_S
    joint_t = np.arange(0.0, time_s[-1], 1.0 / opts.joint_rate_hz)
    phase = rng.uniform(0.0, 1.0 / opts.encoder_update_hz)
    updated = np.floor((joint_t - phase) * opts.encoder_update_hz) / opts.encoder_update_hz + phase
    held = np.clip(np.round(np.maximum(updated, 0.0) / FINE_S).astype(int), 0, n)
    mount = np.array([t["sensor_x"], t["sensor_y"], t["sensor_theta"]])
    stamps = np.arange(0.0, joint_t[-1] - opts.motion_span_s, opts.motion_span_s)
    ends = np.stack([stamps, stamps + opts.motion_span_s], axis=1)
    idx = np.round(ends / FINE_S).astype(int)
    sensor = poses.compose(base, np.broadcast_to(mount, base.shape))
    z = poses.between(sensor[idx[:, 0]], sensor[idx[:, 1]])
    z += rng.normal(0.0, [opts.motion_noise_xy, opts.motion_noise_xy, opts.motion_noise_theta], z.shape)
    z[:, 2] = np.angle(np.exp(1j * z[:, 2]))
    slipping = np.concatenate([[0], np.cumsum(share != 0)])
    spoiled = slipping[idx[:, 1]] > slipping[idx[:, 0]]
    return VehicleSimulation(
        joint_time_s=joint_t,
        joint_names=JOINTS,
        joint_positions=angles[held],
        motion_stamps_s=ends,
        motions=z,
        slipped=spoiled,
        base_poses=base[np.round(joint_t / FINE_S).astype(int)],
        options=opts,
    )


HIGHWAY_LIMITS: Mapping[str, Range] = {
    "duration_s": Range(10.0, 3600.0),
    "seed": Range(0, 2**32 - 1, integer=True),
    "min_speed": Range(0.0, 70.0, lo_open=True),
    "max_speed": Range(0.0, 70.0, lo_open=True),
    "steer_max": Range(0.0, 0.5, lo_open=True),
    "wheel_rate_hz": Range(1.0, 1000.0),
    "pose_rate_hz": Range(0.5, 1000.0),
    "wheel_noise": Range(0.0, 10.0),
    "steer_noise": Range(0.0, 0.1),
}
ROAD_LIMITS: Mapping[str, Range] = {
    "heading_change": Range(-20.0, 20.0),
    "bend_angle": Range(0.0, 0.5),
    "slip_gain": Range(0.0, 0.05),
    "pose_noise_time_s": Range(0.0, 600.0),
}
#: The device's pose noise: position (m), heading (rad).
POSE_NOISE = (Range(0.0, 5.0), Range(0.0, 1.0))


@dataclass(frozen=True)
class RoadOptions:
    """The road the highway car drives and what a real car has there that the kinematic model
    lacks: the heading's net change (rad), bends (the road wheels' largest angle on them, held 10 to
    40 s), the rear axle sliding out of a bend at ``slip_gain`` rad per m/s² of lateral
    acceleration, and the device's noise correlated over ``pose_noise_time_s`` (0: white); the
    car's speed changes with periods within ``speed_periods_s`` (a car on a circuit brakes and
    accelerates every few seconds)."""

    heading_change: float = float(np.radians(1.0))
    bend_angle: float = 0.0
    slip_gain: float = 0.0
    pose_noise_time_s: float = 0.0
    speed_periods_s: tuple[float, float] = (20.0, 120.0)

    def __post_init__(self) -> None:
        _limited(self, ROAD_LIMITS, "road's ")
        lo, hi = self.speed_periods_s
        if not 0.5 <= lo <= hi <= 3600.0:
            raise OptionsError(f"speed_periods_s {self.speed_periods_s} must be 0.5 <= lo <= hi <= 3600 s")


@dataclass(frozen=True)
class HighwayOptions:
    """What to simulate (angles in rad, lengths in m, speeds in m/s, wheel speeds' noise in rad/s,
    the device's ``pose_noise`` as position and heading);
    ``truth`` overrides :data:`~nlp_calib.models.car_like.HIGHWAY_TRUTH` by name."""

    duration_s: float = 60.0
    seed: int = 0
    min_speed: float = 8.0
    max_speed: float = 20.0
    steer_max: float = float(np.radians(0.3))
    road: RoadOptions = field(default_factory=RoadOptions)
    wheel_rate_hz: float = 90.0
    pose_rate_hz: float = 20.0
    wheel_noise: float = 0.02
    steer_noise: float = 2e-4
    pose_noise: tuple[float, float] = (0.02, 0.002)
    truth: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _checked(self, HIGHWAY_LIMITS, HIGHWAY_TRUTH, "car")
        for what, limit, value in zip(("position", "heading"), POSE_NOISE, self.pose_noise):
            if (reason := limit.problem(value)) is not None:
                raise OptionsError(f"pose_noise's {what} {reason}")
        if self.min_speed > self.max_speed:
            raise OptionsError(f"min_speed {self.min_speed:g} is above max_speed {self.max_speed:g}")


@dataclass(frozen=True)
class HighwaySimulation:
    """A simulated car's drive: the joints' stamps, names and values (wheel speeds in rad/s, the
    steer joint's angle in rad), the device's poses ``(m, 3)`` at ``pose_time_s``, the true base
    poses at the joints' stamps and the options."""

    joint_time_s: np.ndarray
    joint_names: tuple[str, ...]
    joint_values: np.ndarray
    pose_time_s: np.ndarray
    poses: np.ndarray
    base_poses: np.ndarray
    options: HighwayOptions

    def joints_csv(self) -> str:
        return format_joint_csv(_ns(self.joint_time_s), self.joint_names, self.joint_values)

    def poses_tum(self, height: float = 1.3) -> str:
        """The device's poses as TUM lines (at ``height`` above the ground)."""
        planar = from_planar(self.poses)
        planar[:, 2] = height
        return format_tum(_ns(self.pose_time_s), planar)

    def truth_dict(self) -> dict[str, Any]:
        heading = np.unwrap(self.base_poses[:, 2])
        return {
            "params": dict(self.options.truth),
            "distance_m": float(np.sum(np.hypot(*np.diff(self.base_poses[:, :2], axis=0).T))),
            "heading_span_rad": float(np.ptp(heading)),
        }

    def write(self, stem: str | Path) -> tuple[Path, Path, Path]:
        """``<stem>.csv`` (joints), ``<stem>.tum`` (the device's poses) and ``<stem>.truth.json``."""
        import json

        paths = vehicle_paths(stem, "highway_car")
        atomic_write_text(paths[0], self.joints_csv())
        atomic_write_text(paths[1], self.poses_tum())
        atomic_write_text(paths[2], json.dumps(self.truth_dict(), indent=2) + "\n")
        return paths


def _smooth(rng: np.random.Generator, t: np.ndarray, periods: tuple[float, float], k: int = 6) -> np.ndarray:
    """A smooth random signal on ``t`` of ``k`` sinusoids with periods within ``periods`` (s), its
    largest magnitude 1."""
    out = np.zeros_like(t)
    for _ in range(k):
        period = rng.uniform(*periods)
        out += rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * t / period + rng.uniform(0, 2 * np.pi))
    return out / np.max(np.abs(out))


def _slide(base: np.ndarray, ds: np.ndarray, slip: np.ndarray) -> np.ndarray:
    """``base`` (poses at the fine steps' ends, one more than ``ds``) with its axle travelling
    ``slip`` rad right of its heading: out of a left bend, as tyres slide under lateral load."""
    course = base[:-1, 2] - slip
    x = np.concatenate([[base[0, 0]], base[0, 0] + np.cumsum(ds * np.cos(course))])
    y = np.concatenate([[base[0, 1]], base[0, 1] + np.cumsum(ds * np.sin(course))])
    return np.stack([x, y, base[:, 2]], axis=1)


def _pose_noise(rng: np.random.Generator, opts: HighwayOptions, n: int) -> np.ndarray:
    """The device's noise ``(n, 3)``: white, or each component a first-order Gauss-Markov process
    of the same σ with the road's time constant ``pose_noise_time_s`` (a GNSS fix's slowly wandering
    error)."""
    std = np.array([opts.pose_noise[0], *opts.pose_noise])
    white = rng.normal(0.0, std, (n, 3))
    if opts.road.pose_noise_time_s <= 0:
        return white
    a = float(np.exp(-1.0 / (opts.pose_rate_hz * opts.road.pose_noise_time_s)))
    out = np.empty_like(white)
    out[0] = white[0]
    for i in range(1, n):
        out[i] = a * out[i - 1] + np.sqrt(1.0 - a * a) * white[i]
    return out


def simulate_highway(opts: HighwayOptions) -> HighwaySimulation:
    """The drive of the module docstring."""
    rng = np.random.default_rng(opts.seed)
    t = opts.truth
    n = int(opts.duration_s / FINE_S)
    time_s = np.arange(n) * FINE_S
    mid, half = 0.5 * (opts.max_speed + opts.min_speed), 0.5 * (opts.max_speed - opts.min_speed)
    speed = mid + half * _smooth(rng, time_s, opts.road.speed_periods_s)
    # A driver's corrections (periods of 1.5 to 4 s) within 80 % of the limit, and a steady angle
    # that turns the heading by the road's heading_change in all.
    wobble = 0.8 * opts.steer_max * _smooth(rng, time_s, (1.5, 4.0))
    road = opts.road
    if road.bend_angle > 0:
        wobble = wobble + road.bend_angle * _smooth(rng, time_s, (20.0, 80.0), k=4)
    ds = speed * FINE_S
    limit = opts.steer_max + road.bend_angle
    phi = np.clip(highway_steer(t, ds, wobble, road.heading_change), -limit, limit)
    curvature = highway_curvature(t, phi)
    base = integrate_base(ds, ds * curvature)
    if road.slip_gain > 0:
        base = _slide(base, ds, road.slip_gain * speed**2 * curvature)
    joint_t = np.arange(0.0, time_s[-1], 1.0 / opts.wheel_rate_hz)
    at = np.round(joint_t / FINE_S).astype(int)
    values = highway_wheels(t, speed[at], curvature[at])
    values += rng.normal(0.0, [*[opts.wheel_noise] * 4, opts.steer_noise], values.shape)
    pose_t = np.arange(0.0, time_s[-1], 1.0 / opts.pose_rate_hz)
    mount = np.array([t["sensor_x"], t["sensor_y"], t["sensor_theta"]])
    device = poses.compose(
        base[np.round(pose_t / FINE_S).astype(int)], np.broadcast_to(mount, (pose_t.size, 3))
    )
    device += _pose_noise(rng, opts, pose_t.size)
    return HighwaySimulation(
        joint_time_s=joint_t,
        joint_names=HIGHWAY_JOINTS,
        joint_values=values,
        pose_time_s=pose_t,
        poses=device,
        base_poses=base[at],
        options=opts,
    )
