"""A tilted camera on a planar robot, with known truth: its TUM trajectory and the joint CSV.

The base drives as in :mod:`nlp_calib.simulation.simulate` (the model's own drive: exact arcs on
a fine time grid, smoothly varying speed and turning, stops and reversals), but the robot logs
joint angles in radians (the model's joint map, :mod:`nlp_calib.models.joints`) at
``joint_rate_hz``, and a camera (x right, y down, z forward) mounted at ``T_base_camera`` reports
its own pose at ``image_rate_hz`` in its own world frame (the first image's camera frame), as a
visual odometry or SLAM system does. Options: pose noise (position, and rotation on the right),
a stamp offset (the camera stamps each image ``stamp_offset_s`` late), the trajectory's scale
(translations written in metres divided by ``scale``: monocular visual odometry) and an uneven
floor (the base rolls and pitches smoothly by up to ``floor_tilt`` rad). The fine grid holds every
image's and joint sample's instant, so samples are exact. Deterministic for a given seed.
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
from nlp_calib.logs import format_joint_csv, format_tum
from nlp_calib.models import MODELS
from nlp_calib.models.drives import integrate_base
from nlp_calib.models.joints import JOINT_MAPS, joint_map
from nlp_calib.sensors.mount import MOUNT_PARAMS, SCALE_PARAM
from nlp_calib.simulation.options import DriveShape, drive_profiles, profiles_on

#: A camera looking forward and 30° down (roll −120°), slightly pitched, on the base's left.
DEFAULT_MOUNT: Mapping[str, float] = {
    "sensor_x": 0.25,
    "sensor_y": 0.06,
    "sensor_z": 0.30,
    "sensor_roll": float(np.radians(-120.0)),
    "sensor_pitch": float(np.radians(3.0)),
    "sensor_yaw": float(np.radians(-90.0)),
}
#: How the camera simulator's base drives unless told: slower, with fewer stops, than a log's.
CAMERA_DRIVE = DriveShape(max_speed=0.5, stop_fraction=0.1)
#: Time step of the fine grid the base is integrated on (s).
FINE_STEP_S = 1e-3
#: Times closer than this are one instant of the fine grid.
SAME_INSTANT_S = 1e-9
#: Both clocks start here (s, a Unix time), as a recording's stamps do.
EPOCH_S = 1_700_000_000.0

LIMITS: Mapping[str, Range] = {
    "duration_s": Range(1.0, 36_000.0),
    "seed": Range(0, 2**32 - 1, integer=True),
    "image_rate_hz": Range(1.0, 1000.0),
    "joint_rate_hz": Range(1.0, 1000.0),
    "stamp_offset_s": Range(-1.0, 1.0),
    "scale": Range(0.0, 1e6, lo_open=True),
}
NOISE_LIMITS: Mapping[str, Range] = {
    "position": Range(0.0, 1.0),
    "rotation": Range(0.0, 1.0),
    "floor_tilt": Range(0.0, 0.3),
}


def _check(options: object, limits: Mapping[str, Range], prefix: str = "") -> None:
    for name, limit in limits.items():
        reason = limit.problem(getattr(options, name))
        if reason is not None:
            raise OptionsError(f"{prefix}{name} {reason}")


@dataclass(frozen=True)
class CameraNoise:
    """1σ white noise of each pose (``position`` in m, ``rotation`` in rad, on the right) and the
    uneven floor's largest tilt of the base (rad)."""

    position: float = 0.0
    rotation: float = 0.0
    floor_tilt: float = 0.0

    def __post_init__(self) -> None:
        _check(self, NOISE_LIMITS, "noise.")


@dataclass(frozen=True)
class CameraSimulationOptions:
    """What to simulate (angles in rad, lengths in m, times in s). ``truth`` maps the model's
    kinematic parameters (joint units) and the mount ``sensor_x … sensor_yaw``; missing entries
    take the model's joint-map defaults and :data:`DEFAULT_MOUNT`."""

    model: str = next(iter(JOINT_MAPS))
    duration_s: float = 60.0
    seed: int = 0
    truth: Mapping[str, float] = field(default_factory=dict)
    image_rate_hz: float = 50.0
    joint_rate_hz: float = 100.0
    stamp_offset_s: float = 0.0
    scale: float = 1.0
    noise: CameraNoise = CameraNoise()
    drive: DriveShape = field(default_factory=lambda: CAMERA_DRIVE)

    def __post_init__(self) -> None:
        _check(self, LIMITS)
        object.__setattr__(self, "truth", full_truth(self.model, self.truth, DEFAULT_MOUNT))


