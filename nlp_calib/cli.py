"""Command line: ``nlp-calib run|compare|simulate ...`` (SPEC §8).

Errors the user can fix print one line ``error: ...`` on stderr and exit with 2 (bad input) or
1 (runtime failure); ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import sys
import traceback
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from nlp_calib import __version__
from nlp_calib.errors import NlpCalibError, UsageError


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{message} (see '{self.prog} --help')")


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "scenario", type=Path, nargs="+", help="scenario YAML file(s); several are summarised side by side"
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder (default: out/<scenario name>; with several scenarios, DIR/<scenario name>)",
    )
    p.add_argument(
        "--data", type=Path, default=None, help="log file to use instead of the scenario's dataset"
    )
    p.add_argument(
        "--report",
        action="store_true",
        help="also draw trajectory, convergence, residual and model-check figures and report.md",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="nlp-calib",
        description="Calibrate a wheeled robot's kinematics and sensor mounting pose.",
    )
    parser.add_argument("--version", action="version", version=f"nlp_calib {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p_run = sub.add_parser("run", help="calibrate with the scenario's solvers (or --solver)")
    _add_common(p_run)
    p_run.add_argument("--solver", choices=("gauss_newton", "ipopt", "both"), default=None)

    p_cmp = sub.add_parser("compare", help="calibrate with Gauss-Newton and IPOPT side by side")
    _add_common(p_cmp)

    p_cg = sub.add_parser("codegen", help="write C source and header of the residual and its Jacobian")
    p_cg.add_argument("scenario", type=Path, help="scenario YAML file (model, horizon, integration)")
    p_cg.add_argument("--out", type=Path, required=True, help="folder for the C files")
    p_cg.add_argument(
        "--data", type=Path, default=None, help="log file to use instead of the scenario's dataset"
    )

    p_odo = sub.add_parser(
        "odometry", help="calibrate, then write the base-link odometry with its propagated covariance"
    )
    _add_common(p_odo)
    p_odo.add_argument("--solver", choices=("gauss_newton", "ipopt"), default="gauss_newton")
    p_odo.add_argument("--sigma", type=float, default=3.0, help="ellipse size in σ for --report (default 3)")

    p_sim = sub.add_parser("simulate", help="write a synthetic log with known truth (truth JSON beside it)")
    p_sim.add_argument("--out", type=Path, required=True, help="log file to write")
    p_sim.add_argument("--config", type=Path, default=None, help="YAML file of simulation options")
    p_sim.add_argument("--records", type=int, default=None)
    p_sim.add_argument("--seed", type=int, default=None)
    p_sim.add_argument("--model", default=None, help="tricycle (default) | diff_drive")
    p_sim.add_argument("--trajectory", default=None, help="s_curves | straight | no_reversals")
    p_sim.add_argument(
        "--noise-xy", type=float, default=None, dest="tracker_noise_xy", help="tracker noise, m"
    )
    p_sim.add_argument(
        "--noise-theta",
        type=float,
        default=None,
        dest="tracker_noise_theta",
        help="tracker noise, rad",
    )
    p_sim.add_argument(
        "--outliers", type=float, default=None, dest="outlier_fraction", help="fraction of outliers"
    )
    p_sim.add_argument("--latency", type=float, default=None, dest="latency_s", help="tracker latency, s")
    return parser


def _out_dir(args: argparse.Namespace, name: str) -> Path:
    from nlp_calib.io.files import prepare_output_dir

    if args.out is None:
        return prepare_output_dir(Path("out") / name)
    return prepare_output_dir(args.out / name if len(args.scenario) > 1 else args.out)


def _cmd_calibrate(args: argparse.Namespace, solvers: Sequence[str] | None) -> int:
    from nlp_calib.calibration import Calibration
    from nlp_calib.io.outdir import StagedOutput
    from nlp_calib.io.results import write_result
    from nlp_calib.io.scenario import load_scenario
    from nlp_calib.report.handoff import CALIBRATION_FILE, URDF_FILE, write_handoff
    from nlp_calib.report.progress import Progress
    from nlp_calib.report.terminal import correlation_table, run_table, summary_table

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
                    from nlp_calib.report.writer import write_report  # imports matplotlib

                    progress.update(i, f"{scenario.name}: drawing the report")
                    written += write_report(calib, run, stage.path)
                    progress.clear()
                stage.commit()
            print("\n" + "\n".join(f"wrote {stage.final(p)}" for p in written) + "\n")
    if len(runs) > 1:
        print(summary_table(runs))
    return 0 if all(r.result.converged for run in runs for r in run.reports.values()) else 1


def _cmd_run(args: argparse.Namespace) -> int:
    solvers: tuple[str, ...] | None = None
    if args.solver == "both":
        solvers = ("gauss_newton", "ipopt")
    elif args.solver is not None:
        solvers = (args.solver,)
    return _cmd_calibrate(args, solvers)


def _cmd_compare(args: argparse.Namespace) -> int:
    return _cmd_calibrate(args, ("gauss_newton", "ipopt"))


def _cmd_simulate(args: argparse.Namespace) -> int:
    from nlp_calib.io.files import prepare_output_dir
    from nlp_calib.io.simconfig import simulation_options
    from nlp_calib.simulate import simulate, write_simulation

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
    import numpy as np

    from nlp_calib.calibration import initial_parameters
    from nlp_calib.codegen import build_for_export, generate
    from nlp_calib.data import build_residual_data
    from nlp_calib.io.files import prepare_output_dir
    from nlp_calib.io.logfile import read_log
    from nlp_calib.io.scenario import load_scenario
    from nlp_calib.models import get_model

    scenario = load_scenario(args.scenario)
    if args.data is not None:
        scenario = scenario.with_dataset(args.data)
    out = prepare_output_dir(args.out)
    log = read_log(scenario.dataset, strict=scenario.strict)
    initial = initial_parameters(scenario, log)
    problems = build_for_export(
        get_model(scenario.model), scenario.residual.horizon, scenario.residual.integration
    )
    last = problems[-1]
    H = last.spec.horizon
    windows = build_residual_data(last, log, scenario.residual)
    # The example evaluates the window with the most motion: a standing robot's Jacobian is 0.
    busiest = int(np.argmax(np.abs(windows.columns[: last.n_inputs * H]).sum(axis=0)))
    params = [initial.get(n, 0.0) for n in last.names]
    origin = (
        f"scenario {scenario.name} (model {scenario.model}, horizon {H}, {scenario.residual.integration})"
    )
    for path in generate(problems, out, np.array(params), windows.columns[:, busiest], origin):
        print(f"wrote {path}")
    return 0


def _cmd_odometry(args: argparse.Namespace) -> int:
    import numpy as np

    from nlp_calib.analysis.odometry import OdometryTrack, propagate
    from nlp_calib.calibration import Calibration
    from nlp_calib.errors import SolverError
    from nlp_calib.io.files import atomic_write_bytes, atomic_write_text
    from nlp_calib.io.scenario import load_scenario

    if len(args.scenario) != 1:
        raise UsageError("odometry takes one scenario")
    scenario = load_scenario(args.scenario[0])
    out = _out_dir(args, scenario.name)
    calib = Calibration.setup(scenario, data=args.data)
    result = calib.solve(args.solver)
    if not result.converged:
        raise SolverError(f"{args.solver} did not converge ({result.reason}); no odometry from it")
    sel, fns = calib.selected, calib.fns
    inputs = calib.model.inputs(sel, scenario.residual.steering_sample)
    T_world_base_0 = np.asarray(fns.base_from_sensor(sel.T_world_sensor[0], result.params)).ravel()
    poses, cov = propagate(fns, result.params, inputs, T_world_base_0, calib.input_noise_std)
    track = OdometryTrack(time_s=sel.time_s, T_world_base=poses, covariance=cov)
    csv = out / "odometry.csv"
    atomic_write_text(csv, track.csv())
    print(f"{args.solver}: {result.param_dict()}")
    print(
        f"final 1σ: x {1e3 * np.sqrt(cov[-1, 0, 0]):.3g} mm, y {1e3 * np.sqrt(cov[-1, 1, 1]):.3g} mm, "
        f"θ {1e3 * np.sqrt(cov[-1, 2, 2]):.3g} mrad after {sel.n_records} records "
        f"(encoder noise per input: {', '.join(f'{v:.3g}' for v in calib.input_noise_std)})"
    )
    print(f"wrote {csv}")
    if args.report:
        from nlp_calib.report.plots import odometry_png

        reference = np.asarray(fns.base_from_sensor.map(sel.n_records)(sel.T_world_sensor.T, result.params)).T
        png = out / "odometry.png"
        title = f"{scenario.name}: calibrated odometry ({args.solver}), {args.sigma:g}σ ellipses"
        atomic_write_bytes(png, odometry_png(track, reference, title, sigma=args.sigma))
        print(f"wrote {png}")
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "odometry": _cmd_odometry,
    "run": _cmd_run,
    "compare": _cmd_compare,
    "codegen": _cmd_codegen,
    "simulate": _cmd_simulate,
}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    try:
        args = build_parser().parse_args(argv)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                return COMMANDS[args.command](args)
            finally:
                for w in caught:
                    print(f"warning: {w.message}", file=sys.stderr)
    except NlpCalibError as exc:
        if debug:
            traceback.print_exc()
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        sys.stderr.close()
        return 1
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # an unexpected failure is still reported in one line
        if debug:
            traceback.print_exc()
        print(
            f"error: internal error: {type(exc).__name__}: {exc} (run with --debug for the traceback)",
            file=sys.stderr,
        )
        return 1
