"""Simulation options from a YAML file and command-line overrides."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nlp_calib.core.config import coerce, fail, from_mapping, key_name, read_yaml
from nlp_calib.core.errors import FieldError, NlpCalibError
from nlp_calib.core.ranges import Range
from nlp_calib.simulation import LIMITS, SimulationOptions
from nlp_calib.simulation.camera import LIMITS as CAMERA_LIMITS
from nlp_calib.simulation.camera import CameraSimulationOptions
from nlp_calib.simulation.imu import ImuSimulationOptions
from nlp_calib.simulation.lidar import LidarSimulationOptions
from nlp_calib.simulation.options import flat_hints
from nlp_calib.simulation.vehicles import HighwayOptions, SkidSpinOptions
from nlp_calib.simulation.vendor import VendorSimulationOptions

#: What a user may ask of ``nlp-calib simulate``: the simulator's own limits (it writes a log block
#: by block, so its memory does not grow with the log's length).
CLI_LIMITS: Mapping[str, Range] = {**LIMITS, "duration_s": CAMERA_LIMITS["duration_s"]}


#: The command-line options a camera simulation reads: each one's place among its options.
CAMERA_OVERRIDES: Mapping[str, tuple[str, ...]] = {
    "seed": ("seed",),
    "model": ("model",),
    "trajectory": ("drive", "trajectory"),
    "duration_s": ("duration_s",),
    "latency_s": ("stamp_offset_s",),
    "tracker_noise_xy": ("noise", "position"),
    "tracker_noise_theta": ("noise", "rotation"),
}


#: The command-line options a lidar's and a vendor odometry's simulation read, by their names there.
LIDAR_OVERRIDES: Mapping[str, tuple[str, ...]] = {
    "seed": ("seed",),
    "model": ("model",),
    "trajectory": ("drive", "trajectory"),
    "duration_s": ("duration_s",),
    "outlier_fraction": ("degraded_fraction",),
    "latency_s": ("stamp_offset_s",),
}
#: The command-line options a gyro's simulation reads (its driver's late stamps: --latency).
IMU_OVERRIDES: Mapping[str, tuple[str, ...]] = {
    "seed": ("seed",),
    "model": ("model",),
    "trajectory": ("drive", "trajectory"),
    "duration_s": ("duration_s",),
    "latency_s": ("stamp_offset_s",),
}
VENDOR_OVERRIDES: Mapping[str, tuple[str, ...]] = {
    "seed": ("seed",),
    "trajectory": ("drive", "trajectory"),
    "duration_s": ("duration_s",),
    "tracker_noise_xy": ("tracker_noise_xy",),
    "tracker_noise_theta": ("tracker_noise_theta",),
}


#: The command-line options each vehicle's simulation reads (``--vehicle``), by their names there
#: (the highway car's device noise, a pair, is its config's ``pose_noise``).
VEHICLE_OVERRIDES: Mapping[str, Mapping[str, tuple[str, ...]]] = {
    "highway_car": {"seed": ("seed",), "duration_s": ("duration_s",)},
    "skid_spins": {
        "seed": ("seed",),
        "duration_s": ("duration_s",),
        "tracker_noise_xy": ("motion_noise_xy",),
        "tracker_noise_theta": ("motion_noise_theta",),
    },
}
VEHICLE_OPTIONS: Mapping[str, type] = {"highway_car": HighwayOptions, "skid_spins": SkidSpinOptions}


def _overridden(
    raw: dict[str, Any], overrides: Mapping[str, Any], places: Mapping[str, tuple[str, ...]], what: str
) -> None:
    """``raw`` with the command line's ``overrides`` put at their ``places``."""
    for key, value in overrides.items():
        if key not in places:
            fail(f"simulate: {key}", f"does not apply to {what}")
        *group, name = places[key]
        if group:
            inner = raw.get(group[0]) or {}
            raw[group[0]] = {**inner, name: value} if isinstance(inner, Mapping) else inner
        else:
            raw[name] = value


