"""Terminal output that can never stop the work: stdout and stderr wrapped while a command runs.

A command prints its tables before it writes its files. A reader that closes the pipe early
(``nlp-calib compare ... | head -3``) or a terminal whose encoding cannot show ``σ`` or ``×``
(``PYTHONIOENCODING=ascii``, ``LC_ALL=C``) would otherwise end the run with an exception and
lose a calibration that succeeded. Through :func:`guarded`, text the stream cannot encode is
spelled in plain characters (``σ`` → ``sigma``) or replaced by ``?``, and output to a closed pipe
(or output the system refuses, e.g. a file on a full disk) is dropped; its descriptor is then
pointed at the null device, so nothing fails later either, not even the flush at exit. The
command runs to its end, and one line on stderr says what the terminal did not get. Once a
signal has arrived, CasADi's warnings (which echo it from inside the solver) are not shown: the
run's one line says it was interrupted.
"""

from __future__ import annotations

import codecs
import contextlib
import errno
import os
import sys
import unicodedata
from collections.abc import Callable, Iterator
from typing import Any, TextIO

from nlp_calib.core import interrupts
from nlp_calib.core.text import escaped

#: Plain spellings of the characters the tool prints, for a stream that cannot encode them.
SPELLINGS = {
    "σ": "sigma",
    "δ": "delta",
    "θ": "theta",
    "Ω": "Omega",
    "λ": "lambda",
    "μ": "u",
    "µ": "u",
    "±": "+/-",
    "×": "x",
    "·": "*",
    "²": "^2",
    "³": "^3",
    "√": "sqrt",
    "°": " deg",
    "≤": "<=",
    "≥": ">=",
    "≈": "~",
    "≠": "!=",
    "→": "->",
    "←": "<-",
    "…": "...",
    "—": "--",
    "–": "-",
    "‘": "'",
    "’": "'",
    "“": '"',
    "”": '"',
    "⊞": "[+]",
    "ᵀ": "^T",
    "⁻": "^-",
    "¹": "^1",
}
_ERRORS = "nlp_calib.spell"


def _spell(exc: UnicodeError) -> tuple[str, int]:
    """Codec error handler: each character the codec cannot encode, spelled in plain text."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    out = []
    for ch in exc.object[exc.start : exc.end]:
        plain = SPELLINGS.get(ch)
        if plain is None:
            base = unicodedata.normalize("NFKD", ch).encode("ascii", "ignore").decode()
            plain = base or "?"
        out.append(plain)
    return "".join(out), exc.end


codecs.register_error(_ERRORS, _spell)


class _Guarded:
    """A text stream whose writes never raise for an encoding or a closed pipe (see the module);
    a line whose first piece ``drop`` holds for is not written (pieces to its end included)."""

    def __init__(
        self, stream: TextIO, drop: Callable[[str], bool] | None = None, *, escape: bool = False
    ) -> None:
        self._stream = stream
        self._drop = drop
        #: Spell every character that is not text as an escape (a name from an input in a table
        #: cannot move the cursor or end a line): the one place stdout's text passes.
        self._escape = escape
        self._dropping = False
        #: Why output stopped (None: it did not): the reader went away, or the system refused.
        self.lost: OSError | None = None
        self.degraded = False

    def write(self, text: str) -> int:
        if self._drop is not None:
            self._dropping = self._dropping or self._drop(text)
            if self._dropping:
                _, newline, rest = text.partition("\n")
                self._dropping = not newline
                return len(text) - len(rest) + (self.write(rest) if rest else 0)
        if self.lost is not None:
            return len(text)
        size, text = len(text), escaped(text, lines=True) if self._escape else text
        try:
            self._stream.write(text)
            return size
        except UnicodeEncodeError:
            self.degraded = True
            encoding = getattr(self._stream, "encoding", None) or "ascii"
            plain = text.encode(encoding, _ERRORS).decode(encoding, "replace")
            return self._attempt(lambda: self._stream.write(plain), size)
        except OSError as exc:
            return self._closed(exc, size)

    def flush(self) -> None:
        if self.lost is None:
            self._attempt(self._stream.flush, 0)

    def _attempt(self, action: Any, size: int) -> int:
        try:
            action()
        except OSError as exc:
            return self._closed(exc, size)
        return size

    def _closed(self, exc: OSError, size: int) -> int:
        """The reader went away, or the system refused the text (a full disk): drop this and all
        later output; the work goes on."""
        self.lost = exc
        with contextlib.suppress(OSError, ValueError, AttributeError):
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._stream.fileno())  # the unflushed rest, flushed at exit, goes nowhere
            os.close(null)
        return size

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


@contextlib.contextmanager
def guarded() -> Iterator[None]:
    """Guard ``sys.stdout`` and ``sys.stderr`` inside the block; when it ends, one line on stderr
    for each way the terminal text was degraded (nothing when nothing was lost)."""
    originals = sys.stdout, sys.stderr
    out = _Guarded(originals[0], escape=True) if originals[0] is not None else None
    err = _Guarded(originals[1], _echo_of_a_signal) if originals[1] is not None else None
    sys.stdout, sys.stderr = out, err
    try:
        yield
    finally:
        try:
            if out is not None:
                out.flush()
            if err is not None:
                for note in _notes(out, err):
                    err.write(note + "\n")
                err.flush()
        finally:
            sys.stdout, sys.stderr = originals


def _echo_of_a_signal(text: str) -> bool:
    """CasADi's warnings once a signal arrived: the exception the signal raised in its callbacks,
    or the NaN they answer from then on, not news to the user."""
    return interrupts.pending() is not None and text.startswith("CasADi - ")


def _notes(out: _Guarded | None, err: _Guarded | None) -> list[str]:
    notes = []
    if out is not None and out.lost is not None:
        closed = out.lost.errno in (errno.EPIPE, errno.EINVAL, errno.ECONNRESET)
        why = "was closed (a pipe into head?)" if closed else f"failed ({out.lost.strerror or out.lost})"
        notes.append(f"note: stdout {why} before the command finished; the rest of its output was dropped")
    if any(s is not None and s.degraded for s in (out, err)):
        notes.append(
            "note: the terminal's encoding cannot show some characters (sigma, times); they are "
            "spelled in plain text (set a UTF-8 locale, e.g. LC_ALL=C.UTF-8, to see them)"
        )
    return notes
