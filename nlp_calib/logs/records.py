"""Record lines read a block at a time: structure with numpy, numbers without a per-line parser.

A record is ``time: <s.ns> ticks: <e_0> … model_pose: <x> <y> <θ> tracker_pose: <x> <y> <θ>``.
:func:`parse_block` finds the lines and tokens of a block of whole lines from its bytes'
whitespace, checks the labels and the characters of every number where a well-formed record has
them, all as array operations, and converts the numbers in one pass each (the time to integer
nanoseconds, counters to integers, poses with Python's own ``float``, so they are the same
doubles as ever). A line it cannot read that way (a field missing or out of order, a character
outside printable ASCII, a malformed number, a comment) is handed back by number, for the
per-line reader to give its exact reason or to read it after all.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass

import numpy as np

from nlp_calib.core.errors import DatasetError

LABELS = (b"time:", b"ticks:", b"model_pose:", b"tracker_pose:")
_RECORD_KEYS = ("time:", "ticks:", "model_pose:", "tracker_pose:")

#: Bytes ``bytes.split`` treats as whitespace.
_WS = np.zeros(256, dtype=bool)
_WS[[9, 10, 11, 12, 13, 32]] = True
#: Bytes a fast-path line may hold: printable ASCII, tab (newlines are removed before).
_PLAIN = np.zeros(256, dtype=bool)
_PLAIN[32:127] = True
_PLAIN[9] = True
#: Timestamps beyond this many seconds (year 2096) cannot be stored in int64 nanoseconds safely.
MAX_SECONDS = 4_000_000_000


@dataclass(frozen=True)
class Block:
    """What a block of lines held: records read (line numbers, time in ns, counter readings,
    the six pose values), and the lines left to the per-line reader (``others``) with, among them,
    those whose first token starts with ``#`` (``comments``)."""

    lines: np.ndarray
    t_ns: np.ndarray
    ticks: np.ndarray
    poses: np.ndarray
    others: np.ndarray
    comments: np.ndarray


