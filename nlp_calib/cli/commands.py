"""The subcommands, each imported when it runs: a command loads only what it needs (``simulate``
no solver, ``run`` no bag reader or worker pool). Each takes the parsed arguments, prints what the
user reads and returns an exit code.
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable

from nlp_calib.core import collector

Command = Callable[[argparse.Namespace], int]


def _on_demand(module: str, name: str) -> Command:
    """The command ``name`` of ``module``, imported at its first call."""

    def command(args: argparse.Namespace) -> int:
        try:
            run: Command = getattr(importlib.import_module(module), name)
        finally:
            collector.resume()  # what the command runs makes the garbage worth collecting
        return run(args)

    command.__name__ = command.__qualname__ = name
    return command


#: What each subcommand runs (a test may put its own function in a command's place).
COMMANDS: dict[str, Command] = {
    "validate": _on_demand("nlp_calib.cli.calibrate", "cmd_validate"),
    "odometry": _on_demand("nlp_calib.cli.calibrate", "cmd_odometry"),
    "run": _on_demand("nlp_calib.cli.calibrate", "cmd_run"),
    "compare": _on_demand("nlp_calib.cli.calibrate", "cmd_compare"),
    "codegen": _on_demand("nlp_calib.cli.codegen", "cmd_codegen"),
    "simulate": _on_demand("nlp_calib.cli.simulate", "cmd_simulate"),
    "import-bag": _on_demand("nlp_calib.cli.import_bag", "cmd_import_bag"),
    "check": _on_demand("nlp_calib.cli.check", "cmd_check"),
    "batch": _on_demand("nlp_calib.cli.fleet", "cmd_batch"),
    "preflight": _on_demand("nlp_calib.cli.preflight", "cmd_preflight"),
    "init": _on_demand("nlp_calib.cli.preflight", "cmd_init"),
}
