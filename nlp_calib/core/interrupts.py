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
run are being moved into place) it is only recorded: the run has finished. A signal that lands in
a finalizer or a weakref callback, where Python can only print the exception, is sent again.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator
from types import FrameType

#: The signals a run ends on; SIGHUP where the platform has it (the terminal was closed).
SIGNALS = tuple(s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s is not None)

_pending: int | None = None
_defer_depth = 0
#: Which block of :func:`handled` is running, and whether a signal's exception was lost in a
#: finalizer since (see :func:`_unraisable`).
_generation = 0
_swallowed = False


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


def _unraisable(args: sys.UnraisableHookArgs) -> None:
    """A signal whose exception was raised inside a finalizer or a weakref callback (where Python
    can only print it) is sent again a moment later, to be raised where the program can unwind;
    unless :func:`check` raised it first, or the block of :func:`handled` has ended."""
    global _swallowed
    if not isinstance(args.exc_value, Interrupted):
        sys.__unraisablehook__(args)
        return
    _swallowed = True
    timer = threading.Timer(0.01, _redeliver, (_generation, args.exc_value.signum))
    timer.daemon = True
    timer.start()


def _redeliver(generation: int, signum: int) -> None:
    if generation == _generation and _swallowed:
        os.kill(os.getpid(), signum)


def pending() -> int | None:
    """The signal received since :func:`handled` began, if any."""
    return _pending


def check() -> None:
    """Raise :class:`Interrupted` if a signal arrived, even one that native code swallowed."""
    global _swallowed
    if _pending is not None:
        _swallowed = False
        raise Interrupted(_pending)


@contextlib.contextmanager
def handled(*, restore: bool = True) -> Iterator[None]:
    """Turn :data:`SIGNALS` into :class:`Interrupted` inside the block (main thread only; elsewhere
    the signal module cannot install handlers and the block runs unchanged).

    ``restore=False`` (a program about to exit) ignores further signals instead: a second Ctrl-C
    while the process exits (or while Python shuts down, which resets the handlers it installed
    but not ignored signals) cannot replace its exit code or print a traceback.
    """
    global _pending, _defer_depth, _generation, _swallowed
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in SIGNALS}
    previous_hook = sys.unraisablehook
    depth = _defer_depth
    _pending, _swallowed = None, False
    _generation += 1
    try:
        sys.unraisablehook = _unraisable
        for s in SIGNALS:
            signal.signal(s, _handler)
        yield
    finally:
        _generation += 1  # no signal is sent again once the block has ended
        for s, old in previous.items():
            signal.signal(s, old if restore else signal.SIG_IGN)
        if restore:
            sys.unraisablehook = previous_hook
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
