"""A 2-D lidar on a planar robot in a room of walls, with known truth: a ROS 2 bag of its scans and
the wheels' joints.

The base drives as the camera simulator's does (:mod:`nlp_calib.simulation.camera`: the model's
own drive on a fine time grid; joints in radians at ``joint_rate_hz``). A room is built around
the drive: walls a margin beyond the ground it covers and boxes standing clear of its path, so
that every scan sees corners. A lidar mounted at ``(sensor_x, sensor_y, sensor_theta)`` on the
base sweeps ``beams`` beams over a full turn at ``scan_rate_hz`` (each scan seen at its stamp),
every range with white noise ``range_noise`` (m); a share ``degraded_fraction`` of the scans is
degraded, half of them by a crowd around the lidar (most beams return clutter close by, the rest
nothing: a match that its matcher finds poor) and half by a late sweep (the scan seen
:data:`LATE_S` after its stamp: a match that looks sound and is wrong while the robot moves). The
lidar's driver stamps every scan ``stamp_offset_s`` late (the ``tracker_lag`` a fit finds). The bag
holds ``/joint_states``, ``/scan`` and ``/tf_static`` (the lidar's nominal mount: its height,
and its x, y and yaw rounded as a drawing gives them); the truth file beside it the parameters,
the options and which scans were degraded. Deterministic for a given seed.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core import poses
from nlp_calib.core.errors import OptionsError
from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.ranges import Range
from nlp_calib.models.joints import JOINT_MAPS, joint_map
from nlp_calib.simulation.camera import EPOCH_S, base_motion, fine_grid, full_truth
from nlp_calib.simulation.options import DriveShape
from nlp_calib.simulation.rosbag import joint_state, laser_scan, tf_static, write_bag

#: A lidar ahead of the wheels' axle, a little to the right, turned slightly.
DEFAULT_MOUNT: Mapping[str, float] = {"sensor_x": 0.18, "sensor_y": -0.04, "sensor_theta": 0.05}
#: The lidar's height above the base (not calibrated: planar driving cannot see it).
LIDAR_Z = 0.25
LIDAR_DRIVE = DriveShape(max_speed=0.5, stop_fraction=0.1)
#: Walls stand this far (m) beyond the ground the lidar covers; boxes at least this far from its path.
MARGIN_M = 2.0
CLEARANCE_M = 0.8
BOXES = 10
#: How late (s) a late sweep is seen after its stamp.
LATE_S = 0.05

LIMITS: Mapping[str, Range] = {
    "duration_s": Range(1.0, 36_000.0),
    "seed": Range(0, 2**32 - 1, integer=True),
    "scan_rate_hz": Range(1.0, 100.0),
    "joint_rate_hz": Range(1.0, 1000.0),
    "beams": Range(16, 10_000, integer=True),
    "range_max": Range(1.0, 200.0),
    "range_noise": Range(0.0, 1.0),
    "degraded_fraction": Range(0.0, 0.5),
    "stamp_offset_s": Range(-1.0, 1.0),
}


@dataclass(frozen=True)
class LidarSimulationOptions:
    """What to simulate (angles in rad, lengths in m, times in s). ``truth`` maps the model's
    kinematic parameters (joint units) and the mount ``sensor_x, sensor_y, sensor_theta``; missing
    entries take the model's joint-map defaults and :data:`DEFAULT_MOUNT`."""

    model: str = next(iter(JOINT_MAPS))
    duration_s: float = 120.0
    seed: int = 0
    truth: Mapping[str, float] = field(default_factory=dict)
    scan_rate_hz: float = 10.0
    joint_rate_hz: float = 50.0
    beams: int = 720
    range_max: float = 15.0
    range_noise: float = 0.01
    degraded_fraction: float = 0.02
    stamp_offset_s: float = 0.0
    drive: DriveShape = field(default_factory=lambda: LIDAR_DRIVE)

    def __post_init__(self) -> None:
        for name, limit in LIMITS.items():
            if (reason := limit.problem(getattr(self, name))) is not None:
                raise OptionsError(f"{name} {reason}")
        object.__setattr__(self, "truth", full_truth(self.model, self.truth, DEFAULT_MOUNT))


