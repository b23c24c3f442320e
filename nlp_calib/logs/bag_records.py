"""A bag's encoder and tracker messages paired into the records of a log.

The pairing rule: each encoder message that can be paired is one record, at its own stamp. Its
tracker pose is the tracker's pose at that stamp: the pose itself when a tracker message has the
same stamp, otherwise the interpolation between the tracker poses just before and just after it
(linear in x and y, along the shorter arc in θ), provided those two are at most ``max_gap`` apart.
Encoder messages before the first tracker pose, after the last, or inside a longer gap of the
tracker are left out. Tracker poses are taken in stamp order (the first recorded, when two share
a stamp); encoder messages stay in the order the bag recorded them, so a stamp that goes back is
reported (or dropped, ``strict: false``) as it is in a text log.

Counter readings are taken modulo :data:`~nlp_calib.core.numeric.COUNTER_MODULUS`, the text
format's uint32 range: a counter published signed or unwrapped then steps exactly as the uint32 a
text log holds. Absolute readings are kept as they are and must lie in ``[0, range)``.

The records are written in the text format (every number exact) and read back by
:func:`~nlp_calib.logs.reader.parse_log`, so a bag passes every check a text log does, with the
same messages; a record's "line" is its line in that text, which ``import-bag`` writes out.
``model_pose`` (the vendor's odometry, used only by the report's model check) is zero: a bag
carries none.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.core.numeric import COUNTER_MODULUS, wrap_angle
from nlp_calib.logs.bag_joints import clock_shift_ns
from nlp_calib.logs.bag_reader import BagError, BagTopics, Drops, Stamped, read_topics
from nlp_calib.logs.log import EncoderKind, Log, LogHeader
from nlp_calib.logs.reader import parse_log
from nlp_calib.logs.writer import format_log


@dataclass(frozen=True)
class Pairing:
    """How many encoder messages found a tracker pose, where the others were, and the messages
    the import did not use as they were (``drops``: malformed JointStates, quaternions that are
    no rotation or were normalised)."""

    encoder_messages: int
    tracker_poses: int
    before: int
    after: int
    in_gaps: int
    max_gap_s: float
    drops: Drops = field(default_factory=Drops)

    @property
    def paired(self) -> int:
        return self.encoder_messages - self.before - self.after - self.in_gaps

    def describe(self) -> str:
        left = (
            f"{self.before} before the first tracker pose, {self.after} after the last, {self.in_gaps} "
            f"in tracker gaps over {self.max_gap_s:g} s"
        )
        dropped = f"; not used as they were: {self.drops.describe()}" if self.drops.counts else ""
        return (
            f"{self.paired} of {self.encoder_messages} encoder messages paired with the tracker's "
            f"{self.tracker_poses} poses ({left}){dropped}"
        )


def pair(encoders: Stamped, tracker: Stamped, max_gap_s: float) -> tuple[np.ndarray, np.ndarray, Pairing]:
    """The encoder messages (indices) that pair with the tracker, their tracker poses, and a summary."""
    order = np.argsort(tracker.stamp_ns, kind="stable")
    ts, poses = tracker.stamp_ns[order], tracker.values[order]
    first = np.concatenate([[True], np.diff(ts) > 0])
    ts, poses = ts[first], poses[first]
    t = encoders.stamp_ns
    hi = np.searchsorted(ts, t, side="left")  # the first tracker pose at or after each encoder stamp
    at = np.minimum(hi, ts.shape[0] - 1)
    exact = ts[at] == t
    lo = np.maximum(hi - 1, 0)
    inside = (hi > 0) & (hi < ts.shape[0])
    bridged = inside & (ts[at] - ts[lo] <= round(max_gap_s * 1e9))
    ok = exact | bridged
    # Fractions from integer nanoseconds: no float time needs to hold an epoch's digits.
    span = np.maximum(ts[at] - ts[lo], 1).astype(float)
    s = ((t - ts[lo]).astype(float) / span)[:, None]
    a, b = poses[lo], poses[at]
    out = a + s * np.concatenate([b[:, :2] - a[:, :2], wrap_angle(b[:, 2:] - a[:, 2:])], axis=1)
    out[:, 2] = wrap_angle(out[:, 2])
    out[exact] = poses[at][exact]  # a shared stamp takes the tracker's pose as it is
    before = int(np.sum(t < ts[0]))
    after = int(np.sum(t > ts[-1]))
    drops = Drops({**encoders.drops.counts, **tracker.drops.counts})
    summary = Pairing(
        encoders.n, int(ts.shape[0]), before, after, int(np.sum(~ok)) - before - after, max_gap_s, drops
    )
    return np.flatnonzero(ok), out[ok], summary


@dataclass(frozen=True)
class BagRecords:
    """The paired records of a bag: stamps (ns), raw counts and the tracker's ``T_world_sensor``."""

    path: str
    time_ns: np.ndarray
    counts: np.ndarray
    T_world_sensor: np.ndarray
    pairing: Pairing

    def text(self, header: LogHeader, encoder_kinds: Mapping[str, EncoderKind]) -> str:
        """The records as a text log under ``header`` (whose encoders are the joints, in order)."""
        if len(header.encoder_names) != self.counts.shape[1]:
            raise ValueError(f"{len(header.encoder_names)} header encoders for {self.counts.shape[1]} joints")
        ticks = self.counts.copy()
        for j, name in enumerate(header.encoder_names):
            if encoder_kinds.get(name) == "counter":
                ticks[:, j] %= COUNTER_MODULUS
        zeros = np.zeros_like(self.T_world_sensor)
        return format_log(header, self.time_ns, ticks, zeros, self.T_world_sensor, digits=None)

    def log(self, header: LogHeader, encoder_kinds: Mapping[str, EncoderKind], *, strict: bool = True) -> Log:
        """The :class:`Log` the text log of :meth:`text` reads as."""
        return parse_log(
            self.text(header, encoder_kinds).splitlines(), encoder_kinds, self.path, strict=strict
        )


