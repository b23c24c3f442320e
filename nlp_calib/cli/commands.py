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

from nlp_calib.cli.parser import ALL_SOLVERS
from nlp_calib.core import interrupts
from nlp_calib.core.errors import SolverError, UsageError
from nlp_calib.core.files import atomic_write_bytes, atomic_write_text, check_output_dir
from nlp_calib.outputs.handoff import CALIBRATION_FILE, URDF_FILE, write_handoff
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.outputs.progress import Progress
from nlp_calib.outputs.results import RESULT_FILE, VALIDATION_FILE, write_result, write_validation
from nlp_calib.outputs.terminal import correlation_table, run_table, summary_table, validation_table
from nlp_calib.pipeline import Calibration, Scenario, load_scenario, steps
from nlp_calib.pipeline.export import write_c_export
from nlp_calib.pipeline.simconfig import simulation_options
from nlp_calib.simulation import simulate, truth_path, write_simulation
from nlp_calib.solvers import SOLVERS

ODOMETRY_CSV = "odometry.csv"
ODOMETRY_PNG = "odometry.png"


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


def _report_files() -> tuple[str, ...]:
    from nlp_calib.outputs import writer  # imports matplotlib

    return (
        writer.TRAJECTORY_FILE,
        writer.CONVERGENCE_FILE,
        writer.RESIDUALS_FILE,
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
    scenarios = [_with_data(load_scenario(p), args.data) for p in args.scenario]
    outs = _out_dirs(args, scenarios)
    names = [RESULT_FILE, CALIBRATION_FILE, URDF_FILE, *(_report_files() if args.report else ())]
    for out in outs:
        refuse_collisions(out, names, force=args.force)
    logs = [steps.read_checked(sc) for sc in scenarios]  # every input checked before any work
    runs = []
    with Progress(len(scenarios), sys.stderr, label="scenarios") as progress:
        for i, (scenario, out, log) in enumerate(zip(scenarios, outs, logs)):
            progress.update(i, f"{scenario.name}: setting up and solving")
            calib = Calibration.setup(scenario, log=log, solvers=solvers)
            run = calib.run(solvers)
            runs.append(run)
            progress.clear()
            print(run_table(run))
            print()
            print(correlation_table(run, next(iter(run.reports))))
            # Staged: an interrupted run leaves the previous run's files, never a mix of both.
            with StagedOutput(out, "run", force=args.force) as stage:
                written = [write_result(run, stage.path), *write_handoff(run, stage.path)]
                if len(written) == 1:
                    print(
                        "warning: no solver converged; no calibration.yaml or URDF written", file=sys.stderr
                    )
                if args.report:
                    from nlp_calib.outputs.writer import write_report  # imports matplotlib

                    progress.update(i, f"{scenario.name}: drawing the report")
                    written += write_report(calib, run, stage.path)
                    progress.clear()
                if i == len(scenarios) - 1:
                    interrupts.hold()  # what is complete stays complete: a later signal changes nothing
                stage.commit()
            print("\n" + "\n".join(_wrote([stage.final(p) for p in written], out)) + "\n")
    if len(runs) > 1:
        print(summary_table(runs))
    return 0 if all(r.result.converged for run in runs for r in run.reports.values()) else 1


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
        final = [stage.final(p) for p in write_c_export(scenario, stage.path)]
        interrupts.hold()
        stage.commit()
    for path in final:
        print(f"wrote {path}")
    return 0


def _cmd_odometry(args: argparse.Namespace) -> int:
    if len(args.scenario) != 1:
        raise UsageError("odometry takes one scenario")
    scenario = _with_data(load_scenario(args.scenario[0]), args.data)
    (out,) = _out_dirs(args, [scenario])
    refuse_collisions(out, [ODOMETRY_CSV, *([ODOMETRY_PNG] if args.report else [])], force=args.force)
    calib = Calibration.setup(scenario)
    result = calib.solve(args.solver)
    if not result.converged:
        raise SolverError(f"{args.solver} did not converge ({result.reason}); no odometry from it")
    track = calib.odometry(result.params)
    cov = track.covariance
    with StagedOutput(out, "odometry", force=args.force) as stage:
        atomic_write_text(stage.path / ODOMETRY_CSV, track.csv())
        if args.report:
            from nlp_calib.outputs.plots import odometry_png  # imports matplotlib

            title = f"{scenario.name}: calibrated odometry ({args.solver}), {args.sigma:g}σ ellipses"
            png = odometry_png(track, calib.base_reference(result.params), title, sigma=args.sigma)
            atomic_write_bytes(stage.path / ODOMETRY_PNG, png)
        interrupts.hold()
        written = stage.commit()
    print(f"{args.solver}: {result.param_dict()}")
    print(
        f"final 1σ: x {1e3 * np.sqrt(cov[-1, 0, 0]):.3g} mm, y {1e3 * np.sqrt(cov[-1, 1, 1]):.3g} mm, "
        f"θ {1e3 * np.sqrt(cov[-1, 2, 2]):.3g} mrad after {calib.selected.n_records} records "
        f"(encoder noise per input: {', '.join(f'{v:.3g}' for v in calib.input_noise_std)})"
    )
    for path in written:
        print(f"wrote {path}")
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    if len(args.scenario) != 1:
        raise UsageError("validate takes one scenario")
    scenario = _with_data(load_scenario(args.scenario[0]), args.data)
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
    return 0 if run.crossval is not None and run.crossval.available else 1


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "validate": _cmd_validate,
    "odometry": _cmd_odometry,
    "run": _cmd_run,
    "compare": _cmd_compare,
    "codegen": _cmd_codegen,
    "simulate": _cmd_simulate,
}
