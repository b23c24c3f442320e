"""Progress of long jobs (many scenarios, benchmarks) on a terminal; silent otherwise.

The reporter writes one status line to the stream it is given, only when that stream is a
terminal, so piped or logged output stays clean. Callers clear the line before printing.
"""

from __future__ import annotations

import time
from types import TracebackType
from typing import TextIO


def _is_tty(stream: TextIO) -> bool:
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty()) if callable(isatty) else False
    except (OSError, ValueError):  # closed or detached streams
        return False


class Progress:
    """``[k/total] label: what (elapsed)`` on one rewritten line of a terminal ``stream``."""

    def __init__(self, total: int, stream: TextIO, label: str = "") -> None:
        self.total = total
        self.stream = stream
        self.label = label
        self.enabled = _is_tty(stream)
        self._t0 = time.perf_counter()
        self._shown = False

    def update(self, done: int, what: str = "") -> None:
        """Show that ``done`` of ``total`` steps are finished and what is running now."""
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self._t0
        head = f"[{done}/{self.total}]" + (f" {self.label}" if self.label else "")
        text = f"{head}: {what}" if what else head
        # \r and erase-line rewrite the status in place; nothing scrolls.
        self.stream.write(f"\r\x1b[K{text} ({elapsed:.1f} s)")
        self.stream.flush()
        self._shown = True

    def clear(self) -> None:
        """Erase the status line so ordinary output starts on a clean line."""
        if self.enabled and self._shown:
            self.stream.write("\r\x1b[K")
            self.stream.flush()
            self._shown = False

    def __enter__(self) -> Progress:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.clear()
