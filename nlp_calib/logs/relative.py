"""A reference that measures its own motion: increments between pairs of a log's records.

A scan matcher (a 2-D lidar's scans matched pairwise), visual odometry or any tool that reports
relative motions gives, for each pair of its stamps, the sensor's motion ``z = (x, y, θ)`` from
its pose at the first stamp to its pose at the second, in its own frame at the first. Each
increment is compared with the wheels' prediction over exactly its two stamps: a bad one spoils
one residual, never the rest of a chain. ``quality`` keeps what the matcher said of each (its
convergence, the share of points it matched, its fit error), for the screen that names bad ones.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from nlp_calib.core import poses
from nlp_calib.core.numeric import wrap_angle


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class RelativeMotions:
    """Increment ``k`` joins record ``first[k]`` to record ``last[k] > first[k]``; ``z[k]`` is the
    sensor's motion over it ``(x, y, θ)`` (m, rad) in its frame at ``first[k]`` (a gyro's: its
    rates integrated over it and its duration, ``(∫ω_x, ∫ω_y, ∫ω_z, Δt)``); ``quality`` maps
    a measure's name to its value per increment; ``line_numbers`` says where each came from (a
    file's line, a scan's message number)."""

    first: np.ndarray
    last: np.ndarray
    z: np.ndarray
    line_numbers: np.ndarray
    quality: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = self.first.shape[0]
        if (
            self.last.shape != (n,)
            or self.z.shape[:1] != (n,)
            or self.z.ndim != 2
            or self.line_numbers.shape != (n,)
        ):
            raise ValueError("increments: first, last, z and line_numbers must have one entry per increment")
        if n and np.any(self.last <= self.first):
            raise ValueError("increments: each must end at a later record than it starts")

    @property
    def n(self) -> int:
        return int(self.first.shape[0])

    def take(self, keep: np.ndarray) -> RelativeMotions:
        """The increments ``keep`` (a mask or indices) marks, in order."""
        return RelativeMotions(
            _frozen(self.first[keep]),
            _frozen(self.last[keep]),
            _frozen(self.z[keep]),
            _frozen(self.line_numbers[keep]),
            {k: _frozen(v[keep]) for k, v in self.quality.items()},
        )

    def select(self, start: int, stop: int) -> RelativeMotions:
        """Those inside records ``start:stop``, their records counted from ``start``."""
        inside = (self.first >= start) & (self.last < stop)
        out = self.take(inside)
        return replace(out, first=_frozen(out.first - start), last=_frozen(out.last - start))

    def single(self) -> np.ndarray:
        """Which increments join two consecutive records (one interval each)."""
        return np.asarray(self.last - self.first == 1)

    def covered(self, n_records: int) -> np.ndarray:
        """Which of the ``n_records - 1`` intervals an increment of one interval measures."""
        mask = np.zeros(max(n_records - 1, 0), dtype=bool)
        one = self.single()
        mask[self.first[one]] = True
        return mask

    def chain(self, n_records: int) -> np.ndarray:
        """The sensor's poses ``(n_records, 3)`` composed from the one-interval increments, from
        the origin, held over the intervals none measures (for figures only: the residuals compare
        each increment itself)."""
        steps = np.zeros((max(n_records - 1, 0), 3))
        one = self.single()
        if self.z.shape[1] == 3:
            steps[self.first[one]] = self.z[one]
        else:  # a gyro's integrated rates: the turn about its own z axis, as a heading
            steps[self.first[one], 2] = self.z[one, 2]
        out = poses.accumulate(np.zeros(3), steps)
        out[:, 2] = wrap_angle(out[:, 2])
        return out
