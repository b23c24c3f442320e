"""The ``#`` header of a log: kinematic model, initial guess, encoder ranges, nominal sensor pose.

Every problem is named by ``file:line``. A key given twice is an error naming both lines (which
one would count is anyone's guess). The calibration is planar: a sensor rotation that tilts the
sensor out of the plane, or a value beyond any plausible magnitude, is named in a warning (the
yaw is used), or is an error when the log is read strictly.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.logs.log import LogHeader

#: Header keys (``#key: value``); each may appear once.
KEYS = (
    "kinematic_model",
    "parameters",
    "parameter_values",
    "joints_max_enc",
    "joints_max_enc_values",
    "translation",
    "rotation",
)
#: Largest out-of-plane tilt (degrees) of the sensor rotation read without a word.
MAX_TILT_DEG = 1.0
#: Largest magnitude of a length (m), angle (rad) or gain anywhere in a log: beyond it a value is
#: not a measurement (a corrupt field, a unit mix-up).
MAX_MAGNITUDE = 1e6


def yaw_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> float:
    """Heading of a quaternion ``(x, y, z, w)`` about the vertical axis."""
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def tilt_deg(qx: float, qy: float, qz: float, qw: float) -> float:
    """Angle (degrees) between the rotated vertical axis and the vertical."""
    norm2 = qx * qx + qy * qy + qz * qz + qw * qw
    return math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (qx * qx + qy * qy) / norm2))))


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


def _doubtful(path: str, line: int, problem: str, strict: bool) -> None:
    """A header value that can be used but is probably wrong: an error when reading strictly."""
    if strict:
        raise DatasetError(path, line, problem)
    warnings.warn(f"{path}:{line}: {problem}", NlpCalibWarning, stacklevel=4)


_Fields = dict[str, tuple[int, str]]


def _fields(lines: Sequence[tuple[int, str]], path: str) -> tuple[_Fields, str]:
    """Each known header key's (line, text), and the sensor's frame name (``#<frame> wrt ...``)."""
    fields: _Fields = {}
    sensor_frame = "sensor"
    frame_line: int | None = None
    for lineno, raw in lines:
        body = raw.lstrip("#").strip()
        if " wrt " in body:
            if frame_line is not None:
                raise DatasetError(
                    path, lineno, f"a second sensor frame line (the first is line {frame_line}); keep one"
                )
            sensor_frame, frame_line = body.split(" wrt ")[0].strip(), lineno
            continue
        key, sep, value = body.partition(":")
        key = key.strip()
        if not sep or key not in KEYS:
            continue
        if key in fields:
            raise DatasetError(
                path,
                lineno,
                f"header line '#{key}:' appears twice, at lines {fields[key][0]} and {lineno}; keep one",
            )
        fields[key] = (lineno, value)
    return fields, sensor_frame


def _need(fields: _Fields, key: str, path: str) -> tuple[int, str]:
    if key not in fields:
        if key in ("translation", "rotation"):
            raise DatasetError(path, None, f"header line '#\t{key}: [...]' of the sensor pose is missing")
        raise DatasetError(path, None, f"header line '#{key}: ...' is missing")
    return fields[key]


def _parameters(fields: _Fields, path: str) -> tuple[int, list[str], list[float]]:
    names = _names(_need(fields, "parameters", path)[1])
    ln_vals, vals_text = _need(fields, "parameter_values", path)
    values = _numbers(vals_text, path, ln_vals, "#parameter_values", finite=True)
    if len(values) != len(names):
        raise DatasetError(
            path, ln_vals, f"#parameter_values has {len(values)} numbers, #parameters names {len(names)}"
        )
    return ln_vals, names, values


def _encoders(fields: _Fields, path: str) -> tuple[tuple[str, ...], tuple[int, ...]]:
    enc_names = tuple(_names(_need(fields, "joints_max_enc", path)[1]))
    ln_enc, enc_text = _need(fields, "joints_max_enc_values", path)
    enc_max = _numbers(enc_text, path, ln_enc, "#joints_max_enc_values", finite=True)
    if len(enc_max) != len(enc_names) or any(not 0 < v <= 2**32 or v != int(v) for v in enc_max):
        raise DatasetError(
            path,
            ln_enc,
            f"expected {len(enc_names)} integer encoder ranges in [1, 2^32] (one per "
            f"#joints_max_enc name), got {enc_text.strip()!r}",
        )
    return enc_names, tuple(int(v) for v in enc_max)


def _sensor_pose(fields: _Fields, path: str) -> tuple[int, list[float], int, str, list[float]]:
    ln_t, t_text = _need(fields, "translation", path)
    ln_r, r_text = _need(fields, "rotation", path)
    trans = _numbers(t_text, path, ln_t, "sensor translation", finite=True)
    quat = _numbers(r_text, path, ln_r, "sensor rotation quaternion")
    if len(trans) != 3:
        raise DatasetError(path, ln_t, f"sensor translation: expected [x, y, z], got {t_text.strip()!r}")
    if len(quat) != 4 or not math.isclose(math.fsum(q * q for q in quat), 1.0, rel_tol=1e-3):
        raise DatasetError(
            path, ln_r, f"sensor rotation: expected a unit quaternion [x, y, z, w], got {r_text.strip()!r}"
        )
    return ln_t, trans, ln_r, r_text, quat


def _check_plausible(fields: _Fields, path: str, strict: bool) -> None:
    """Values that can be used but are probably wrong: an error when reading strictly."""
    ln_vals, _, values = _parameters(fields, path)
    ln_t, trans, ln_r, r_text, quat = _sensor_pose(fields, path)
    for ln, what, vals in ((ln_vals, "#parameter_values", values), (ln_t, "sensor translation", trans)):
        if any(abs(v) > MAX_MAGNITUDE for v in vals):
            _doubtful(
                path,
                ln,
                f"{what} {' '.join(f'{v:g}' for v in vals)}: a value beyond ±{MAX_MAGNITUDE:g} "
                "(metres, radians or gain) is not plausible; check the header",
                strict,
            )
    tilt = tilt_deg(*quat)
    if tilt > MAX_TILT_DEG:
        _doubtful(
            path,
            ln_r,
            f"sensor rotation {r_text.strip()!r} tilts the sensor {tilt:.1f}° out of the plane (roll or "
            f"pitch); the calibration is planar and uses only its yaw, {yaw_from_quaternion(*quat):.4f} rad",
            strict,
        )


def parse_header(
    lines: Sequence[tuple[int, str]], path: str, *, strict: bool = True, checks: bool = True
) -> LogHeader:
    """The header of the ``(line number, text)`` lines; ``checks`` names doubtful values."""
    fields, sensor_frame = _fields(lines, path)
    model = _need(fields, "kinematic_model", path)[1].strip()
    _, names, values = _parameters(fields, path)
    enc_names, enc_max = _encoders(fields, path)
    _, trans, _, _, quat = _sensor_pose(fields, path)
    if checks:
        _check_plausible(fields, path, strict)
    return LogHeader(
        kinematic_model=model,
        parameters=dict(zip(names, values)),
        encoder_names=enc_names,
        encoder_max=enc_max,
        sensor_frame=sensor_frame,
        T_base_sensor=(trans[0], trans[1], yaw_from_quaternion(*quat)),
    )
