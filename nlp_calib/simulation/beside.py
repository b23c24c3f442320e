"""A lidar (or a camera) and an IMU on one drive: one ROS 2 bag of ``/joint_states``, ``/scan`` and ``/imu``
(or, in place of the scans, a tracker's poses of the lidar's frame on ``/tracker``: a motion
capture's markers where the lidar sits, each pose with white noise).

The base drives in a room as the lidar simulator's does (:mod:`nlp_calib.simulation.lidar`; its
fine grid also holds the IMU's samples); the IMU on it reads as the IMU simulator's does
(:mod:`nlp_calib.simulation.imu`: tilt, biases, noise). Each driver stamps its own
``stamp_offset_s`` late (two clocks). The truth file holds the lidar's mount, the gyro's
parameters, the wheels and both clocks' offsets (``tracker_lag``, ``gyro_lag``) in their names.
A camera's drive (:mod:`nlp_calib.simulation.camera`) takes the IMU's readings the same way: its
TUM file and joint CSV, the gyro's CSV beside them. Deterministic for a given seed.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core.errors import OptionsError
from nlp_calib.core.files import atomic_write_text
from nlp_calib.logs.imu import format_gyro_csv
from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.logs.tum import format_tum
from nlp_calib.models.clock import LAG_PARAM
from nlp_calib.sensors.beside import GYRO_LAG
from nlp_calib.simulation.camera import DEFAULT_MOUNT as CAMERA_MOUNT
from nlp_calib.simulation.camera import (
    EPOCH_S,
    CameraSimulation,
    CameraSimulationOptions,
    camera_paths,
    simulate_camera,
    write_camera_simulation,
)
from nlp_calib.simulation.imu import (
    DEFAULT_GYRO,
    ImuSimulation,
    ImuSimulationOptions,
    gyro_readings,
    imu_messages,
    imu_rotation,
    imu_times,
)
from nlp_calib.simulation.lidar import (
    DEFAULT_MOUNT,
    LidarSimulation,
    LidarSimulationOptions,
    lidar_messages,
    lidar_paths,
    simulate_lidar,
)
from nlp_calib.simulation.rosbag import pose_stamped, write_bag
from nlp_calib.simulation.simulate import SimulatedLog

#: A motion capture's pose noise (m, rad per pose and axis) and its topic.
TRACKER_NOISE = (0.002, 0.002)
TRACKER_TOPIC = "/tracker"


def _with_gyro(
    reference: dict[str, Any], truth: Mapping[str, float], lag_s: float, imu: ImuSimulation
) -> dict[str, Any]:
    """A reference's truth record with the gyro's parameters and both clocks' offsets added."""
    gyro = imu.truth_dict()
    params = {**truth, **gyro["params"], LAG_PARAM: lag_s, GYRO_LAG: imu.options.stamp_offset_s}
    return {**reference, "params": params, "imu_options": gyro["options"]}


@dataclass(frozen=True)
class BesideSimulation:
    """The lidar's simulation and the IMU's on the same drive."""

    lidar: LidarSimulation
    imu: ImuSimulation

    def truth_dict(self) -> dict[str, Any]:
        lidar = self.lidar
        return _with_gyro(lidar.truth_dict(), lidar.options.truth, lidar.options.stamp_offset_s, self.imu)


def simulate_beside(lidar: LidarSimulationOptions, imu: ImuSimulationOptions) -> BesideSimulation:
    """The lidar's drive with the IMU's readings on it (the IMU's model and duration the lidar's;
    its truth's wheels the lidar's; each driver stamps its own ``stamp_offset_s`` late)."""
    kinematic = {k: v for k, v in lidar.truth.items() if k not in DEFAULT_MOUNT}
    imu = replace(
        imu,
        model=lidar.model,
        duration_s=lidar.duration_s,
        truth={**{k: imu.truth[k] for k in DEFAULT_GYRO}, **kinematic},
    )
    scans = simulate_lidar(lidar, also_s=imu_times(imu))
    return BesideSimulation(scans, _gyro_on(imu, scans.fine_time_s, scans.base_poses, scans))


