"""A 2-D lidar's scans (``sensor_msgs/LaserScan``) and the lidar's own motion between them.

Each scan becomes points in the lidar's frame (returns inside ``[range_min, range_max]``); each
scan is matched to the one before by generalized ICP (small_gicp, a maintained registration
library: ``pip install 'nlp_calib[lidar]'``), which gives the lidar's motion from the earlier scan
to the later one and what the match is worth: whether it converged, the share of the later
scan's points it matched (``inliers``) and its cost per matched point (``fit_error``). A 2-D
scan's points all lie in one plane, where a point's neighbours give it no plane of its own; each
scan is stood up as a short wall (copies at a few heights), so that every wall it sees is a
vertical plane and the match constrains x, y and yaw as a scan's geometry allows.

A scan is taken as seen at its header stamp (no correction for the motion during a sweep: at
10 Hz and 0.5 m/s the sweep moves the lidar up to 5 cm, the same for every scan, so it biases the
lidar's position along its direction of travel by half that at most; give scans from a driver
that de-skews them where this matters).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.core.ranges import Range
from nlp_calib.logs.bag_files import BagError, messages, opened
from nlp_calib.logs.motions import MotionTable

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
_INSTALL = (
    "matching a lidar's scans needs small_gicp: install the lidar extra: pip install 'nlp_calib[lidar]'"
)


@dataclass(frozen=True)
class LaserScans:
    """A topic's scans in stamp order: stamps (ns), ranges ``(n, beams)`` (m; inf where no return),
    the beams' angles (rad, the lidar's frame), the valid range and the lidar's frame."""

    topic: str
    stamp_ns: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    range_min: float
    range_max: float
    frame: str

    @property
    def n(self) -> int:
        return int(self.stamp_ns.size)

    def points(self, k: int) -> np.ndarray:
        """Scan ``k``'s returns as points ``(m, 2)`` in the lidar's frame."""
        r = self.ranges[k]
        ok = np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max)
        return np.column_stack([r[ok] * np.cos(self.angles[ok]), r[ok] * np.sin(self.angles[ok])])


#: Returns a scan needs for a match (fewer: the match is skipped as not converged).
MIN_RETURNS = 10
#: Returns whose median lies farther than this (m) are no 2-D lidar's in metres (mm, most likely).
MAX_TYPICAL_RANGE_M = 200.0
#: Closest two scans' stamps may be (ns) for a lidar (a lidar sweeps at 5-50 Hz; 1 kHz is none).
MIN_SCAN_INTERVAL_NS = 1_000_000


def _geometry(p: Path, topic: str, number: int, msg: Any) -> str | None:
    """Why scan ``number``'s beam geometry cannot be right (None when it can): angles and limits
    finite, and as many ranges as ``angle_min``, ``angle_max`` and ``angle_increment`` give."""
    a0, a1, step = (float(msg.angle_min), float(msg.angle_max), float(msg.angle_increment))
    r0, r1, n = float(msg.range_min), float(msg.range_max), len(msg.ranges)
    where = f"scan {number} on {topic!r}"
    if not all(math.isfinite(v) for v in (a0, a1, step, r0, r1)):
        return (
            f"{where}: its beam geometry is not finite (angle_min {a0}, angle_max {a1}, angle_increment "
            f"{step}, range_min {r0}, range_max {r1}); the driver's message is damaged"
        )
    if n == 0:
        return f"{where} holds no ranges"
    if not 0.0 <= r0 < r1:
        return f"{where}: range_min {r0} and range_max {r1} admit no return; the driver's limits are wrong"
    beams = (a1 - a0) / step + 1 if step != 0 else math.inf
    if n > 1 and (abs(beams - n) > 1.01 or abs(step) * (n - 1) > 2 * math.pi + abs(step)):
        return (
            f"{where}: its beam geometry does not fit its ranges: angle_min {a0:g}, angle_max {a1:g} and "
            f"angle_increment {step:g} give {beams:.4g} beams, the message holds {n} ranges; the driver's "
            "angles are wrong (a beam's angle is angle_min + k·angle_increment), and every point would be "
            "placed at a wrong bearing"
        )
    return None


