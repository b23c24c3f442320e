"""Signals that end a run (SIGINT, SIGTERM, SIGHUP) as an exception that unwinds cleanly.

Python's default SIGTERM and SIGHUP kill the process on the spot, which leaves no chance to
remove a staging folder. :func:`handled` turns each of these signals into :class:`Interrupted`,
raised where the program is, so ``with`` blocks and ``finally`` clauses run and the command line
exits with ``128 + signal number``. A SIGHUP the parent ignored (``nohup``) stays ignored.

Some native code catches the exception a signal raises and carries on: CasADi's IPOPT interface
checks for signals at every iteration, catches what the handler raises and returns normally
(with a return status such as ``NonIpopt_Exception_Thrown``). The signal is therefore also
recorded, and :func:`check` raises it again wherever a result is about to be used; once a signal
is recorded it decides the exit code (:func:`exit_code`), whatever error or success follows.
Inside :func:`deferred` (moving finished files into place) a signal is only recorded, and raised
when the block ends, so a set of files is never half replaced; after :func:`hold` (the last files
of a run are being moved into place) it is only recorded: the run has finished. A signal that
lands in a finalizer or a weakref callback, where Python can only print the exception, is sent
again.

The command line calls :func:`install` as its first instruction: from then on a signal ends the
process quietly even while the libraries load (before :func:`handled` runs, as ``SystemExit``).
A Python handler only runs between bytecodes, so native code that never returns (a BLAS
routine retrying an allocation forever under ``ulimit -v``) would make the process deaf to
signals: in the command line a watchdog thread, woken by the signal itself, ends the process
:data:`GRACE_S` seconds after a signal it did not act on (never while files are being moved).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from types import FrameType

#: The signals a run ends on; SIGHUP where the platform has it (the terminal was closed).
SIGNALS = tuple(s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s is not None)
#: Seconds the watchdog gives the program to end after a signal before it ends the process.
GRACE_S = 3.0

_pending: int | None = None
_defer_depth = 0
#: Which block of :func:`handled` is running, and whether a signal's exception was lost in a
#: finalizer since (see :func:`_unraisable`).
_generation = 0
_swallowed = False
#: How many blocks of :func:`handled` are open (0: the program is still starting).
_active = 0
#: The program has said that it reported the interruption (the watchdog then stays quiet).
_reported = False


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
        if _active == 0:  # the program is still starting: nothing to clean up, leave quietly
            raise SystemExit(128 + _pending)
        raise Interrupted(_pending)


def _unraisable(args: sys.UnraisableHookArgs) -> None:
    """A signal whose exception was raised inside a finalizer or a weakref callback (where Python
    can only print it) is sent again a moment later, to be raised where the program can unwind;
    unless :func:`check` raised it first, or the block of :func:`handled` has ended."""
    global _swallowed, _defer_depth
    if not isinstance(args.exc_value, (Interrupted, SystemExit)) or _pending is None:
        sys.__unraisablehook__(args)
        return
    _swallowed = True
    timer = threading.Timer(0.01, _redeliver, (_generation, _pending))
    timer.daemon = True
    # Starting the timer waits for its thread: a signal handled in that wait only records (the
    # timer sends it again). Raised there, it was lost with the timer (a loaded machine, once).
    _defer_depth += 1
    try:
        timer.start()
    finally:
        _defer_depth -= 1


def _redeliver(generation: int, signum: int) -> None:
    if generation == _generation and _swallowed:
        os.kill(os.getpid(), signum)


def _takes(s: int) -> bool:
    """Whether to handle signal ``s``: not a SIGHUP the parent ignored (``nohup``)."""
    return not (s == getattr(signal, "SIGHUP", None) and signal.getsignal(s) == signal.SIG_IGN)


def install() -> None:
    """The command line's first instruction: from now on a signal ends the process quietly, and
    the first one is remembered (a library that swallows it cannot turn it into success)."""
    if threading.current_thread() is not threading.main_thread():
        return
    sys.unraisablehook = _unraisable
    for s in SIGNALS:
        if _takes(s):
            signal.signal(s, _handler)


def pending() -> int | None:
    """The signal received since :func:`handled` began, if any."""
    return _pending


def exit_code() -> int | None:
    """``128 + signal`` when a signal arrived and the run had not reached :func:`hold`: the exit
    code the process must end with, whatever happened after the signal."""
    return None if _pending is None or _defer_depth > 0 else 128 + _pending


def reported() -> None:
    """The program has told the user that it was interrupted (see :func:`handled`'s watchdog)."""
    global _reported
    _reported = True


def was_reported() -> bool:
    """Whether :func:`reported` was called since :func:`handled` began."""
    return _reported


def check() -> None:
    """Raise :class:`Interrupted` if a signal arrived, even one that native code swallowed."""
    global _swallowed
    if _pending is not None:
        _swallowed = False
        raise Interrupted(_pending)


@contextlib.contextmanager
def handled(*, restore: bool = True, watchdog: bool = False) -> Iterator[None]:
    """Turn :data:`SIGNALS` into :class:`Interrupted` inside the block (main thread only; elsewhere
    the signal module cannot install handlers and the block runs unchanged).

    ``restore=False`` (a program about to exit) ignores further signals instead: a second Ctrl-C
    while the process exits (or while Python shuts down, which resets the handlers it installed
    but not ignored signals) cannot replace its exit code or print a traceback; a signal that
    arrived before the block (while the program started) stays recorded. ``watchdog`` (a
    program) ends the process :data:`GRACE_S` seconds after a signal it did not end on.
    """
    global _pending, _defer_depth, _generation, _swallowed, _active, _reported
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in SIGNALS if _takes(s)}
    previous_hook = sys.unraisablehook
    depth = _defer_depth
    if restore:
        _pending = None
    _swallowed = _reported = False
    _generation += 1
    wakeup = _Watchdog.start() if watchdog else None
    try:
        sys.unraisablehook = _unraisable
        _active += 1
        for s in previous:
            signal.signal(s, _handler)
        yield
    finally:
        _generation += 1  # no signal is sent again once the block has ended
        _active -= 1
        for s, old in previous.items():
            signal.signal(s, old if restore else signal.SIG_IGN)
        if restore:
            if wakeup is not None:
                wakeup.stop()
            sys.unraisablehook = previous_hook
            _pending, _defer_depth = None, depth


