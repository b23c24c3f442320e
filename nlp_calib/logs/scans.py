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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core.errors import DatasetError
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


def read_scans(path: str | Path, topic: str, receive: bool = False) -> LaserScans:
    """The LaserScan messages on ``topic`` (timed by their header stamps, or the bag's record
    times with ``receive``); every scan must have the first one's beams."""
    p = Path(path)
    stamps: list[int] = []
    rows: list[np.ndarray] = []
    first: tuple[tuple[float, float, int], float, float, str] | None = None
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
    (angle_min, step, n_beams), range_min, range_max, frame = first
    order = np.argsort(np.array(stamps, dtype=np.int64), kind="stable")
    return LaserScans(
        topic,
        np.array(stamps, dtype=np.int64)[order],
        np.array(rows)[order],
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
