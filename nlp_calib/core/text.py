"""Text from inputs made safe to show or to write where a program reads it back.

A name from a recording (a frame id, a topic, a joint) or a file may hold characters that end a
line or a comment where it is written (``\\n``, ``\\r``, U+0085, U+2028: every one a line break to
YAML), move a terminal's cursor (ANSI escapes) or turn text around (bidirectional overrides).
:func:`escaped` spells each such character as Python does in a string literal, so a message stays
one line and a comment holds only text that cannot end it; :func:`unprintable` finds the first.
"""

from __future__ import annotations

import unicodedata

#: Characters that reorder the text around them on screen (Trojan-Source style).
_BIDI = frozenset("\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069\u200e\u200f\u061c")
#: Unicode categories of characters that are not text: controls, line and paragraph separators.
_NOT_TEXT = frozenset(("Cc", "Zl", "Zp", "Cs"))


def _bad(c: str) -> bool:
    # A tab is white space to YAML, XML, C comments and a terminal alike: text.
    return c != "\t" and (c in _BIDI or unicodedata.category(c) in _NOT_TEXT)


def unprintable(text: str) -> str | None:
    """The first character of ``text`` that is not printable text (a line break, a control, a
    bidirectional override), spelled as an escape (``\\n``, ``\\x1b``, ``\\u2028``); None if none."""
    return next((_spelled(c) for c in text if _bad(c)), None)


def _spelled(c: str) -> str:
    return repr(c)[1:-1] if c != "'" else c


def escaped(text: str, *, lines: bool = False) -> str:
    """``text`` with every character that is not printable text spelled as an escape; with
    ``lines``, line feeds are kept (a message of several lines of the tool's own)."""
    if not any(_bad(c) for c in text):
        return text
    return "".join(c if not _bad(c) or (lines and c == "\n") else _spelled(c) for c in text)


def numbered(word: str, first: int, last: int | None = None) -> str:
    """``line 5`` or ``lines 5-9``: where in its source a record came from, ``word`` what the source
    counts (a file's ``line``, a bag topic's ``/topic message``)."""
    if last is None or last == first:
        return f"{word} {first}"
    return f"{word}s {first}-{last}"
