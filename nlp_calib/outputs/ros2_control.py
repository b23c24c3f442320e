"""``ros2_control.yaml``: the calibration as the robot's ros2_control controller takes it.

A ROS 2 parameter file (``<controller>: ros__parameters: ...``) holding only what the calibration
determines (the geometry: wheel radius, separation or wheelbase, track, multipliers; the
odometry's covariance diagonals), under the names of the ros2_controllers release it targets
(``--ros-distro``); the joint names, limits and odometry settings stay the user's. Comments give
each value's 1σ, each of the controller's values left out and why, and every calibrated value
with no place there and where it belongs (the hardware interface's transmission, the URDF). Load
it after the controller's own file: later files override earlier ones.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.text import escaped
from nlp_calib.core.version import __version__
from nlp_calib.results import CalibrationRun
from nlp_calib.results.handoff import UNMEASURED, ControllerParams, OdometryNoise

#: The ROS 2 releases whose ros2_controllers names the file can use; the default is the first.
ROS_DISTROS = ("jazzy", "humble", "iron", "kilted", "rolling")
DEFAULT_ROS_DISTRO = ROS_DISTROS[0]
#: The releases that name the steering controllers' geometry by axle (front, rear), not by role
#: (traction, steering): with the steering in front, the traction axle is the rear one.
_BY_AXLE = ("humble", "iron")
_AXLE_NAMES: Mapping[str, Mapping[str, str]] = {
    "tricycle_steering_controller": {
        "traction_track_width": "wheel_track",
        "traction_wheels_radius": "rear_wheels_radius",
    },
    "ackermann_steering_controller": {
        "traction_track_width": "rear_wheel_track",
        "steering_track_width": "front_wheel_track",
        "traction_wheels_radius": "rear_wheels_radius",
    },
    "bicycle_steering_controller": {"traction_wheel_radius": "rear_wheel_radius"},
}
_AXLE_NOTES: Mapping[str, str] = {
    "ackermann_steering_controller": (
        "this release's ackermann_steering_controller takes rear_wheel_track for both axles' geometry"
    ),
}
#: Controllers that publish the odometry's covariance diagonals (every one this file is for).
_COVARIANCES = ("pose_covariance_diagonal", "twist_covariance_diagonal")


def release_name(distro: str, controller: str, name: str) -> str:
    """What release ``distro`` of ``controller`` calls the parameter the newest release calls ``name``."""
    if distro in _BY_AXLE:
        return _AXLE_NAMES.get(controller, {}).get(name, name)
    return name


def _covariance_lines(noise: OdometryNoise | None) -> tuple[list[str], dict[str, str]]:
    """The covariance diagonals with what they are, or why they are left out."""
    if noise is None or not all(v == v for v in (*noise.pose, *noise.twist)):
        why = "the log's drift against the tracker does not determine the odometry's noise"
        return [], dict.fromkeys(_COVARIANCES, why)
    pose = ", ".join(repr(v) for v in noise.pose)
    twist = ", ".join(repr(v) for v in noise.twist)
    return [
        f"    pose_covariance_diagonal: [{pose}]  # x, y, z, roll, pitch, yaw (m², rad²)",
        f"    twist_covariance_diagonal: [{twist}]  # vx, vy, vz, wx, wy, wz ((m/s)², (rad/s)²)",
    ], {}


def _covariance_notes(noise: OdometryNoise | None) -> list[str]:
    if noise is None or not all(v == v for v in (*noise.pose, *noise.twist)):
        return []
    ms = 1e3 * noise.interval_s
    return [
        "# Covariance diagonals: the wheels' noise calibrated on this log's drift against the tracker;",
        f"#   the pose's after {noise.distance_m:g} m of driving as the log drives (a fixed diagonal "
        "cannot follow the drift's growth),",
        f"#   the twist's over one interval of the log ({ms:.3g} ms); averaged over a window of W ms "
        f"(the controller's rolling mean) it is about {ms:.3g}/W of it.",
        f"#   {UNMEASURED:g}: what planar wheel odometry does not measure (height, roll, pitch, their rates, "
        "lateral velocity).",
    ]


def ros2_control_yaml(run: CalibrationRun, solver: str, params: ControllerParams, distro: str) -> str:
    """The parameter file's text, for ros2_controllers of ROS 2 ``distro``."""
    controller = params.controller
    lines = [
        f"# {controller} parameters calibrated by nlp_calib {__version__} for ROS 2 {distro} (its "
        f"ros2_controllers' names): scenario {escaped(run.scenario.name)}, {solver}'s estimate.",
        "# Only what the calibration determines; load it after your controller's own parameter file.",
        *([f"# Note: {params.assumes}."] if params.assumes else []),
        *(
            [f"# Note: {_AXLE_NOTES[controller]}."]
            if distro in _BY_AXLE and controller in _AXLE_NOTES
            else []
        ),
        f"{controller}:",
        "  ros__parameters:",
    ]
    for name, value in params.parameters.items():
        lines.append(
            f"    {release_name(distro, controller, name)}: {value!r}  # ± {params.std[name]:.2g} (1σ)"
        )
    noise, omitted = params.noise, dict(params.omitted)
    covariances, left_out = _covariance_lines(noise)
    lines += covariances
    omitted.update(left_out)
    lines += _covariance_notes(noise)
    if omitted:
        lines += ["", "# Left out (your own file's values stay):"]
        lines += [f"#   {release_name(distro, controller, n)}: {why}" for n, why in omitted.items()]
    if params.elsewhere:
        lines += ["", f"# Calibrated, but not parameters of {controller}:"]
        for p in params.elsewhere:
            unit = "" if p.unit in ("", "1") else f" {p.unit}"
            lines.append(f"#   {p.name} = {p.value!r}{unit} ± {p.std:.2g}: {p.where}")
    lines.append("# The sensor's mount: robot.urdf (or sensor_mount.urdf.xml) beside this file.")
    return "\n".join(lines) + "\n"


def write_ros2_control(run: CalibrationRun, folder: Path, name: str, distro: str) -> list[Path]:
    """Write ``ros2_control.yaml`` for the handed-off estimate (none when nothing is handed off)."""
    solver = run.handoff_solver()
    params = run.reports[solver].controller if solver is not None else None
    if params is None:
        (folder / name).unlink(missing_ok=True)
        return []
    atomic_write_text(folder / name, ros2_control_yaml(run, solver, params, distro))  # type: ignore[arg-type]
    return [folder / name]
