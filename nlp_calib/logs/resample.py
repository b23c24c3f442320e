"""Encoder readings re-sampled on a shifted clock (the tracker's), for time alignment."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.core.numeric import COUNTER_MODULUS, wrapped_difference
from nlp_calib.logs.log import EncoderKind, Log


def bspline_at(t: np.ndarray, y: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """The uniform cubic B-spline whose control points are the readings ``y`` at times ``t``,
    evaluated at times ``tq`` (through each time's fractional record index).

    Every value is a weighted mean of four readings whose weights change smoothly with the
    offset, so a reading's noise is smoothed alike at every offset (linear interpolation smooths
    it most halfway between records, which makes a fit's cost ripple with the offset)."""
    n = len(t)
    x = np.interp(tq, t, np.arange(n, dtype=float))
    i = np.clip(np.floor(x).astype(np.int64), 0, max(n - 2, 0))
    f = (x - i)[:, None]
    w = np.hstack([(1 - f) ** 3, 3 * f**3 - 6 * f**2 + 4, -3 * f**3 + 3 * f**2 + 3 * f + 1, f**3]) / 6.0
    idx = np.clip(i[:, None] + np.arange(-1, 3)[None, :], 0, n - 1)
    return np.sum(w * y[idx], axis=1)


def resample_encoders(
    log: Log,
    lag_s: float,
    kinds: Mapping[str, EncoderKind],
    delays: Mapping[str, float] | None = None,
    spline: bool = False,
) -> tuple[Log, tuple[int, int]]:
    """Encoder readings re-sampled at ``t - lag_s``: the tracker reports ``lag_s`` after the encoders.

    Shifting the inputs rather than the tracker keeps the measurements, and so the cost, comparable
    across lags. Counters are interpolated on their unwrapped cumulative count, absolute encoders on
    their unwrapped angle; linearly, or with ``spline`` through a cubic B-spline of the stream
    (:func:`bspline_at`, a continuous-time stream). ``delays`` reads an encoder that much later
    still (s, by name): a stream whose effect lags its readings. Returns the log and the record
    range ``[first, stop)`` whose shifted times lie inside the log (outside it the readings are
    clamped and must not be used).
    """
    delays = delays or {}
    if lag_s == 0.0 and not spline and not any(delays.values()):
        return log, (0, log.n_records)
    t = log.time_s
    tq = t - lag_s
    late = [delays.get(name, 0.0) for name in log.header.encoder_names]
    valid = np.flatnonzero((tq - max(late) >= t[0]) & (tq - min(late) <= t[-1]))
    if valid.size < 2:
        raise ProblemError(
            f"a lag of {lag_s:g} s leaves fewer than 2 records of the {t[-1] - t[0]:.1f} s log; "
            "use a lag well below the log's duration"
        )
    at = bspline_at if spline else lambda t_, y_, tq_: np.interp(tq_, t_, y_)
    columns = []
    for j, (name, vmax) in enumerate(zip(log.header.encoder_names, log.header.encoder_max)):
        raw, when = log.ticks[:, j], tq - delays.get(name, 0.0)
        if kinds.get(name) == "absolute":
            turns = np.unwrap(2.0 * np.pi * raw / vmax) / (2.0 * np.pi)
            columns.append(np.mod(np.round(at(t, turns, when) * vmax), vmax))
        else:
            count = np.concatenate([[0], np.cumsum(wrapped_difference(raw))]).astype(float)
            columns.append(np.mod(np.round(at(t, count, when)) + raw[0], COUNTER_MODULUS))
    ticks = np.stack(columns, axis=1).astype(np.int64)
    ticks.flags.writeable = False
    return replace(log, ticks=ticks), (int(valid[0]), int(valid[-1]) + 1)
