"""The subcommands: each takes the parsed arguments, prints what the user reads and returns an exit code.

Every command checks what it can before it computes (scenarios, option ranges, output folders and
files it would replace), and writes its files through a staged output folder, so a run that
fails or is interrupted writes nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.cli.explain import no_crossvalidation
from nlp_calib.cli.fleet import cmd_batch, cmd_check
from nlp_calib.cli.import_bag import cmd_import_bag
from nlp_calib.cli.parser import ALL_SOLVERS
from nlp_calib.core import interrupts
from nlp_calib.core.errors import SolverError, UsageError
from nlp_calib.core.files import check_output_dir
from nlp_calib.logs import Log
from nlp_calib.outputs import registry, urdf
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.outputs.progress import Progress
from nlp_calib.outputs.summary import summary_lines
from nlp_calib.outputs.terminal import correlation_table, run_table, summary_table, validation_table
from nlp_calib.pipeline import Calibration, JointCalibration, Scenario, Wanted, load_scenario
from nlp_calib.pipeline.export import write_c_export
from nlp_calib.pipeline.prepare import read_checked
from nlp_calib.pipeline.scenario import refuse_off_the_base
from nlp_calib.pipeline.simconfig import camera_options, lidar_options, simulation_options, vendor_options
from nlp_calib.results import CalibrationRun
from nlp_calib.simulation import simulate_to_file, truth_path
from nlp_calib.simulation.camera import camera_paths, simulate_camera, write_camera_simulation
from nlp_calib.simulation.lidar import lidar_paths, simulate_lidar, write_lidar_simulation
from nlp_calib.simulation.vendor import write_vendor_simulation
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


def _with_data(sc: Scenario, data: Path | None) -> Scenario:
    return sc.with_dataset(data) if data is not None else sc


def _load_with_data(paths: Sequence[Path], data: Sequence[Path] | None) -> list[Scenario]:
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
CALIBRATE = ("result", "handoff", "figures")


def _robot_urdf(args: argparse.Namespace) -> None:
    """The user's URDF (``--urdf``), read and checked before any work (``args.robot_urdf``)."""
    if (args.urdf is None) != (args.sensor_link is None):
        raise UsageError("give --urdf and --sensor-link together: the URDF and the sensor's link in it")
    args.robot_urdf = None if args.urdf is None else urdf.load(args.urdf, args.sensor_link)


def _cmd_calibrate(args: argparse.Namespace, solvers: Sequence[str] | None) -> int:
    _robot_urdf(args)
    scenarios = _load_with_data(args.scenario, args.data)
    outs = _out_dirs(args, scenarios)
    outputs = registry.selected(CALIBRATE, args.report)
    # Every input read and checked before any work; read first, so that an output over an input
    # is refused now, not after the solve.
    logs = [[read_checked(s) for s in sc.per_log()] for sc in scenarios]
    for out in outs:
        refuse_collisions(out, registry.files(outputs), force=args.force)
    runs: list[CalibrationRun] = []
    wanted = Wanted(series=args.report)
    with Progress(len(scenarios), sys.stderr, label="scenarios") as progress:
        for i, (scenario, out, log_list) in enumerate(zip(scenarios, outs, logs)):
            progress.update(i, f"{scenario.name}: setting up and solving")
            last = i == len(scenarios) - 1
            if scenario.data.joint:
                runs += _calibrate_joint(scenario, log_list, out, args, (solvers, outputs), progress, last)
                continue
            run = Calibration.setup(scenario, log=log_list[0], solvers=solvers).run(solvers, wanted)
            runs.append(run)
            progress.clear()
            print(run_table(run))
            print()
            print(correlation_table(run, next(iter(run.reports))))
            progress.update(i, f"{scenario.name}: writing the results")
            final = _write_outputs(out, args, outputs, [(run, "")], (run, last))
            progress.clear()
            _closing(run, final, out)
    if len(scenarios) > 1:
        print(summary_table(runs))
    converged = all(r.result.converged for run in runs for r in run.reports.values())
    return 0 if converged and all(run.verdict.handoff for run in runs) else 1


