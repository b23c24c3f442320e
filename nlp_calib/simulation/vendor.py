"""A differential drive that publishes only its own odometry, integrated with a wrong model, and a
tracker on it: the vendor's odometry, the tracker's TUM trajectory and the truth.

The base drives as the camera simulator's does (:mod:`nlp_calib.simulation.camera`). Its
controller integrates the wheels' angles (read at ``odometry_rate_hz``) with its own model, the
wheel radius ``vendor_radius`` for both wheels and the separation ``vendor_separation``, exact
arcs: the odometry is written as ``t x y θ``. A tracker sees a sensor mounted at ``(sensor_x,
sensor_y, sensor_theta)`` at ``tracker_rate_hz`` with white noise. The truth holds the wheels'
true radii and separation, the mount, and the corrections the vendor's controller needs: each true
radius over ``vendor_radius`` and the true separation over ``vendor_separation``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core import poses, poses3d
from nlp_calib.core.errors import OptionsError
from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.ranges import Range
from nlp_calib.logs import format_tum
from nlp_calib.logs.vendor import format_odometry
from nlp_calib.models.joints import joint_map
from nlp_calib.simulation.camera import EPOCH_S, base_motion, fine_grid
from nlp_calib.simulation.options import DriveShape

#: The true robot: its wheels' radii (m per rad) and separation, and the tracked sensor's mount.
DEFAULT_TRUTH: Mapping[str, float] = {
    "k_left": 0.1012,
    "k_right": 0.0994,
    "baseline": 0.462,
    "sensor_x": 0.12,
    "sensor_y": 0.03,
    "sensor_theta": 0.04,
}
LIMITS: Mapping[str, Range] = {
    "duration_s": Range(1.0, 36_000.0),
    "seed": Range(0, 2**32 - 1, integer=True),
    "odometry_rate_hz": Range(1.0, 1000.0),
    "tracker_rate_hz": Range(1.0, 1000.0),
    "vendor_radius": Range(1e-3, 10.0),
    "vendor_separation": Range(1e-2, 10.0),
    "tracker_noise_xy": Range(0.0, 1.0),
    "tracker_noise_theta": Range(0.0, 1.0),
}


@dataclass(frozen=True)
class VendorSimulationOptions:
    """What to simulate (lengths in m, angles in rad, times in s); ``truth`` maps ``k_left``,
    ``k_right`` (the wheels' radii), ``baseline`` and the mount (:data:`DEFAULT_TRUTH` otherwise)."""

    duration_s: float = 120.0
    seed: int = 0
    truth: Mapping[str, float] = field(default_factory=dict)
    odometry_rate_hz: float = 50.0
    tracker_rate_hz: float = 100.0
    vendor_radius: float = 0.1
    vendor_separation: float = 0.45
    tracker_noise_xy: float = 0.001
    tracker_noise_theta: float = 0.002
    drive: DriveShape = field(default_factory=lambda: DriveShape(max_speed=0.5, stop_fraction=0.1))

    def __post_init__(self) -> None:
        for name, limit in LIMITS.items():
            if (reason := limit.problem(getattr(self, name))) is not None:
                raise OptionsError(f"{name} {reason}")
        unknown = sorted(set(self.truth) - set(DEFAULT_TRUTH))
        if unknown:
            raise OptionsError(f"unknown parameter(s) {unknown}; known: {', '.join(DEFAULT_TRUTH)}")
        object.__setattr__(self, "truth", {**DEFAULT_TRUTH, **self.truth})

    def corrections(self) -> dict[str, float]:
        """What the vendor's controller needs: each true radius and the separation over its own."""
        t = self.truth
        return {
            "left_wheel_radius_multiplier": t["k_left"] / self.vendor_radius,
            "right_wheel_radius_multiplier": t["k_right"] / self.vendor_radius,
            "wheel_separation_multiplier": t["baseline"] / self.vendor_separation,
        }


def vendor_odometry(angles: np.ndarray, radius: float, separation: float) -> np.ndarray:
    """The base poses ``(n, 3)`` a controller integrates (exact arcs) from the wheels' angles
    ``(n, 2)`` with its own radius and separation."""
    d = np.diff(angles, axis=0) * radius
    travel, turn = 0.5 * (d[:, 0] + d[:, 1]), (d[:, 1] - d[:, 0]) / separation
    half = 0.5 * turn
    with np.errstate(divide="ignore", invalid="ignore"):
        sinc = np.where(np.abs(half) > 1e-9, np.sin(half) / half, 1.0)
    steps = np.column_stack([travel * sinc * np.cos(half), travel * sinc * np.sin(half), turn])
    return poses.accumulate(np.zeros(3), steps)


def write_vendor_simulation(
    opts: VendorSimulationOptions, odometry_path: str | Path
) -> tuple[Path, Path, Path]:
    """Simulate and write ``<name>`` (the vendor's odometry, ``t x y θ``), ``<name>.tum`` (the
    tracker) and ``<name>.truth.json`` beside it; returns the three paths."""
    rng = np.random.default_rng(opts.seed)
    t_odo = np.arange(0.0, opts.duration_s, 1.0 / opts.odometry_rate_hz)
    t_trk = np.arange(0.25, opts.duration_s - 0.25, 1.0 / opts.tracker_rate_hz) + 0.0013
    t_fine = fine_grid(t_trk, t_odo)
    planar, channels = base_motion("diff_drive", opts.truth, opts.drive, rng, t_fine)
    at_odo = np.searchsorted(t_fine, t_odo)
    wheels = joint_map("diff_drive").angles(opts.truth, {k: v[at_odo] for k, v in channels.items()})
    base = vendor_odometry(np.column_stack(list(wheels.values())), opts.vendor_radius, opts.vendor_separation)
    mount = np.array([opts.truth[n] for n in ("sensor_x", "sensor_y", "sensor_theta")])
    sensor = poses.compose(planar[np.searchsorted(t_fine, t_trk)], mount)
    sensor[:, :2] += rng.normal(0.0, opts.tracker_noise_xy, (sensor.shape[0], 2))
    sensor[:, 2] += rng.normal(0.0, opts.tracker_noise_theta, sensor.shape[0])
    p = Path(odometry_path)
    tum, truth = p.with_suffix(".tum"), p.with_suffix(".truth.json")
    ns = lambda t: np.round((EPOCH_S + t) * 1e9).astype(np.int64)  # noqa: E731
    atomic_write_text(p, format_odometry(ns(t_odo), base))
    atomic_write_text(tum, format_tum(ns(t_trk), poses3d.from_planar(sensor)))
    doc: dict[str, Any] = {
        "params": dict(opts.truth),
        "corrections": opts.corrections(),
        "options": asdict(opts),
    }
    atomic_write_text(truth, json.dumps(doc, indent=2) + "\n")
    return p, tum, truth
