"""The command line's grammar: subcommands, options and their help."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import NoReturn

from nlp_calib.core.errors import UsageError
from nlp_calib.core.version import __version__
from nlp_calib.models import MODELS
from nlp_calib.simulation import TRAJECTORIES
from nlp_calib.solvers import SOLVERS

#: ``--solver`` values that mean every registered solver.
ALL_SOLVERS = ("all", "both")


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
    p_run.add_argument(
        "--solver",
        choices=(*SOLVERS, *ALL_SOLVERS),
        default=None,
        help="solver to run (default: the scenario's solvers; 'all' or 'both': every solver)",
    )

    p_cmp = sub.add_parser("compare", help="calibrate with every solver, side by side")
    _add_common(p_cmp)

    p_val = sub.add_parser(
        "validate",
        help="cross-validate on contiguous blocks: fit without each block, score it, compare the σ",
    )
    _add_common(p_val)
    p_val.add_argument(
        "--blocks", type=int, default=None, help="contiguous blocks (default: validation.blocks, else 10)"
    )

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
    p_odo.add_argument("--solver", choices=tuple(SOLVERS), default=next(iter(SOLVERS)))
    p_odo.add_argument("--sigma", type=float, default=3.0, help="ellipse size in σ for --report (default 3)")

    p_sim = sub.add_parser("simulate", help="write a synthetic log with known truth (truth JSON beside it)")
    p_sim.add_argument("--out", type=Path, required=True, help="log file to write")
    p_sim.add_argument("--config", type=Path, default=None, help="YAML file of simulation options")
    p_sim.add_argument("--records", type=int, default=None)
    p_sim.add_argument("--seed", type=int, default=None)
    p_sim.add_argument("--model", default=None, help=f"{' | '.join(MODELS)} (default: {next(iter(MODELS))})")
    p_sim.add_argument("--trajectory", default=None, help=" | ".join(TRAJECTORIES))
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
