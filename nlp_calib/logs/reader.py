"""Reading the robot log text format into an immutable :class:`~nlp_calib.logs.log.Log`.

A log is a header of ``#`` lines (kinematic model, initial guess, encoder ranges, nominal sensor
pose; :mod:`nlp_calib.logs.header`) followed by one record per line::

    time: <s.ns> ticks: <enc_0> <enc_1> model_pose: <x> <y> <theta> tracker_pose: <x> <y> <theta>

The file is read as a stream of blocks of whole lines, each parsed with array operations
(:mod:`nlp_calib.logs.records`); a line that is not a plain record goes to the per-line reader,
which reads it after all or says exactly what is wrong with it. Memory follows the records kept,
and the read stops early: a strict read at the first block with a problem (naming the earliest),
a non-strict one when unreadable or unusable lines exceed :data:`MAX_BAD_LINES` and a tenth of the
lines. Special files (a FIFO, a device, a folder) are refused before they are opened; a UTF-8 byte
order mark is skipped.

The reader knows no model: the caller says which encoders are absolute and which are counters
(``encoder_kinds``), and the header's parameter names are kept as written.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import BinaryIO

import numpy as np

from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.core.files import SpecialFileError, open_regular
from nlp_calib.core.numeric import COUNTER_MODULUS
from nlp_calib.logs.checks import counter_drops, drop_summary, value_problems
from nlp_calib.logs.header import parse_header, yaw_from_quaternion
from nlp_calib.logs.log import DroppedRecord, EncoderKind, Log, LogClock, LogHeader, frozen
from nlp_calib.logs.records import parse_block, parse_line

__all__ = ["parse_log", "read_header", "read_log", "yaw_from_quaternion"]

#: Bytes read at a time.
BLOCK_BYTES = 1 << 22
#: A line longer than this is not a record (records are about 100 characters).
MAX_LINE_BYTES = 1 << 16
#: Header lines before the first record beyond which the file is not a log.
MAX_HEADER_LINES = 10_000
#: A non-strict read gives up when more lines than this, and more than a tenth, are unusable.
MAX_BAD_LINES = 1000
_BOM = b"\xef\xbb\xbf"


# --- the stream -------------------------------------------------------------------------------


def open_log(p: Path) -> BinaryIO:
    """A log file opened for reading; special files are refused before they can block."""
    try:
        return open_regular(p)
    except SpecialFileError as exc:
        raise DatasetError(
            str(p), None, f"is {exc.kind}, not a regular file; pass the log file itself"
        ) from None
    except FileNotFoundError:
        raise DatasetError(str(p), None, "no such file") from None
    except IsADirectoryError:
        raise DatasetError(
            str(p), None, "is a folder, not a regular file; pass the log file itself"
        ) from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL in the path
        raise DatasetError(
            str(p), None, f"cannot read the log ({getattr(exc, 'strerror', None) or exc})"
        ) from None


def _chunks(fh: BinaryIO, size: int | None = None) -> Iterator[bytes]:
    while chunk := fh.read(size or BLOCK_BYTES):
        yield chunk


def _blocks(chunks: Iterable[bytes]) -> Iterator[tuple[int, bytes, dict[int, int]]]:
    """Blocks of whole lines, each with its first line's number and the lines cut for length.

    Lines end with ``\\n``, ``\\r\\n`` or ``\\r``; a line longer than :data:`MAX_LINE_BYTES` is
    replaced by an empty one and its length reported.
    """
    line, carry, first = 1, b"", True
    long_len = -1  # bytes of the over-long line being skipped, -1 when none
    for chunk in chunks:
        if first:
            chunk, first = chunk.removeprefix(_BOM), False
        data = carry + chunk
        keep_cr = data.endswith(b"\r")  # a "\r\n" split across two chunks
        data = data[:-1] if keep_cr else data
        if b"\r" in data:
            data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
        long: dict[int, int] = {}
        if long_len >= 0:
            end = data.find(b"\n")
            if end < 0:
                long_len += len(data)
                carry = b"\r" if keep_cr else b""
                continue
            long[line] = long_len + end
            data, long_len = b"\n" + data[end + 1 :], -1
        cut = data.rfind(b"\n") + 1
        body, carry = data[:cut], data[cut:] + (b"\r" if keep_cr else b"")
        if len(carry) > MAX_LINE_BYTES:
            long_len, carry = len(carry), b""
        if body:
            body = _cut_long_lines(body, line, long)
            yield line, body, long
            line += body.count(b"\n")
    if long_len >= 0:
        yield line, b"\n", {line: long_len}
    elif carry.rstrip(b"\r"):
        yield line, carry.rstrip(b"\r") + b"\n", {}


def _cut_long_lines(body: bytes, line: int, long: dict[int, int]) -> bytes:
    """``body`` with each line longer than :data:`MAX_LINE_BYTES` emptied (its length noted)."""
    ends = np.flatnonzero(np.frombuffer(body, dtype=np.uint8) == 10)
    lengths = np.diff(np.concatenate([[-1], ends])) - 1
    too_long = np.flatnonzero(lengths > MAX_LINE_BYTES)
    if not too_long.size:
        return body
    lines = body.split(b"\n")
    for k in too_long.tolist():
        long[line + k] = len(lines[k])
        lines[k] = b""
    return b"\n".join(lines)


def _text_chunks(lines: Iterable[str]) -> Iterator[bytes]:
    batch: list[bytes] = []
    size = 0
    for text in lines:
        raw = text.encode("utf-8", errors="surrogatepass").replace(b"\r", b" ").replace(b"\n", b" ")
        batch.append(raw)
        size += len(raw) + 1
        if size >= BLOCK_BYTES:
            yield b"\n".join(batch) + b"\n"
            batch, size = [], 0
    if batch:
        yield b"\n".join(batch) + b"\n"


def _decode(raw: bytes, path: str, line: int) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DatasetError(path, line, f"cannot read the log (not UTF-8 text: {exc.reason})") from None


def _split_header(
    blocks: Iterator[tuple[int, bytes, dict[int, int]]], path: str
) -> tuple[list[tuple[int, str]], Iterator[tuple[int, bytes, dict[int, int]]]]:
    """The header's ``(line, text)`` and the blocks that follow it (records only)."""
    header: list[tuple[int, str]] = []
    for first, blob, long in blocks:
        lines = blob.split(b"\n")[:-1]
        for k, raw in enumerate(lines):
            stripped = raw.strip()
            if first + k in long or (stripped and not stripped.startswith(b"#")):
                rest = b"\n".join(lines[k:]) + b"\n"
                return header, _chain((first + k, rest, long), blocks)
            if stripped:
                header.append((first + k, _decode(stripped, path, first + k)))
                if len(header) > MAX_HEADER_LINES:
                    raise DatasetError(
                        path,
                        first + k,
                        f"more than {MAX_HEADER_LINES} '#' lines before any record: not a log",
                    )
    return header, iter(())


