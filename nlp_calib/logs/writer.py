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
    names = list(header.parameters)
    x, y, th = header.T_base_sensor
    out = [
        f"#kinematic_model: {header.kinematic_model}",
        "#parameters: [ " + " ".join(names) + " ]",
        "#parameter_values: " + " ".join(f"{header.parameters[n]:.9g}" for n in names),
        "#joints_max_enc: [ " + " ".join(header.encoder_names) + " ]",
        "#joints_max_enc_values: " + " ".join(str(v) for v in header.encoder_max),
        f"#{header.sensor_frame} wrt base_link",
        f"#\ttranslation:\t[ {x:.9g}, {y:.9g}, 0 ],",
        f"#\trotation:\t [ 0, 0, {math.sin(th / 2):.9g}, {math.cos(th / 2):.9g} ]",
    ]
    for k in range(time_ns.shape[0]):
        enc = " ".join(str(int(v)) for v in ticks[k])
        mp = " ".join(_number(v, digits) for v in model_pose[k])
        tp = " ".join(_number(v, digits) for v in T_world_sensor[k])
        out.append(f"time: {format_time(int(time_ns[k]))} ticks: {enc} model_pose: {mp} tracker_pose: {tp}")
    return "\n".join(out) + "\n"


def format_time(t_ns: int) -> str:
    """``t_ns`` as the text format's seconds: sign, whole seconds, nine decimals (−1.5 s is
    ``-1.500000000``, as the reader reads it, not ``-2.500000000``)."""
    sec, ns = divmod(abs(t_ns), 1_000_000_000)
    return f"{'-' if t_ns < 0 else ''}{sec}.{ns:09d}"


def _number(v: float, digits: int | None) -> str:
    return repr(float(v)) if digits is None else f"{v:.{digits}g}"