@dataclass(frozen=True)
class CameraBesideSimulation:
    """A camera's simulation and the IMU's on the same drive."""

    camera: CameraSimulation
    imu: ImuSimulation

    def truth_dict(self) -> dict[str, Any]:
        camera = self.camera
        return _with_gyro(camera.truth_dict(), camera.truth, camera.options.stamp_offset_s, self.imu)


def simulate_camera_beside(
    camera: CameraSimulationOptions, imu: ImuSimulationOptions
) -> CameraBesideSimulation:
    """The camera's drive with the IMU's readings on it (as :func:`simulate_beside` lays them on
    the lidar's; the floor level, as a gyro about the base's vertical alone needs)."""
    if camera.noise.floor_tilt:
        raise OptionsError("noise.floor_tilt: a gyro beside the camera reads a level base's turning (give 0)")
    kinematic = {k: v for k, v in camera.truth.items() if k not in CAMERA_MOUNT}
    imu = replace(
        imu,
        model=camera.model,
        duration_s=camera.duration_s,
        truth={**{k: imu.truth[k] for k in DEFAULT_GYRO}, **kinematic},
    )
    cam = simulate_camera(camera, also_s=imu_times(imu))
    return CameraBesideSimulation(cam, _gyro_on(imu, cam.fine_time_s, cam.base_poses, cam))


def _gyro_on(
    imu: ImuSimulationOptions,
    t_fine: np.ndarray,
    base: np.ndarray,
    joints: CameraSimulation | LidarSimulation,
) -> ImuSimulation:
    """The IMU's readings over the base's poses ``base`` on the fine grid, beside ``joints``' joints."""
    rng = np.random.default_rng([imu.seed, 1])
    rates, accel = gyro_readings(imu, rng, t_fine, base)
    return ImuSimulation(
        imu_time_s=EPOCH_S + imu_times(imu) + imu.stamp_offset_s,
        rates=rates,
        accel=accel,
        joint_time_s=joints.joint_time_s,
        joint_names=joints.joint_names,
        joint_positions=joints.joint_positions,
        options=imu,
    )


def camera_beside_paths(tum_path: str | Path) -> tuple[Path, Path, Path, Path]:
    """The camera's files (:func:`~nlp_calib.simulation.camera.camera_paths`) and ``<name>.gyro.csv``."""
    tum, joints, truth = camera_paths(tum_path)
    return tum, joints, tum.with_suffix(".gyro.csv"), truth


def write_camera_beside_simulation(
    sim: CameraBesideSimulation, tum_path: str | Path
) -> tuple[Path, Path, Path, Path]:
    """The camera's TUM file and joint CSV, the gyro's CSV (``t,wx,wy,wz``) and the truth JSON."""
    tum, joints, gyro, truth = camera_beside_paths(tum_path)
    write_camera_simulation(sim.camera, tum)
    atomic_write_text(gyro, format_gyro_csv(sim.imu.imu_time_s, sim.imu.rates))
    atomic_write_text(truth, json.dumps(sim.truth_dict(), indent=2) + "\n")
    return tum, joints, gyro, truth


def tracker_poses(sim: LidarSimulation) -> np.ndarray:
    """The lidar's frame as a tracker sees it: its true pose at each scan's stamp with
    :data:`TRACKER_NOISE` (deterministic for the seed)."""
    rng = np.random.default_rng([sim.options.seed, 2])
    xy, theta = TRACKER_NOISE
    return np.asarray(
        sim.lidar_poses + rng.normal(0.0, 1.0, sim.lidar_poses.shape) * np.array([xy, xy, theta])
    )


