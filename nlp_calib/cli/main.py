"""The ``nlp-calib`` entry point: runs a command, prints warnings as they happen, maps errors to exit codes.

Errors the user can fix print one line ``error: ...`` on stderr and exit with 2 (bad input) or
1 (runtime failure); ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import errno
import sys
import traceback
import warnings
from collections.abc import Sequence
from typing import TextIO

from nlp_calib.cli.commands import COMMANDS
from nlp_calib.cli.parser import build_parser
from nlp_calib.core import interrupts
from nlp_calib.core.errors import NlpCalibError
from nlp_calib.core.files import forget_inputs


def _show_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: TextIO | None = None,
    line: str | None = None,
) -> None:
    """Print a warning at once, as one line (clearing a progress line on a terminal first)."""
    stream = sys.stderr
    clear = "\r\x1b[K" if getattr(stream, "isatty", lambda: False)() else ""
    print(f"{clear}warning: {message}", file=stream)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    args_in = list(sys.argv[1:] if argv is None else argv)
    # Called as a program (no argv): the handlers stay to the end, so a late signal cannot
    # replace the exit code.
    with interrupts.handled(restore=argv is not None):
        try:
            return _run(args_in)
        except interrupts.Interrupted as exc:  # another signal while the first was reported
            return exc.exit_code


def _run(argv: list[str]) -> int:
    debug = "--debug" in argv
    forget_inputs()  # each command protects its own inputs from its outputs
    try:
        args = build_parser().parse_args(argv)
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = _show_warning
            return COMMANDS[args.command](args)
    except NlpCalibError as exc:
        if debug:
            traceback.print_exc()
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        sys.stderr.close()
        return 1
    except interrupts.Interrupted as exc:
        print(f"error: interrupted ({exc.name}); the files in progress were discarded", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("error: interrupted; the files in progress were discarded", file=sys.stderr)
        return 130
    except OSError as exc:  # the system refused: a full disk, a permission, a vanished folder
        if debug:
            traceback.print_exc()
        where = f"{exc.filename}: " if exc.filename else ""
        hint = "; free some space and run again" if exc.errno == errno.ENOSPC else ""
        print(f"error: {where}{exc.strerror or exc}{hint}", file=sys.stderr)
        return 1
    except MemoryError:
        print("error: out of memory; select fewer records or a shorter horizon", file=sys.stderr)
        return 1
    except Exception as exc:  # an unexpected failure is still reported in one line
        if debug:
            traceback.print_exc()
        print(
            f"error: internal error: {type(exc).__name__}: {exc} (run with --debug for the traceback)",
            file=sys.stderr,
        )
        return 1
