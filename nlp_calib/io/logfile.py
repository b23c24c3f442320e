"""The robot log text format (SPEC §2): reading into an immutable :class:`Dataset`, and writing.

A log is a header of ``#`` lines (kinematic model, initial guess, encoder ranges, nominal sensor
pose) followed by one record per line::

    time: <s.ns> ticks: <enc_0> <enc_1> model_pose: <x> <y> <theta> tracker_pose: <x> <y> <theta>
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from nlp_calib.errors import DatasetError
from nlp_calib.io import logcheck
from nlp_calib.io.logcheck import DroppedRecord, drop_summary
from nlp_calib.numeric import COUNTER_MODULUS, wrapped_difference

#: Header parameter names mapped onto the package's parameter names.
_PARAMETER_ALIASES = {
    "ksteer": "k_steer",
    "ktraction": "k_traction",
    "axis_length": "axis_length",
    "base_line": "axis_length",
    "baseline": "baseline",
    "steer_offset": "steer_offset",
    "kleft": "k_left",
    "kright": "k_right",
}

_RECORD_KEYS = ("time:", "ticks:", "model_pose:", "tracker_pose:")


@dataclass(frozen=True)
class LogHeader:
    """What the ``#`` lines say: model, initial guess, encoders, nominal ``T_base_sensor``.

    ``T_base_sensor`` is ordered ``(x, y, theta)``; ``parameters`` uses the package's names.
    """

    kinematic_model: str
    parameters: Mapping[str, float]
    encoder_names: tuple[str, ...]
    encoder_max: tuple[int, ...]
    sensor_frame: str
    T_base_sensor: tuple[float, float, float]

    def encoder_index(self, name: str) -> int:
        """Column of the encoder called ``name`` in :attr:`Dataset.ticks`."""
        if name not in self.encoder_names:
            raise DatasetError(
                "<header>",
                None,
                f"the log has no encoder called {name!r} (it lists {list(self.encoder_names)})",
            )
        return self.encoder_names.index(name)


@dataclass(frozen=True)
class Dataset:
    """An immutable robot log: per-record arrays of equal length ``n_records``.

    ``ticks`` holds the raw encoder readings (columns in ``header.encoder_names`` order),
    ``T_world_sensor`` the tracker poses and ``model_pose`` the vendor odometry, both
    ``(x, y, theta)`` per row. ``time_s`` is relative to the first record of the file.
    """

    path: str
    header: LogHeader
    time_s: np.ndarray
    ticks: np.ndarray
    model_pose: np.ndarray
    T_world_sensor: np.ndarray
    line_numbers: np.ndarray
    dropped: tuple[DroppedRecord, ...] = field(default=())

    @property
    def n_records(self) -> int:
        return int(self.time_s.shape[0])

    def encoder(self, name: str) -> np.ndarray:
        """Raw readings of one encoder, ``(n_records,)`` int64."""
        return self.ticks[:, self.header.encoder_index(name)]

    def increments(self, name: str) -> np.ndarray:
        """Signed increments of an incremental (wrapping uint32) encoder, ``(n_records - 1,)``."""
        return wrapped_difference(self.encoder(name))

    def select(self, start: int, stop: int) -> Dataset:
        """The records ``start:stop`` (time stays relative to the file's first record)."""
        sl = slice(start, stop)
        return replace(
            self,
            time_s=_frozen(self.time_s[sl]),
            ticks=_frozen(self.ticks[sl]),
            model_pose=_frozen(self.model_pose[sl]),
            T_world_sensor=_frozen(self.T_world_sensor[sl]),
            line_numbers=_frozen(self.line_numbers[sl]),
        )


def yaw_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> float:
    """Heading of a quaternion ``(x, y, z, w)`` about the vertical axis."""
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


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
    names = [_PARAMETER_ALIASES.get(n.lower(), n.lower()) for n in _names(names_text)]
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


def read_log(path: str | Path, *, strict: bool = True) -> Dataset:
    """Read a log file; malformed lines raise :class:`DatasetError` naming ``file:line``.

    With ``strict=False`` records that cannot be read (too few fields, not numbers, a line cut
    short) or used (NaN, encoder out of range, time not increasing, a counter jump no wheel can
    make, see :mod:`nlp_calib.io.logcheck`) are dropped with one warning and listed in
    :attr:`Dataset.dropped`; header problems are errors in either mode.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="strict")
    except FileNotFoundError:
        raise DatasetError(
            str(p), None, "no such file; pass the log with --data or fix 'dataset' in the scenario"
        ) from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # ValueError: a NUL in the path
        raise DatasetError(str(p), None, f"cannot read the log ({exc})") from None
    return parse_log(text.splitlines(), str(p), strict=strict)


def parse_log(lines: Iterable[str], path: str = "<log>", *, strict: bool = True) -> Dataset:
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
        (name, vmax if is_absolute_encoder(name) else COUNTER_MODULUS)
        for name, vmax in zip(header.encoder_names, header.encoder_max)
    ]
    bad = logcheck.value_problems(t_ns, tick_arr, poses, lines_arr, limits)
    problems.update({int(lines_arr[i]): reason for i, reason in bad.items()})
    keep = np.ones(len(rows), dtype=bool)
    keep[list(bad)] = False
    if strict and problems:
        first = min(problems)
        raise DatasetError(
            path, first, f"{problems[first]} (set 'strict: false' in the scenario to drop such records)"
        )
    counters = [(j, name) for j, name in enumerate(header.encoder_names) if not is_absolute_encoder(name)]
    problems.update(
        logcheck.counter_drops(t_ns, tick_arr, lines_arr, keep, counters, path, strict, COUNTER_MODULUS)
    )
    t_ns, tick_arr, poses, lines_arr = t_ns[keep], tick_arr[keep], poses[keep], lines_arr[keep]
    dropped = tuple(DroppedRecord(line, problems[line]) for line in sorted(problems))
    if t_ns.shape[0] < 2:
        why = f"; the first dropped: {dropped[0].line}: {dropped[0].reason}" if dropped else ""
        raise DatasetError(path, None, f"expected at least 2 usable records, found {t_ns.shape[0]}{why}")
    if dropped:
        warnings.warn(f"{path}: {drop_summary(dropped, len(record_lines))}", stacklevel=2)
    return Dataset(
        path=path,
        header=header,
        time_s=_frozen((t_ns - t_ns[0]).astype(float) * 1e-9),
        ticks=_frozen(tick_arr),
        model_pose=_frozen(poses[:, 0:3]),
        T_world_sensor=_frozen(poses[:, 3:6]),
        line_numbers=_frozen(lines_arr),
        dropped=dropped,
    )


def is_absolute_encoder(encoder_name: str) -> bool:
    """True for absolute encoders (readings in [0, max)); False for wrapping uint32 counters."""
    # Only steering encoders are absolute in the supported models; wheel counters are uint32.
    return "steer" in encoder_name.lower()


def format_log(
    header: LogHeader,
    time_ns: np.ndarray,
    ticks: np.ndarray,
    model_pose: np.ndarray,
    T_world_sensor: np.ndarray,
    digits: int = 9,
) -> str:
    """Render a log in the format :func:`read_log` reads; poses with ``digits`` significant digits."""
    names = list(header.parameters)
    inv_alias = {
        "k_steer": "Ksteer",
        "k_traction": "Ktraction",
        "k_left": "Kleft",
        "k_right": "Kright",
    }
    x, y, th = header.T_base_sensor
    out = [
        f"#kinematic_model: {header.kinematic_model}",
        "#parameters: [ " + " ".join(inv_alias.get(n, n) for n in names) + " ]",
        "#parameter_values: " + " ".join(f"{header.parameters[n]:.9g}" for n in names),
        "#joints_max_enc: [ " + " ".join(header.encoder_names) + " ]",
        "#joints_max_enc_values: " + " ".join(str(v) for v in header.encoder_max),
        f"#{header.sensor_frame} wrt base_link",
        f"#\ttranslation:\t[ {x:.9g}, {y:.9g}, 0 ],",
        f"#\trotation:\t [ 0, 0, {math.sin(th / 2):.9g}, {math.cos(th / 2):.9g} ]",
    ]
    for k in range(time_ns.shape[0]):
        sec, ns = divmod(int(time_ns[k]), 1_000_000_000)
        enc = " ".join(str(int(v)) for v in ticks[k])
        mp = " ".join(f"{v:.{digits}g}" for v in model_pose[k])
        tp = " ".join(f"{v:.{digits}g}" for v in T_world_sensor[k])
        out.append(f"time: {sec}.{ns:09d} ticks: {enc} model_pose: {mp} tracker_pose: {tp}")
    return "\n".join(out) + "\n"
