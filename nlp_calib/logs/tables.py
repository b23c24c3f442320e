"""Small numeric text tables (a TUM trajectory, a joint CSV): lines, numbers and time order, with
errors that name the file and the line."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.logs.reader import open_log

_BOM = "\ufeff"


def data_lines(path: str | Path) -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of every line that is neither blank nor a ``#`` comment."""
    p = Path(path)
    with open_log(p) as fh:
        raw = fh.read()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise DatasetError(str(p), line, "is not UTF-8 text; expected a text table") from None
    for number, content in enumerate(text.removeprefix(_BOM).splitlines(), start=1):
        stripped = content.strip()
        if stripped and not stripped.startswith("#"):
            yield number, stripped


def numbers(path: str, line: int, fields: Sequence[str], layout: str) -> list[float]:
    """The fields of one line as finite numbers; an error says which is not and the layout."""
    out = []
    for field in fields:
        try:
            value = float(field)
        except ValueError:
            raise DatasetError(path, line, f"{field!r} is not a number; expected {layout}") from None
        if not np.isfinite(value):
            raise DatasetError(
                path, line, f"holds a non-finite value ({field}); every value must be a finite number"
            )
        out.append(value)
    return out


def check_time_order(path: str, time_s: np.ndarray, line_numbers: np.ndarray) -> None:
    """Refuse timestamps that do not increase strictly, naming the first line out of order."""
    bad = np.flatnonzero(np.diff(time_s) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise DatasetError(
            path,
            int(line_numbers[k]),
            f"timestamp {time_s[k]:.9f} is not after the previous one ({time_s[k - 1]:.9f} on line "
            f"{int(line_numbers[k - 1])}); sort the file by time and remove duplicate stamps",
        )
