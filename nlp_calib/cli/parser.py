"""The command line's grammar: subcommands, options and their help."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from nlp_calib.core.errors import UsageError
from nlp_calib.core.ranges import Range
from nlp_calib.core.version import __version__
from nlp_calib.models import MODELS
from nlp_calib.pipeline.scenario import BLOCKS
from nlp_calib.pipeline.simconfig import CLI_LIMITS
from nlp_calib.simulation import TRAJECTORIES
from nlp_calib.solvers import SOLVERS

#: ``--solver`` values that mean every registered solver.
ALL_SOLVERS = ("all", "both")


#: ``odometry --sigma``: the size of the drawn covariance ellipses, in standard deviations.
SIGMA = Range(0.0, 10.0, lo_open=True)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{message} (see '{self.prog} --help')")

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        parsed, extra = super().parse_known_args(args, namespace)
        # argparse drops a value "--" ("--records=--") and stores an empty list without calling
        # the option's type: no value at all.
        for action in self._actions:
            if action.nargs is None and action.option_strings and getattr(parsed, action.dest, None) == []:
                limit = getattr(action.type, "limit", None)
                expected = f"must be {limit.describe()}" if limit is not None else "expected a value"
                self.error(f"argument {'/'.join(action.option_strings)}: {expected}, got none")
        return parsed, extra


def _path(text: str) -> Path:
    """A path option: not empty (``--out ""`` would mean the current folder), no NUL."""
    if not text or "\0" in text:
        raise argparse.ArgumentTypeError(f"expected a path, got {text!r}")
    return Path(text)


def _in(limit: Range) -> Callable[[str], int | float]:
    """An option type that accepts numbers in ``limit`` and names the range otherwise."""

    def parse(text: str) -> int | float:
        try:
            return limit.parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parse.__name__ = "number"
    parse.limit = limit  # type: ignore[attr-defined]
    return parse


def _add_force(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--force", action="store_true", help=f"overwrite {what} that nlp_calib did not write")


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "scenario", type=Path, nargs="+", help="scenario YAML file(s); several are summarised side by side"
    )
    p.add_argument(
        "--out",
        type=_path,
        default=None,
        help="output folder (default: out/<scenario name>; with several scenarios, DIR/<scenario name>)",
    )
    p.add_argument(
        "--data", type=_path, default=None, help="log file to use instead of the scenario's dataset"
    )
    p.add_argument(
        "--report",
        action="store_true",
        help="also draw trajectory, convergence, residual and model-check figures and report.md",
    )
    _add_force(p, "files in the output folder")


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
        "--blocks",
        type=_in(BLOCKS),
        default=None,
        help="contiguous blocks (default: validation.blocks, else 10)",
    )

    p_cg = sub.add_parser("codegen", help="write C source and header of the residual and its Jacobian")
    p_cg.add_argument("scenario", type=Path, help="scenario YAML file (model, horizon, integration)")
    p_cg.add_argument("--out", type=_path, required=True, help="folder for the C files")
    p_cg.add_argument(
        "--data", type=_path, default=None, help="log file to use instead of the scenario's dataset"
    )
    _add_force(p_cg, "files in the output folder")

    p_odo = sub.add_parser(
        "odometry", help="calibrate, then write the base-link odometry with its propagated covariance"
    )
    _add_common(p_odo)
    p_odo.add_argument("--solver", choices=tuple(SOLVERS), default=next(iter(SOLVERS)))
    p_odo.add_argument(
        "--sigma",
        type=_in(SIGMA),
        default=3.0,
        help=f"ellipse size in σ for --report, {SIGMA.describe()} (default 3)",
    )

    p_sim = sub.add_parser("simulate", help="write a synthetic log with known truth (truth JSON beside it)")
    p_sim.add_argument("--out", type=_path, required=True, help="log file to write")
    _add_force(p_sim, "an existing log or truth file")
    p_sim.add_argument("--config", type=_path, default=None, help="YAML file of simulation options")
    p_sim.add_argument("--model", choices=tuple(MODELS), default=None, help=f"default: {next(iter(MODELS))}")
    p_sim.add_argument("--trajectory", choices=TRAJECTORIES, default=None)
    for flag, field, what in (
        ("--records", "records", "records to write"),
        ("--seed", "seed", "random seed"),
        ("--noise-xy", "tracker_noise_xy", "tracker noise, m"),
        ("--noise-theta", "tracker_noise_theta", "tracker noise, rad"),
        ("--outliers", "outlier_fraction", "fraction of outliers"),
        ("--latency", "latency_s", "tracker latency, s"),
    ):
        limit = CLI_LIMITS[field]
        p_sim.add_argument(
            flag, type=_in(limit), default=None, dest=field, help=f"{what}: {limit.describe()}"
        )
    return parser
