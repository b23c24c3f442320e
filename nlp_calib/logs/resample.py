"""Encoder readings re-sampled on a shifted clock (the tracker's), for time alignment."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.core.numeric import COUNTER_MODULUS, wrapped_difference
from nlp_calib.logs.log import EncoderKind, Log, frozen


def resample_encoders(
    log: Log,
    lag_s: float,
    kinds: Mapping[str, EncoderKind],
    delays: Mapping[str, float] | None = None,
    records: tuple[int, int] | None = None,
    beside_lag_s: float | None = None,
) -> tuple[Log, tuple[int, int]]:
    """Encoder readings re-sampled at ``t - lag_s``: the tracker reports ``lag_s`` after the encoders.

    Shifting the inputs rather than the tracker keeps the measurements, and so the cost, comparable
    across lags. Counters are interpolated on their unwrapped cumulative count, absolute encoders on
    their unwrapped angle (both keep fractional ticks: :attr:`Log.ticks` then holds
    floats); joints in radians are re-sampled from their own stream,
    at its own stamps (:attr:`Log.joint_stream`), never from values already interpolated. Returns the
    log and the record range ``[first, stop)`` whose shifted times lie inside the log (outside it
    the readings are clamped and must not be used). ``delays`` reads an encoder that much later still (s, by
    name): a stream whose effect lags its readings. The lag adds to the log's own
    (:attr:`Log.encoder_lag_s`). ``records``: only those records' readings re-sampled (each the
    value the whole log's re-sampling gives it), the others' left as logged, for a caller that
    reads those records alone (a profile over a stretch of a long log). ``beside_lag_s``: in a log
    of two sensors, the second's clock's offset over the reference's (s, absolute: its records
    read that much later still; None: the log's own, :meth:`Log.read_times`).
    """
    return Resampler(log, kinds, delays).at(lag_s, records, beside_lag_s)


class Resampler:
    """:func:`resample_encoders` of one log at any number of lags: what does not depend on the
    lag (each counter's unwrapped cumulative count, each absolute encoder's unwrapped turns) is
    computed once, at the first lag that needs it."""

    def __init__(
        self, log: Log, kinds: Mapping[str, EncoderKind], delays: Mapping[str, float] | None = None
    ) -> None:
        self.log, self.kinds = log, kinds
        self.late = [(delays or {}).get(name, 0.0) for name in log.header.encoder_names]
        self._levels: list[np.ndarray] | None = None

    def levels(self) -> list[np.ndarray]:
        """Each encoder's readings as a level to interpolate: turns (absolute), counts (counters)."""
        if self._levels is None:
            log, out = self.log, []
            for j, (name, vmax) in enumerate(zip(log.header.encoder_names, log.header.encoder_max)):
                raw = log.ticks[:, j]
                if self.kinds.get(name) == "absolute":
                    out.append(np.unwrap(2.0 * np.pi * raw / vmax) / (2.0 * np.pi))
                else:
                    out.append(np.concatenate([[0], np.cumsum(wrapped_difference(raw))]).astype(float))
            self._levels = out
        return self._levels

    def at(
        self,
        lag_s: float,
        records: tuple[int, int] | None = None,
        beside_lag_s: float | None = None,
        kinked: bool = False,
    ) -> tuple[Log, tuple[int, int]]:
        """The log re-sampled at ``lag_s`` (see :func:`resample_encoders`); ``kinked``: each
        counter's reading between records less its interpolation's expected error
        (:func:`kink_error`), a plausible other reading of the same records (absolute encoders,
        and joints re-sampled from their own stream, as they are)."""
        log, late = self.log, self.late
        moved = beside_lag_s is not None and beside_lag_s != log.clock.beside_lag_s
        if lag_s == 0.0 and not any(late) and not moved:
            return log, (0, log.n_records)
        if log.joint_stream is not None:
            return _joints_resampled(log, lag_s, late, records, beside_lag_s)
        t = log.time_s
        tq = t - lag_s
        valid = np.flatnonzero((tq - max(late) >= t[0]) & (tq - min(late) <= t[-1]))
        if valid.size < 2:
            raise ProblemError(
                f"a lag of {lag_s:g} s leaves fewer than 2 records of the {t[-1] - t[0]:.1f} s log; "
                "use a lag well below the log's duration"
            )
        return self._shifted(lag_s, tq, records, kinked), (int(valid[0]), int(valid[-1]) + 1)

    def _shifted(
        self, lag_s: float, tq: np.ndarray, records: tuple[int, int] | None, kinked: bool = False
    ) -> Log:
        log, t = self.log, self.log.time_s
        rows = slice(*(records or (0, log.n_records)))
        columns = []
        for j, (name, vmax) in enumerate(zip(log.header.encoder_names, log.header.encoder_max)):
            level, when = self.levels()[j], tq[rows] - self.late[j]
            value = np.interp(when, t, level)
            if kinked and self.kinds.get(name) != "absolute":
                # A count's: an interval's increment is two readings' difference, so a reading's
                # error is the increment's (an angle's interval value is its readings' mean,
                # corrected for their curvature: a reading's error is not the value's).
                value = value - kink_error(t, level, when)
            # Fractional ticks: rounded back to whole ticks, a lag within a fraction of a tick per
            # interval gave the logged readings back under the shifted label, and the alignment
            # walked the lag by the same step at every re-sampling.
            if self.kinds.get(name) == "absolute":
                columns.append(np.mod(value * vmax, vmax))
            else:
                columns.append(np.mod(value + log.ticks[0, j], COUNTER_MODULUS))
        ticks = np.stack(columns, axis=1).astype(float)
        if records is not None:  # the other records as logged (one copy of a long log's, not three)
            stretch, ticks = ticks, np.array(log.ticks, dtype=float)
            ticks[rows] = stretch
        ticks.flags.writeable = False
        return replace(log, ticks=ticks, clock=replace(log.clock, encoder_lag_s=log.encoder_lag_s + lag_s))


