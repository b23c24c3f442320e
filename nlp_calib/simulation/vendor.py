"""A robot that publishes only its own odometry, integrated with a wrong model, and a tracker on
it: the vendor's odometry, the tracker's TUM trajectory and the truth.

The base drives as the camera simulator's does (:mod:`nlp_calib.simulation.camera`). Its
controller integrates the joints' angles (read at ``odometry_rate_hz``) with its own model
(``vendor``; the model's drive says how, and its defaults: any model whose drive is a
:class:`~nlp_calib.models.drives.VendorController` and that turns its odometry back, see
:func:`vendor_models`): the odometry is written as ``t x y θ``.
A tracker sees a sensor mounted at ``(sensor_x, sensor_y, sensor_theta)`` at ``tracker_rate_hz``
with white noise. The truth holds the true parameters (joint units), the mount, the vendor's model
and the corrections its controller needs: each true parameter over the vendor's, by the names a
scenario gives them (joints in radians).
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
from nlp_calib.models import MODELS, OdometryInverse
from nlp_calib.models.base import reference
from nlp_calib.models.drives import VendorController
from nlp_calib.models.joints import JOINT_MAPS, joint_map
from nlp_calib.models.radians import in_units
from nlp_calib.simulation.camera import EPOCH_S, base_motion, fine_grid
from nlp_calib.simulation.options import DriveShape

#: The tracked sensor's mount.
DEFAULT_MOUNT: Mapping[str, float] = {"sensor_x": 0.12, "sensor_y": 0.03, "sensor_theta": 0.04}


def vendor_models() -> tuple[str, ...]:
    """The models whose simulated drive has a vendor's controller (its odometry and defaults) and
    a joint map, and that turn that odometry back into their joints (the joint maps' order)."""
    return tuple(
        name
        for name in JOINT_MAPS
        if isinstance(MODELS[name].drive, VendorController) and isinstance(MODELS[name], OdometryInverse)
    )


def correction(model: str, name: str, value: float, vendor: float) -> float:
    """What turns the vendor's value ``vendor`` of parameter ``name`` (the model ``model`` read from
    joints in radians) into ``value``: the ratio of a parameter known relative to its size (a gain,
    a length), the difference of one known absolutely (an offset)."""
    relative = reference(in_units(MODELS[model], "radians"), name)[0] == "relative"
    return value / vendor if relative else value - vendor


def _controller(model: str) -> VendorController:
    drive = MODELS[model].drive
    assert isinstance(drive, VendorController)  # vendor_models() holds only these
    return drive


LIMITS: Mapping[str, Range] = {
    "duration_s": Range(1.0, 36_000.0),
    "seed": Range(0, 2**32 - 1, integer=True),
    "odometry_rate_hz": Range(1.0, 1000.0),
    "tracker_rate_hz": Range(1.0, 1000.0),
    "tracker_noise_xy": Range(0.0, 1.0),
    "tracker_noise_theta": Range(0.0, 1.0),
}


@dataclass(frozen=True)
class VendorSimulationOptions:
    """What to simulate (lengths in m, angles in rad, times in s); ``truth`` maps the model's
    kinematic parameters (joint units) and the mount, ``vendor`` the controller's model (the
    drive's defaults and :data:`DEFAULT_MOUNT` otherwise)."""

    model: str = field(default_factory=lambda: vendor_models()[0])
    duration_s: float = 120.0
    seed: int = 0
    truth: Mapping[str, float] = field(default_factory=dict)
    vendor: Mapping[str, float] = field(default_factory=dict)
    odometry_rate_hz: float = 50.0
    tracker_rate_hz: float = 100.0
    tracker_noise_xy: float = 0.001
    tracker_noise_theta: float = 0.002
    drive: DriveShape = field(default_factory=lambda: DriveShape(max_speed=0.5, stop_fraction=0.1))

    def __post_init__(self) -> None:
        for name, limit in LIMITS.items():
            if (reason := limit.problem(getattr(self, name))) is not None:
                raise OptionsError(f"{name} {reason}")
        if self.model not in vendor_models():
            raise OptionsError(f"model must be one of {', '.join(vendor_models())}, got {self.model!r}")
        drive = _controller(self.model)
        for key, defaults in (
            ("truth", {**drive.vendor_truth, **DEFAULT_MOUNT}),
            ("vendor", drive.vendor_model),
        ):
            given = getattr(self, key)
            unknown = sorted(set(given) - set(defaults))
            if unknown:
                raise OptionsError(f"{key}: unknown parameter(s) {unknown}; known: {', '.join(defaults)}")
            object.__setattr__(self, key, {**defaults, **given})

    def corrections(self) -> dict[str, float]:
        """What the vendor's controller needs (:func:`correction`), by the names of the model read
        from joints in radians."""
        rename = getattr(in_units(MODELS[self.model], "radians"), "rename", lambda n: n)
        return {
            rename(n): correction(self.model, rename(n), self.truth[n], v) for n, v in self.vendor.items()
        }

    def vendor_in_radians(self) -> dict[str, float]:
        """The vendor's model by the names and units of the model read from joints in radians."""
        return dict(getattr(in_units(MODELS[self.model], "radians"), "from_counts", dict)(self.vendor))


def write_vendor_simulation(
    opts: VendorSimulationOptions, odometry_path: str | Path
) -> tuple[Path, Path, Path]:
    """Simulate and write ``<name>`` (the vendor's odometry, ``t x y θ``), ``<name>.tum`` (the
    tracker) and ``<name>.truth.json`` beside it; returns the three paths."""
    rng = np.random.default_rng(opts.seed)
    t_odo = np.arange(0.0, opts.duration_s, 1.0 / opts.odometry_rate_hz)
    t_trk = np.arange(0.25, opts.duration_s - 0.25, 1.0 / opts.tracker_rate_hz) + 0.0013
    t_fine = fine_grid(t_trk, t_odo)
    planar, channels = base_motion(opts.model, opts.truth, opts.drive, rng, t_fine)
    at_odo = np.searchsorted(t_fine, t_odo)
    joints = joint_map(opts.model).angles(opts.truth, {k: v[at_odo] for k, v in channels.items()})
    base = _controller(opts.model).odometry(joints, opts.vendor)
    mount = np.array([opts.truth[n] for n in DEFAULT_MOUNT])
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
        "vendor": opts.vendor_in_radians(),
        "corrections": opts.corrections(),
        "options": asdict(opts),
    }
    atomic_write_text(truth, json.dumps(doc, indent=2) + "\n")
    return p, tum, truth