@dataclass(frozen=True)
class LidarSimulation:
    """Scan stamps and ranges ``(n, beams)`` (inf: no return), the beams' angles, the joints'
    stamps, names and angles, the room's walls ``(m, 4)`` (segments x0 y0 x1 y1), the degraded
    scans and the options."""

    scan_time_s: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    joint_time_s: np.ndarray
    joint_names: tuple[str, ...]
    joint_positions: np.ndarray
    walls: np.ndarray
    degraded: np.ndarray
    options: LidarSimulationOptions
    #: The lidar's true pose ``(x, y, θ)`` at each scan's stamp (where a late sweep is not seen).
    lidar_poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    #: The base's drive on the fine grid: its times (s, from the start) and planar poses ``(n, 3)``.
    fine_time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    base_poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def true_motions(self) -> np.ndarray:
        """The lidar's true motion ``(n - 1, 3)`` between consecutive scans' stamps."""
        return poses.between(self.lidar_poses[:-1], self.lidar_poses[1:])

    def truth_dict(self) -> dict[str, Any]:
        return {
            "params": dict(self.options.truth),
            "lag_s": self.options.stamp_offset_s,
            "options": asdict(self.options),
            "scans": int(self.scan_time_s.size),
            "degraded_scans": self.degraded.tolist(),
        }


def _box(centre: np.ndarray, size: np.ndarray, turn: float) -> np.ndarray:
    """The four walls ``(4, 4)`` of a box of ``size`` at ``centre``, turned by ``turn``."""
    c, s = np.cos(turn), np.sin(turn)
    w, h = size
    corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2 @ np.array([[c, s], [-s, c]]) + centre
    return np.hstack([corners, np.roll(corners, -1, axis=0)])


def room(rng: np.random.Generator, path_xy: np.ndarray) -> np.ndarray:
    """Walls ``(m, 4)`` around the ground ``path_xy`` covers, and boxes clear of the path."""
    lo, hi = path_xy.min(axis=0) - MARGIN_M, path_xy.max(axis=0) + MARGIN_M
    walls = [_box(0.5 * (lo + hi), hi - lo, 0.0)]
    for _ in range(40 * BOXES):
        if len(walls) > BOXES:
            break
        centre, size = rng.uniform(lo + 0.5, hi - 0.5), rng.uniform(0.3, 1.2, 2)
        if np.min(np.linalg.norm(path_xy - centre, axis=1)) > CLEARANCE_M + 0.5 * np.hypot(*size):
            walls.append(_box(centre, size, float(rng.uniform(0, np.pi))))
    return np.vstack(walls)