def full_truth(model: str, truth: Mapping[str, float], mount: Mapping[str, float]) -> dict[str, float]:
    """A simulation's truth: ``truth`` over the defaults of ``model``'s joint map and ``mount``;
    a model or a parameter that is not known refused."""
    if model not in MODELS:
        raise OptionsError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    defaults = {**joint_map(model).default_truth, **mount}
    unknown = sorted(set(truth) - set(defaults))
    if unknown:
        raise OptionsError(f"unknown parameter(s) {unknown}; known: {', '.join(defaults)}")
    return {**defaults, **truth}


@dataclass(frozen=True)
class DriveSettings:
    """What a model's drive reads of the simulation options."""

    truth: Mapping[str, float]
    guess: Mapping[str, float] = field(default_factory=dict)
    encoder_ranges: Mapping[str, int] = field(default_factory=dict)
    wrap_after_ticks: int = 0


@dataclass(frozen=True)
class CameraSimulation:
    """Image stamps and camera poses ``(n, 7)`` (as written), joint times and angles, the true
    base poses ``(n, 3)`` at the images, and the truth (every parameter, the scale and the lag)."""

    image_time_s: np.ndarray
    camera_poses: np.ndarray
    joint_time_s: np.ndarray
    joint_names: tuple[str, ...]
    joint_positions: np.ndarray
    T_world_base_true: np.ndarray
    options: CameraSimulationOptions
    #: The fine grid (s from the start) and the base's planar poses on it (a gyro's rates beside).
    fine_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    base_poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def truth(self) -> dict[str, float]:
        """The model's parameters and the mount, plus the scale."""
        return {**self.options.truth, SCALE_PARAM: self.options.scale}

    def truth_dict(self) -> dict[str, Any]:
        return {
            "params": self.truth,
            "lag_s": self.options.stamp_offset_s,
            "options": asdict(self.options),
            "images": int(self.image_time_s.size),
            "joint_samples": int(self.joint_time_s.size),
        }


def _tilt(rng: np.random.Generator, t: np.ndarray, amplitude: float) -> np.ndarray:
    """Smooth roll and pitch ``(n, 2)`` of the base on an uneven floor, at most ``amplitude``."""
    out = np.zeros((t.size, 2))
    if amplitude == 0.0:
        return out
    for j in range(2):
        freq, phase = rng.uniform(0.1, 0.8, 3), rng.uniform(0, 2 * np.pi, 3)
        out[:, j] = np.sin(2 * np.pi * freq[:, None] * t[None, :] + phase[:, None]).sum(axis=0) / 3.0
    return amplitude * out