class _Watchdog:
    """Woken by every handled signal (``signal.set_wakeup_fd``, written by the C-level handler even
    while the main thread is stuck in native code); ends the process with the signal's exit code
    :data:`GRACE_S` seconds later, unless the run's last files are being moved into place."""

    def __init__(self, read_fd: int, write_fd: int, previous: int) -> None:
        self._read, self._write, self._previous = read_fd, write_fd, previous

    @classmethod
    def start(cls) -> _Watchdog | None:
        read_fd, write_fd = os.pipe()
        os.set_blocking(write_fd, False)
        try:
            previous = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        except (ValueError, OSError):  # not the main thread of the main interpreter
            os.close(read_fd)
            os.close(write_fd)
            return None
        dog = cls(read_fd, write_fd, previous)
        threading.Thread(target=dog._watch, name="nlp_calib-signals", daemon=True).start()
        return dog

    def stop(self) -> None:
        signal.set_wakeup_fd(self._previous)
        os.close(self._write)  # the watching thread reads the end of the pipe and returns

    def _watch(self) -> None:
        while True:
            try:
                data = os.read(self._read, 64)
            except OSError:
                return
            if not data:
                os.close(self._read)
                return
            taken = [s for s in data if s in SIGNALS]
            if taken:
                time.sleep(GRACE_S)
                if _defer_depth == 0:
                    _end(_pending or taken[0])


def _end(signum: int) -> None:
    """End the process now, from a thread other than the stuck main thread (no lock it may hold
    is taken: the message goes straight to file descriptor 2)."""
    if not _reported:
        name = signal.Signals(signum).name
        message = (
            f"error: interrupted ({name}); the run did not stop within {GRACE_S:g} s (busy in native "
            "code) and was ended; the files in progress were discarded\n"
        )
        with contextlib.suppress(OSError):
            os.write(2, message.encode("ascii", "replace"))
    os._exit(128 + signum)


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