def _chain(
    head: tuple[int, bytes, dict[int, int]], rest: Iterator[tuple[int, bytes, dict[int, int]]]
) -> Iterator[tuple[int, bytes, dict[int, int]]]:
    yield head
    yield from rest


def read_header(path: str | Path) -> LogHeader:
    """The header of a log file (its ``#`` lines up to the first record)."""
    p = Path(path)
    with open_log(p) as fh:
        header, records = _split_header(_blocks(_chunks(fh)), str(p))
        first = next(records, None)
    if not header and first is None:
        raise DatasetError(str(p), None, "the file is empty; expected a '#' header and records")
    if not header:
        assert first is not None
        line, blob, _ = first
        fields = len(blob.split(b"\n", 1)[0].split())
        raise DatasetError(
            str(p),
            line,
            f"no '#' header before this record ({fields} fields): a text log starts with '#' lines "
            "naming its model and encoders (docs/log-format.md); a robot's own odometry (t x y θ) is "
            "read as dataset: {odometry: FILE, poses: POSES.tum} (docs/vendor.md)",
        )
    return parse_header(header, str(p), checks=False)


def read_log(path: str | Path, encoder_kinds: Mapping[str, EncoderKind], *, strict: bool = True) -> Log:
    """Read a log file; malformed lines raise :class:`DatasetError` naming ``file:line``.

    ``encoder_kinds`` says which encoders are absolute and which are wrapping counters (an encoder
    it does not name is range-checked as a counter, without the jump check). With
    ``strict=False`` records that cannot be read (too few fields, not numbers, a line cut short)
    or used (NaN or implausible values, encoder out of range, time not increasing, a counter jump
    no wheel can make, see :mod:`nlp_calib.logs.checks`) are dropped with one warning and listed in
    :attr:`Log.dropped`; header problems are errors in either mode.
    """
    p = Path(path)
    with open_log(p) as fh:
        return _parse(_blocks(_chunks(fh)), encoder_kinds, str(p), strict)


