"""The calibrating commands: ``run``, ``compare``, ``odometry`` and ``validate``.

Every command checks what it can before it computes (scenarios, option ranges, output folders and
files it would replace), and writes its files through a staged output folder, so a run that
fails or is interrupted writes nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from nlp_calib.cli.explain import no_crossvalidation
from nlp_calib.cli.gate import set_up_and_gate
from nlp_calib.cli.parser import ALL_SOLVERS
from nlp_calib.core import interrupts
from nlp_calib.core.errors import SolverError, UsageError
from nlp_calib.core.files import check_output_dir
from nlp_calib.logs import Log
from nlp_calib.outputs import compare, registry, urdf
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.outputs.progress import Progress
from nlp_calib.outputs.summary import summary_lines
from nlp_calib.outputs.terminal import correlation_table, run_table, summary_table, validation_table
from nlp_calib.outputs.write import output_options
from nlp_calib.pipeline import Calibration, Scenario, Wanted, load_scenario
from nlp_calib.pipeline.prepare import read_checked
from nlp_calib.pipeline.scenario import refuse_off_the_base, with_joint_limits
from nlp_calib.results import CalibrationRun
from nlp_calib.solvers import SOLVERS


def _out_dirs(args: argparse.Namespace, scenarios: Sequence[Scenario]) -> list[Path]:
    """Each scenario's output folder, created and checked before any work."""
    seen: dict[str, Scenario] = {}
    for sc in scenarios:
        if sc.name in seen:
            raise UsageError(
                f"two scenarios are named {sc.name!r} ({seen[sc.name].path} and {sc.path}); their "
                "results would overwrite each other: give each its own 'name'"
            )
        seen[sc.name] = sc
    if args.out is None:
        return [check_output_dir(Path("out") / sc.name) for sc in scenarios]
    if len(scenarios) > 1:
        return [check_output_dir(args.out / sc.name) for sc in scenarios]
    return [check_output_dir(args.out)]


def with_data(sc: Scenario, data: Path | None) -> Scenario:
    return sc.with_dataset(data) if data is not None else sc


def _loadwith_data(paths: Sequence[Path], data: Sequence[Path] | None) -> list[Scenario]:
    """The scenarios, each on the log ``--data`` gives it: one ``PATH`` replaces the dataset that
    every scenario names (never several different ones), ``NAME=PATH`` the named scenario's."""
    scenarios = [load_scenario(p) for p in paths]
    if not data:
        return scenarios
    names = {sc.name for sc in scenarios}
    per_name: dict[str, Path] = {}
    plain: list[Path] = []
    for item in data:
        name, sep, rest = str(item).partition("=")
        if sep and name in names:
            if name in per_name:
                raise UsageError(f"--data gives scenario {name!r} two logs")
            per_name[name] = Path(rest)
        else:
            plain.append(item)
    if (plain and per_name) or len(plain) > 1:
        raise UsageError("give --data once as PATH, or as NAME=PATH once per scenario, not both")
    if plain:
        shared = {sc.dataset.resolve() for sc in scenarios}
        if len(shared) > 1:
            listed = ", ".join(f"{sc.name}: {sc.dataset}" for sc in scenarios)
            raise UsageError(
                f"--data {plain[0]} would replace different logs ({listed}); give NAME=PATH for each "
                "scenario to replace, or run them separately"
            )
        return [sc.with_dataset(plain[0]) for sc in scenarios]
    return [sc.with_dataset(per_name[sc.name]) if sc.name in per_name else sc for sc in scenarios]


def _wrote(paths: Sequence[Path], out: Path) -> list[str]:
    """One line per file written into ``out``, one per subfolder."""
    lines: list[str] = []
    folders: dict[str, list[Path]] = {}
    for p in paths:
        rel = p.relative_to(out)
        if len(rel.parts) > 1:
            folders.setdefault(rel.parts[0], []).append(p)
        else:
            lines.append(f"wrote {p}")
    lines += [f"wrote {out / name}/ ({len(files)} files)" for name, files in folders.items()]
    return lines