def _counts(flag: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """How many bytes ``flag`` marks in each token."""
    c = np.zeros(flag.size + 1, dtype=np.int32)  # a block is far below 2^31 bytes
    np.cumsum(flag.view(np.uint8), dtype=np.int32, out=c[1:])
    return c[ends] - c[starts]


def _integer_form(arr: np.ndarray, digit: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Tokens of the form ``-?[0-9]+`` (no other sign, no spaces, no underscores)."""
    neg = arr[starts] == 45
    n_digits = _counts(digit, starts, ends)
    return (n_digits == ends - starts - neg) & (n_digits >= 1)


#: What :func:`_times_ns` gives a token that is not a time (a time cannot be negative and that
#: far from 0 at once).
_NOT_A_TIME = -(2**62)
_POW10 = 10 ** np.arange(19, dtype=np.int64)


def _token_bytes(arr: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bytes of each token, one row each (``(n, longest)``), and which columns it fills."""
    width = int(np.max(ends - starts, initial=0))
    at = starts[:, None] + np.arange(width)[None, :]
    inside = at < ends[:, None]
    return np.where(inside, arr[np.minimum(at, max(arr.size - 1, 0))], 0), inside


def _digit_sum(chars: np.ndarray, use: np.ndarray, power: np.ndarray) -> np.ndarray:
    """``Σ digit·10^power`` over the characters ``use`` marks, per row (int64, exact)."""
    terms = (chars.astype(np.int64) - 48) * _POW10[np.clip(power, 0, 18)]
    return np.where(use, terms, 0).sum(axis=1)


def _integers(arr: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """``int`` of tokens of the form ``-?[0-9]{1,18}``, as array operations."""
    chars, inside = _token_bytes(arr, starts, ends)
    neg = chars[:, 0] == 45 if chars.shape[1] else np.zeros(starts.size, dtype=bool)
    k = np.arange(chars.shape[1])[None, :]
    value = _digit_sum(chars, inside & (k >= neg[:, None]), (ends - starts)[:, None] - 1 - k)
    return np.where(neg, -value, value)


def _times_ns(arr: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Integer nanoseconds of tokens of the form ``-?[0-9.]+`` with at most one dot, as array
    operations: 1 to 10 digits of whole seconds (below :data:`MAX_SECONDS`), then the first nine
    of the fraction; :data:`_NOT_A_TIME` for any other token (as :func:`_parse_time_ns` reads
    them, without the per-line error)."""
    chars, inside = _token_bytes(arr, starts, ends)
    n = starts.size
    if chars.shape[1] == 0:
        return np.full(n, _NOT_A_TIME, dtype=np.int64)
    neg = chars[:, 0] == 45
    is_dot = chars == 46
    dot = np.where(is_dot.any(axis=1), np.argmax(is_dot, axis=1), ends - starts)[:, None]
    k = np.arange(chars.shape[1])[None, :]
    whole_digits = dot[:, 0] - neg
    fine = (whole_digits >= 1) & (whole_digits <= 10)
    whole = _digit_sum(chars, inside & (k >= neg[:, None]) & (k < dot) & fine[:, None], dot - 1 - k)
    fine &= whole < MAX_SECONDS
    frac = _digit_sum(chars, inside & (k > dot) & (k <= dot + 9), dot + 9 - k)
    ns = np.where(fine, whole, 0) * 1_000_000_000 + frac
    return np.where(fine, np.where(neg, -ns, ns), _NOT_A_TIME)


def _floats(tokens: list[bytes], index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Python's ``float`` of ``tokens[index]``, and which could be read."""
    picked = [tokens[i] for i in index.tolist()]
    try:
        return np.fromiter(map(float, picked), dtype=float, count=len(picked)), np.ones(len(picked), bool)
    except ValueError:
        values, ok = np.zeros(len(picked)), np.ones(len(picked), bool)
        for k, tok in enumerate(picked):
            try:
                values[k] = float(tok)
            except ValueError:
                ok[k] = False
        return values, ok


def _label_at(arr: np.ndarray, starts: np.ndarray, ends: np.ndarray, label: bytes) -> np.ndarray:
    ok = ends - starts == len(label)
    last = arr.size - 1
    for i, ch in enumerate(label):
        ok &= arr[np.minimum(starts + i, last)] == ch
    return ok


def _tokenise(arr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every token's start and end, each line's token count and first token, and the lines with a
    character no record holds."""
    nl = np.flatnonzero(arr == 10)
    n_lines = nl.size + (1 if arr.size and arr[-1] != 10 else 0)
    ws = _WS[arr]
    before = np.concatenate([[True], ws[:-1]])
    after = np.concatenate([ws[1:], [True]])
    tok_start = np.flatnonzero(~ws & before)
    tok_end = np.flatnonzero(~ws & after) + 1
    counts = np.bincount(np.searchsorted(nl, tok_start), minlength=n_lines)
    odd = np.zeros(n_lines, dtype=bool)
    odd[np.unique(np.searchsorted(nl, np.flatnonzero(~_PLAIN[arr] & (arr != 10))))] = True
    return tok_start, tok_end, counts, np.cumsum(counts) - counts, odd


#: Bytes a line of a clean block holds: printable ASCII and spaces (tabs, newlines aside).
_PRINTABLE = bytes(range(32, 127)) + b"\t\n"
#: Widths of the time and counter fields a clean block is read with: a longer one is not clean.
_TIME_WIDTH, _TICK_WIDTH = 33, 20


def _clean_dtype(n_encoders: int) -> np.dtype:
    """One record line as numpy's text reader reads it: labels, time and counters as bytes (checked
    and converted exactly here), poses as doubles."""
    label = f"S{max(len(x) for x in LABELS) + 1}"
    fields = [("l0", label), ("time", f"S{_TIME_WIDTH}"), ("l1", label)]
    fields += [(f"tick{j}", f"S{_TICK_WIDTH}") for j in range(n_encoders)]
    fields += [("l2", label), *((f"p{j}", "f8") for j in range(3)), ("l3", label)]
    fields += [(f"p{j}", "f8") for j in range(3, 6)]
    return np.dtype(fields)


def _fixed(column: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A fixed-width bytes column (tokens left-aligned, padded with NULs, which no clean line holds)
    as its bytes' values less ``'0'``, one row per place (``(width, n)``, int64; only as wide as the
    longest token), each token's length and whether it starts with ``-``."""
    n, width = column.size, column.dtype.itemsize
    chars = np.ascontiguousarray(column).view(np.uint8).reshape(n, width)
    lengths = np.count_nonzero(chars, axis=1)
    places = chars[:, : int(lengths.max(initial=0))].T.astype(np.int64) - 48
    neg = places[0] == 45 - 48 if places.shape[0] else np.zeros(n, dtype=bool)
    return places, lengths, neg


def _fixed_times_ns(column: np.ndarray) -> np.ndarray:
    """:func:`_times_ns` of a fixed-width column, with :func:`parse_block`'s checks of the time's
    form (:data:`_NOT_A_TIME` where they fail); digits read place by place (Horner), exactly."""
    places, length, neg = _fixed(column)
    n = length.size
    is_dot = places == 46 - 48
    n_dots = is_dot.sum(axis=0)
    n_digits = ((places >= 0) & (places <= 9)).sum(axis=0)
    dot = np.where(n_dots > 0, np.argmax(is_dot, axis=0) if places.shape[0] else 0, length)
    fine = (n_digits + n_dots == length - neg) & (n_dots <= 1) & (n_digits >= 1) & (length <= 32)
    fine &= (dot - neg >= 1) & (dot - neg <= 10)
    if n and fine.all() and not neg.any() and np.ptp(dot) == 0 and np.ptp(length) == 0:
        # One layout for every time (a logger's fixed format): each place has one power of ten.
        point, fraction = int(dot[0]), max(0, min(int(length[0]) - int(dot[0]) - 1, 9))
        whole = _POW10[point - 1 :: -1] @ places[:point]
        frac = _POW10[fraction - 1 :: -1][:fraction] @ places[point + 1 : point + 1 + fraction]
    else:
        whole, frac = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        for k, d in enumerate(places):
            whole = np.where((k >= neg) & (k < dot) & fine, whole * 10 + d, whole)
            frac = np.where((k > dot) & (k <= dot + 9) & (k < length) & fine, frac * 10 + d, frac)
    fine &= whole < MAX_SECONDS
    frac *= _POW10[9 - np.clip(length - dot - 1, 0, 9)]
    ns = np.where(fine, whole, 0) * 1_000_000_000 + frac
    return np.where(fine, np.where(neg, -ns, ns), _NOT_A_TIME)


def _fixed_integers(column: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``int`` of a fixed-width column's tokens and which have the form ``-?[0-9]{1,18}``."""
    places, length, neg = _fixed(column)
    n_digits = ((places >= 0) & (places <= 9)).sum(axis=0)
    ok = (n_digits == length - neg) & (n_digits >= 1) & (n_digits <= 18)
    value = np.zeros(length.size, dtype=np.int64)
    for k, d in enumerate(places):
        value = np.where((k >= neg) & (k < length) & ok, value * 10 + d, value)
    return np.where(neg, -value, value), ok


def parse_clean_block(blob: bytes, first_line: int, n_encoders: int) -> Block | None:
    """The records of a block in which every line is a plain record (the common case), read with
    numpy's compiled text reader and checked as :func:`parse_block` checks them (the same values
    to the bit); None when any line is not, for :func:`parse_block` to find which."""
    if blob.translate(None, _PRINTABLE) or b"\n\n" in blob:
        return None  # a character no plain record holds, or a blank line (the reader skips those)
    try:
        rec = np.loadtxt(io.BytesIO(blob), dtype=_clean_dtype(n_encoders), comments=None, ndmin=1)
    except ValueError:
        return None
    n = rec.size
    if n != blob.count(b"\n") + (0 if blob.endswith(b"\n") else 1):
        return None
    good = np.ones(n, dtype=bool)
    for k, label in enumerate(LABELS):
        good &= rec[f"l{k}"] == label
    t_ns = _fixed_times_ns(rec["time"])
    good &= t_ns != _NOT_A_TIME
    ticks = np.empty((n, n_encoders), dtype=np.int64)
    for j in range(n_encoders):
        ticks[:, j], ok = _fixed_integers(rec[f"tick{j}"])
        good &= ok
    if not good.all():
        return None
    poses = np.stack([rec[f"p{j}"] for j in range(6)], axis=1)
    none = np.zeros(0, dtype=np.intp)
    lines = first_line + np.arange(n)
    return Block(lines=lines, t_ns=t_ns, ticks=ticks, poses=poses, others=none, comments=none)


def parse_block(blob: bytes, first_line: int, n_encoders: int) -> Block:
    """The records of ``blob`` (whole lines joined by ``\\n``; line ``first_line`` first)."""
    clean = parse_clean_block(blob, first_line, n_encoders)
    if clean is not None:
        return clean
    arr = np.frombuffer(blob, dtype=np.uint8)
    tok_start, tok_end, counts, first_tok, odd = _tokenise(arr)
    n_lines = counts.size

    K = 11 + n_encoders
    cand = np.flatnonzero((counts == K) & ~odd)
    t0 = first_tok[cand]
    layout = {0: LABELS[0], 2: LABELS[1], 3 + n_encoders: LABELS[2], 7 + n_encoders: LABELS[3]}
    good = np.ones(cand.size, dtype=bool)
    for offset, label in layout.items():
        good &= _label_at(arr, tok_start[t0 + offset], tok_end[t0 + offset], label)
    digit = (arr >= 48) & (arr <= 57)
    tokens = blob.split()
    # Time: digits with at most one dot (what else the form allows is checked as it is read).
    ts, te = tok_start[t0 + 1], tok_end[t0 + 1]
    neg = arr[ts] == 45
    n_digits, n_dots = _counts(digit, ts, te), _counts(arr == 46, ts, te)
    good &= (n_digits + n_dots == te - ts - neg) & (n_dots <= 1) & (n_digits >= 1) & (te - ts <= 32)
    t_ns = np.zeros(cand.size, dtype=np.int64)
    t_ns[good] = _times_ns(arr, ts[good], te[good])
    good &= t_ns != _NOT_A_TIME
    tick_cols = (t0[:, None] + 3 + np.arange(n_encoders)[None, :]).ravel()
    tick_ok = _integer_form(arr, digit, tok_start[tick_cols], tok_end[tick_cols])
    tick_ok &= tok_end[tick_cols] - tok_start[tick_cols] - (arr[tok_start[tick_cols]] == 45) <= 18
    good &= tick_ok.reshape(-1, n_encoders).all(axis=1)
    tick_cols = tick_cols.reshape(-1, n_encoders)[good].ravel()
    ticks = _integers(arr, tok_start[tick_cols], tok_end[tick_cols])
    pose_offsets = np.array([4, 5, 6, 8, 9, 10]) + n_encoders
    pose_cols = (t0[good][:, None] + pose_offsets[None, :]).ravel()
    poses, readable = _floats(tokens, pose_cols)
    ok = readable.reshape(-1, 6).all(axis=1)
    kept = np.flatnonzero(good)[ok]
    good[:] = False
    good[kept] = True
    ticks, poses = ticks.reshape(-1, n_encoders)[ok], poses.reshape(-1, 6)[ok]
    t_ns = t_ns[good]

    blank = counts == 0
    fast = np.zeros(n_lines, dtype=bool)
    fast[cand[good]] = True
    others = np.flatnonzero(~fast & ~blank)
    hash_first = np.zeros(n_lines, dtype=bool)
    has_tok = counts > 0
    hash_first[has_tok] = arr[tok_start[first_tok[has_tok]]] == 35
    return Block(
        lines=first_line + cand[good],
        t_ns=t_ns,
        ticks=ticks,
        poses=poses,
        others=first_line + others,
        comments=first_line + np.flatnonzero(hash_first & ~blank),
    )


# --- one line at a time: the lines parse_block leaves ---------------------------------------------


def _split_record(text: str, path: str, line: int) -> dict[str, list[str]]:
    tokens = text.split()
    parts: dict[str, list[str]] = {}
    current: str | None = None
    for tok in tokens:
        if tok.endswith(":"):
            if tok not in _RECORD_KEYS:
                raise DatasetError(
                    path, line, f"unknown field {tok[:80]!r}; a record has {' '.join(_RECORD_KEYS)}"
                )
            current = tok
            parts[current] = []
        elif current is None:
            raise DatasetError(path, line, f"a record starts with 'time:', got {tok[:80]!r}")
        else:
            parts[current].append(tok)
    return parts


_TIME = re.compile(r"(-?)([0-9]{1,10})(?:\.([0-9]*))?")
_INT = re.compile(r"-?[0-9]{1,18}")


def _parse_time_ns(token: str, path: str, line: int) -> int:
    m = _TIME.fullmatch(token)
    if m is None or int(m.group(2)) >= MAX_SECONDS:
        raise DatasetError(
            path, line, f"time: expected seconds like 1700000123.456789012, got {token[:80]!r}"
        )
    ns = int(m.group(2)) * 1_000_000_000 + int(((m.group(3) or "") + "000000000")[:9])
    return -ns if m.group(1) else ns


def parse_line(body: str, path: str, lineno: int, n_enc: int) -> tuple[int, list[int], list[float]]:
    """Time (ns), encoder readings and the six pose values of one record line, or the reason
    it is not one (:class:`DatasetError`)."""
    parts = _split_record(body, path, lineno)
    expected = {"time:": 1, "ticks:": n_enc, "model_pose:": 3, "tracker_pose:": 3}
    for key, count in expected.items():
        got = parts.get(key)
        if got is None or len(got) != count:
            found = "none" if got is None else f"{len(got)}"
            raise DatasetError(path, lineno, f"'{key}' needs {count} value(s), found {found}: {body[:80]!r}")
    time_ns = _parse_time_ns(parts["time:"][0], path, lineno)
    if not all(_INT.fullmatch(tok) for tok in parts["ticks:"]):
        raise DatasetError(
            path, lineno, f"ticks: expected {n_enc} integers of at most 18 digits, got {parts['ticks:']}"
        )
    values = []
    for key in ("model_pose:", "tracker_pose:"):
        try:  # plain numbers only: no brackets or commas inside a record
            values += [float(tok) for tok in parts[key]]
        except ValueError:
            raise DatasetError(
                path, lineno, f"{key[:-1]}: expected numbers, got {' '.join(parts[key])[:80]!r}"
            ) from None
    return time_ns, [int(tok) for tok in parts["ticks:"]], values
