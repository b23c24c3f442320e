"""What ``nlp-calib run`` writes, from Python: :func:`write_run` on a run's result.

The same registry entries, the same options (the robot's own URDF and the sensor's link in it,
the ROS 2 release of ``ros2_control.yaml``, the σ of drawn ellipses) and the same staged, all or
nothing writing as the command, so a script that calibrates hands the robot stack the same
files: ``calibration.yaml``, ``sensor_mount.urdf.xml``, ``robot.urdf``, ``ros2_control.yaml``,
``result.json`` and, with ``report=True``, the figures and ``report.md``.
"""

from __future__ import annotations

from pathlib import Path

from nlp_calib.core.errors import FieldError, UsageError
from nlp_calib.core.files import check_output_dir
from nlp_calib.core.ranges import check_ros_name
from nlp_calib.outputs import registry, ros2_control, urdf
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.results import CalibrationRun


def output_options(
    sigma: float = 3.0,
    robot_urdf: str | Path | None = None,
    sensor_link: str | None = None,
    ros_distro: str = ros2_control.DEFAULT_ROS_DISTRO,
    controller_name: str | None = None,
) -> registry.OutputOptions:
    """The output options, checked as the command line checks them: the URDF read (and the
    sensor's link found in it) before anything is written; ``controller_name``: the top key of
    ``ros2_control.yaml`` (a ROS 2 node name)."""
    if (robot_urdf is None) != (sensor_link is None):
        raise UsageError("give --urdf and --sensor-link together: the URDF and the sensor's link in it")
    if ros_distro not in ros2_control.ROS_DISTROS:
        known = ", ".join(ros2_control.ROS_DISTROS)
        raise UsageError(f"unknown ROS 2 release {ros_distro!r} (--ros-distro); known: {known}")
    if controller_name is not None:
        try:
            check_ros_name("--controller-name", controller_name)
        except FieldError as exc:
            raise UsageError(f"{exc.field}: {exc.reason}") from None
    description = None if robot_urdf is None else urdf.load(Path(robot_urdf), str(sensor_link))
    return registry.OutputOptions(sigma, description, sensor_link, ros_distro, controller_name)


def write_run(
    run: CalibrationRun,
    out_dir: str | Path,
    *,
    report: bool = False,
    options: registry.OutputOptions | None = None,
    force: bool = False,
) -> list[Path]:
    """Write into ``out_dir`` what ``nlp-calib run`` writes for ``run`` (over several logs: each
    log's files in its subfolder, the joint fit's and the hand-off files once), staged: all or
    nothing. ``options`` from :func:`output_options` (default: no URDF of the robot's,
    ``ros2_control.yaml`` for the default release). Files nlp_calib did not write are not
    replaced unless ``force``. Returns the paths written."""
    options = options or registry.OutputOptions()
    outputs = registry.selected(registry.RUN_GROUPS, report)
    folder = check_output_dir(Path(out_dir))
    refuse_collisions(folder, registry.files(outputs), force=force)
    with StagedOutput(folder, "run", force=force) as stage:
        written = registry.write(
            outputs, [(r, stage.path / sub) for r, sub in run.parts()], (run, stage.path), options
        )
        stage.commit()
    return [stage.final(p) for p in written]