#: The output groups each calibrating command writes.
CALIBRATE = registry.RUN_GROUPS


def _robot_urdf(args: argparse.Namespace) -> None:
    """The user's URDF (``--urdf``), read and checked before any work (``args.robot_urdf``)."""
    options = output_options(robot_urdf=args.urdf, sensor_link=args.sensor_link, ros_distro=args.ros_distro)
    args.robot_urdf = options.urdf


def _urdf_limits(args: argparse.Namespace, scenarios: Sequence[Scenario]) -> list[Scenario]:
    """Each scenario with its steered wheels' reach from the user's URDF (``--urdf``) where it
    gives none (the plan steers within it), said."""
    if args.robot_urdf is None:
        return list(scenarios)
    limits = urdf.joint_limits(args.robot_urdf)
    out = []
    for sc in scenarios:
        sc, said = with_joint_limits(sc, limits)
        if said is not None:
            print(said)
        out.append(sc)
    return out


def _one_link(args: argparse.Namespace, scenarios: Sequence[Scenario]) -> None:
    """``--urdf`` re-poses one sensor link: refused, before any work, for a fit with a mount per log."""
    if args.robot_urdf is None:
        return
    for sc in scenarios:
        if sc.data.joint and sc.objective.sensor.mounts == "per_log":
            raise UsageError(
                f"--urdf re-poses one sensor link, and {sc.name} fits a mount per log (sensor: "
                "{mounts: per_log}); run it without --urdf: robot.urdf and sensor_mount.urdf.xml "
                "then hold one joint per log"
            )


def _compare_dir(args: argparse.Namespace, outs: Sequence[Path]) -> Path:
    """Where ``compare.md`` and ``compare.csv`` go: one scenario's output folder, or the folder
    holding several."""
    if len(outs) == 1:
        return outs[0]
    return check_output_dir(args.out if args.out is not None else Path("out"))


def _cmd_calibrate(
    args: argparse.Namespace, solvers: Sequence[str] | None, side_by_side: bool = False
) -> int:
    _robot_urdf(args)
    scenarios = _urdf_limits(args, _loadwith_data(args.scenario, args.data))
    _one_link(args, scenarios)
    outs = _out_dirs(args, scenarios)
    outputs = registry.selected(CALIBRATE, args.report)
    # Every input read and checked before any work; read first, so that an output over an input
    # is refused now, not after the solve.
    logs = [[read_checked(s) for s in sc.per_log()] for sc in scenarios]
    for out in outs:
        refuse_collisions(out, registry.files(outputs), force=args.force)
    aligned = set_up_and_gate(scenarios, logs, args.skip_preflight, solvers, (outs, args.force))
    compared = _compare_dir(args, outs) if side_by_side else None
    if compared is not None:
        refuse_collisions(compared, compare.FILES, force=args.force)
    runs: list[CalibrationRun] = []
    wanted = Wanted(series=args.report)
    with Progress(len(scenarios), sys.stderr, label="scenarios") as progress:
        for i, (scenario, out, log_list) in enumerate(zip(scenarios, outs, logs)):
            progress.update(i, f"{scenario.name}: setting up and solving")
            last = i == len(scenarios) - 1
            if scenario.data.joint:
                runs += _calibrate_joint(scenario, log_list, out, args, (solvers, outputs), progress, last)
                continue
            stages, aligned[i] = aligned[i], None  # let go of them with the run
            run = Calibration(scenario, log_list[0], solvers, stages).run(solvers, wanted)
            runs.append(run)
            progress.clear()
            print(run_table(run))
            print()
            print(correlation_table(run, next(iter(run.reports))))
            progress.update(i, f"{scenario.name}: writing the results")
            final = _write_outputs(out, args, outputs, [(run, "")], (run, last), scenario=scenario)
            progress.clear()
            _closing(run, final, out)
    if compared is not None:
        _side_by_side(runs, compared, args.force)
    elif len(scenarios) > 1:
        print(summary_table(runs))
    converged = all(r.result.converged for run in runs for r in run.reports.values())
    return 0 if converged and all(run.verdict.handoff for run in runs) else 1