def _read(p: Path, topic: str, receive: bool) -> tuple[list[int], list[np.ndarray], tuple[Any, ...]]:
    """The scans' stamps and ranges, and the first scan's beams, limits and frame."""
    stamps: list[int] = []
    rows: list[np.ndarray] = []
    first: tuple[Any, ...] | None = None
    with opened(p) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        if types.get(topic) != SCAN_TYPE:
            held = f"holds {types[topic]}" if topic in types else "is not in the bag"
            raise BagError(
                p,
                f"scan: topic {topic!r} {held}; name a {SCAN_TYPE} topic (nlp-calib import-bag {p} lists "
                "them)",
            )
        for _, recorded, msg in messages(reader, p, (topic,)):
            if (problem := _geometry(p, topic, len(rows) + 1, msg)) is not None:
                raise BagError(p, problem)
            beams = (float(msg.angle_min), float(msg.angle_increment), len(msg.ranges))
            if first is None:
                first = (beams, float(msg.range_min), float(msg.range_max), str(msg.header.frame_id))
            elif beams != first[0]:
                raise BagError(
                    p,
                    f"scan {len(rows) + 1} on {topic!r} has other beams than the first ({beams} against "
                    f"{first[0]})",
                )
            stamp = recorded if receive else int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)
            stamps.append(stamp)
            rows.append(np.asarray(msg.ranges, dtype=float))
    if first is None or len(rows) < 2:
        raise BagError(p, f"scan: topic {topic!r} has {len(rows)} scan(s); a lidar needs at least 2")
    return stamps, rows, first