def lidar_options(config: Path | None, overrides: Mapping[str, Any]) -> LidarSimulationOptions:
    """A lidar simulation's options from ``config`` (a YAML mapping of
    :class:`~nlp_calib.simulation.lidar.LidarSimulationOptions`' fields), then ``overrides``."""
    raw, source = _config(config)
    _overridden(raw, overrides, LIDAR_OVERRIDES, "a lidar simulation (--lidar)")
    options: LidarSimulationOptions = from_mapping(LidarSimulationOptions, raw, source)
    return options


def imu_options(config: Path | None, overrides: Mapping[str, Any]) -> ImuSimulationOptions:
    """A gyro simulation's options from ``config`` (a YAML mapping of
    :class:`~nlp_calib.simulation.imu.ImuSimulationOptions`' fields), then ``overrides``."""
    raw, source = _config(config)
    _overridden(raw, overrides, IMU_OVERRIDES, "a gyro simulation (--imu)")
    options: ImuSimulationOptions = from_mapping(ImuSimulationOptions, raw, source)
    return options


def vendor_options(config: Path | None, overrides: Mapping[str, Any]) -> VendorSimulationOptions:
    """A vendor odometry simulation's options from ``config``, then ``overrides``."""
    raw, source = _config(config)
    _overridden(raw, overrides, VENDOR_OVERRIDES, "a vendor odometry simulation (--vendor)")
    options: VendorSimulationOptions = from_mapping(VendorSimulationOptions, raw, source)
    return options


def vehicle_options(vehicle: str, config: Path | None, overrides: Mapping[str, Any]) -> Any:
    """A ``vehicle``'s simulation options from ``config`` (a YAML mapping of
    :class:`~nlp_calib.simulation.vehicles.HighwayOptions`' or ``SkidSpinOptions``' fields), then
    ``overrides``."""
    raw, source = _config(config)
    _overridden(raw, overrides, VEHICLE_OVERRIDES[vehicle], f"a {vehicle} simulation (--vehicle)")
    return from_mapping(VEHICLE_OPTIONS[vehicle], raw, source)


def _config(config: Path | None) -> tuple[dict[str, Any], str]:
    """The mapping in ``config`` (empty without one) and the name messages give its source."""
    if config is None:
        return {}, "simulate"
    loaded = read_yaml(config, "simulation config")
    if loaded is not None and not isinstance(loaded, Mapping):
        fail(str(config), "expected a mapping of simulation options")
    return dict(loaded or {}), str(config)


def camera_options(config: Path | None, overrides: Mapping[str, Any]) -> CameraSimulationOptions:
    """A camera simulation's options from ``config`` (a YAML mapping of
    :class:`~nlp_calib.simulation.camera.CameraSimulationOptions`' fields, ``noise`` and ``drive``
    nested), then the command line's ``overrides`` (by their flat names)."""
    raw, source = _config(config)
    _overridden(raw, overrides, CAMERA_OVERRIDES, "a camera simulation (--out ending in .tum)")
    options: CameraSimulationOptions = from_mapping(CameraSimulationOptions, raw, source)
    return options


def simulation_options(config: Path | None, overrides: Mapping[str, Any]) -> SimulationOptions:
    """Options from ``config`` (a YAML mapping of options by their flat names), then overrides."""
    raw, source = _config(config)
    if "duration_s" in overrides:
        fail(
            "simulate: duration",
            "applies to a camera simulation (--out ending in .tum); a log takes --records",
        )
    raw.update(overrides)
    hints = flat_hints()
    for key in raw:
        if key not in hints:
            fail(f"{source}.{key_name(key)}", f"unknown key; valid keys are {', '.join(hints)}")
    typed = {k: coerce(v, hints[k], f"{source}.{k}") for k, v in raw.items()}
    try:
        return SimulationOptions.of(**typed)
    except FieldError as exc:
        fail(f"{source}.{exc.field}", exc.reason)
    except (ValueError, TypeError, NlpCalibError) as exc:
        fail(source, str(exc))
