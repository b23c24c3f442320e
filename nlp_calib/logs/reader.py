"""Reading the robot log text format into an immutable :class:`~nlp_calib.logs.log.Log`.

A log is a header of ``#`` lines (kinematic model, initial guess, encoder ranges, nominal sensor
pose) followed by one record per line::

    time: <s.ns> ticks: <enc_0> <enc_1> model_pose: <x> <y> <theta> tracker_pose: <x> <y> <theta>

The reader knows no model: the caller says which encoders are absolute and which are counters
(``encoder_kinds``), and the header's parameter names are kept as written.
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.core.numeric import COUNTER_MODULUS
from nlp_calib.logs.checks import counter_drops, drop_summary, value_problems
from nlp_calib.logs.log import DroppedRecord, EncoderKind, Log, LogHeader, frozen

_RECORD_KEYS = ("time:", "ticks:", "model_pose:", "tracker_pose:")


def yaw_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> float:
    """Heading of a quaternion ``(x, y, z, w)`` about the vertical axis."""
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def _numbers(text: str, path: str, line: int, what: str, *, finite: bool = False) -> list[float]:
    cleaned = text.replace("[", " ").replace("]", " ").replace(",", " ")
    try:
        values = [float(tok) for tok in cleaned.split()]
    except ValueError:
        raise DatasetError(path, line, f"{what}: expected numbers, got {text.strip()!r}") from None
    # Header values are used as they are: NaN or infinity there is an error in any mode.
    if finite and not all(math.isfinite(v) for v in values):
        raise DatasetError(path, line, f"{what}: expected finite numbers, got {text.strip()!r}")
    return values


def _names(text: str) -> list[str]:
    return text.replace("[", " ").replace("]", " ").replace(",", " ").split()


def _parse_header(lines: Sequence[tuple[int, str]], path: str) -> LogHeader:
    fields: dict[str, tuple[int, str]] = {}
    sensor_frame = "sensor"
    pose_lines: dict[str, tuple[int, str]] = {}
    for lineno, raw in lines:
        body = raw.lstrip("#").strip()
        if " wrt " in body:
            sensor_frame = body.split(" wrt ")[0].strip()
            continue
        key, sep, value = body.partition(":")
        if not sep:
            continue
        key = key.strip()
        if key in ("translation", "rotation"):
            pose_lines[key] = (lineno, value)
        else:
            fields[key] = (lineno, value)

    def need(key: str) -> tuple[int, str]:
        if key not in fields:
            raise DatasetError(path, None, f"header line '#{key}: ...' is missing")
        return fields[key]

    model = need("kinematic_model")[1].strip()
    _, names_text = need("parameters")
    ln_vals, vals_text = need("parameter_values")
    names = _names(names_text)
    values = _numbers(vals_text, path, ln_vals, "#parameter_values", finite=True)
    if len(values) != len(names):
        raise DatasetError(
            path,
            ln_vals,
            f"#parameter_values has {len(values)} numbers, #parameters names {len(names)}",
        )
    enc_names = tuple(_names(need("joints_max_enc")[1]))
    ln_enc, enc_text = need("joints_max_enc_values")
    enc_max_f = _numbers(enc_text, path, ln_enc, "#joints_max_enc_values", finite=True)
    if len(enc_max_f) != len(enc_names) or any(not 0 < v <= 2**32 or v != int(v) for v in enc_max_f):
        raise DatasetError(
            path,
            ln_enc,
            f"expected {len(enc_names)} integer encoder ranges in [1, 2^32] (one per "
            f"#joints_max_enc name), got {enc_text.strip()!r}",
        )
    for key in ("translation", "rotation"):
        if key not in pose_lines:
            raise DatasetError(path, None, f"header line '#\t{key}: [...]' of the sensor pose is missing")
    ln_t, t_text = pose_lines["translation"]
    ln_r, r_text = pose_lines["rotation"]
    trans = _numbers(t_text, path, ln_t, "sensor translation", finite=True)
    quat = _numbers(r_text, path, ln_r, "sensor rotation quaternion")
    if len(trans) != 3:
        raise DatasetError(path, ln_t, f"sensor translation: expected [x, y, z], got {t_text.strip()!r}")
    if len(quat) != 4 or not math.isclose(math.fsum(q * q for q in quat), 1.0, rel_tol=1e-3):
        raise DatasetError(
            path,
            ln_r,
            f"sensor rotation: expected a unit quaternion [x, y, z, w], got {r_text.strip()!r}",
        )
    return LogHeader(
        kinematic_model=model,
        parameters=dict(zip(names, values)),
        encoder_names=enc_names,
        encoder_max=tuple(int(v) for v in enc_max_f),
        sensor_frame=sensor_frame,
        T_base_sensor=(trans[0], trans[1], yaw_from_quaternion(*quat)),
    )


def _split_record(text: str, path: str, line: int) -> dict[str, list[str]]:
    tokens = text.split()
    parts: dict[str, list[str]] = {}
    current: str | None = None
    for tok in tokens:
        if tok.endswith(":"):
            if tok not in _RECORD_KEYS:
                raise DatasetError(
                    path, line, f"unknown field {tok!r}; a record has {' '.join(_RECORD_KEYS)}"
                )
            current = tok
            parts[current] = []
        elif current is None:
            raise DatasetError(path, line, f"a record starts with 'time:', got {tok!r}")
        else:
            parts[current].append(tok)
    return parts


_TIME = re.compile(r"(-?)([0-9]{1,10})(?:\.([0-9]*))?")
_INT = re.compile(r"-?[0-9]{1,18}")
#: Timestamps beyond this many seconds (year 2096) cannot be stored in int64 nanoseconds safely.
_MAX_SECONDS = 4_000_000_000


def _parse_time_ns(token: str, path: str, line: int) -> int:
    m = _TIME.fullmatch(token)
    if m is None or int(m.group(2)) >= _MAX_SECONDS:
        raise DatasetError(
            path,
            line,
            f"time: expected seconds like 1700000123.456789012, got {token!r}",
        )
    ns = int(m.group(2)) * 1_000_000_000 + int(((m.group(3) or "") + "000000000")[:9])
    return -ns if m.group(1) else ns


def _parse_record(body: str, path: str, lineno: int, n_enc: int) -> tuple[int, list[int], list[float]]:
    """Time (ns), encoder readings and the six pose values of one record line."""
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
                path, lineno, f"{key[:-1]}: expected numbers, got {' '.join(parts[key])!r}"
            ) from None
    return time_ns, [int(tok) for tok in parts["ticks:"]], values


def _open_error(p: Path, exc: BaseException) -> DatasetError:
    if isinstance(exc, FileNotFoundError):
        return DatasetError(str(p), None, "no such file")
    return DatasetError(str(p), None, f"cannot read the log ({exc})")


def read_header(path: str | Path) -> LogHeader:
    """The header of a log file (its ``#`` lines up to the first record)."""
    p = Path(path)
    lines: list[tuple[int, str]] = []
    empty = True
    try:
        with p.open(encoding="utf-8", errors="strict") as fh:
            for lineno, raw in enumerate(fh, start=1):
                stripped = raw.strip()
                empty = empty and not stripped
                if stripped and not stripped.startswith("#"):
                    break
                if stripped:
                    lines.append((lineno, stripped))
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # ValueError: a NUL in the path
        raise _open_error(p, exc) from None
    if empty:
        raise DatasetError(str(p), None, "the file is empty; expected a '#' header and records")
    return _parse_header(lines, str(p))


def read_log(path: str | Path, encoder_kinds: Mapping[str, EncoderKind], *, strict: bool = True) -> Log:
    """Read a log file; malformed lines raise :class:`DatasetError` naming ``file:line``.

    ``encoder_kinds`` says which encoders are absolute and which are wrapping counters (an encoder
    it does not name is range-checked as a counter, without the jump check). With
    ``strict=False`` records that cannot be read (too few fields, not numbers, a line cut short)
    or used (NaN, encoder out of range, time not increasing, a counter jump no wheel can make, see
    :mod:`nlp_calib.logs.checks`) are dropped with one warning and listed in :attr:`Log.dropped`;
    header problems are errors in either mode.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="strict")
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # ValueError: a NUL in the path
        raise _open_error(p, exc) from None
    return parse_log(text.splitlines(), encoder_kinds, str(p), strict=strict)


def parse_log(
    lines: Iterable[str],
    encoder_kinds: Mapping[str, EncoderKind],
    path: str = "<log>",
    *,
    strict: bool = True,
) -> Log:
    """Parse the lines of a log (see :func:`read_log`)."""
    header_lines: list[tuple[int, str]] = []
    record_lines: list[tuple[int, str]] = []
    for lineno, raw in enumerate(lines, start=1):
        stripped = raw.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            if record_lines:
                raise DatasetError(
                    path, lineno, f"header line after the first record: {stripped[:80]!r}; one header per log"
                )
            header_lines.append((lineno, stripped))
        else:
            record_lines.append((lineno, stripped))
    if not header_lines and not record_lines:
        raise DatasetError(path, None, "the file is empty; expected a '#' header and records")
    header = _parse_header(header_lines, path)
    if not record_lines:
        raise DatasetError(
            path,
            header_lines[-1][0],
            "the file ends after the header: no records (expected lines 'time: ... ticks: ... "
            "model_pose: ... tracker_pose: ...'; did the logger stop before its first record?)",
        )

    # Unreadable lines and unusable values are collected first, so that a strict read reports the
    # earliest problem in the file and a non-strict one drops every bad record.
    problems: dict[int, str] = {}
    rows: list[tuple[int, list[int], list[float]]] = []
    linenos: list[int] = []
    for lineno, body in record_lines:
        try:
            rows.append(_parse_record(body, path, lineno, len(header.encoder_names)))
            linenos.append(lineno)
        except DatasetError as exc:
            last = lineno == record_lines[-1][0]
            problems[lineno] = exc.problem + (
                " (the last line: cut short by a crashed logger?)" if last else ""
            )
    t_ns = np.array([r[0] for r in rows], dtype=np.int64)
    tick_arr = np.array([r[1] for r in rows], dtype=np.int64).reshape(len(rows), len(header.encoder_names))
    poses = np.array([r[2] for r in rows], dtype=float).reshape(len(rows), 6)
    lines_arr = np.array(linenos, dtype=np.int64)
    limits = [
        (name, vmax if encoder_kinds.get(name) == "absolute" else COUNTER_MODULUS)
        for name, vmax in zip(header.encoder_names, header.encoder_max)
    ]
    bad = value_problems(t_ns, tick_arr, poses, lines_arr, limits)
    problems.update({int(lines_arr[i]): reason for i, reason in bad.items()})
    keep = np.ones(len(rows), dtype=bool)
    keep[list(bad)] = False
    if strict and problems:
        first = min(problems)
        raise DatasetError(path, first, problems[first], droppable=True)
    counters = [
        (j, name) for j, name in enumerate(header.encoder_names) if encoder_kinds.get(name) == "counter"
    ]
    problems.update(counter_drops(t_ns, tick_arr, lines_arr, keep, counters, path, strict, COUNTER_MODULUS))
    t_ns, tick_arr, poses, lines_arr = t_ns[keep], tick_arr[keep], poses[keep], lines_arr[keep]
    dropped = tuple(DroppedRecord(line, problems[line]) for line in sorted(problems))
    if t_ns.shape[0] < 2:
        why = f"; the first dropped: {dropped[0].line}: {dropped[0].reason}" if dropped else ""
        raise DatasetError(path, None, f"expected at least 2 usable records, found {t_ns.shape[0]}{why}")
    if dropped:
        warnings.warn(f"{path}: {drop_summary(dropped, len(record_lines))}", NlpCalibWarning, stacklevel=2)
    return Log(
        path=path,
        header=header,
        time_s=frozen((t_ns - t_ns[0]).astype(float) * 1e-9),
        ticks=frozen(tick_arr),
        model_pose=frozen(poses[:, 0:3]),
        T_world_sensor=frozen(poses[:, 3:6]),
        line_numbers=frozen(lines_arr),
        dropped=dropped,
    )
