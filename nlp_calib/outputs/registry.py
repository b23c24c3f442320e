"""Every file a run can write, in one registry: its name, what it is for, when it is written.

A command picks the groups it writes (``result``, ``handoff``, ``figures``, ``odometry``,
``validation``, ``check``); ``--report`` adds the entries marked ``report``. The same entries give the
names a run checks for collisions before it computes, the writers it calls, and the lines the
closing summary says of each file. Adding an output is one module with a writer
``(run, folder, name, options) -> [paths]`` and one entry in :data:`OUTPUTS`.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from nlp_calib.outputs import check, handoff, markdown, plan, results, ros2_control, trajectories, urdf
from nlp_calib.outputs.outdir import StagedOutput
from nlp_calib.results import CalibrationRun


@dataclass(frozen=True)
class OutputOptions:
    """What a user says about the outputs on the command line: ``sigma`` of the drawn ellipses,
    the robot's own URDF and the sensor's link in it (``robot.urdf`` re-poses that joint) and the
    ROS 2 release whose ros2_controllers' names ``ros2_control.yaml`` uses, and the controller's
    name there (None: its type, with a line saying to rename it)."""

    sigma: float = 3.0
    urdf: urdf.Description | None = None
    sensor_link: str | None = None
    ros_distro: str = ros2_control.DEFAULT_ROS_DISTRO
    controller_name: str | None = None


Writer = Callable[[CalibrationRun, Path, str, OutputOptions], list[Path]]


@dataclass(frozen=True)
class Output:
    """One file (or folder) a run writes.

    ``group``: which commands write it; ``report``: only with ``--report``; ``per_log``: one per log
    (a joint run writes it into each log's folder) or, when False, once per calibration into the
    top folder; ``next_step``: what the closing summary says of it ("" for nothing).
    """

    name: str
    group: str
    write: Writer
    report: bool = False
    per_log: bool = True
    next_step: str = ""
    #: A folder of files (its files, not the folder, are checked for collisions as they are written).
    folder: bool = False
    #: What the summary says of it for a given run, in place of ``next_step`` (what it holds varies).
    next_step_of: Callable[[CalibrationRun], str] | None = None


def _plain(function: Callable[[CalibrationRun, Path, str], list[Path]]) -> Writer:
    """A writer that needs no options."""
    return lambda run, folder, name, options: function(run, folder, name)


def _figure(function: str) -> Writer:
    """A figure's writer, importing matplotlib only when a figure is drawn."""

    def write(run: CalibrationRun, folder: Path, name: str, options: OutputOptions) -> list[Path]:
        drawn: list[Path] = getattr(importlib.import_module("nlp_calib.outputs.figures"), function)(
            run, folder, name
        )
        return drawn

    return write


def _odometry_png(run: CalibrationRun, folder: Path, name: str, options: OutputOptions) -> list[Path]:
    figures: Any = importlib.import_module("nlp_calib.outputs.figures")
    drawn: list[Path] = figures.odometry(run, folder, name, sigma=options.sigma)
    return drawn


def _plan_png(run: CalibrationRun, folder: Path, name: str, options: OutputOptions) -> list[Path]:
    """The plan's sketch, matplotlib imported only when there is a plan to sketch."""
    if run.checks.plan is None or not run.checks.plan.ranked:
        return []
    return _figure("plan")(run, folder, name, options)


def _robot(run: CalibrationRun, folder: Path, name: str, options: OutputOptions) -> list[Path]:
    if options.urdf is None or options.sensor_link is None:
        return handoff.write_robot(run, folder, name)
    return handoff.write_users_robot(run, folder, name, options.urdf, options.sensor_link)


def _joint(run: CalibrationRun, folder: Path, name: str, options: OutputOptions) -> list[Path]:
    return handoff.write_joint(run, folder, name, users=options.urdf is not None)


def placed(run: CalibrationRun, options: OutputOptions) -> CalibrationRun:
    """``run`` with each estimate's mount as the user's own joint of the sensor's link when they
    give their URDF (``--urdf``, ``--sensor-link``): what every hand-off file then states."""
    if options.urdf is None or options.sensor_link is None:
        return run
    description, link = options.urdf, options.sensor_link
    reports = {
        name: rep
        if rep.mount is None
        else dataclasses.replace(rep, mount=urdf.placed(description, link, rep.mount))
        for name, rep in run.reports.items()
    }
    return dataclasses.replace(run, reports=reports)


def _odometry_step(run: CalibrationRun) -> str:
    """What odometry.csv holds: its covariance only where one was written."""
    why = run.odometry.undetermined if run.odometry is not None else ""
    if why:
        return f"the base link's odometry, one row per record, with no covariance: {why}"
    return "the base link's odometry with its covariance, one row per record"


def _controller(run: CalibrationRun, folder: Path, name: str, options: OutputOptions) -> list[Path]:
    return ros2_control.write_ros2_control(run, folder, name, options.ros_distro, options.controller_name)


def _report(run: CalibrationRun, folder: Path, name: str, options: OutputOptions) -> list[Path]:
    files = names(("handoff",)) if run.handoff_solver() is not None else []
    if handoff.urdf_mount(run) is None:  # a mount not determined: no URDF file is written
        files = [f for f in files if f not in (handoff.URDF_FILE, handoff.ROBOT_URDF_FILE)]
    return markdown.write_report(run, folder, name, files, next_steps(files, run))


OUTPUTS: tuple[Output, ...] = (
    Output("calibration.yaml", "handoff", _plain(handoff.write_calibration), per_log=False,
           next_step="the parameters with units and 1σ, for your robot's configuration"),
    Output("sensor_mount.urdf.xml", "handoff", _joint, per_log=False,
           next_step="paste its <joint> into your robot's URDF (its comment says what was calibrated)"),
    Output("robot.urdf", "handoff", _robot, per_log=False,
           next_step="the same joint in a complete robot description (with --urdf: yours), for URDF tools"),
    Output("ros2_control.yaml", "handoff", _controller, per_log=False,
           next_step="the controller's parameters (wheel radius, separation or wheelbase) for ros2_control"),
    Output("result.json", "result", _plain(results.write_result)),
    Output("plan.md", "result", _plain(plan.write_plan),
           next_step="what to drive next, the manoeuvres ranked by how much each would help"),
    Output("plan.png", "result", _plan_png),
    Output("odometry.csv", "odometry", _plain(results.write_odometry),
           next_step="the base link's odometry, one row per record", next_step_of=_odometry_step),
    Output("odometry.png", "odometry", _odometry_png, report=True),
    Output("validation.json", "validation", _plain(results.write_validation)),
    Output("check.json", "check", _plain(check.write_check),
           next_step="the verdict and each parameter's change in its σ, for a cron job or a fleet table"),
    Output("trajectory.png", "figures", _figure("trajectory"), report=True),
    Output("convergence.png", "figures", _figure("convergence"), report=True),
    Output("residuals.png", "figures", _figure("residuals"), report=True),
    Output("residuals_time.png", "figures", _figure("residuals_time"), report=True),
    Output("model_check.png", "figures", _figure("model_check"), report=True),
    Output("trust.png", "figures", _figure("trust"), report=True),
    Output("lag.png", "figures", _figure("lag"), report=True),
    Output("report.md", "figures", _report, report=True,
           next_step="the figures and tables of this run on one page"),
    Output(trajectories.FOLDER, "figures", _plain(trajectories.write_trajectories), report=True, folder=True),
)  # fmt: skip


#: The groups a calibration writes (``nlp-calib run``, ``compare``; ``write_run``).
RUN_GROUPS = ("result", "handoff", "figures")


def selected(groups: Collection[str], report: bool) -> tuple[Output, ...]:
    """The outputs of ``groups``, those needing ``--report`` only with ``report``."""
    return tuple(o for o in OUTPUTS if o.group in groups and (report or not o.report))


def names(groups: Collection[str], report: bool = False) -> list[str]:
    """The file names the outputs of ``groups`` write."""
    return [o.name for o in selected(groups, report)]


def files(outputs: Sequence[Output]) -> list[str]:
    """The names of the single files among ``outputs`` (what a run checks before any work)."""
    return [o.name for o in outputs if not o.folder]


def next_steps(files: Sequence[str], run: CalibrationRun | None = None) -> list[str]:
    """What the closing summary says of each of ``files`` that has something to say (of ``run``'s
    where what a file holds varies)."""
    said = {
        o.name: o.next_step_of(run) if o.next_step_of is not None and run is not None else o.next_step
        for o in OUTPUTS
        if o.next_step
    }
    return [f"{name}: {said[name]}" for name in files if name in said]


def write(
    outputs: Sequence[Output],
    runs: Sequence[tuple[CalibrationRun, Path]],
    top: tuple[CalibrationRun, Path],
    options: OutputOptions,
) -> list[Path]:
    """Write ``outputs``: those per log for each ``(run, folder)`` of ``runs``, the others once for
    the calibration ``top`` (its run and folder). Returns the paths written, in that order."""
    # The mount each hand-off file states is made once, before any of them is written.
    runs = [(placed(run, options), folder) for run, folder in runs]
    top = (placed(top[0], options), top[1])
    written: list[Path] = []
    for output in outputs:
        targets = runs if output.per_log else [top]
        for run, folder in targets:
            if output.report and run.series is None and run.scenario.datasets:
                continue  # the joint fit of several logs: each log's folder holds its figures
            folder.mkdir(exist_ok=True)
            written += output.write(run, folder, output.name, options)
    return written


def write_staged(
    out: Path,
    outputs: Sequence[Output],
    run: CalibrationRun,
    options: OutputOptions,
    group: str,
    *,
    force: bool,
) -> list[Path]:
    """``outputs`` of ``run`` into ``out`` through a staged folder (all or nothing, the manifest's
    ``group``; over several logs, each log's in its subfolder); returns the final paths."""
    with StagedOutput(out, group, force=force) as stage:
        runs = [(part, stage.path / sub) for part, sub in run.parts()]
        written = write(outputs, runs, (run, stage.path), options)
        stage.commit()
    return [stage.final(p) for p in written]
