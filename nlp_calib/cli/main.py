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

from nlp_calib.cli import streams
from nlp_calib.cli.commands import COMMANDS
from nlp_calib.core import interrupts, memory
from nlp_calib.core.errors import NlpCalibError, shown_path
from nlp_calib.core.files import forget_inputs
from nlp_calib.core.text import escaped

#: The warnings this command has printed.
_SHOWN: set[str] = set()


def _show_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: TextIO | None = None,
    line: str | None = None,
) -> None:
    """Print a warning at once, as one line (clearing a progress line on a terminal first); a
    warning the command printed already is not printed again (a file read twice, by a draft and by
    its check, says what it says of itself once)."""
    text = str(message)
    if text in _SHOWN:
        return
    _SHOWN.add(text)
    stream = sys.stderr
    clear = "\r\x1b[K" if getattr(stream, "isatty", lambda: False)() else ""
    print(f"{clear}warning: {escaped(text, lines=True)}", file=stream)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    args_in = list(sys.argv[1:] if argv is None else argv)
    program = argv is None
    # Called as a program (no argv): the handlers stay to the end, so a late signal cannot
    # replace the exit code, and a watchdog ends a process that native code keeps from stopping.
    with interrupts.handled(restore=not program, watchdog=program), streams.guarded():
        try:
            code = _run(args_in)
        except interrupts.Interrupted as exc:  # another signal while the first was reported
            return exc.exit_code
        # A signal some library swallowed before the run's last files were complete decides.
        late = interrupts.exit_code()
        if late is None:
            return code
        return late if interrupts.was_reported() else _report(interrupts.Interrupted(late - 128), False)


def _run(argv: list[str]) -> int:
    debug = "--debug" in argv
    forget_inputs()  # each command protects its own inputs from its outputs
    try:
        interrupts.check()  # a signal while the program started
        # The grammar names every model, solver and option range: loaded only to parse.
        from nlp_calib.cli.parser import build_parser, named_command

        args = build_parser(named_command(argv)).parse_args(argv)
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            # A library's own warnings (numpy's floating point, say) once each, not once per call.
            warnings.simplefilter("default", RuntimeWarning)
            # A file an interrupted import left open is Python's business, not the user's.
            warnings.simplefilter("ignore", ResourceWarning)
            warnings.showwarning = _show_warning
            _SHOWN.clear()
            return COMMANDS[args.command](args)
    except BaseException as exc:
        if isinstance(exc, SystemExit):  # argparse: --help, --version, a usage error
            raise
        return _report(exc, debug)


def _report(exc: BaseException, debug: bool) -> int:
    """Print one line for what ended the command; its exit code."""
    signum = interrupts.pending()
    if signum is not None and interrupts.exit_code() is not None:
        # Whatever ended the run after a signal (an error CasADi made of the exception the
        # signal raised in a callback, say) is the signal's doing.
        exc = exc if isinstance(exc, interrupts.Interrupted) else interrupts.Interrupted(signum)
    if isinstance(exc, interrupts.Interrupted):
        print(f"error: interrupted ({exc.name}); the files in progress were discarded", file=sys.stderr)
        interrupts.reported()
        return exc.exit_code
    if isinstance(exc, KeyboardInterrupt):
        print("error: interrupted; the files in progress were discarded", file=sys.stderr)
        return 130
    if debug:
        traceback.print_exception(exc)
    if isinstance(exc, NlpCalibError):
        print(f"error: {escaped(str(exc), lines=True)}", file=sys.stderr)
        return exc.exit_code
    if isinstance(exc, OSError):  # the system refused: a full disk, a permission, a vanished folder
        where = f"{shown_path(exc.filename)}: " if exc.filename else ""
        hint = {
            errno.ENOSPC: "; free some space and run again",
            errno.ENAMETOOLONG: "; a name in this path is longer than the file system allows: shorten it",
        }.get(exc.errno or 0, "")
        print(f"error: {escaped(f'{where}{exc.strerror or exc}{hint}')}", file=sys.stderr)
        return 1
    if isinstance(exc, MemoryError) or (isinstance(exc, RuntimeError) and "std::bad_alloc" in str(exc)):
        print(f"error: {memory.OUT_OF_MEMORY}", file=sys.stderr)
        return 1
    if isinstance(exc, RuntimeError) and "can't start new thread" in str(exc):
        print(f"error: {memory.NO_THREAD}", file=sys.stderr)
        return 1
    if not isinstance(exc, Exception):
        raise exc
    # An unexpected failure is still reported in one line.
    print(
        f"error: internal error: {type(exc).__name__}: {escaped(str(exc))} "
        "(run with --debug for the traceback)",
        file=sys.stderr,
    )
    return 1