def fine_grid(images: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """A grid of :data:`FINE_STEP_S` over the samples' span (a second more each side), holding every
    sample's instant: of times within :data:`SAME_INSTANT_S` of each other (one instant computed
    two ways, ``0.3`` and ``0.1 · 3``) only the last, which ``np.searchsorted`` finds for each. A
    step of 1e-17 s between them turns rounding into a rate: the simulated gyro's, whose rates
    differentiate this grid, had put its clock offset 0.15 ms early on a 60 s bag (1σ)."""
    start = min(images[0], joints[0]) - 1.0
    stop = max(images[-1], joints[-1]) + 1.0
    regular = np.arange(start, stop + FINE_STEP_S, FINE_STEP_S)
    grid = np.unique(np.concatenate([regular, images, joints]))
    return grid[np.append(np.diff(grid) > SAME_INSTANT_S, True)]


def base_motion(
    model: str, truth: Mapping[str, float], shape: DriveShape, rng: np.random.Generator, t_fine: np.ndarray
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Planar base poses ``(n, 3)`` of ``model``'s drive (``truth``, driven as ``shape`` says) on the
    fine grid, and the drive's channels there."""
    knots = drive_profiles(shape, rng, float(t_fine[-1] - t_fine[0]) + 1.0)
    speed, turn, turn_end = profiles_on(knots, t_fine, float(t_fine[0]))
    drive = MODELS[model].drive
    turn_start = float(knots[2][0])
    ds, w, channels = drive.steps(DriveSettings(truth), speed, turn, turn_end, np.diff(t_fine), turn_start)
    return integrate_base(ds, w), channels


def simulate_camera(opts: CameraSimulationOptions, also_s: np.ndarray | None = None) -> CameraSimulation:
    """Simulate a drive, the camera's trajectory and the joint log; ``also_s``: further times (s
    from the start) the fine grid holds (a gyro's samples)."""
    rng = np.random.default_rng(opts.seed)
    t_images = np.arange(0.0, opts.duration_s, 1.0 / opts.image_rate_hz)
    t_joints = np.arange(-0.5, opts.duration_s + 0.5, 1.0 / opts.joint_rate_hz)
    more = np.zeros(0) if also_s is None else np.asarray(also_s, dtype=float)
    t_fine = fine_grid(np.sort(np.concatenate([t_images, more])), t_joints)
    planar, channels = base_motion(opts.model, opts.truth, opts.drive, rng, t_fine)
    at_images = np.searchsorted(t_fine, t_images)
    at_joints = np.searchsorted(t_fine, t_joints)
    base = poses3d.from_planar(planar[at_images])
    tilt = _tilt(rng, t_images, opts.noise.floor_tilt)
    rpy = np.column_stack([tilt, planar[at_images, 2]])
    base[:, 3:] = poses3d.matrix_to_quat(poses3d.rpy_to_matrix(rpy))
    mount = poses3d.mount_pose(np.array([opts.truth[n] for n in MOUNT_PARAMS]))
    world_camera = poses3d.compose(base, np.broadcast_to(mount, base.shape))
    camera = poses3d.between(np.broadcast_to(world_camera[0], base.shape), world_camera)
    camera = _noisy(rng, camera, opts)
    camera[:, :3] /= opts.scale
    angles = joint_map(opts.model).angles(opts.truth, {k: v[at_joints] for k, v in channels.items()})
    return CameraSimulation(
        image_time_s=EPOCH_S + t_images + opts.stamp_offset_s,
        camera_poses=camera,
        joint_time_s=EPOCH_S + t_joints,
        joint_names=tuple(angles),
        joint_positions=np.column_stack(list(angles.values())),
        T_world_base_true=planar[at_images],
        options=opts,
        fine_time_s=t_fine,
        base_poses=planar,
    )


def _noisy(rng: np.random.Generator, poses: np.ndarray, opts: CameraSimulationOptions) -> np.ndarray:
    """Poses with white noise: position in the world frame, rotation on the right."""
    out = poses.copy()
    n = poses.shape[0]
    out[:, :3] += rng.normal(0.0, opts.noise.position, (n, 3))
    turn = poses3d.rotvec_to_quat(rng.normal(0.0, opts.noise.rotation, (n, 3)))
    out[:, 3:] = poses3d.quat_multiply(out[:, 3:], turn)
    return out


def camera_paths(tum_path: str | Path) -> tuple[Path, Path, Path]:
    """Where a simulation's files go: the TUM file, ``<name>.joints.csv`` and ``<name>.truth.json``."""
    p = Path(tum_path)
    return p, p.with_suffix(".joints.csv"), p.with_suffix(".truth.json")


def _ns(time_s: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(time_s) * 1e9).astype(np.int64)


def write_camera_simulation(sim: CameraSimulation, tum_path: str | Path) -> tuple[Path, Path, Path]:
    """Write the TUM trajectory, the joint CSV and the truth JSON (atomically); returns the paths."""
    tum, joints, truth = camera_paths(tum_path)
    atomic_write_text(tum, format_tum(_ns(sim.image_time_s), sim.camera_poses))
    atomic_write_text(joints, format_joint_csv(_ns(sim.joint_time_s), sim.joint_names, sim.joint_positions))
    atomic_write_text(truth, json.dumps(sim.truth_dict(), indent=2) + "\n")
    return tum, joints, truth