def _side_by_side(runs: Sequence[CalibrationRun], folder: Path, force: bool) -> None:
    """Every run's parameters, lag and sensor side by side, printed and written (staged)."""
    print(compare.compare_table(runs))
    with StagedOutput(folder, "compare", force=force) as stage:
        written = compare.write_compare(runs, stage.path)
        stage.commit()
    print("\n" + "\n".join(f"wrote {stage.final(p)}" for p in written))


def _closing(run: CalibrationRun, final: Sequence[Path], out: Path) -> None:
    """The files written and the closing summary."""
    print("\n" + "\n".join(_wrote(final, out)) + "\n")
    names = list(dict.fromkeys(p.name for p in final))
    print("\n".join(summary_lines(run, registry.next_steps(names, run))) + "\n")


def _write_outputs(
    out: Path,
    args: argparse.Namespace,
    outputs: Sequence[registry.Output],
    pieces: Sequence[tuple[CalibrationRun, str]],
    top: tuple[CalibrationRun, bool],
    group: str = "run",
    scenario: Scenario | None = None,
) -> list[Path]:
    """``outputs`` of each piece's run in its subfolder (``""``: ``out`` itself), those of the whole
    calibration once in ``out`` for ``top``'s run; returns the final paths. Staged: an interrupted
    run leaves the previous run's files, never a mix of both. ``top[1]``: the last of the runs;
    ``group``: the output folder's manifest group the files belong to."""
    options = registry.OutputOptions(
        sigma=getattr(args, "sigma", 3.0),
        urdf=getattr(args, "robot_urdf", None),
        sensor_link=getattr(args, "sensor_link", None),
        ros_distro=getattr(args, "ros_distro", registry.OutputOptions.ros_distro),
        controller_name=getattr(args, "controller_name", None)
        or (scenario.handoff.controller_name if scenario is not None else None),
    )
    with StagedOutput(out, group, force=args.force) as stage:
        runs = [(run, stage.path / sub) for run, sub in pieces]
        written = registry.write(outputs, runs, (top[0], stage.path), options)
        handoff = registry.names(("handoff",))
        if any(o.group == "handoff" for o in outputs) and not any(p.name in handoff for p in written):
            why = "no solver converged" if top[0].chosen_solver() is None else top[0].verdict.line()
            print(f"warning: no calibration.yaml or URDF written: {why}", file=sys.stderr)
        if top[1]:
            interrupts.hold()  # what is complete stays complete: a later signal changes nothing
        stage.commit()
    return [stage.final(p) for p in written]


def _calibrate_joint(
    scenario: Scenario,
    logs: Sequence[Log],
    out: Path,
    args: argparse.Namespace,
    what: tuple[Sequence[str] | None, Sequence[registry.Output]],
    progress: Progress,
    last: bool,
) -> list[CalibrationRun]:
    """One calibration from several logs: the hand-off files in ``out``, each log's result (and
    report) in ``out/<log>/``."""
    solvers, outputs = what
    whole = Calibration(scenario, logs, solvers).run(solvers, Wanted(series=args.report))
    progress.clear()
    parts = whole.logs
    for part in parts:
        print(f"log {part.scenario.name} ({part.scenario.dataset}), figures with the joint parameters")
        print(run_table(part))
        print()
    print(correlation_table(whole, next(iter(whole.reports))))
    print()
    print(
        f"joint fit of {len(parts)} logs, {whole.data.n_residuals} windows; each log with the joint "
        "parameters, then the joint fit on every log:"
    )
    print(summary_table([*parts, whole]))
    final = _write_outputs(out, args, outputs, whole.parts(), (whole, last), scenario=scenario)
    _closing(whole, final, out)
    return [whole]


