"""A gyro on a planar robot, with known truth: a ROS 2 bag of its Imu messages and the wheels' joints.

The base drives as the camera simulator's does (:mod:`nlp_calib.simulation.camera`: the model's
own drive on a fine time grid; joints in radians at ``joint_rate_hz``). An IMU tilted on the base
by ``imu_roll`` and ``imu_pitch`` reads, at ``imu_rate_hz``, ``ω = gyro_scale·Rᵀ·(0, 0, θ̇) + b``
(``b``: ``gyro_bias_x``, ``_y``, ``_z``) with white noise ``rate_noise`` (rad/s per sample and
axis), and gravity on its accelerometer; its driver stamps each message ``stamp_offset_s`` late
(the ``tracker_lag`` a fit finds). The bag holds ``/joint_states``, ``/imu`` and ``/tf_static``
(the IMU's nominal mount, level); the truth file beside it the parameters in their names.
Deterministic for a given seed.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core import poses3d
from nlp_calib.core.errors import OptionsError
from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.ranges import Range
from nlp_calib.models.clock import LAG_PARAM
from nlp_calib.models.joints import JOINT_MAPS, joint_map
from nlp_calib.simulation.camera import EPOCH_S, base_motion, fine_grid, full_truth
from nlp_calib.simulation.lidar import LIDAR_DRIVE, lidar_paths
from nlp_calib.simulation.options import DriveShape
from nlp_calib.simulation.rosbag import imu, joint_state, tf_static, write_bag

#: A gyro with the bias of a consumer MEMS part (about 0.2 °/s) on an IMU tilted by a degree or two.
DEFAULT_GYRO: Mapping[str, float] = {
    "gyro_bias_x": 0.003,
    "gyro_bias_y": -0.002,
    "gyro_bias_z": 0.004,
    "imu_roll": 0.02,
    "imu_pitch": -0.03,
}
#: Where the IMU sits on the base (not calibrated: a gyro cannot see it).
IMU_XYZ = (0.1, 0.0, 0.15)
GRAVITY = 9.81

LIMITS: Mapping[str, Range] = {
    "duration_s": Range(1.0, 36_000.0),
    "seed": Range(0, 2**32 - 1, integer=True),
    "imu_rate_hz": Range(1.0, 2000.0),
    "joint_rate_hz": Range(1.0, 1000.0),
    "rate_noise": Range(0.0, 1.0),
    "stamp_offset_s": Range(-1.0, 1.0),
    "scale": Range(0.5, 2.0),
}


@dataclass(frozen=True)
class ImuSimulationOptions:
    """What to simulate (angles in rad, rates in rad/s, times in s). ``truth`` maps the model's
    kinematic parameters (joint units) and the gyro's ``gyro_bias_x … imu_pitch``; missing entries
    take the model's joint-map defaults and :data:`DEFAULT_GYRO`."""

    model: str = next(iter(JOINT_MAPS))
    duration_s: float = 120.0
    seed: int = 0
    truth: Mapping[str, float] = field(default_factory=dict)
    imu_rate_hz: float = 200.0
    joint_rate_hz: float = 50.0
    rate_noise: float = 0.002
    stamp_offset_s: float = 0.0
    scale: float = 1.0
    drive: DriveShape = field(default_factory=lambda: LIDAR_DRIVE)
    #: The Imu messages' ``frame_id`` (and the child of its ``/tf_static`` transform).
    frame: str = "imu_link"
    #: The seed of the gyro noise's own generator (None: the drive's goes on to draw it): the same
    #: drive with other draws of its noise.
    noise_seed: int | None = None

    def __post_init__(self) -> None:
        for name, limit in LIMITS.items():
            if (reason := limit.problem(getattr(self, name))) is not None:
                raise OptionsError(f"{name} {reason}")
        if self.noise_seed is not None and (reason := LIMITS["seed"].problem(self.noise_seed)) is not None:
            raise OptionsError(f"noise_seed {reason}")
        object.__setattr__(self, "truth", full_truth(self.model, self.truth, DEFAULT_GYRO))


@dataclass(frozen=True)
class ImuSimulation:
    """The IMU's stamps (as its driver wrote them), rates ``(n, 3)`` and accelerations, the joints'
    stamps, names and angles, and the options."""

    imu_time_s: np.ndarray
    rates: np.ndarray
    accel: np.ndarray
    joint_time_s: np.ndarray
    joint_names: tuple[str, ...]
    joint_positions: np.ndarray
    options: ImuSimulationOptions

    def truth_dict(self) -> dict[str, Any]:
        o = self.options
        return {
            "params": {**o.truth, "gyro_scale": o.scale, LAG_PARAM: o.stamp_offset_s},
            "options": asdict(o),
            "imu_samples": int(self.imu_time_s.size),
            "joint_samples": int(self.joint_time_s.size),
        }


