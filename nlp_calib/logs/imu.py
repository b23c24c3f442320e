"""A gyro's rates (``sensor_msgs/Imu``'s angular velocity, or a CSV ``t,wx,wy,wz``), integrated
into the increments a gyro reference is compared over.

The rates are read in the IMU's own frame (rad/s) at their stamps (header stamps, or the bag's
record times). An **integration interval** joins two samples about ``interval_s`` apart (a whole
number of the gyro's own periods); over it the rates are integrated by trapezoids, sample to
sample, into ``(∫ω_x, ∫ω_y, ∫ω_z, Δt)``: one increment of the reference, timed at its two samples'
stamps (:func:`~nlp_calib.logs.motions.timed_by_motions` then makes a record at each, the joints
interpolated there). An interval across a gap in the rates (over :data:`GAP_PERIODS` of the
gyro's median period) is left out: a trapezoid across it would guess the turn.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.logs.bag_files import BagError, messages, opened
from nlp_calib.logs.log import frozen
from nlp_calib.logs.motions import MotionTable
from nlp_calib.logs.text_tables import data_lines, numbers, stamp_ns

IMU_TYPE = "sensor_msgs/msg/Imu"
#: The columns of a gyro's CSV.
COLUMNS = ("t", "wx", "wy", "wz")
#: A step between samples longer than this many median periods is a gap.
GAP_PERIODS = 5.0


@dataclass(frozen=True)
class GyroRates:
    """A gyro's samples in stamp order (one per stamp): stamps (ns), rates ``(n, 3)`` (rad/s, its
    own frame), each sample's message or line number, and its frame."""

    source: str
    stamp_ns: np.ndarray
    rates: np.ndarray
    numbers: np.ndarray
    frame: str = "imu_link"

    @property
    def n(self) -> int:
        return int(self.stamp_ns.size)


def _sorted(source: str, ns: list[int], rows: list[list[float]], at: list[int], frame: str) -> GyroRates:
    stamps = np.array(ns, dtype=np.int64)
    order = np.argsort(stamps, kind="stable")
    stamps = stamps[order]
    first = np.concatenate([[True], np.diff(stamps) > 0])
    rates = np.array(rows, dtype=float).reshape(-1, 3)[order][first]
    if stamps[first].size < 2 or not np.all(np.isfinite(rates)):
        bad = int(np.sum(~np.all(np.isfinite(rates), axis=1)))
        raise DatasetError(
            source, None, f"a gyro needs at least 2 samples of finite rates ({bad} not finite)"
        )
    return GyroRates(source, stamps[first], rates, np.array(at, dtype=np.int64)[order][first], frame)


def read_imu(path: str | Path, topic: str, receive: bool = False) -> GyroRates:
    """The angular velocities on the Imu ``topic`` (header stamps, or with ``receive`` the bag's
    record times)."""
    p = Path(path)
    ns: list[int] = []
    rows: list[list[float]] = []
    frame = ""
    with opened(p) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        if types.get(topic) != IMU_TYPE:
            held = f"holds {types[topic]}" if topic in types else "is not in the bag"
            raise BagError(
                p,
                f"imu: topic {topic!r} {held}; name a {IMU_TYPE} topic (nlp-calib import-bag {p} lists them)",
            )
        for _, recorded, msg in messages(reader, p, (topic,)):
            w = msg.angular_velocity
            stamp = recorded if receive else int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)
            ns.append(int(stamp))
            rows.append([float(w.x), float(w.y), float(w.z)])
            frame = frame or str(msg.header.frame_id).strip("/")
    if len(rows) < 2:
        raise BagError(p, f"imu: topic {topic!r} has {len(rows)} message(s); a gyro needs at least 2")
    return _sorted(f"{p} {topic}", ns, rows, list(range(1, len(rows) + 1)), frame or "imu_link")


def read_gyro_csv(path: str | Path) -> GyroRates:
    """A gyro's CSV: a header row ``t,wx,wy,wz``, then a row per sample (s, read to the
    nanosecond; rad/s in the IMU's frame); ``#`` lines are comments."""
    p = str(path)
    lines = data_lines(path)
    first = next(lines, None)
    if first is None or tuple(f.strip() for f in first[1].split(",")) != COLUMNS:
        raise DatasetError(
            p, None if first is None else first[0], f"expected a header row '{','.join(COLUMNS)}'"
        )
    ns, rows, at = [], [], []
    for number, text in lines:
        fields = text.split(",")
        if len(fields) != len(COLUMNS):
            raise DatasetError(p, number, f"has {len(fields)} fields; expected 4 ({','.join(COLUMNS)})")
        ns.append(stamp_ns(fields[0], p, number))
        rows.append(numbers(p, number, fields[1:], "3 rates (rad/s)"))
        at.append(number)
    return _sorted(p, ns, rows, at, "imu_link")


def integrated(rates: GyroRates, interval_s: float) -> MotionTable:
    """The gyro's increments over integration intervals of about ``interval_s`` (see the module
    docstring), each ``(∫ω_x, ∫ω_y, ∫ω_z, Δt)``."""
    t = rates.stamp_ns
    dt = np.diff(t).astype(float) * 1e-9
    period = float(np.median(dt))
    every = max(1, round(interval_s / period))
    ends = np.arange(0, rates.n, every)
    area = np.vstack(
        [np.zeros((1, 3)), np.cumsum(0.5 * (rates.rates[1:] + rates.rates[:-1]) * dt[:, None], axis=0)]
    )
    gap = np.concatenate([[0], np.cumsum(dt > GAP_PERIODS * period)])
    a, b = ends[:-1], ends[1:]
    keep = gap[b] == gap[a]
    a, b = a[keep], b[keep]
    if a.size == 0:
        raise DatasetError(
            rates.source, None, f"no integration interval of {interval_s:g} s lies inside the rates"
        )
    z = np.column_stack([area[b] - area[a], (t[b] - t[a]).astype(float) * 1e-9])
    return MotionTable(rates.source, frozen(t[a]), frozen(t[b]), frozen(z), frozen(rates.numbers[a]), {})