def parse_log(
    lines: Iterable[str],
    encoder_kinds: Mapping[str, EncoderKind],
    path: str = "<log>",
    *,
    strict: bool = True,
) -> Log:
    """Parse the lines of a log (see :func:`read_log`)."""
    return _parse(_blocks(_text_chunks(lines)), encoder_kinds, path, strict)


def _parse(
    blocks: Iterator[tuple[int, bytes, dict[int, int]]],
    encoder_kinds: Mapping[str, EncoderKind],
    path: str,
    strict: bool,
) -> Log:
    header_lines, record_blocks = _split_header(blocks, path)
    if not header_lines:
        head = next(record_blocks, None)
        if head is None:
            raise DatasetError(path, None, "the file is empty; expected a '#' header and records")
        record_blocks = _chain(head, record_blocks)
    header = parse_header(header_lines, path, strict=strict)
    reader = _RecordReader(header, encoder_kinds, path, strict)
    for block, last in _with_last(record_blocks):
        reader.add(*block, last=last)
    return reader.log(header_lines[-1][0] if header_lines else None)


def _with_last(
    blocks: Iterator[tuple[int, bytes, dict[int, int]]],
) -> Iterator[tuple[tuple[int, bytes, dict[int, int]], bool]]:
    """Each block and whether it is the last with anything but whitespace in it."""
    pending = None
    for block in blocks:
        if not block[1].strip() and not block[2]:
            continue
        if pending is not None:
            yield pending, False
        pending = block
    if pending is not None:
        yield pending, True


