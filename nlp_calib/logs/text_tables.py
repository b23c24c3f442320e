"""Small numeric text tables (a CSV joint log, a TUM trajectory): their lines, stamps and numbers,
with errors that name the file and the line."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.core.files import SpecialFileError, open_regular
from nlp_calib.logs.records import _parse_time_ns

_BOM = "\ufeff"


def data_lines(path: str | Path) -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of every line that is neither blank nor a ``#`` comment."""
    p = Path(path)
    try:
        with open_regular(p) as fh:
            raw = fh.read()
    except SpecialFileError as exc:
        raise DatasetError(str(p), None, f"is {exc.kind}, not a regular file; pass the file itself") from None
    except FileNotFoundError:
        raise DatasetError(str(p), None, "no such file") from None
    except (OSError, ValueError) as exc:
        raise DatasetError(str(p), None, f"cannot read the file ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DatasetError(str(p), raw[: exc.start].count(b"\n") + 1, "is not UTF-8 text") from None
    for number, line in enumerate(text.removeprefix(_BOM).splitlines(), start=1):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            yield number, stripped


def stamp_ns(token: str, path: str, line: int) -> int:
    """A time in seconds (``1700000123.456789012``) as integer nanoseconds, exactly."""
    return _parse_time_ns(token.strip(), path, line)


def numbers(path: str, line: int, fields: Sequence[str], layout: str) -> list[float]:
    """The fields of one line as finite numbers; an error says which is not and the layout."""
    out = []
    for f in fields:
        try:
            value = float(f)
        except ValueError:
            raise DatasetError(path, line, f"{f.strip()[:40]!r} is not a number; expected {layout}") from None
        if not np.isfinite(value):
            raise DatasetError(
                path, line, f"holds a non-finite value ({f.strip()}); every value must be a finite number"
            )
        out.append(value)
    return out


def check_increasing(path: str, time_ns: np.ndarray, line_numbers: np.ndarray) -> None:
    """Refuse times that do not increase strictly, naming the first line out of order."""
    bad = np.flatnonzero(np.diff(time_ns) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise DatasetError(
            path,
            int(line_numbers[k]),
            f"timestamp {seconds(int(time_ns[k]))} is not after the previous one "
            f"({seconds(int(time_ns[k - 1]))} on line {int(line_numbers[k - 1])}); sort the file by "
            "time and remove repeated times",
        )


def seconds(ns: int) -> str:
    """Integer nanoseconds as seconds, to the nanosecond."""
    sign = "-" if ns < 0 else ""
    return f"{sign}{abs(ns) // 10**9}.{abs(ns) % 10**9:09d}"
