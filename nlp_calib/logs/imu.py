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

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.logs.bag_files import BagError, messages, opened
from nlp_calib.logs.log import frozen
from nlp_calib.logs.motions import MotionTable
from nlp_calib.logs.text_tables import check_increasing, data_lines, numbers, seconds, stamp_ns

IMU_TYPE = "sensor_msgs/msg/Imu"
#: The columns of a gyro's CSV.
COLUMNS = ("t", "wx", "wy", "wz")
#: A step between samples longer than this many median periods is a gap.
GAP_PERIODS = 5.0
#: A rate no wheeled base turns at (rad/s, two turns a second): rates beyond it on more than
#: 1 - :data:`RATE_QUANTILE` of the samples are not rad/s (a slow turn's 0.21 rad/s reads 12 in
#: degrees per second).
MAX_RATE = 12.0
RATE_QUANTILE = 0.99


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


def _one_stamp(source: str, stamps: np.ndarray, fix: str) -> None:
    """Refuse samples that all carry one stamp (a driver that never stamps them): ``fix`` says how."""
    if stamps.size >= 2 and np.all(stamps == stamps[0]):
        raise DatasetError(
            source, None, f"all {stamps.size} samples carry one stamp ({seconds(int(stamps[0]))} s); {fix}"
        )


def _said(source: str, count: int, total: int, first: str, what: str) -> None:
    warnings.warn(
        f"{source}: {count} of {total} samples {what} (first: {first})", NlpCalibWarning, stacklevel=4
    )


def _checked(
    source: str, ns: list[int], rows: list[list[float]], at: list[int], word: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The samples in stamp order, each stamp once, with finite rates in rad/s: a sample of
    non-finite rates is left out, one stamped before its predecessor sorted into place, one
    repeating an earlier stamp dropped (the first kept), each counted and said; rates no wheeled
    base turns at (degrees per second) refused."""
    stamps, numbers_ = np.array(ns, dtype=np.int64), np.array(at, dtype=np.int64)
    rates = np.array(rows, dtype=float).reshape(-1, 3)
    finite = np.all(np.isfinite(rates), axis=1)
    if finite.size < 2:
        raise DatasetError(source, None, f"has {finite.size} sample(s); a gyro needs at least 2")
    if not finite.any():
        raise DatasetError(source, None, f"none of its {finite.size} samples has finite rates (NaN or inf)")
    if not finite.all():
        what = "have non-finite rates (NaN or inf) and are left out: the rates are integrated across them"
        _said(source, int((~finite).sum()), finite.size, f"{word} {int(numbers_[~finite][0])}", what)
        stamps, rates, numbers_ = stamps[finite], rates[finite], numbers_[finite]
    behind = np.flatnonzero(np.diff(stamps) < 0) + 1
    if behind.size:
        what = "are stamped before the sample received before them; sorted by stamp"
        _said(source, behind.size, stamps.size, f"{word} {int(numbers_[behind[0]])}", what)
    order = np.argsort(stamps, kind="stable")
    stamps, rates, numbers_ = stamps[order], rates[order], numbers_[order]
    again = np.concatenate([[False], np.diff(stamps) == 0])
    if again.any():
        what = "repeat an earlier sample's stamp; each stamp is kept once, from its first sample"
        _said(source, int(again.sum()), stamps.size, f"{word} {int(numbers_[again][0])}", what)
        stamps, rates, numbers_ = stamps[~again], rates[~again], numbers_[~again]
    if stamps.size < 2:
        raise DatasetError(
            source, None, f"has {stamps.size} sample(s) of finite rates; a gyro needs at least 2"
        )
    _check_rad_s(source, rates)
    return stamps, rates, numbers_


def _check_rad_s(source: str, rates: np.ndarray) -> None:
    """Refuse rates beyond any wheeled base's turning: a gyro's degrees per second taken for rad/s."""
    top = float(np.quantile(np.linalg.norm(rates, axis=1), RATE_QUANTILE))
    if top > MAX_RATE:
        raise DatasetError(
            source,
            None,
            f"its rates reach {top:.4g} rad/s ({RATE_QUANTILE:.0%} of the samples below), beyond any "
            f"wheeled base's turning ({MAX_RATE:g} rad/s): degrees per second? ({top:.4g}°/s is "
            f"{np.radians(top):.3g} rad/s); give the angular velocity in rad/s (REP 103), e.g. × π/180",
        )


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
    source = f"{p} {topic}"
    how = "the bag's record times" if receive else "its header stamps"
    fix = f"{how} are not the samples' times" + ("" if receive else "; give dataset.stamps: receive")
    _one_stamp(source, np.array(ns, dtype=np.int64), fix)
    stamps, rates, at = _checked(source, ns, rows, list(range(1, len(rows) + 1)), "message")
    return GyroRates(source, stamps, rates, at, frame or "imu_link")


def format_gyro_csv(time_s: np.ndarray, rates: np.ndarray) -> str:
    """A gyro's CSV as :func:`read_gyro_csv` reads it: the header row ``t,wx,wy,wz``, then a row
    per sample (s; rad/s in the IMU's frame, to the float's last digit)."""
    rows = (f"{t:.9f},{w[0]:.17g},{w[1]:.17g},{w[2]:.17g}\n" for t, w in zip(time_s, rates))
    return "t,wx,wy,wz\n" + "".join(rows)


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
    stamps = np.array(ns, dtype=np.int64)
    _one_stamp(p, stamps, "column t holds each sample's time (s)")
    check_increasing(p, stamps, np.array(at, dtype=np.int64))
    stamps, rates, numbers_ = _checked(p, ns, rows, at, "line")
    return GyroRates(p, stamps, rates, numbers_, "imu_link")


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