class _RecordReader:
    """The records of a log, gathered block by block (see the module docstring)."""

    def __init__(
        self, header: LogHeader, encoder_kinds: Mapping[str, EncoderKind], path: str, strict: bool
    ) -> None:
        self.header, self.path, self.strict = header, path, strict
        self.n_enc = len(header.encoder_names)
        self.limits = [
            (name, vmax if encoder_kinds.get(name) == "absolute" else COUNTER_MODULUS)
            for name, vmax in zip(header.encoder_names, header.encoder_max)
        ]
        self.counters = [
            (j, name) for j, name in enumerate(header.encoder_names) if encoder_kinds.get(name) == "counter"
        ]
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.problems: dict[int, str] = {}
        self.n_lines = 0
        self.n_records = 0
        self.last_kept: tuple[int, int] | None = None

    def _give_up(self, lines_read: int) -> None:
        bad = len(self.problems)
        if not self.strict and bad > MAX_BAD_LINES and bad > 0.1 * lines_read:
            line = min(self.problems)
            raise DatasetError(
                self.path,
                None,
                f"{bad} of the first {lines_read} record lines cannot be used (the first, line {line}: "
                f"{self.problems[line]}); is this a log in the expected format?",
            )

    def add(self, first: int, blob: bytes, long: Mapping[int, int], *, last: bool) -> None:
        """Read a block of lines (``first`` the number of its first); ``last``: no records follow."""
        block = parse_block(blob, first, self.n_enc)
        final = max(int(block.lines.max(initial=0)), int(block.others.max(initial=0)), max(long, default=0))
        offsets = np.concatenate([[0], np.flatnonzero(np.frombuffer(blob, dtype=np.uint8) == 10) + 1])
        form = "'time: ... ticks: ... model_pose: ... tracker_pose: ...'"
        bad = {ln: f"a line of {n} bytes; a record is one line {form}" for ln, n in long.items()}
        extra: list[tuple[int, int, list[int], list[float]]] = []
        for ln in block.others.tolist():
            k = ln - first
            text = _decode(blob[offsets[k] : offsets[k + 1] - 1], self.path, ln).strip()
            if text.startswith("#"):
                raise DatasetError(
                    self.path, ln, f"header line after the first record: {text[:80]!r}; one header per log"
                )
            try:
                extra.append((ln, *parse_line(text, self.path, ln, self.n_enc)))
            except DatasetError as exc:
                cut = " (the last line: cut short by a crashed logger?)" if last and ln == final else ""
                bad[ln] = exc.problem + cut
                if self.strict:
                    break
                self.problems[ln] = bad[ln]
                self._give_up(self.n_lines + k + 1)
        lines, t_ns, ticks, poses = block.lines, block.t_ns, block.ticks, block.poses
        if extra:
            lines = np.concatenate([lines, [r[0] for r in extra]])
            t_ns = np.concatenate([t_ns, np.array([r[1] for r in extra], dtype=np.int64)])
            ticks = np.concatenate(
                [ticks, np.array([r[2] for r in extra], dtype=np.int64).reshape(-1, self.n_enc)]
            )
            poses = np.concatenate([poses, np.array([r[3] for r in extra], dtype=float).reshape(-1, 6)])
            order = np.argsort(lines, kind="stable")
            lines, t_ns, ticks, poses = lines[order], t_ns[order], ticks[order], poses[order]
        reasons, self.last_kept = value_problems(t_ns, ticks, poses, lines, self.limits, self.last_kept)
        self.n_lines += int(offsets.size - 1)
        self.n_records += int(block.lines.size + block.others.size + len(long))
        if self.strict and (bad or reasons):
            where = {**bad, **{int(lines[i]): r for i, r in reasons.items()}}
            line = min(where)
            raise DatasetError(self.path, line, where[line], droppable=True)
        self.problems.update(bad)
        self.problems.update({int(lines[i]): r for i, r in reasons.items()})
        keep = np.ones(lines.size, dtype=bool)
        keep[list(reasons)] = False
        self.parts.append((lines[keep], t_ns[keep], ticks[keep], poses[keep]))
        self._give_up(self.n_lines)

    def log(self, header_end: int | None) -> Log:
        """The log read, after the counter checks (which need the whole log)."""
        if self.n_records == 0:
            raise DatasetError(
                self.path,
                header_end,
                "the file ends after the header: no records (expected lines 'time: ... ticks: ... "
                "model_pose: ... tracker_pose: ...'; did the logger stop before its first record?)",
            )
        parts, self.parts = self.parts, []  # each column gathered once, its blocks let go at once
        lines_arr, t_ns, tick_arr, poses = (
            np.concatenate([p[i] for p in parts]) if parts else np.zeros((0,)) for i in range(4)
        )
        del parts
        tick_arr = tick_arr.reshape(-1, self.n_enc).astype(np.int64, copy=False)
        poses = poses.reshape(-1, 6)
        t_ns, lines_arr = t_ns.astype(np.int64, copy=False), lines_arr.astype(np.int64, copy=False)
        keep = np.ones(t_ns.size, dtype=bool)
        self.problems.update(
            counter_drops(
                t_ns, tick_arr, lines_arr, keep, self.counters, self.path, self.strict, COUNTER_MODULUS
            )
        )
        if not keep.all():
            t_ns, tick_arr, poses, lines_arr = t_ns[keep], tick_arr[keep], poses[keep], lines_arr[keep]
        dropped = tuple(DroppedRecord(line, self.problems[line]) for line in sorted(self.problems))
        if t_ns.shape[0] < 2:
            why = f"; the first dropped: {dropped[0].line}: {dropped[0].reason}" if dropped else ""
            raise DatasetError(
                self.path, None, f"expected at least 2 usable records, found {t_ns.shape[0]}{why}"
            )
        if dropped:
            n_records = int(t_ns.size) + len(dropped)
            warnings.warn(f"{self.path}: {drop_summary(dropped, n_records)}", NlpCalibWarning, stacklevel=4)
        return Log(
            path=self.path,
            header=self.header,
            time_s=frozen((t_ns - t_ns[0]).astype(float) * 1e-9),
            ticks=frozen(tick_arr),
            model_pose=frozen(poses[:, 0:3]),
            T_world_sensor=frozen(poses[:, 3:6]),
            line_numbers=frozen(lines_arr),
            dropped=dropped,
            clock=LogClock(start_ns=int(t_ns[0])),
        )