def tracker_messages(sim: LidarSimulation) -> list[Any]:
    """``/tf_static`` and ``/joint_states`` as the lidar's bag has them, then
    :func:`tracker_poses` on ``/tracker`` at the scans' stamps."""
    ns = lambda t: round(float(t) * 1e9)  # noqa: E731
    messages = [m for m in lidar_messages(sim) if m[0] != "/scan"]
    return messages + [
        pose_stamped(ns(s), TRACKER_TOPIC, "map", p) for s, p in zip(sim.scan_time_s, tracker_poses(sim))
    ]


def write_beside_simulation(
    sim: BesideSimulation, bag: str | Path, tracker: bool = False
) -> tuple[Path, Path]:
    """Write the bag (``/joint_states``, ``/scan`` or with ``tracker`` ``/tracker``, ``/imu``,
    ``/tf_static``) and the truth JSON."""
    path, truth = lidar_paths(bag)
    reference = tracker_messages(sim.lidar) if tracker else lidar_messages(sim.lidar)
    write_bag(path, reference + imu_messages(sim.imu))
    atomic_write_text(truth, json.dumps(sim.truth_dict(), indent=2) + "\n")
    return path, truth


def write_text_log_gyro(
    sim: SimulatedLog,
    path: str | Path,
    gyro: Mapping[str, float],
    rate_noise: float,
    seed: int,
    late_s: float = 0.0,
) -> Path:
    """A gyro's CSV (``t,wx,wy,wz``) beside a simulated text log, sampled at 200 Hz on the log's
    clock: the base's turn rate over each record interval (its heading change over its duration, as
    the drive's arcs turn) through the IMU's tilt (``gyro``: ``imu_roll``, ``imu_pitch`` and the
    biases ``gyro_bias_x``, ``_y``, ``_z``), white noise of ``rate_noise`` (rad/s a sample, its own
    generator from ``seed``), each sample stamped ``late_s`` late (the truth's ``gyro_lag``)."""
    time_s = (sim.time_ns - sim.time_ns[0]).astype(float) * 1e-9
    t = np.arange(0.0, time_s[-1], 0.005)
    rate = np.diff(np.unwrap(sim.T_world_base_true[:, 2])) / np.diff(time_s)
    turn = rate[np.clip(np.searchsorted(time_s, t, side="right") - 1, 0, rate.size - 1)]
    bias = np.array([gyro[f"gyro_bias_{a}"] for a in "xyz"])
    w = turn[:, None] * imu_rotation(gyro)[2][None, :] + bias
    w += np.random.default_rng(seed).normal(0.0, rate_noise, w.shape)
    stamps = float(sim.time_ns[0]) * 1e-9 + t + late_s
    atomic_write_text(Path(path), format_gyro_csv(stamps, w))
    return Path(path)


def write_tracked_files(sim: BesideSimulation, folder: str | Path) -> tuple[Path, Path, Path]:
    """The tracked base beside its gyro as files without a bag: ``drive.tum`` (:func:`tracker_poses`
    at the scans' stamps, level), ``drive.csv`` (the joints) and ``gyro.csv``."""
    folder = Path(folder)
    ns = lambda t: np.round(np.asarray(t) * 1e9).astype(np.int64)  # noqa: E731
    planar = tracker_poses(sim.lidar)
    half = planar[:, 2] / 2
    tum = np.column_stack([planar[:, :2], np.zeros((len(planar), 3)), np.sin(half), np.cos(half)])
    paths = folder / "drive.tum", folder / "drive.csv", folder / "gyro.csv"
    atomic_write_text(paths[0], format_tum(ns(sim.lidar.scan_time_s), tum))
    lidar = sim.lidar
    atomic_write_text(
        paths[1], format_joint_csv(ns(lidar.joint_time_s), lidar.joint_names, lidar.joint_positions)
    )
    atomic_write_text(paths[2], format_gyro_csv(sim.imu.imu_time_s, sim.imu.rates))
    return paths
