"""Signals that end a run (SIGINT, SIGTERM, SIGHUP) as an exception that unwinds cleanly.

Python's default SIGTERM and SIGHUP kill the process on the spot, which leaves no chance to
remove a staging folder. :func:`handled` turns each of these signals into :class:`Interrupted`,
raised where the program is, so ``with`` blocks and ``finally`` clauses run and the command line
exits with ``128 + signal number``.

Some native code catches the exception a signal raises and carries on: CasADi's IPOPT interface
checks for signals at every iteration, catches what the handler raises and returns normally
(with a return status such as ``NonIpopt_Exception_Thrown``). The signal is therefore also
recorded, and :func:`check` raises it again wherever a result is about to be used. Inside
:func:`deferred` (moving finished files into place) a signal is only recorded, and raised when
the block ends, so a set of files is never half replaced; after :func:`hold` (the last files of a
run are being moved into place) it is only recorded: the run has finished.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

#: The signals a run ends on; SIGHUP where the platform has it (the terminal was closed).
SIGNALS = tuple(s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s is not None)

_pending: int | None = None
_defer_depth = 0


class Interrupted(KeyboardInterrupt):
    """A run ended by signal ``signum``; the process should exit with :attr:`exit_code`."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


def _handler(signum: int, frame: FrameType | None) -> None:
    global _pending
    if _pending is None:
        _pending = signum
    if _defer_depth == 0:
        raise Interrupted(_pending)


def pending() -> int | None:
    """The signal received since :func:`handled` began, if any."""
    return _pending


def check() -> None:
    """Raise :class:`Interrupted` if a signal arrived, even one that native code swallowed."""
    if _pending is not None:
        raise Interrupted(_pending)


@contextlib.contextmanager
def handled(*, restore: bool = True) -> Iterator[None]:
    """Turn :data:`SIGNALS` into :class:`Interrupted` inside the block (main thread only; elsewhere
    the signal module cannot install handlers and the block runs unchanged).

    ``restore=False`` (a program about to exit) ignores further signals instead: a second Ctrl-C
    while the process exits (or while Python shuts down, which resets the handlers it installed
    but not ignored signals) cannot replace its exit code or print a traceback.
    """
    global _pending, _defer_depth
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in SIGNALS}
    depth = _defer_depth
    _pending = None
    try:
        for s in SIGNALS:
            signal.signal(s, _handler)
        yield
    finally:
        for s, old in previous.items():
            signal.signal(s, old if restore else signal.SIG_IGN)
        if restore:
            _pending, _defer_depth = None, depth


def hold() -> None:
    """Only record signals from now to the end of :func:`handled`: the run's last files are about
    to be moved into place, and a run whose files are all in place has finished. A signal that
    came before is still raised by the next :func:`check`."""
    global _defer_depth
    _defer_depth += 1


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold signals back inside the block; one that arrived is raised when the block ends."""
    global _defer_depth
    _defer_depth += 1
    try:
        yield
    finally:
        _defer_depth -= 1
        if _defer_depth == 0:
            check()  # the interrupt wins over an error raised inside the block
