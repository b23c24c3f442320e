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

import numpy as np

from nlp_calib.cli.explain import no_crossvalidation
from nlp_calib.cli.import_bag import cmd_import_bag
from nlp_calib.cli.parser import ALL_SOLVERS
from nlp_calib.core import interrupts
from nlp_calib.core.errors import SolverError, UsageError
from nlp_calib.core.files import atomic_write_bytes, atomic_write_text, check_output_dir
from nlp_calib.logs import Log
from nlp_calib.outputs.handoff import HANDOFF_FILES, write_handoff
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.outputs.progress import Progress
from nlp_calib.outputs.results import (
    ODOMETRY_CSV,
    ODOMETRY_PNG,
    RESULT_FILE,
    VALIDATION_FILE,
    write_result,
    write_validation,
)
from nlp_calib.outputs.summary import summary_lines
from nlp_calib.outputs.terminal import correlation_table, run_table, summary_table, validation_table
from nlp_calib.pipeline import Calibration, CalibrationRun, Scenario, load_scenario, steps
from nlp_calib.pipeline.export import write_c_export
from nlp_calib.pipeline.joint import JointCalibration
from nlp_calib.pipeline.simconfig import simulation_options
from nlp_calib.simulation import simulate, truth_path, write_simulation
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


def _report_files() -> tuple[str, ...]:
    from nlp_calib.outputs import writer  # imports matplotlib

    return (
        writer.TRAJECTORY_FILE,
        writer.CONVERGENCE_FILE,
        writer.RESIDUALS_FILE,
        writer.RESIDUALS_TIME_FILE,
        writer.MODEL_CHECK_FILE,
        writer.REPORT_FILE,
    )


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


def _cmd_calibrate(args: argparse.Namespace, solvers: Sequence[str] | None) -> int:
    scenarios = _load_with_data(args.scenario, args.data)
    outs = _out_dirs(args, scenarios)
    names = [RESULT_FILE, *HANDOFF_FILES, *(_report_files() if args.report else ())]
    for out in outs:
        refuse_collisions(out, names, force=args.force)
    # Every input checked before any work.
    logs = [[steps.read_checked(s) for s in (sc.per_log() or (sc,))] for sc in scenarios]
    runs = []
    with Progress(len(scenarios), sys.stderr, label="scenarios") as progress:
        for i, (scenario, out, log_list) in enumerate(zip(scenarios, outs, logs)):
            progress.update(i, f"{scenario.name}: setting up and solving")
            if scenario.datasets:
                last = i == len(scenarios) - 1
                runs += _calibrate_joint(scenario, log_list, out, args, solvers, progress, last)
                continue
            log = log_list[0]
            calib = Calibration.setup(scenario, log=log, solvers=solvers)
            run = calib.run(solvers)
            runs.append(run)
            progress.clear()
            print(run_table(run))
            print()
            print(correlation_table(run, next(iter(run.reports))))
            progress.update(i, f"{scenario.name}: writing the results")
            final = _write_outputs(out, args, run, [(run, calib, "")], last=i == len(scenarios) - 1)
            progress.clear()
            print("\n" + "\n".join(_wrote(final, out)) + "\n")
            print("\n".join(summary_lines(run, final)) + "\n")
    if len(scenarios) > 1:
        print(summary_table(runs))
    return 0 if all(r.result.converged for run in runs for r in run.reports.values()) else 1


def _write_outputs(
    out: Path,
    args: argparse.Namespace,
    handoff: CalibrationRun,
    pieces: Sequence[tuple[CalibrationRun, Calibration, str]],
    last: bool,
) -> list[Path]:
    """The hand-off files of ``handoff`` in ``out``, and each piece's ``result.json`` (and report)
    in its subfolder (``""``: ``out`` itself); returns the final paths. Staged: an interrupted
    run leaves the previous run's files, never a mix of both."""
    with StagedOutput(out, "run", force=args.force) as stage:
        written = write_handoff(handoff, stage.path)
        if not written:
            print("warning: no solver converged; no calibration.yaml or URDF written", file=sys.stderr)
        for run, calib, sub in pieces:
            folder = stage.path / sub
            folder.mkdir(exist_ok=True)
            written.append(write_result(run, folder))
            if args.report:
                from nlp_calib.outputs.writer import write_report  # imports matplotlib

                written += write_report(calib, run, folder)
        if last:
            interrupts.hold()  # what is complete stays complete: a later signal changes nothing
        stage.commit()
    return [stage.final(p) for p in written]


