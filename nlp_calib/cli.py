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

    p_sim = sub.add_parser("simulate", help="write a synthetic log with known truth (truth JSON beside it)")
    p_sim.add_argument("--out", type=Path, required=True, help="log file to write")
    p_sim.add_argument("--config", type=Path, default=None, help="YAML file of simulation options")
    p_sim.add_argument("--records", type=int, default=None)
    p_sim.add_argument("--seed", type=int, default=None)
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


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "run": _cmd_run,
    "compare": _cmd_compare,
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