def cmd_run(args: argparse.Namespace) -> int:
    solvers: tuple[str, ...] | None = None
    if args.solver in ALL_SOLVERS:
        solvers = tuple(SOLVERS)
    elif args.solver is not None:
        solvers = (args.solver,)
    return _cmd_calibrate(args, solvers)


def cmd_compare(args: argparse.Namespace) -> int:
    return _cmd_calibrate(args, tuple(SOLVERS), side_by_side=True)


def cmd_odometry(args: argparse.Namespace) -> int:
    if len(args.scenario) != 1:
        raise UsageError("odometry takes one scenario")
    _robot_urdf(args)
    (scenario,) = _urdf_limits(args, _loadwith_data(args.scenario, args.data))
    refuse_off_the_base(
        scenario,
        "odometry",
        "its covariance is propagated on the planar base pose, and a camera's poses lie in its own "
        "world frame; 'nlp-calib run' gives the calibration",
    )
    (out,) = _out_dirs(args, [scenario])
    outputs = registry.selected(("result", "handoff", "odometry"), args.report)
    log = read_checked(scenario)
    refuse_collisions(out, registry.files(outputs), force=args.force)
    (stages,) = set_up_and_gate([scenario], [[log]], args.skip_preflight, None, ([out], args.force))
    calib = Calibration(scenario, log, None, stages)
    run = calib.run((args.solver,), Wanted(odometry=args.solver))
    print(run_table(run))
    print()
    print(correlation_table(run, args.solver))
    result = run.reports[args.solver].result
    if not result.converged or run.odometry is None:
        raise SolverError(f"{args.solver} did not converge ({result.reason}); no odometry from it")
    final = _write_outputs(out, args, outputs, [(run, "")], (run, True), "odometry", scenario)
    odo = run.odometry
    cov = odo.covariance
    units = calib.model.input_units
    shaped = ", ".join(
        f"{n} {v:.3g} {units[n]} (quantisation {odo.quantisation[n]:.3g})" for n, v in odo.input_noise.items()
    )
    grown = "the odometry's noise per metre driven and per radian turned"
    if odo.rates is not None:
        grown += f" (calibration.yaml's odometry_noise, ros2_control.yaml's diagonals): {odo.rates.words()}"
    final_sigma = (
        f"no covariance (nor in odometry.csv, calibration.yaml or ros2_control.yaml): {odo.undetermined}"
        if odo.undetermined
        else f"final 1σ: x {1e3 * np.sqrt(cov[-1, 0, 0]):.3g} mm, y {1e3 * np.sqrt(cov[-1, 1, 1]):.3g} mm, "
        f"θ {1e3 * np.sqrt(cov[-1, 2, 2]):.3g} mrad, grown as a filter grows {grown}; shaped by each "
        f"input's noise per interval, calibrated on this log's drift against the tracker: {shaped}"
    )
    print(f"\nodometry over {odo.time_s.size} records, {final_sigma}")
    _closing(run, final, out)
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    if len(args.scenario) != 1:
        raise UsageError("validate takes one scenario")
    (scenario,) = _loadwith_data(args.scenario, args.data)
    blocks = args.blocks if args.blocks is not None else (scenario.validation.blocks or 10)
    scenario = dataclasses.replace(
        scenario, validation=dataclasses.replace(scenario.validation, blocks=blocks)
    )
    (out,) = _out_dirs(args, [scenario])
    outputs = registry.selected(("validation",), report=False)
    log = read_checked(scenario)
    refuse_collisions(out, registry.files(outputs), force=args.force)
    run = Calibration.setup(scenario, log=log).run(scenario.solvers[:1])
    print(validation_table(run))
    written = _write_outputs(out, args, outputs, [(run, "")], (run, True), "validate")
    print("\n" + "\n".join(_wrote(written, out)))
    cv = run.checks.crossval
    if cv is None or not cv.available:
        print(f"error: {no_crossvalidation(run, blocks)}", file=sys.stderr)
        return 1
    return 0
