"""``nlp-calib simulate``: a synthetic drive log (or a camera's trajectory and joints, a lidar's or a
gyro's bag, a vendor's odometry) with its truth."""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from nlp_calib.core import interrupts
from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import check_output_dir
from nlp_calib.models.car_like import HIGHWAY_SCENARIO
from nlp_calib.models.skid_steer import SPIN_SCENARIO
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.pipeline.simconfig import (
    camera_options,
    imu_options,
    lidar_options,
    simulation_options,
    vehicle_options,
    vendor_options,
)
from nlp_calib.simulation import simulate_to_file, truth_path
from nlp_calib.simulation.beside import (
    camera_beside_paths,
    simulate_beside,
    simulate_camera_beside,
    write_beside_simulation,
    write_camera_beside_simulation,
)
from nlp_calib.simulation.camera import camera_paths, simulate_camera, write_camera_simulation
from nlp_calib.simulation.imu import imu_paths, simulate_imu, write_imu_simulation
from nlp_calib.simulation.lidar import lidar_paths, simulate_lidar, write_lidar_simulation
from nlp_calib.simulation.vehicles import simulate_highway, simulate_skid_spins, vehicle_paths
from nlp_calib.simulation.vendor import write_vendor_simulation


def cmd_simulate(args: argparse.Namespace) -> int:
    overrides = {
        k: getattr(args, k)
        for k in (
            "records",
            "seed",
            "model",
            "trajectory",
            "tracker_noise_xy",
            "tracker_noise_theta",
            "outlier_fraction",
            "latency_s",
            "duration_s",
        )
        if getattr(args, k) is not None
    }
    out: Path = args.out
    if out.is_dir() or out.name in ("", ".", ".."):
        raise UsageError(f"--out {out} is a folder; give the path of the log file to write")
    imu, tracker = getattr(args, "imu", False), getattr(args, "tracker", False)
    if getattr(args, "vehicle", None) is not None:
        if imu or tracker:
            raise UsageError("--vehicle goes alone: its drive has its own reference (no --imu, no --tracker)")
        return _simulate_vehicle(args, overrides)
    if tracker and (not imu or getattr(args, "lidar", False)):
        raise UsageError("--tracker goes with --imu alone (a tracker's poses beside the gyro, in one bag)")
    if getattr(args, "lidar", False) or tracker:
        return _simulate_beside(args, overrides, tracker) if imu else _simulate_lidar(args, overrides)
    if imu and getattr(args, "vendor", False):
        raise UsageError(
            "--imu goes alone, beside --lidar or --tracker (one bag) or beside a camera (--out X.tum)"
        )
    if imu and out.suffix.lower() == ".tum":
        return _simulate_camera_beside(args, overrides)
    if getattr(args, "vendor", False):
        return _simulate_vendor(args, overrides)
    if imu:
        return _simulate_imu(args, overrides)
    if out.suffix.lower() == ".tum":
        return _simulate_camera(args, overrides)
    opts = simulation_options(args.config, overrides)
    log_path, truth = _staged(args, [out, truth_path(out)], lambda path: simulate_to_file(opts, path))
    print(f"wrote {log_path} ({opts.records} records) and {truth}")
    return 0


def _staged(
    args: argparse.Namespace, paths: Sequence[Path], write: Callable[[Path], Sequence[Path]]
) -> list[Path]:
    """The files ``write`` writes for ``--out`` (``paths``: their names, none of them a user's
    own file unless ``--force``), written in a staging folder and moved beside ``--out`` whole."""
    out: Path = args.out
    folder = check_output_dir(out.parent)
    refuse_collisions(folder, [p.name for p in paths], tracked=False, force=args.force)
    with StagedOutput(folder, None, force=args.force) as stage:
        written = write(stage.path / out.name)
        interrupts.hold()
        stage.commit()
    return [stage.final(p) for p in written]


