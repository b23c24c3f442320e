"""Writing a log in the text format :func:`nlp_calib.logs.reader.read_log` reads."""

from __future__ import annotations

import math

import numpy as np

from nlp_calib.logs.log import LogHeader


def format_log(
    header: LogHeader,
    time_ns: np.ndarray,
    ticks: np.ndarray,
    model_pose: np.ndarray,
    T_world_sensor: np.ndarray,
    digits: int | None = 9,
) -> str:
    """Render a log; poses with ``digits`` significant digits (None: the shortest text that reads back
    as the same float), header parameters as named there."""
    return format_header(header) + format_records(time_ns, ticks, model_pose, T_world_sensor, digits)


def format_header(header: LogHeader) -> str:
    """The header lines of a log, each ending in a newline."""
    names = list(header.parameters)
    x, y, th = header.T_base_sensor
    lines = [
        f"#kinematic_model: {header.kinematic_model}",
        "#parameters: [ " + " ".join(names) + " ]",
        "#parameter_values: " + " ".join(f"{header.parameters[n]:.9g}" for n in names),
        "#joints_max_enc: [ " + " ".join(header.encoder_names) + " ]",
        "#joints_max_enc_values: " + " ".join(str(v) for v in header.encoder_max),
        f"#{header.sensor_frame} wrt base_link",
        f"#\ttranslation:\t[ {x:.9g}, {y:.9g}, 0 ],",
        f"#\trotation:\t [ 0, 0, {math.sin(th / 2):.9g}, {math.cos(th / 2):.9g} ]",
    ]
    return "".join(f"{line}\n" for line in lines)


def format_records(
    time_ns: np.ndarray,
    ticks: np.ndarray,
    model_pose: np.ndarray,
    T_world_sensor: np.ndarray,
    digits: int | None = 9,
) -> str:
    """The record lines of a log (any run of its records: a log may be written in blocks), each
    ending in a newline."""
    number = "%r" if digits is None else f"%.{digits}g"
    poses = " ".join([number] * 3)
    encoders = " ".join(["%d"] * ticks.shape[1])
    line = f"time: %s%d.%09d ticks: {encoders} model_pose: {poses} tracker_pose: {poses}\n"
    t = np.asarray(time_ns, dtype=np.int64)
    # Sign, then the magnitude: -1.5 s is -1.500000000, as the reader reads it, not -2.500000000.
    sec, ns = np.divmod(np.abs(t), 1_000_000_000)
    columns = zip(
        np.where(t < 0, "-", "").tolist(),
        sec.tolist(),
        ns.tolist(),
        np.asarray(ticks).astype(np.int64).tolist(),
        np.asarray(model_pose, dtype=float).tolist(),
        np.asarray(T_world_sensor, dtype=float).tolist(),
    )
    return "".join(line % (sg, s, n, *enc, *mp, *tp) for sg, s, n, enc, mp, tp in columns)


def format_time(t_ns: int) -> str:
    """``t_ns`` as the text format's seconds: sign, whole seconds, nine decimals (−1.5 s is
    ``-1.500000000``, as the reader reads it, not ``-2.500000000``)."""
    sec, ns = divmod(abs(t_ns), 1_000_000_000)
    return f"{'-' if t_ns < 0 else ''}{sec}.{ns:09d}"