def ray_cast(walls: np.ndarray, pose: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """The range (m) along each beam from ``pose`` ``(x, y, θ)`` to the nearest wall (inf: none)."""
    d = np.column_stack([np.cos(angles + pose[2]), np.sin(angles + pose[2])])
    p, e = walls[:, :2], walls[:, 2:] - walls[:, :2]
    den = d[:, 0, None] * e[None, :, 1] - d[:, 1, None] * e[None, :, 0]
    w = p[None, :, :] - pose[:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[None, :, 1] - w[..., 1] * e[None, :, 0]) / den
        s = (w[..., 0] * d[:, 1, None] - w[..., 1] * d[:, 0, None]) / den
    hit = (den != 0) & (t > 0) & (s >= 0) & (s <= 1)
    return np.where(hit, t, np.inf).min(axis=1)


def _crowd(rng: np.random.Generator, ranges: np.ndarray, range_max: float) -> np.ndarray:
    """A scan most of whose beams return clutter close by (a crowd around the lidar) or nothing."""
    out = ranges.copy()
    n = out.size
    clutter, lost = rng.random(n) < 0.8, rng.random(n) < 0.5
    out[clutter] = rng.uniform(0.3, min(4.0, range_max), int(clutter.sum()))
    out[lost & ~clutter] = np.inf
    return out


def simulate_lidar(opts: LidarSimulationOptions, also_s: np.ndarray | None = None) -> LidarSimulation:
    """Simulate a drive in a room, the lidar's scans and the joints; ``also_s``: further times (s)
    the drive's fine grid holds (another sensor's samples)."""
    rng = np.random.default_rng(opts.seed)
    t_scans = np.arange(0.0, opts.duration_s, 1.0 / opts.scan_rate_hz)
    t_joints = np.arange(-0.5, opts.duration_s + 0.5, 1.0 / opts.joint_rate_hz)
    more = np.zeros(0) if also_s is None else np.asarray(also_s, dtype=float)
    t_fine = fine_grid(np.concatenate([t_scans, t_scans + LATE_S, more]), t_joints)
    planar, channels = base_motion(opts.model, opts.truth, opts.drive, rng, t_fine)
    mount = np.array([opts.truth[n] for n in ("sensor_x", "sensor_y", "sensor_theta")])
    stamped = poses.compose(planar[np.searchsorted(t_fine, t_scans)], mount)
    walls = room(rng, stamped[:, :2])
    angles = -np.pi + 2.0 * np.pi * np.arange(opts.beams) / opts.beams
    n_bad = round(opts.degraded_fraction * t_scans.size)
    degraded = (
        np.sort(rng.choice(np.arange(1, t_scans.size - 1), size=n_bad, replace=False))
        if n_bad
        else np.zeros(0, int)
    )
    late = degraded[rng.random(degraded.size) < 0.5]
    seen = t_scans.copy()
    seen[late] += LATE_S
    lidar = poses.compose(planar[np.searchsorted(t_fine, seen)], mount)
    ranges = np.array([ray_cast(walls, p, angles) for p in lidar])
    ranges += rng.normal(0.0, opts.range_noise, ranges.shape)
    ranges[ranges > opts.range_max] = np.inf
    for k in np.setdiff1d(degraded, late):
        ranges[k] = _crowd(rng, ranges[k], opts.range_max)
    at_joints = np.searchsorted(t_fine, t_joints)
    angles_j = joint_map(opts.model).angles(opts.truth, {k: v[at_joints] for k, v in channels.items()})
    return LidarSimulation(
        scan_time_s=EPOCH_S + t_scans + opts.stamp_offset_s,
        ranges=ranges,
        angles=angles,
        joint_time_s=EPOCH_S + t_joints,
        joint_names=tuple(angles_j),
        joint_positions=np.column_stack(list(angles_j.values())),
        walls=walls,
        degraded=degraded.astype(np.int64),
        options=opts,
        lidar_poses=stamped,
        fine_time_s=t_fine,
        base_poses=planar,
    )


def lidar_paths(bag: str | Path) -> tuple[Path, Path]:
    """Where a simulation goes: the bag folder and ``<name>.truth.json`` beside it."""
    p = Path(bag)
    return p, p.with_name(p.name + ".truth.json") if p.suffix else p.with_suffix(".truth.json")


def write_lidar_simulation(sim: LidarSimulation, bag: str | Path) -> tuple[Path, Path]:
    """Write the bag (``/joint_states``, ``/scan``, ``/tf_static``) and the truth JSON."""
    path, truth = lidar_paths(bag)
    write_bag(path, lidar_messages(sim))
    atomic_write_text(truth, json.dumps(sim.truth_dict(), indent=2) + "\n")
    return path, truth


def lidar_messages(sim: LidarSimulation) -> list[Any]:
    """The bag's messages: ``/tf_static``, ``/joint_states`` and ``/scan``."""
    ns = lambda t: round(float(t) * 1e9)  # noqa: E731
    t = sim.options.truth
    nominal = (round(t["sensor_x"], 1), round(t["sensor_y"], 1), LIDAR_Z)
    period = 1.0 / sim.options.scan_rate_hz
    messages = [tf_static(ns(sim.joint_time_s[0]), "base_link", "laser", nominal, 0.0)]
    messages += [
        joint_state(ns(s), sim.joint_names, row) for s, row in zip(sim.joint_time_s, sim.joint_positions)
    ]
    messages += [
        laser_scan(ns(s), "laser", sim.angles, r, sim.options.range_max, period)
        for s, r in zip(sim.scan_time_s, sim.ranges)
    ]
    return messages
