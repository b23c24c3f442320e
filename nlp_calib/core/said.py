"""The warnings a stage raised, kept as text while they go on to whatever shows them.

A run's result holds every warning the run printed (result.json's ``warnings``), yet the stages warn
as they go (a log's reader of its gaps in time, of poses it normalised) and the command prints each
as it happens: :func:`kept` records what reaches the display without holding it back, so a stage
run before the result exists (a log read, its stages before the gate) hands its words to the run.
A warning the filters in force suppress is neither shown nor kept.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO


@contextmanager
def kept() -> Iterator[list[str]]:
    """The text of each warning shown inside, in order, each shown as it would have been."""
    texts: list[str] = []
    with warnings.catch_warnings():
        shown = warnings.showwarning

        def keep(
            message: Warning | str,
            category: type[Warning],
            filename: str,
            lineno: int,
            file: TextIO | None = None,
            line: str | None = None,
        ) -> None:
            texts.append(str(message))
            shown(message, category, filename, lineno, file, line)

        warnings.showwarning = keep
        yield texts


def each_once(*parts: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """``parts`` end to end, each text once, in the order first said."""
    return tuple(dict.fromkeys(text for part in parts for text in part))
