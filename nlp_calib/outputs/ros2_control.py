"""``ros2_control.yaml``: the calibration as the robot's ros2_control controller takes it.

A ROS 2 parameter file (``<controller>: ros__parameters: ...``) holding only what the calibration
determines (the geometry: wheel radius, separation or wheelbase, multipliers); the joint names,
limits and odometry settings stay the user's. Comments give each value's 1σ and, below, every
calibrated value with no place there and where it belongs (the hardware interface's transmission,
the URDF). Load it after the controller's own file: later files override earlier ones.
"""

from __future__ import annotations

from pathlib import Path

from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.version import __version__
from nlp_calib.results import CalibrationRun
from nlp_calib.results.handoff import ControllerParams


def ros2_control_yaml(run: CalibrationRun, solver: str, params: ControllerParams) -> str:
    """The parameter file's text."""
    lines = [
        f"# {params.controller} parameters calibrated by nlp_calib {__version__}: scenario "
        f"{run.scenario.name}, {solver}'s estimate.",
        "# Only what the calibration determines; load it after your controller's own parameter file.",
        *([f"# Note: {params.assumes}."] if params.assumes else []),
        f"{params.controller}:",
        "  ros__parameters:",
    ]
    for name, value in params.parameters.items():
        lines.append(f"    {name}: {value!r}  # ± {params.std[name]:.2g} (1σ)")
    if params.elsewhere:
        lines += ["", f"# Calibrated, but not parameters of {params.controller}:"]
        for p in params.elsewhere:
            unit = "" if p.unit in ("", "1") else f" {p.unit}"
            lines.append(f"#   {p.name} = {p.value!r}{unit} ± {p.std:.2g}: {p.where}")
    lines.append("# The sensor's mount: robot.urdf (or sensor_mount.urdf.xml) beside this file.")
    return "\n".join(lines) + "\n"


def write_ros2_control(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """Write ``ros2_control.yaml`` for the handed-off estimate (none when nothing is handed off)."""
    solver = run.handoff_solver()
    params = run.reports[solver].controller if solver is not None else None
    if params is None:
        (folder / name).unlink(missing_ok=True)
        return []
    atomic_write_text(folder / name, ros2_control_yaml(run, solver, params))  # type: ignore[arg-type]
    return [folder / name]