def kink_error(t: np.ndarray, level: np.ndarray, when: np.ndarray, resolution: float = 1.0) -> np.ndarray:
    """The expected error of ``level`` (readings at ``t``) interpolated linearly at ``when``, where
    its rate changes inside the interval, from the rate over the interval before ``v_a`` to the one
    after ``v_b``, at a point unknown, even odds anywhere in it (a start from rest: the speed rises
    within one interval). A change at ``s`` of the interval puts the chord
    ``h·(v_b − v_a)·f·(1 − s)`` (``f < s``) or ``h·(v_b − v_a)·s·(1 − f)`` off at its fraction ``f``:
    at most ``f(1 − f)·h·|v_b − v_a|`` (at ``s = f``), ``f(1 − f)/2·h·(v_b − v_a)`` over ``s``, which is
    returned (twice the error of a rate that changes evenly over the three intervals). The change is
    taken less what the readings' rounding alone could give (each reading within half its
    ``resolution``, so each rate within ``resolution`` over its interval): the least change the
    readings show (on coarse counts, the rounding's changes had made a noise of their own). 0 on a
    record and in the first and last interval."""
    n = t.size
    if n < 4:
        return np.zeros(np.shape(when))
    k = np.clip(np.searchsorted(t, when, side="right") - 1, 0, n - 2)
    h = np.diff(t)
    span = np.where(h > 0, h, np.inf)  # records on one stamp: no rate, no fraction between them
    f = np.clip((when - t[k]) / span[k], 0.0, 1.0)
    rate = np.diff(level) / span
    before, after = np.maximum(k - 1, 0), np.minimum(k + 1, n - 2)
    change = rate[after] - rate[before]
    rounding = resolution * (1.0 / span[before] + 1.0 / span[after])
    shown = np.sign(change) * np.maximum(np.abs(change) - rounding, 0.0)
    inside = (k >= 1) & (k <= n - 3) & (h[k] > 0)
    return np.where(inside, 0.5 * f * (1.0 - f) * h[k] * shown, 0.0)


def _joints_resampled(
    log: Log,
    lag_s: float,
    late: list[float],
    records: tuple[int, int] | None = None,
    beside_lag_s: float | None = None,
) -> tuple[Log, tuple[int, int]]:
    """Joints in radians re-sampled from their own stream (at its own stamps) at ``t - lag_s`` (a
    second sensor's records ``beside_lag_s`` later), each joint ``late`` (s) later still
    (``records``: those alone, as :func:`resample_encoders`)."""
    stream = log.joint_stream
    assert stream is not None
    records = records if log.joint_positions is not None else None
    lag_s += log.encoder_lag_s  # the stream is as published: shift by the log's own lag too
    beside = log.clock.beside_lag_s if beside_lag_s is None else float(beside_lag_s)
    tq = log.read_times(lag_s, beside)
    valid = np.flatnonzero(stream.covers(tq - max(late)) & stream.covers(tq - min(late)))
    if valid.size < 2:
        raise ProblemError(
            f"a lag of {lag_s:g} s leaves fewer than 2 records inside the joints' "
            f"{stream.time_s[-1] - stream.time_s[0]:.1f} s stream; use a lag well below the log's duration"
        )
    rows = slice(*(records or (0, log.n_records)))
    positions = np.stack([stream.at(tq[rows] - d)[:, j] for j, d in enumerate(late)], axis=1)
    if records is not None and (held := log.joint_positions) is not None:  # the others as logged
        positions = np.concatenate([held[: rows.start], positions, held[rows.stop :]])
    clock = replace(log.clock, encoder_lag_s=lag_s, beside_lag_s=beside)
    shifted = replace(log, joint_positions=frozen(positions), clock=clock)
    return shifted, (int(valid[0]), int(valid[-1]) + 1)


def speeds_read(log: Log, side: float) -> Log:
    """``log`` with its joints integrated from speeds read as held over the interval after each
    stamp (``side`` +1) or as the mean over the interval before (−1) instead of sampled at it (the
    trapezoids', :attr:`~nlp_calib.logs.log.JointStream.quadrature`), at the log's own lag; the
    log itself where no joint was integrated."""
    stream = log.joint_stream
    if stream is None or stream.quadrature is None:
        return log
    moved = replace(stream, positions=frozen(stream.positions + side * stream.quadrature))
    return _joints_resampled(replace(log, joint_stream=moved), 0.0, [0.0] * stream.positions.shape[1])[0]
