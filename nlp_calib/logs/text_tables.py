"""Numeric text tables (a CSV joint log, a TUM trajectory): their lines, stamps and numbers, read
as arrays, with errors that name the file and the line.

A table is read a block of whole lines at a time (as the text log is, :mod:`nlp_calib.logs.reader`)
and each block parsed with array operations: the lines and their tokens from the bytes' separators,
the time of each line to the nanosecond (:mod:`nlp_calib.logs.records`), the other numbers by
Python's ``float``. A line that is not a plain row (a comment, a blank, another number of fields,
a value that is not a finite number, a character outside printable ASCII) goes to the per-line
reader, which skips it or says exactly what is wrong with it. Memory follows the rows kept: a
``keep`` test drops rows (by time) as each block is read, so a long joint log of which a few
seconds pair with a short trajectory costs those seconds.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.core.files import SpecialFileError, open_regular
from nlp_calib.logs.reader import _blocks, _chunks
from nlp_calib.logs.records import (
    _NOT_A_TIME,
    MAX_SECONDS,
    _counts,
    _floats,
    _parse_time_ns,
    _times_ns,
    _tokenise,
)

#: Rows of a time range: the rows to keep of a block, from their times (ns).
Keep = Callable[[np.ndarray], np.ndarray]
#: Bytes of a table read at a time (a block's tokens are Python objects: small blocks, small peaks).
TABLE_BLOCK_BYTES = 1 << 20
#: Times parsed at once (their digits take rows × 20 int64 at a time).
TIME_BATCH = 1 << 14


@dataclass(frozen=True)
class Table:
    """The rows of a table: times (ns), values ``(n, width)`` and line numbers, of the rows kept;
    the header line (its number and text) when the table has one; how many rows the file holds and
    the times of its first and last."""

    time_ns: np.ndarray
    values: np.ndarray
    line_numbers: np.ndarray
    header: tuple[int, str] | None
    rows: int
    first_ns: int
    last_ns: int


@dataclass(frozen=True)
class Layout:
    """What a row is: ``width`` numbers after its time, separated by ``sep`` (``None``: any
    whitespace), described as ``words`` in messages; ``header``: the first row names the columns."""

    width: int
    sep: bytes | None
    words: str
    header: bool = False
    #: What a line with another number of fields is told (``{n}``: its number).
    miscount: str = "has {n} fields; expected {words}"

    def fields(self, text: str) -> list[str]:
        return text.split(self.sep.decode()) if self.sep is not None else text.split()


def _open(p: Path) -> Iterator[tuple[int, bytes, dict[int, int]]]:
    try:
        fh = open_regular(p)
    except SpecialFileError as exc:
        raise DatasetError(str(p), None, f"is {exc.kind}, not a regular file; pass the file itself") from None
    except FileNotFoundError:
        raise DatasetError(str(p), None, "no such file") from None
    except IsADirectoryError:
        raise DatasetError(str(p), None, "is a folder, not a regular file; pass the file itself") from None
    except (OSError, ValueError) as exc:
        raise DatasetError(
            str(p), None, f"cannot read the file ({getattr(exc, 'strerror', None) or exc})"
        ) from None
    with fh:
        yield from _blocks(_chunks(fh, TABLE_BLOCK_BYTES))


def _fast_rows(blob: bytes, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plain rows of a block: their indices among its lines, times (ns) and values."""
    if not blob:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, layout.width))
    tokens_of = blob if layout.sep is None else blob.replace(layout.sep, b" ")
    arr = np.frombuffer(tokens_of, dtype=np.uint8)
    tok_start, tok_end, counts, first_tok, odd = _tokenise(arr)
    fields = layout.width + 1
    plain = (counts == fields) & ~odd
    if layout.sep is not None:
        raw = np.frombuffer(blob, dtype=np.uint8)
        nl = np.flatnonzero(raw == 10)
        seps = np.bincount(np.searchsorted(nl, np.flatnonzero(raw == layout.sep[0])), minlength=counts.size)
        plain &= seps == layout.width
    cand = np.flatnonzero(plain)
    ts, te = tok_start[first_tok[cand]], tok_end[first_tok[cand]]
    digit = (arr >= 48) & (arr <= 57)
    n_digits, n_dots = _counts(digit, ts, te), _counts(arr == 46, ts, te)
    neg = arr[ts] == 45
    good = (n_digits + n_dots == te - ts - neg) & (n_dots <= 1) & (n_digits >= 1) & (te - ts <= 32)
    t_ns = np.full(cand.size, _NOT_A_TIME, dtype=np.int64)
    at = np.flatnonzero(good)
    for k in range(0, at.size, TIME_BATCH):  # the times' digit arrays are rows × digits: in batches
        part = at[k : k + TIME_BATCH]
        t_ns[part] = _times_ns(arr, ts[part], te[part])
    good &= t_ns != _NOT_A_TIME
    cols = (first_tok[cand[good]][:, None] + 1 + np.arange(layout.width)[None, :]).ravel()
    values, readable = _floats(tokens_of.split(), cols)
    values = np.where(readable, values, np.nan).reshape(-1, layout.width)
    ok = np.all(np.isfinite(values), axis=1)
    rows = cand[good][ok]
    return rows, t_ns[good][ok], values[ok]