def read_bag_records(path: str | Path, topics: BagTopics) -> BagRecords:
    """Read and pair a bag's encoder and tracker messages (see the module docstring for the rule)."""
    encoders, tracker = read_topics(path, topics)
    encoders = replace(
        encoders,
        stamp_ns=encoders.stamp_ns + clock_shift_ns(Path(path), encoders, tracker, topics.clock_offset),
    )
    tracker = replace(
        tracker, values=tracker.values[:, :3]
    )  # the planar pose (z is kept for joints in radians)
    index, poses, summary = pair(encoders, tracker, topics.max_gap)
    if index.shape[0] < 2:
        span = (
            f"encoder stamps {_span(encoders)}, tracker stamps {_span(tracker)}"
            if summary.in_gaps == 0
            else f"the tracker's poses are over {topics.max_gap:g} s apart; raise max_gap"
        )
        raise BagError(
            path, f"{summary.describe()}; at least 2 are needed ({span}: do both topics share a clock?)"
        )
    return BagRecords(
        path=str(path),
        time_ns=encoders.stamp_ns[index],
        counts=np.round(encoders.values[index]).astype(np.int64),
        T_world_sensor=poses,
        pairing=summary,
    )


def _span(s: Stamped) -> str:
    return f"{s.stamp_ns.min() * 1e-9:.3f}-{s.stamp_ns.max() * 1e-9:.3f} s"


def read_bag(
    path: str | Path,
    topics: BagTopics,
    header: LogHeader,
    encoder_kinds: Mapping[str, EncoderKind],
    *,
    strict: bool = True,
) -> Log:
    """A bag read as a :class:`Log` with ``header`` (a bag has none): the same checks, drops and errors
    as the text log ``import-bag`` writes from it; a warning says when tracker gaps left messages out
    or messages were dropped or changed (:class:`~nlp_calib.logs.bag_reader.Drops`)."""
    records = read_bag_records(path, topics)
    if records.pairing.in_gaps or records.pairing.drops.worrying:
        warnings.warn(f"{path}: {records.pairing.describe()}", NlpCalibWarning, stacklevel=2)
    return records.log(header, encoder_kinds, strict=strict)