def _calibrate_joint(
    scenario: Scenario,
    logs: Sequence[Log],
    out: Path,
    args: argparse.Namespace,
    solvers: Sequence[str] | None,
    progress: Progress,
    last: bool,
) -> list[CalibrationRun]:
    """One calibration from several logs: the hand-off files in ``out``, each log's result (and
    report) in ``out/<log>/``."""
    calib = JointCalibration(scenario, logs, solvers)
    joint = calib.run(solvers)
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
    pieces = [(part, pcalib, part.scenario.name) for part, pcalib in zip(parts, calib.parts)]
    final = _write_outputs(out, args, dataclasses.replace(parts[0], scenario=scenario), pieces, last)
    print("\n" + "\n".join(_wrote(final, out)) + "\n")
    print("\n".join(summary_lines(parts[0], final)) + "\n")
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
        )
        if getattr(args, k) is not None
    }
    opts = simulation_options(args.config, overrides)
    out: Path = args.out
    if out.is_dir() or out.name in ("", ".", ".."):
        raise UsageError(f"--out {out} is a folder; give the path of the log file to write")
    folder = check_output_dir(out.parent)
    # The target may be the user's own log: never replaced without --force.
    refuse_collisions(folder, [out.name, truth_path(out).name], tracked=False, force=args.force)
    sim = simulate(opts)
    with StagedOutput(folder, None, force=args.force) as stage:
        log_path, truth = write_simulation(sim, stage.path / out.name)
        interrupts.hold()
        stage.commit()
    print(f"wrote {stage.final(log_path)} ({opts.records} records) and {stage.final(truth)}")
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
    (scenario,) = _load_with_data(args.scenario, args.data)
    (out,) = _out_dirs(args, [scenario])
    names = [RESULT_FILE, *HANDOFF_FILES, ODOMETRY_CSV, *([ODOMETRY_PNG] if args.report else [])]
    refuse_collisions(out, names, force=args.force)
    calib = Calibration.setup(scenario, log=steps.read_checked(scenario))
    run = calib.run((args.solver,))
    print(run_table(run))
    print()
    print(correlation_table(run, args.solver))
    result = run.reports[args.solver].result
    if not result.converged:
        raise SolverError(f"{args.solver} did not converge ({result.reason}); no odometry from it")
    track = calib.odometry(result.params)
    cov = track.covariance
    with StagedOutput(out, "odometry", force=args.force) as stage:
        written = [write_result(run, stage.path), *write_handoff(run, stage.path)]
        written.append(stage.path / ODOMETRY_CSV)
        atomic_write_text(written[-1], track.csv())
        if args.report:
            from nlp_calib.outputs.plots import odometry_png  # imports matplotlib

            title = f"{scenario.name}: calibrated odometry ({args.solver}), {args.sigma:g}σ ellipses"
            png = odometry_png(track, calib.base_reference(result.params), title, sigma=args.sigma)
            written.append(stage.path / ODOMETRY_PNG)
            atomic_write_bytes(written[-1], png)
        interrupts.hold()
        stage.commit()
    final = [stage.final(p) for p in written]
    noise = ", ".join(
        f"{n} {v:.3g} {calib.model.input_units[n]}"
        for n, v in zip(calib.model.input_names, calib.input_noise_std)
    )
    print(
        f"\nodometry over {calib.selected.n_records} records, final 1σ: "
        f"x {1e3 * np.sqrt(cov[-1, 0, 0]):.3g} mm, y {1e3 * np.sqrt(cov[-1, 1, 1]):.3g} mm, "
        f"θ {1e3 * np.sqrt(cov[-1, 2, 2]):.3g} mrad from encoder noise alone (per interval: {noise})"
    )
    print("\n" + "\n".join(_wrote(final, out)) + "\n")
    print("\n".join(summary_lines(run, final)) + "\n")
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
    refuse_collisions(out, [VALIDATION_FILE], force=args.force)
    run = Calibration.setup(scenario, log=steps.read_checked(scenario)).run(scenario.solvers[:1])
    print(validation_table(run))
    with StagedOutput(out, "validate", force=args.force) as stage:
        atomic = write_validation(run, stage.path)
        interrupts.hold()
        written = stage.commit()
    assert written == [stage.final(atomic)]
    print("\n" + "\n".join(_wrote(written, out)))
    if run.crossval is None or not run.crossval.available:
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
}