def _once_each(p: Path, topic: str, stamp_ns: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Which scans (in stamp order) to keep: each stamp once (the first scan of it), the others
    counted and said; a lidar's scans sweep at a lidar's rate."""
    keep = np.ones(stamp_ns.size, dtype=bool)
    keep[1:] = np.diff(stamp_ns) != 0
    dropped = int((~keep).sum())
    if keep.sum() < 2:
        raise BagError(
            p,
            f"scan: all {stamp_ns.size} scans on {topic!r} carry one stamp; the driver does not stamp its "
            "scans: time them by the bag's record times (stamps: receive)",
        )
    if dropped:
        twice = np.flatnonzero(~keep)
        same = int(sum(np.array_equal(ranges[k], ranges[k - 1], equal_nan=True) for k in twice))
        warnings.warn(
            f"{p}: {dropped} of {stamp_ns.size} scans on {topic!r} carry the stamp of the scan before "
            f"({same} of them the same scan recorded twice); each stamp's first scan is kept, the "
            f"{dropped} others dropped",
            NlpCalibWarning,
            stacklevel=3,
        )
    gaps = np.diff(stamp_ns[keep])
    if float(np.median(gaps)) < MIN_SCAN_INTERVAL_NS:
        raise BagError(
            p,
            f"scan: the scans on {topic!r} are stamped {float(np.median(gaps)) / 1e6:.3g} ms apart (median), "
            "faster than any lidar sweeps; their stamps are not the scans' times: time them by the bag's "
            "record times (stamps: receive)",
        )
    return keep


#: A field of view narrower than this (rad) is said: a matcher's motions from it are weak (a depth
#: camera's scan looks down a corridor), and the drive may not determine the mount.
NARROW_FIELD = np.pi / 2


def _field_of_view(p: Path, topic: str, n_beams: int, step: float) -> None:
    """Refuse scans of fewer beams than a match needs, and say a narrow field of view."""
    degrees = np.degrees(abs(step) * n_beams)
    if n_beams < MIN_RETURNS:
        raise BagError(
            p,
            f"scan: each scan on {topic!r} holds {n_beams} beams over {degrees:.3g}° (its field of view); a "
            f"scan match needs at least {MIN_RETURNS} returns: widen the driver's field of view (angle_min, "
            "angle_max) or give a reference of more beams",
        )
    if abs(step) * n_beams < NARROW_FIELD:
        warnings.warn(
            f"{p}: {topic}: the scans cover {degrees:.3g}° ({n_beams} beams): a narrow field of view, whose "
            "matches are weak along what it sees; parameters the drive seems not to determine may be the "
            "field of view's doing (a lidar sweeping 180° or more fixes it)",
            NlpCalibWarning,
            stacklevel=3,
        )


def _valid_returns(p: Path, topic: str, ranges: np.ndarray, range_min: float, range_max: float) -> None:
    """Refuse scans that hold no usable returns, naming why (the first cause found)."""
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(ranges) & (ranges >= range_min) & (ranges <= range_max)
    usable = int((ok.sum(axis=1) >= MIN_RETURNS).sum())
    if usable >= 2:
        typical = float(np.median(ranges[ok]))
        if typical > MAX_TYPICAL_RANGE_M:
            raise BagError(
                p,
                f"scan: the returns on {topic!r} lie {typical:.4g} m away (their median; range_max "
                f"{range_max:g}), farther than a 2-D lidar sees: its ranges look like millimetres; give "
                "them in metres (REP 103, sensor_msgs/LaserScan)",
            )
        return
    finite = np.isfinite(ranges)
    with np.errstate(invalid="ignore"):
        negative, beyond = int((ranges < 0).sum()), int((finite & (ranges > range_max)).sum())
    raise BagError(
        p,
        f"scan: no valid lidar returns on {topic!r}: {usable} of {ranges.shape[0]} scans hold {MIN_RETURNS} "
        f"ranges inside [range_min {range_min:g}, range_max {range_max:g}] ({ranges.size} ranges: "
        f"{int((~finite).sum())} NaN or inf, {negative} negative, {beyond} beyond range_max); check the "
        "driver's ranges and limits",
    )


def read_scans(path: str | Path, topic: str, receive: bool = False) -> LaserScans:
    """The LaserScan messages on ``topic`` (timed by their header stamps, or the bag's record
    times with ``receive``); every scan must have the first one's beams, a beam geometry that fits
    its ranges, and a stamp of its own (a scan recorded twice is kept once, and said)."""
    p = Path(path)
    stamps, rows, first = _read(p, topic, receive)
    (angle_min, step, n_beams), range_min, range_max, frame = first
    order = np.argsort(np.array(stamps, dtype=np.int64), kind="stable")
    stamp_ns, ranges = np.array(stamps, dtype=np.int64)[order], np.array(rows)[order]
    keep = _once_each(p, topic, stamp_ns, ranges)
    stamp_ns, ranges = stamp_ns[keep], ranges[keep]
    _field_of_view(p, topic, int(n_beams), step)
    _valid_returns(p, topic, ranges, range_min, range_max)
    if not frame.strip("/"):
        warnings.warn(
            f"{p}: the scans on {topic!r} carry no frame_id; the hand-off files name their frame "
            "'laser' and no /tf_static mount is looked up (set the driver's frame_id)",
            NlpCalibWarning,
            stacklevel=2,
        )
    return LaserScans(
        topic,
        stamp_ns,
        ranges,
        angle_min + step * np.arange(int(n_beams)),
        range_min,
        range_max,
        frame.strip("/") or "laser",
    )


#: What the matcher may be told.
RESOLUTION = Range(1e-3, 1.0)
CORRESPONDENCE = Range(1e-3, 10.0)
ITERATIONS = Range(1, 1000, integer=True)


@dataclass(frozen=True)
class ScanMatching:
    """How scans are matched: the voxel size they are thinned to (m), the farthest two points are
    paired across (m), the matcher's iterations, and the heights (m) a scan is stood up at."""

    resolution: float = 0.05
    max_correspondence: float = 0.3
    max_iterations: int = 50
    heights: tuple[float, ...] = (-0.1, 0.0, 0.1)

    def __post_init__(self) -> None:
        for name, limit in (
            ("resolution", RESOLUTION),
            ("max_correspondence", CORRESPONDENCE),
            ("max_iterations", ITERATIONS),
        ):
            if (reason := limit.problem(getattr(self, name))) is not None:
                raise DatasetError("<scan matching>", None, f"{name} {reason}")

    def stood_up(self, points: np.ndarray) -> np.ndarray:
        """A scan's points ``(m, 2)`` as a short wall ``(m·heights, 3)``."""
        return np.vstack([np.column_stack([points, np.full(points.shape[0], h)]) for h in self.heights])


def _se2(z: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    c, s = math.cos(z[2]), math.sin(z[2])
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = z[:2]
    return T


def match_scans(scans: LaserScans, options: ScanMatching | None = None) -> MotionTable:
    """Each scan matched to the one before: the lidar's motions between consecutive stamps, with
    each match's ``converged``, ``inliers`` and ``fit_error`` (see the module docstring)."""
    try:
        import small_gicp
    except ImportError:
        raise DatasetError(scans.topic, None, _INSTALL) from None
    opts = options or ScanMatching()
    n = scans.n
    z, quality = np.zeros((n - 1, 3)), {k: np.zeros(n - 1) for k in ("converged", "inliers", "fit_error")}

    def cloud(k: int) -> tuple[Any, Any]:
        return small_gicp.preprocess_points(opts.stood_up(scans.points(k)), opts.resolution, 10, 1)

    target, tree = cloud(0)
    guess = np.zeros(3)
    for k in range(1, n):
        source, source_tree = cloud(k)
        size = source.size()
        if size < 10 or target.size() < 10:
            quality["converged"][k - 1] = 0.0
        else:
            result = small_gicp.align(
                target,
                source,
                tree,
                init_T_target_source=_se2(guess),
                registration_type="GICP",
                max_correspondence_distance=opts.max_correspondence,
                num_threads=1,
                max_iterations=opts.max_iterations,
            )
            T = np.asarray(result.T_target_source)
            z[k - 1] = (T[0, 3], T[1, 3], math.atan2(T[1, 0], T[0, 0]))
            inliers = int(result.num_inliers)
            quality["converged"][k - 1] = float(result.converged)
            quality["inliers"][k - 1] = inliers / size
            quality["fit_error"][k - 1] = float(result.error) / max(inliers, 1)
            # The next match starts from this motion while this one looks sound (constant speed).
            guess = z[k - 1] if result.converged and inliers > size // 2 else np.zeros(3)
        target, tree = source, source_tree
    return MotionTable(
        scans.topic,
        scans.stamp_ns[:-1].copy(),
        scans.stamp_ns[1:].copy(),
        z,
        np.arange(2, n + 1, dtype=np.int64),  # a motion's "line": its later scan's message number
        quality,
    )