def imu_rotation(truth: Mapping[str, float]) -> np.ndarray:
    """The IMU's frame turned onto the base's (its roll and pitch; no yaw)."""
    return np.asarray(poses3d.rpy_to_matrix(np.array([truth["imu_roll"], truth["imu_pitch"], 0.0])))


def imu_times(opts: ImuSimulationOptions) -> np.ndarray:
    """The IMU's sample times (s from the start, as sampled)."""
    return np.arange(0.0, opts.duration_s, 1.0 / opts.imu_rate_hz)


def gyro_readings(
    opts: ImuSimulationOptions, rng: np.random.Generator, t_fine: np.ndarray, planar: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The gyro's rates and the accelerometer's readings at :func:`imu_times` over the base's
    drive ``planar`` on the fine grid ``t_fine`` (which holds those times)."""
    t_imu = imu_times(opts)
    # The base's turn rate at each sample: the fine grid's steps (1 ms) are exact arcs.
    turn_rate = np.diff(np.unwrap(planar[:, 2])) / np.diff(t_fine)
    yaw_rate = np.interp(t_imu, 0.5 * (t_fine[1:] + t_fine[:-1]), turn_rate)
    R = imu_rotation(opts.truth)
    bias = np.array([opts.truth[n] for n in ("gyro_bias_x", "gyro_bias_y", "gyro_bias_z")])
    rates = opts.scale * yaw_rate[:, None] * R[2][None, :] + bias
    rates += rng.normal(0.0, opts.rate_noise, rates.shape)
    return rates, np.array(np.broadcast_to(GRAVITY * R[2], rates.shape))


def simulate_imu(opts: ImuSimulationOptions) -> ImuSimulation:
    """Simulate a drive, the gyro's rates and the joints."""
    rng = np.random.default_rng(opts.seed)
    t_imu = imu_times(opts)
    t_joints = np.arange(-0.5, opts.duration_s + 0.5, 1.0 / opts.joint_rate_hz)
    t_fine = fine_grid(t_imu, t_joints)
    planar, channels = base_motion(opts.model, opts.truth, opts.drive, rng, t_fine)
    noise = rng if opts.noise_seed is None else np.random.default_rng(opts.noise_seed)
    rates, accel = gyro_readings(opts, noise, t_fine, planar)
    at_joints = np.searchsorted(t_fine, t_joints)
    angles = joint_map(opts.model).angles(opts.truth, {k: v[at_joints] for k, v in channels.items()})
    return ImuSimulation(
        imu_time_s=EPOCH_S + t_imu + opts.stamp_offset_s,
        rates=rates,
        accel=accel,
        joint_time_s=EPOCH_S + t_joints,
        joint_names=tuple(angles),
        joint_positions=np.column_stack(list(angles.values())),
        options=opts,
    )


def imu_paths(bag: str | Path) -> tuple[Path, Path]:
    """Where a simulation goes: the bag folder and ``<name>.truth.json`` beside it."""
    return lidar_paths(bag)


def write_imu_simulation(sim: ImuSimulation, bag: str | Path) -> tuple[Path, Path]:
    """Write the bag (``/joint_states``, ``/imu``, ``/tf_static``) and the truth JSON."""
    path, truth = imu_paths(bag)
    ns = lambda t: round(float(t) * 1e9)  # noqa: E731
    messages = [
        joint_state(ns(s), sim.joint_names, row) for s, row in zip(sim.joint_time_s, sim.joint_positions)
    ]
    write_bag(path, imu_messages(sim) + messages)
    atomic_write_text(truth, json.dumps(sim.truth_dict(), indent=2) + "\n")
    return path, truth


def imu_messages(sim: ImuSimulation) -> list[Any]:
    """The IMU's messages: its ``/tf_static`` and ``/imu``."""
    ns = lambda t: round(float(t) * 1e9)  # noqa: E731
    frame = sim.options.frame
    messages = [tf_static(ns(sim.joint_time_s[0]), "base_link", frame, IMU_XYZ, 0.0)]
    return messages + [imu(ns(s), frame, w, a) for s, w, a in zip(sim.imu_time_s, sim.rates, sim.accel)]