def _plain_block(blob: bytes, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A block of nothing but plain rows, read at once (its tokens in order, the times from their
    digits, the numbers by ``float``); None when it holds anything else (the caller then reads it
    row by row)."""
    n_lines = blob.count(b"\n")
    if not n_lines or b"#" in blob or not blob.isascii():
        return None
    if layout.sep is not None and blob.count(layout.sep) != n_lines * layout.width:
        return None
    tokens = (blob.replace(layout.sep, b" ") if layout.sep is not None else blob).split()
    fields = layout.width + 1
    if len(tokens) != n_lines * fields:
        return None
    t_ns = times_of(tokens[::fields])
    if np.any(t_ns == _NOT_A_TIME) or np.any(np.diff(t_ns) <= 0):
        return None
    try:
        values = np.stack(
            [
                np.fromiter(map(float, tokens[k::fields]), dtype=float, count=n_lines)
                for k in range(1, fields)
            ],
            axis=1,
        )
    except ValueError:
        return None
    if not np.all(np.isfinite(values)):
        return None
    return np.arange(n_lines), t_ns, values


def _time_ns(token: bytes) -> int:
    """A time token's integer nanoseconds (as :func:`~nlp_calib.logs.records._parse_time_ns` reads
    it: ``-?[0-9]{1,10}(.[0-9]*)?`` below ``MAX_SECONDS``, the fraction's first nine digits), or
    :data:`~nlp_calib.logs.records._NOT_A_TIME`."""
    whole, _, frac = token.partition(b".")
    digits = whole[1:] if whole.startswith(b"-") else whole
    if not (0 < len(digits) <= 10 and digits.isdigit() and (not frac or frac.isdigit())):
        return _NOT_A_TIME
    seconds = int(digits)
    if seconds >= MAX_SECONDS:
        return _NOT_A_TIME
    ns = seconds * 1_000_000_000 + int((frac[:9] + b"000000000")[:9])
    return -ns if whole.startswith(b"-") else ns


def times_of(tokens: Sequence[bytes]) -> np.ndarray:
    """Integer nanoseconds of time tokens (:func:`_time_ns` each): tokens all written alike
    (``SSSSSSSSSS.FFFFFFFFF``, one width, the dot in one place: what loggers write) from the
    matrix of their digits, any others one by one."""
    chars = np.array(tokens)
    width = chars.dtype.itemsize
    if not chars.size or width > 32:
        return np.fromiter(map(_time_ns, tokens), dtype=np.int64, count=len(tokens))
    digits = chars.view(np.uint8).reshape(-1, width).astype(np.int64) - 48
    dot = tokens[0].find(b".")
    whole_width = dot if dot >= 0 else width
    column = np.arange(width)
    digit_cols = column != dot
    uniform = (
        0 < whole_width <= 10
        and np.all((digits[:, digit_cols] >= 0) & (digits[:, digit_cols] <= 9))
        and (dot < 0 or np.all(digits[:, dot] == 46 - 48))
    )
    if not uniform:
        return np.fromiter(map(_time_ns, tokens), dtype=np.int64, count=len(tokens))
    whole = digits[:, :whole_width] @ (10 ** np.arange(whole_width - 1, -1, -1, dtype=np.int64))
    fraction = digits[:, whole_width + 1 : whole_width + 10] if dot >= 0 else digits[:, :0]
    frac = fraction @ (10 ** np.arange(8, 8 - fraction.shape[1], -1, dtype=np.int64))
    ok = whole < MAX_SECONDS
    return np.where(ok, whole * 1_000_000_000 + frac, _NOT_A_TIME)


def _slow_row(path: str, line: int, text: str, layout: Layout) -> tuple[int, list[float]]:
    """One row read on its own, or the reason it is not one (:class:`DatasetError`)."""
    fields = layout.fields(text)
    if len(fields) != layout.width + 1:
        raise DatasetError(path, line, layout.miscount.format(n=len(fields), words=layout.words))
    values = numbers(path, line, fields[1:], layout.words)
    return stamp_ns(fields[0], path, line), values


class _Rows:
    """A table's rows gathered block by block (see the module docstring)."""

    def __init__(self, path: str, layout: Layout, keep: Keep | None, capacity: int) -> None:
        self.path, self.layout, self.keep = path, layout, keep
        # The columns, allocated once for every line of the file and filled block by block: a
        # large allocation's pages are touched only as they fill, and no block's pieces are held
        # beside a copy of them (blocks freed into the heap are not given back to the system).
        self.columns = _Columns(capacity, layout.width)
        self.header: tuple[int, str] | None = None
        self.rows = 0
        self.first_ns: int | None = None
        self.last: tuple[int, int] | None = None  # the last row's time and line, for the order

    def add(self, first: int, blob: bytes, long: dict[int, int]) -> None:
        if long:
            line = min(long)
            raise DatasetError(self.path, line, f"a line of {long[line]} bytes; expected {self.layout.words}")
        if self.layout.header and self.header is None:
            blob, first = self._find_header(first, blob)
        rows, t_ns, values = _plain_block(blob, self.layout) or _fast_rows(blob, self.layout)
        lines = np.concatenate([[0], np.flatnonzero(np.frombuffer(blob, dtype=np.uint8) == 10) + 1])
        fast = np.zeros(lines.size - 1, dtype=bool)
        fast[rows] = True
        extra = [
            self._slow(first + k, blob[lines[k] : lines[k + 1] - 1]) for k in np.flatnonzero(~fast).tolist()
        ]
        found = [(k, r) for k, r in zip(np.flatnonzero(~fast).tolist(), extra) if r is not None]
        if found:
            order = np.argsort(np.concatenate([rows, [k for k, _ in found]]), kind="stable")
            t_ns = np.concatenate([t_ns, np.array([r[0] for _, r in found], dtype=np.int64)])[order]
            values = np.concatenate(
                [values, np.array([r[1] for _, r in found]).reshape(-1, self.layout.width)]
            )[order]
            rows = np.concatenate([rows, [k for k, _ in found]])[order]
        self._gather(first + rows.astype(np.int64), t_ns, values)

    def _find_header(self, first: int, blob: bytes) -> tuple[bytes, int]:
        """The block without its lines up to the header (comments before it), the header noted."""
        offset = 0
        for k, raw in enumerate(blob.split(b"\n")[:-1]):
            text = _decode(raw, self.path, first + k).strip()
            offset += len(raw) + 1
            if text and not text.startswith("#"):
                self.header = (first + k, text)
                return blob[offset:], first + k + 1
        return b"", first + blob.count(b"\n")

    def _slow(self, line: int, raw: bytes) -> tuple[int, list[float]] | None:
        text = _decode(raw, self.path, line).strip()
        if not text or text.startswith("#"):
            return None
        return _slow_row(self.path, line, text, self.layout)

    def _gather(self, lines: np.ndarray, t_ns: np.ndarray, values: np.ndarray) -> None:
        if not t_ns.size:
            return
        if self.last is not None:
            t_ns_all, lines_all = (
                np.concatenate([[self.last[0]], t_ns]),
                np.concatenate([[self.last[1]], lines]),
            )
        else:
            t_ns_all, lines_all = t_ns, lines
        check_increasing(self.path, t_ns_all, lines_all)
        self.rows += int(t_ns.size)
        self.first_ns = int(t_ns[0]) if self.first_ns is None else self.first_ns
        self.last = (int(t_ns[-1]), int(lines[-1]))
        kept = self.keep(t_ns) if self.keep is not None else slice(None)
        self.columns.add(t_ns[kept], values[kept], lines[kept])

    def table(self) -> Table:
        time_ns, values, lines = self.columns.filled()
        last = self.last[0] if self.last is not None else 0
        return Table(
            time_ns.astype(np.int64, copy=False),
            values.reshape(-1, self.layout.width).astype(float, copy=False),
            lines.astype(np.int64, copy=False),
            self.header,
            self.rows,
            self.first_ns or 0,
            last,
        )


class _Columns:
    """A table's three columns (times, values, line numbers) filled in order up to a capacity;
    rows beyond it (a file that grew while read) are kept in blocks and joined at the end."""

    def __init__(self, capacity: int, width: int) -> None:
        self.time_ns = np.empty(capacity, dtype=np.int64)
        self.values = np.empty((capacity, width))
        self.lines = np.empty(capacity, dtype=np.int64)
        self.at = 0
        self.beyond: list[tuple[np.ndarray, ...]] = []

    def add(self, t_ns: np.ndarray, values: np.ndarray, lines: np.ndarray) -> None:
        n = t_ns.shape[0]
        if self.beyond or self.at + n > self.time_ns.shape[0]:
            self.beyond.append((t_ns, values, lines))
            return
        self.time_ns[self.at : self.at + n] = t_ns
        self.values[self.at : self.at + n] = values
        self.lines[self.at : self.at + n] = lines
        self.at += n

    def filled(self) -> list[np.ndarray]:
        head = (self.time_ns[: self.at], self.values[: self.at], self.lines[: self.at])
        return joined([head, *self.beyond], 3) if self.beyond else list(head)


def line_count(path: Path) -> int:
    """How many lines the file at ``path`` holds (its line feeds, and a last line without one)."""
    with open_regular(path) as fh:
        return 1 + sum(chunk.count(b"\n") for chunk in iter(lambda: fh.read(TABLE_BLOCK_BYTES), b""))


def joined(parts: list[tuple[np.ndarray, ...]], width: int) -> list[np.ndarray]:
    """The ``width`` columns of blocks of rows (``parts``, emptied), each copied block by block into
    its place and each block's piece let go once copied (the column's pages are touched only as it
    fills): the peak is the rows' arrays and a block, not the arrays twice."""
    held = [list(q) for q in parts]
    parts.clear()
    out = []
    for i in range(width):
        if not held:
            out.append(np.zeros(0))
            continue
        pieces = [q[i] for q in held]
        column = np.empty(
            (sum(x.shape[0] for x in pieces), *pieces[0].shape[1:]), dtype=np.result_type(*pieces)
        )
        del pieces
        at = 0
        for q in held:
            n = q[i].shape[0]
            column[at : at + n] = q[i]
            at += n
            q[i] = _NOTHING
        out.append(column)
    return out


_NOTHING = np.zeros(0)


def _decode(raw: bytes, path: str, line: int) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise DatasetError(path, line, "is not UTF-8 text") from None


def data_lines(path: str | Path) -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of every line that is neither blank nor a ``#`` comment, a block
    at a time (for small files read line by line: a vendor's odometry, a file of motions)."""
    p = Path(path)
    for first, blob, _ in _open(p):
        for k, raw in enumerate(blob.split(b"\n")[:-1]):
            text = _decode(raw, str(p), first + k).strip()
            if text and not text.startswith("#"):
                yield first + k, text


def first_row(path: str | Path) -> tuple[int, str] | None:
    """The first line that is neither blank nor a comment (its number and text), reading no
    further; None when there is none."""
    return next(data_lines(path), None)


def read_table(path: str | Path, layout: Layout, keep: Keep | None = None) -> Table:
    """The rows of the table at ``path`` (the module docstring says how); ``keep``: which rows of
    each block to keep, by their times (all when None)."""
    p = Path(path)
    rows: _Rows | None = None
    for first, blob, long in _open(p):  # opened (or refused) before its lines are counted
        rows = rows or _Rows(str(p), layout, keep, line_count(p))
        rows.add(first, blob, long)
    return (rows or _Rows(str(p), layout, keep, 0)).table()


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
