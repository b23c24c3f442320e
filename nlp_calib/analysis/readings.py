"""An encoder's readings in the log's own unit, for the fault screens: raw ``ticks`` (counts), or
``rad`` for joints in radians (a ROS 2 robot's ``JointState``).

The screens judge a stream by its own history, so they need its readings, their smallest step and
how many readings make a radian; this module gives those for either kind of log, and writes
interpolated readings back where a glitch was, without the screens knowing which kind they read.
A joint in radians is judged on its own stream, as published (interpolated at the tracker's
stamps, one bad message would be spread over the records around it): a glitch found there is
placed on the records whose positions it reaches (:meth:`Readings.records_of`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.core.numeric import wrapped_difference
from nlp_calib.logs import Log
from nlp_calib.logs.log import frozen

#: A joint in radians whose positions are not quantised steps by at least this (rad) when the
#: screens ask for its smallest step: far below any steering joint's real motion per record.
MIN_JOINT_STEP = 1e-4


@dataclass(frozen=True)
class Readings:
    """Encoder ``name``'s readings ``values`` at times ``t`` (an absolute encoder's unwrapped
    across its range), in ``unit``; ``per_radian`` readings make one radian of an absolute encoder
    and ``step`` is the smallest change a reading shows (1 tick; a joint's resolution). ``records``
    (the log's record times) is None when the readings are the records themselves."""

    name: str
    unit: str
    t: np.ndarray
    values: np.ndarray
    per_radian: float
    step: float
    records: np.ndarray | None = None

    def records_of(self, a: int, b: int) -> tuple[int, int]:
        """The records ``[lo, hi)`` whose values readings ``a..b`` reach: themselves, or for a
        stream the records stamped strictly between the readings around them (may be empty)."""
        if self.records is None:
            return a, b + 1
        t = self.t
        before = t[a - 1] if a > 0 else -np.inf
        after = t[b + 1] if b + 1 < t.size else np.inf
        lo = int(np.searchsorted(self.records, before, side="right"))
        return lo, max(int(np.searchsorted(self.records, after, side="left")), lo)

    def shown(self, value: float, signed: bool = False) -> str:
        """``value`` as the log writes it: whole ticks, or radians to four significant digits."""
        sign = "+" if signed else ""
        return f"{value:{sign}.0f} ticks" if self.unit == "ticks" else f"{value:{sign}.4g} rad"


def in_radians(log: Log) -> bool:
    return log.joint_positions is not None


def unit(log: Log) -> str:
    return "rad" if in_radians(log) else "ticks"


def readings(log: Log, name: str) -> Readings:
    """Encoder ``name``'s readings; an absolute encoder's counts are unwrapped across their range."""
    col = log.header.encoder_index(name)
    stream = log.joint_stream
    if stream is not None:
        step = max(stream.resolution[col], MIN_JOINT_STEP)
        return Readings(name, "rad", stream.time_s, stream.positions[:, col], 1.0, step, log.time_s)
    if log.joint_positions is not None:
        return Readings(name, "rad", log.time_s, log.joint_positions[:, col], 1.0, MIN_JOINT_STEP)
    vmax = log.header.encoder_max[col]
    per_radian = vmax / (2.0 * np.pi)
    values = np.unwrap(log.ticks[:, col] / per_radian) * per_radian
    return Readings(name, "ticks", log.time_s, values, per_radian, 1.0)


def turning(log: Log, names: list[str], records: bool = False) -> np.ndarray | None:
    """Per interval of the readings' axis (see :func:`readings`: a joint stream's messages, else
    the records; ``records``: the records' whatever the stream), whether any of the counters
    ``names`` changed (None: no counter)."""
    if not names:
        return None
    if log.joint_stream is not None and not records:
        cols = [log.header.encoder_index(n) for n in names]
        return np.any(np.diff(log.joint_stream.positions[:, cols], axis=0) != 0, axis=1)
    if log.joint_positions is not None:
        cols = [log.header.encoder_index(n) for n in names]
        return np.any(np.diff(log.joint_positions[:, cols], axis=0) != 0, axis=1)
    return np.any([wrapped_difference(log.encoder(n)) != 0 for n in names], axis=0)


def interpolated_over(log: Log, name: str, bad: np.ndarray) -> Log:
    """``log`` with absolute encoder ``name``'s readings at the records ``bad`` interpolated in time
    from the others (for joints in radians, in the joints' own stream too, so that re-sampling at
    a tracker lag keeps the change)."""
    t, col = log.time_s, log.header.encoder_index(name)
    y = log.joint_positions[:, col] if log.joint_positions is not None else readings(log, name).values
    fixed = np.interp(t[bad], t[~bad], y[~bad])
    if log.joint_positions is None:
        vmax = log.header.encoder_max[col]
        ticks = np.array(log.ticks)  # its own dtype: whole ticks as logged, fractional re-sampled
        ticks[bad, col] = np.mod(np.round(fixed), vmax)
        return replace(log, ticks=frozen(ticks))
    positions = np.array(log.joint_positions, dtype=float)
    positions[bad, col] = fixed
    stream = log.joint_stream
    if stream is None:
        return replace(log, joint_positions=frozen(positions))
    # The stream's messages between the good records around each bad run go the same way.
    inside = _between_good(stream.time_s, t, bad)
    values = np.array(stream.positions, dtype=float)
    values[inside, col] = np.interp(stream.time_s[inside], t[~bad], y[~bad])
    repaired = replace(stream, positions=frozen(values))
    return replace(log, joint_positions=frozen(positions), joint_stream=repaired)


def _between_good(ts: np.ndarray, t: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Which of the stream's times ``ts`` lie strictly between the good records around a bad run."""
    good = np.flatnonzero(~bad)
    left = np.searchsorted(t[good], ts, side="right") - 1
    inside = np.zeros(ts.size, dtype=bool)
    ok = (left >= 0) & (left + 1 < good.size)
    lo, hi = good[left[ok]], good[np.minimum(left[ok] + 1, good.size - 1)]
    inside[ok] = (hi - lo > 1) & (ts[ok] > t[lo]) & (ts[ok] < t[hi])
    return inside
