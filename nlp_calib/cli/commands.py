"""The subcommands: each takes the parsed arguments, prints what the user reads and returns an exit code."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from nlp_calib.cli.parser import ALL_SOLVERS
from nlp_calib.core.errors import SolverError, UsageError
from nlp_calib.core.files import atomic_write_bytes, atomic_write_text, prepare_output_dir
from nlp_calib.outputs.handoff import CALIBRATION_FILE, URDF_FILE, write_handoff
from nlp_calib.outputs.outdir import StagedOutput
from nlp_calib.outputs.progress import Progress
from nlp_calib.outputs.results import write_result, write_validation
from nlp_calib.outputs.terminal import correlation_table, run_table, summary_table, validation_table
from nlp_calib.pipeline import Calibration, load_scenario
from nlp_calib.pipeline.export import write_c_export
from nlp_calib.pipeline.simconfig import simulation_options
from nlp_calib.simulation import simulate, write_simulation
from nlp_calib.solvers import SOLVERS


def _out_dir(args: argparse.Namespace, name: str) -> Path:
    if args.out is None:
        return prepare_output_dir(Path("out") / name)
    return prepare_output_dir(args.out / name if len(args.scenario) > 1 else args.out)


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
    scenarios = [load_scenario(p) for p in args.scenario]  # validate all before any work
    runs = []
    with Progress(len(scenarios), sys.stderr, label="scenarios") as progress:
        for i, scenario in enumerate(scenarios):
            out = _out_dir(args, scenario.name)
            progress.update(i, f"{scenario.name}: setting up and solving")
            calib = Calibration.setup(scenario, data=args.data)
            run = calib.run(solvers)
            runs.append(run)
            progress.clear()
            print(run_table(run))
            print()
            print(correlation_table(run, next(iter(run.reports))))
            # Staged: an interrupted run leaves the previous run's files, never a mix of both.
            with StagedOutput(out, owned=(CALIBRATION_FILE, URDF_FILE)) as stage:
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
    if args.out.is_dir():
        raise UsageError(f"--out {args.out} is a folder; give the path of the log file to write")
    prepare_output_dir(args.out.parent)
    log_path, truth = write_simulation(simulate(opts), args.out)
    print(f"wrote {log_path} ({opts.records} records) and {truth}")
    return 0


def _cmd_codegen(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    if args.data is not None:
        scenario = scenario.with_dataset(args.data)
    for path in write_c_export(scenario, prepare_output_dir(args.out)):
        print(f"wrote {path}")
    return 0


def _cmd_odometry(args: argparse.Namespace) -> int:
    if len(args.scenario) != 1:
        raise UsageError("odometry takes one scenario")
    scenario = load_scenario(args.scenario[0])
    out = _out_dir(args, scenario.name)
    calib = Calibration.setup(scenario, data=args.data)
    result = calib.solve(args.solver)
    if not result.converged:
        raise SolverError(f"{args.solver} did not converge ({result.reason}); no odometry from it")
    track = calib.odometry(result.params)
    cov = track.covariance
    csv = out / "odometry.csv"
    atomic_write_text(csv, track.csv())
    print(f"{args.solver}: {result.param_dict()}")
    print(
        f"final 1σ: x {1e3 * np.sqrt(cov[-1, 0, 0]):.3g} mm, y {1e3 * np.sqrt(cov[-1, 1, 1]):.3g} mm, "
        f"θ {1e3 * np.sqrt(cov[-1, 2, 2]):.3g} mrad after {calib.selected.n_records} records "
        f"(encoder noise per input: {', '.join(f'{v:.3g}' for v in calib.input_noise_std)})"
    )
    print(f"wrote {csv}")
    if args.report:
        from nlp_calib.outputs.plots import odometry_png  # imports matplotlib

        png = out / "odometry.png"
        title = f"{scenario.name}: calibrated odometry ({args.solver}), {args.sigma:g}σ ellipses"
        atomic_write_bytes(
            png, odometry_png(track, calib.base_reference(result.params), title, sigma=args.sigma)
        )
        print(f"wrote {png}")
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    if len(args.scenario) != 1:
        raise UsageError("validate takes one scenario")
    scenario = load_scenario(args.scenario[0])
    blocks = args.blocks if args.blocks is not None else (scenario.validation.blocks or 10)
    if not 2 <= blocks <= 100:
        raise UsageError(f"--blocks must lie in [2, 100], got {blocks}")
    scenario = dataclasses.replace(
        scenario, validation=dataclasses.replace(scenario.validation, blocks=blocks)
    )
    out = _out_dir(args, scenario.name)
    run = Calibration.setup(scenario, data=args.data).run(scenario.solvers[:1])
    print(validation_table(run))
    with StagedOutput(out) as stage:
        written = [write_validation(run, stage.path)]
        stage.commit()
    print("\n" + "\n".join(_wrote([stage.final(p) for p in written], out)))
    return 0 if run.crossval is not None and run.crossval.available else 1


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "validate": _cmd_validate,
    "odometry": _cmd_odometry,
    "run": _cmd_run,
    "compare": _cmd_compare,
    "codegen": _cmd_codegen,
    "simulate": _cmd_simulate,
}
