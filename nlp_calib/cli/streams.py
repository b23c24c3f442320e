"""Terminal output that can never stop the work: stdout and stderr wrapped while a command runs.

A command prints its tables before it writes its files. A reader that closes the pipe early
(``nlp-calib compare ... | head -3``) or a terminal whose encoding cannot show ``σ`` or ``×``
(``PYTHONIOENCODING=ascii``, ``LC_ALL=C``) would otherwise end the run with an exception and
lose a calibration that succeeded. Through :func:`guarded`, text the stream cannot encode is
spelled in plain characters (``σ`` → ``sigma``) or replaced by ``?``, and output to a closed pipe
is dropped (the descriptor is pointed at the null device, so nothing fails later either, not
even the flush at exit); the command then runs to its end and :func:`guarded` returns a one-line
note of what was degraded, for stderr.
"""

from __future__ import annotations

import codecs
import contextlib
import errno
import os
import sys
import unicodedata
from collections.abc import Iterator
from typing import Any, TextIO

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
    """A text stream whose writes never raise for an encoding or a closed pipe (see the module)."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream
        self.closed_early = False
        self.degraded = False

    def write(self, text: str) -> int:
        if self.closed_early:
            return len(text)
        try:
            return self._stream.write(text)
        except UnicodeEncodeError:
            self.degraded = True
            encoding = getattr(self._stream, "encoding", None) or "ascii"
            plain = text.encode(encoding, _ERRORS).decode(encoding, "replace")
            return self._attempt(lambda: self._stream.write(plain), len(text))
        except OSError as exc:
            return self._closed(exc, len(text))

    def flush(self) -> None:
        if not self.closed_early:
            self._attempt(self._stream.flush, 0)

    def _attempt(self, action: Any, size: int) -> int:
        try:
            action()
        except OSError as exc:
            return self._closed(exc, size)
        return size

    def _closed(self, exc: OSError, size: int) -> int:
        """The reader went away: drop this and all later output (any other error is raised)."""
        if exc.errno not in (errno.EPIPE, errno.EINVAL, errno.ECONNRESET):
            raise exc
        self.closed_early = True
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
    out, err = (_Guarded(s) if s is not None else None for s in originals)
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


def _notes(out: _Guarded | None, err: _Guarded | None) -> list[str]:
    notes = []
    if out is not None and out.closed_early:
        notes.append(
            "note: stdout was closed before the command finished (a pipe into head?); the rest of "
            "its terminal output was dropped"
        )
    if any(s is not None and s.degraded for s in (out, err)):
        notes.append(
            "note: the terminal's encoding cannot show some characters (sigma, times); they are "
            "spelled in plain text (set a UTF-8 locale, e.g. LC_ALL=C.UTF-8, to see them)"
        )
    return notes