def _simulate_camera(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A tilted camera's TUM trajectory, its joint CSV and the truth, beside each other."""
    opts = camera_options(args.config, overrides)
    write = functools.partial(write_camera_simulation, simulate_camera(opts))
    tum, joints, truth = _staged(args, camera_paths(args.out), write)
    print(f"wrote {tum} ({opts.duration_s:g} s at {opts.image_rate_hz:g} Hz), {joints} and {truth}")
    return 0


def _simulate_camera_beside(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A camera's TUM trajectory and joint CSV, a gyro's CSV of the same drive and the truth (the
    options and --config: the camera's; the gyro takes its defaults, its seed and its driver's late
    stamps the camera's)."""
    camera = camera_options(args.config, overrides)
    gyro = imu_options(None, {"seed": camera.seed, "latency_s": camera.stamp_offset_s})
    write = functools.partial(write_camera_beside_simulation, simulate_camera_beside(camera, gyro))
    tum, joints, rates, truth = _staged(args, camera_beside_paths(args.out), write)
    print(
        f"wrote {tum} ({camera.duration_s:g} s at {camera.image_rate_hz:g} Hz), {joints}, {rates} (the gyro "
        f"at {gyro.imu_rate_hz:g} Hz; both stamped {1000 * camera.stamp_offset_s:g} ms late) and {truth}"
    )
    print(
        f"a scenario reads it as: dataset: {{poses: {tum}, joints: {joints}, gyro: {rates}, encoders: …}}, "
        "with sensor: {mount: 3d, beside: gyro} (docs/imu.md)"
    )
    return 0


def _simulate_lidar(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A lidar's bag and the truth beside it."""
    opts = lidar_options(args.config, overrides)
    bag, truth = _staged(
        args, lidar_paths(args.out), functools.partial(write_lidar_simulation, simulate_lidar(opts))
    )
    print(
        f"wrote {bag} ({opts.duration_s:g} s, scans at {opts.scan_rate_hz:g} Hz, "
        f"{100 * opts.degraded_fraction:g} % degraded) and {truth}"
    )
    print(
        f"a scenario reads it as: dataset: {{bag: {bag}, joint_states: /joint_states, joints: "
        "[left_wheel_joint, right_wheel_joint], scan: /scan}"
    )
    return 0


def _simulate_imu(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A gyro's bag and the truth beside it."""
    opts = imu_options(args.config, overrides)
    sim = simulate_imu(opts)
    bag, truth = _staged(args, imu_paths(args.out), functools.partial(write_imu_simulation, sim))
    print(
        f"wrote {bag} ({opts.duration_s:g} s, the gyro at {opts.imu_rate_hz:g} Hz stamped "
        f"{1000 * opts.stamp_offset_s:g} ms late) and {truth}"
    )
    joints = ", ".join(sim.joint_names)
    print(
        f"a scenario reads it as: dataset: {{bag: {bag}, joint_states: /joint_states, joints: "
        f"[{joints}], imu: /imu}}, with model: {opts.model} and sensor: gyro (docs/imu.md; nlp-calib init "
        f"{bag} drafts it)"
    )
    return 0


def _simulate_beside(args: argparse.Namespace, overrides: dict[str, Any], tracker: bool) -> int:
    """A lidar's (or with ``tracker`` a tracker's) and a gyro's bag of one drive, and the truth beside
    it (the options and --config: the lidar's; the gyro takes its defaults, its seed and its driver's
    late stamps the lidar's)."""
    lidar = lidar_options(args.config, overrides)
    sim = simulate_beside(lidar, imu_options(None, {"seed": lidar.seed, "latency_s": lidar.stamp_offset_s}))
    write = functools.partial(write_beside_simulation, sim, tracker=tracker)
    bag, truth = _staged(args, lidar_paths(args.out), write)
    what = (
        f"a tracker's poses at {lidar.scan_rate_hz:g} Hz"
        if tracker
        else f"scans at {lidar.scan_rate_hz:g} Hz"
    )
    print(
        f"wrote {bag} ({lidar.duration_s:g} s, {what}, the gyro at "
        f"{sim.imu.options.imu_rate_hz:g} Hz, both stamped {1000 * lidar.stamp_offset_s:g} ms late) "
        f"and {truth}"
    )
    print(
        f"a scenario reads it as: dataset: {{bag: {bag}, joint_states: /joint_states, joints: "
        f"[{', '.join(sim.lidar.joint_names)}], {'tracker: /tracker' if tracker else 'scan: /scan'}, "
        "imu: /imu}, with sensor: {mount: planar, beside: gyro} (docs/imu.md)"
    )
    return 0


def _simulate_vendor(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A vendor's odometry, the tracker's TUM file and the truth, beside each other."""
    opts = vendor_options(args.config, overrides)
    out: Path = args.out
    paths = [out, out.with_suffix(".tum"), out.with_suffix(".truth.json")]
    odometry, tum, truth = _staged(args, paths, functools.partial(write_vendor_simulation, opts))
    print(
        f"wrote {odometry} (the robot's own odometry, integrated with the model "
        f"{', '.join(f'{n} {v:g}' for n, v in opts.vendor_in_radians().items())}), {tum} and {truth}"
    )
    return 0


#: How a scenario reads each vehicle's files (after its ``joints``/reference paths), and its model.
VEHICLE_SCENARIOS = {"highway_car": ("poses", HIGHWAY_SCENARIO), "skid_spins": ("motions", SPIN_SCENARIO)}


def _simulate_vehicle(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A real vehicle's drive (``--vehicle``): its joints, its reference and the truth, beside each other."""
    vehicle: str = args.vehicle
    opts = vehicle_options(vehicle, args.config, overrides)
    sim = simulate_highway(opts) if vehicle == "highway_car" else simulate_skid_spins(opts)
    joints, reference, truth = _staged(args, vehicle_paths(args.out, vehicle), sim.write)
    print(f"wrote {joints} ({opts.duration_s:g} s of {vehicle}, seed {opts.seed}), {reference} and {truth}")
    key, rest = VEHICLE_SCENARIOS[vehicle]
    print(f"a scenario reads it as: dataset: {{joints: {joints}, {key}: {reference}, {rest}")
    return 0