def _closing(run: CalibrationRun, final: Sequence[Path], out: Path) -> None:
    """The files written and the closing summary."""
    print("\n" + "\n".join(_wrote(final, out)) + "\n")
    names = list(dict.fromkeys(p.name for p in final))
    print("\n".join(summary_lines(run, registry.next_steps(names))) + "\n")


def _write_outputs(
    out: Path,
    args: argparse.Namespace,
    outputs: Sequence[registry.Output],
    pieces: Sequence[tuple[CalibrationRun, str]],
    top: tuple[CalibrationRun, bool],
    group: str = "run",
) -> list[Path]:
    """``outputs`` of each piece's run in its subfolder (``""``: ``out`` itself), those of the whole
    calibration once in ``out`` for ``top``'s run; returns the final paths. Staged: an interrupted
    run leaves the previous run's files, never a mix of both. ``top[1]``: the last of the runs;
    ``group``: the output folder's manifest group the files belong to."""
    options = registry.OutputOptions(
        sigma=getattr(args, "sigma", 3.0),
        urdf=getattr(args, "robot_urdf", None),
        sensor_link=getattr(args, "sensor_link", None),
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
    joint = JointCalibration(scenario, logs, solvers).run(solvers, Wanted(series=args.report))
    progress.clear()
    parts = joint.parts
    for part in parts:
        print(f"log {part.scenario.name} ({part.scenario.dataset}), figures with the joint parameters")
        print(run_table(part))
        print()
    print(correlation_table(parts[0], next(iter(joint.reports))))
    print()
    print(f"joint fit of {len(parts)} logs, {joint.n_residuals} windows; each log with the joint parameters:")
    print(summary_table(list(parts)))
    handoff = dataclasses.replace(parts[0], scenario=joint.scenario)
    pieces = [(part, part.scenario.name) for part in parts]
    final = _write_outputs(out, args, outputs, pieces, (handoff, last))
    _closing(parts[0], final, out)
    return list(parts)


def _cmd_run(args: argparse.Namespace) -> int:
    solvers: tuple[str, ...] | None = None
    if args.solver in ALL_SOLVERS:
        solvers = tuple(SOLVERS)
    elif args.solver is not None:
        solvers = (args.solver,)
    return _cmd_calibrate(args, solvers)


def _cmd_compare(args: argparse.Namespace) -> int:
    return _cmd_calibrate(args, tuple(SOLVERS))


def _cmd_simulate(args: argparse.Namespace) -> int:
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
    if getattr(args, "lidar", False):
        return _simulate_lidar(args, overrides)
    if getattr(args, "vendor", False):
        return _simulate_vendor(args, overrides)
    if out.suffix.lower() == ".tum":
        return _simulate_camera(args, overrides)
    opts = simulation_options(args.config, overrides)
    folder = check_output_dir(out.parent)
    # The target may be the user's own log: never replaced without --force.
    refuse_collisions(folder, [out.name, truth_path(out).name], tracked=False, force=args.force)
    with StagedOutput(folder, None, force=args.force) as stage:
        log_path, truth = simulate_to_file(opts, stage.path / out.name)
        interrupts.hold()
        stage.commit()
    print(f"wrote {stage.final(log_path)} ({opts.records} records) and {stage.final(truth)}")
    return 0


def _simulate_camera(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A tilted camera's TUM trajectory, its joint CSV and the truth, beside each other."""
    opts = camera_options(args.config, overrides)
    out: Path = args.out
    folder = check_output_dir(out.parent)
    names = [p.name for p in camera_paths(out)]
    refuse_collisions(folder, names, tracked=False, force=args.force)
    with StagedOutput(folder, None, force=args.force) as stage:
        written = write_camera_simulation(simulate_camera(opts), stage.path / out.name)
        interrupts.hold()
        stage.commit()
    tum, joints, truth = (stage.final(p) for p in written)
    print(f"wrote {tum} ({opts.duration_s:g} s at {opts.image_rate_hz:g} Hz), {joints} and {truth}")
    return 0


def _simulate_lidar(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A lidar's bag and the truth beside it."""
    opts = lidar_options(args.config, overrides)
    out: Path = args.out
    folder = check_output_dir(out.parent)
    names = [p.name for p in lidar_paths(out)]
    refuse_collisions(folder, names, tracked=False, force=args.force)
    with StagedOutput(folder, None, force=args.force) as stage:
        written = write_lidar_simulation(simulate_lidar(opts), stage.path / out.name)
        interrupts.hold()
        stage.commit()
    bag, truth = (stage.final(p) for p in written)
    print(
        f"wrote {bag} ({opts.duration_s:g} s, scans at {opts.scan_rate_hz:g} Hz, "
        f"{100 * opts.degraded_fraction:g} % degraded) and {truth}"
    )
    print(
        f"a scenario reads it as: dataset: {{bag: {bag}, joint_states: /joint_states, joints: "
        "[left_wheel_joint, right_wheel_joint], scan: /scan}"
    )
    return 0


def _simulate_vendor(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A vendor's odometry, the tracker's TUM file and the truth, beside each other."""
    opts = vendor_options(args.config, overrides)
    out: Path = args.out
    folder = check_output_dir(out.parent)
    names = [out.name, out.with_suffix(".tum").name, out.with_suffix(".truth.json").name]
    refuse_collisions(folder, names, tracked=False, force=args.force)
    with StagedOutput(folder, None, force=args.force) as stage:
        written = write_vendor_simulation(opts, stage.path / out.name)
        interrupts.hold()
        stage.commit()
    odometry, tum, truth = (stage.final(p) for p in written)
    print(
        f"wrote {odometry} (the robot's own odometry, integrated with the model "
        f"{', '.join(f'{n} {v:g}' for n, v in opts.vendor_in_radians().items())}), {tum} and {truth}"
    )
    return 0


def _cmd_codegen(args: argparse.Namespace) -> int:
    scenario = _with_data(load_scenario(args.scenario), args.data)
    with StagedOutput(check_output_dir(args.out), "codegen", force=args.force) as stage:
        files, example = write_c_export(scenario, stage.path)
        final = [stage.final(p) for p in files]
        interrupts.hold()
        stage.commit()
    for path in final:
        print(f"wrote {path}")
    print(
        f"\nexample.c evaluates the residual and its Jacobian at the parameters {example.params_from}, on "
        f"{example.window}, and prints its largest difference from Python's values for the same call.\n"
        f"build and run it: make -C {args.out} example && {args.out / 'example'}"
    )
    return 0


def _cmd_odometry(args: argparse.Namespace) -> int:
    if len(args.scenario) != 1:
        raise UsageError("odometry takes one scenario")
    _robot_urdf(args)
    (scenario,) = _load_with_data(args.scenario, args.data)
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
    calib = Calibration.setup(scenario, log=log)
    run = calib.run((args.solver,), Wanted(odometry=args.solver))
    print(run_table(run))
    print()
    print(correlation_table(run, args.solver))
    result = run.reports[args.solver].result
    if not result.converged or run.odometry is None:
        raise SolverError(f"{args.solver} did not converge ({result.reason}); no odometry from it")
    final = _write_outputs(out, args, outputs, [(run, "")], (run, True), "odometry")
    odo = run.odometry
    cov = odo.covariance
    units = calib.model.input_units
    noise = ", ".join(
        f"{n} {v:.3g} {units[n]} (quantisation {odo.quantisation[n]:.3g})" for n, v in odo.input_noise.items()
    )
    print(
        f"\nodometry over {odo.time_s.size} records, final 1σ: "
        f"x {1e3 * np.sqrt(cov[-1, 0, 0]):.3g} mm, y {1e3 * np.sqrt(cov[-1, 1, 1]):.3g} mm, "
        f"θ {1e3 * np.sqrt(cov[-1, 2, 2]):.3g} mrad from each input's noise per interval, calibrated on this "
        f"log's drift against the tracker: {noise}; {100 * odo.coverage:.0f} % of that drift over segments "
        "lies within the propagated 2σ"
    )
    _closing(run, final, out)
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    if len(args.scenario) != 1:
        raise UsageError("validate takes one scenario")
    (scenario,) = _load_with_data(args.scenario, args.data)
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


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "validate": _cmd_validate,
    "odometry": _cmd_odometry,
    "run": _cmd_run,
    "compare": _cmd_compare,
    "codegen": _cmd_codegen,
    "simulate": _cmd_simulate,
    "import-bag": cmd_import_bag,
    "check": cmd_check,
    "batch": cmd_batch,
}
