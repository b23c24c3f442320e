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
from nlp_calib.results.handoff import UNMEASURED, ControllerParams, NoiseRates, OdometryNoise

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
        "# Covariance diagonals: the odometry's noise per metre and per radian (below), calibrated on this",
        "#   log's drift against the tracker, with each reading's rounding;",
        f"#   the pose's after {noise.distance_m:g} m of driving as the log drives (a fixed diagonal "
        "cannot follow the drift's growth),",
        f"#   the twist's over one interval of the log ({ms:.3g} ms); averaged over a window of W ms "
        f"(the controller's rolling mean) it is about {ms:.3g}/W of it.",
        f"#   {UNMEASURED:g}: what planar wheel odometry does not measure (height, roll, pitch, their rates, "
        "lateral velocity).",
        "#   Both over the metres and intervals no fault touched (the variance whose 2σ holds 95 % of them):",
        "#   not through a fault, nor a pivot the ground slipped on (its drift is stated apart, below).",
        *_rates_notes(noise.rates),
    ]


def _rates_notes(rates: NoiseRates | None) -> list[str]:
    """The same noise per metre and per radian (a filter's process noise), with how it held."""
    if rates is None:
        return []
    return [f"#   As a filter's process noise: {rates.words()} (calibration.yaml: odometry_noise)."]


def _comment(text: str) -> str:
    """``text`` on one comment line: no line break or control character from an input (a YAML
    reader breaks lines at more characters than newline) ends the comment or reaches a terminal."""
    return escaped(" ".join(text.split("\n")))


def _header(
    run: CalibrationRun, solver: str, params: ControllerParams, distro: str, name: str | None
) -> list[str]:
    """The file's comment header: the key to rename (when no name was given), what it holds, the verdict."""
    controller = params.controller
    rename = (
        [
            f"# Rename the top key '{controller}' to your controller's name (its key under "
            "controller_manager, e.g. diffbot_base_controller), or give --controller-name NAME (scenario: "
            "handoff.controller_name): under any other name your controller ignores this file."
        ]
        if name is None
        else []
    )
    return [
        *rename,
        _comment(
            f"# {controller} parameters calibrated by nlp_calib {__version__} for ROS 2 {distro} (its "
            f"ros2_controllers' names): scenario {run.scenario.name}, {solver}'s estimate."
        ),
        _comment(f"# Verdict: {run.verdict.line()}"),
        "# Live: what the calibration determines; a value it does not determine well enough is commented",
        "# out, its reason on the line above; a value you gave is written as given. Load it after your",
        "# controller's own file.",
        *([_comment(f"# Note: {params.assumes}.")] if params.assumes else []),
        *(
            [f"# Note: {_AXLE_NOTES[controller]}."]
            if distro in _BY_AXLE and controller in _AXLE_NOTES
            else []
        ),
    ]


def _doubts(doubts: Mapping[str, str], params: ControllerParams, name: str) -> list[str]:
    """Why the parameters a controller value rests on are not determined well enough to use
    (``doubts``: :meth:`CalibrationRun.doubts`)."""
    return list(dict.fromkeys(doubts[n] for n in params.rests_on.get(name, ()) if n in doubts))


def _value_lines(run: CalibrationRun, solver: str, params: ControllerParams, distro: str) -> list[str]:
    """One line per value (live, or commented out with why on the line above)."""
    lines, doubted, waived = [], run.doubts(solver), run.waived(solver)
    for name, value in params.parameters.items():
        key = release_name(distro, params.controller, name)
        if name in waived:
            lines.append(f"    {key}: {value!r}  # ± {params.std[name]:.2g} (1σ); {_comment(waived[name])}")
        elif name in params.settings:
            lines.append(f"    {key}: {value!r}  # {_comment(params.settings[name])}")
        elif name in params.given:
            lines += [
                _comment(f"    # {key} is yours, not calibrated: {params.given[name]}"),
                f"    {key}: {value!r}",
            ]
        elif doubts := _doubts(doubted, params, name):
            lines += [
                _comment(
                    f"    # {key}: not determined well enough to use ({'; '.join(doubts)}); keep yours:"
                ),
                f"    # {key}: {value!r}  # ± {params.std[name]:.2g} (1σ)",
            ]
        else:
            lines.append(f"    {key}: {value!r}  # ± {params.std[name]:.2g} (1σ)")
    return lines


def _elsewhere_lines(run: CalibrationRun, solver: str, params: ControllerParams) -> list[str]:
    """The values with no place among the controller's parameters, and where each belongs."""
    lines, doubted = [], run.doubts(solver)
    for p in params.elsewhere:
        unit = "" if p.unit in ("", "1") else f" {p.unit}"
        sd = "given, not calibrated" if p.std != p.std else f"± {p.std:.2g}"
        doubt = doubted.get(p.name)
        flag = f" [not determined well enough to use: {doubt}]" if doubt else ""
        lines.append(_comment(f"#   {p.name} = {p.value!r}{unit} {sd}{flag}: {p.where}"))
    return ["", f"# Calibrated, but not parameters of {params.controller}:", *lines] if lines else []


def _mount_line(run: CalibrationRun, solver: str) -> str:
    """Where the sensor's mount is: the URDF files, unless a component is not determined."""
    mount = run.reports[solver].mount
    doubted = mount.undetermined if mount is not None else {}
    if not doubted:
        return "# The sensor's mount: robot.urdf (or sensor_mount.urdf.xml) beside this file."
    return _comment(
        f"# The sensor's mount: no URDF file, {', '.join(doubted)} not determined well enough to use "
        "(calibration.yaml's mount: undetermined); keep yours."
    )


def ros2_control_yaml(
    run: CalibrationRun, solver: str, params: ControllerParams, distro: str, name: str | None = None
) -> str:
    """The parameter file's text, for ros2_controllers of ROS 2 ``distro``, under the controller's
    ``name`` (None: its type, with a first line saying to rename it)."""
    controller = params.controller
    lines = [*_header(run, solver, params, distro, name), f"{name or controller}:", "  ros__parameters:"]
    lines += _value_lines(run, solver, params, distro)
    noise, omitted = params.noise, dict(params.omitted)
    covariances, left_out = _covariance_lines(noise)
    lines += covariances
    omitted.update(left_out)
    lines += _covariance_notes(noise)
    if omitted:
        lines += ["", "# Left out (your own file's values stay):"]
        lines += [_comment(f"#   {release_name(distro, controller, n)}: {why}") for n, why in omitted.items()]
    lines += _elsewhere_lines(run, solver, params)
    lines.append(_mount_line(run, solver))
    return "\n".join(lines) + "\n"


def write_ros2_control(
    run: CalibrationRun, folder: Path, name: str, distro: str, controller_name: str | None = None
) -> list[Path]:
    """Write ``ros2_control.yaml`` for the handed-off estimate (none when nothing is handed off),
    keyed by ``controller_name`` (None: the controller's type)."""
    solver = run.handoff_solver()
    params = run.reports[solver].controller if solver is not None else None
    if params is None:
        (folder / name).unlink(missing_ok=True)
        return []
    text = ros2_control_yaml(run, solver, params, distro, controller_name)  # type: ignore[arg-type]
    atomic_write_text(folder / name, text)
    return [folder / name]
