"""Trajectory errors as a run reports them: evo's statistics and the figures of one parameter set.

The figures are computed by :mod:`nlp_calib.analysis.metrics` (dead reckoning against the
tracker); this module holds only what they are, so that a result can be read, stored and
formatted without the computation.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

#: Distances (m) along the tracker's path over which the relative pose error is reported.
RPE_DISTANCES = (1.0, 5.0)
#: Relative tolerance on a pair's distance (evo's default).
RPE_TOLERANCE = 0.1
#: The labels of :meth:`TrajectoryMetrics.fair_figures`.
FAIR_FIGURES = ("segment ATE mean [m]", *(f"RPE over {d:g} m [m]" for d in RPE_DISTANCES))


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of a set of errors (m or rad), as evo reports them; NaN when there are none."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    n: int

    @classmethod
    def of(cls, errors: np.ndarray) -> ErrorStats:
        e = np.asarray(errors, dtype=float)
        if e.size == 0:
            nan = float("nan")
            return cls(nan, nan, nan, nan, nan, nan, 0)
        return cls(
            rmse=float(np.sqrt(np.mean(e * e))),
            mean=float(e.mean()),
            median=float(np.median(e)),
            std=float(e.std()),
            min=float(e.min()),
            max=float(e.max()),
            n=int(e.size),
        )

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)


@dataclass(frozen=True)
class TrajectoryMetrics:
    """Position errors (m) of dead-reckoned sensor tracks against the tracker over ``records``.

    ``ate``, ``ate_final``: the full-run track's statistics and final error; ``rpe_trans`` / ``rpe_rot``: mean
    relative pose error over windows of ``rpe_window`` records (m, rad); ``segment_ate`` and
    ``segment_ate_aligned``: the track restarted after each fault; ``rpe_distance``: translation
    error over each of :data:`RPE_DISTANCES` of travel (m → stats); ``segments``: the number of
    fault-free stretches; ``distance_m``: the tracker's path length. Poses marked bad (tracker
    jumps) are left out of every figure and of the path length.
    """

    ate_final: float
    rpe_trans: float
    rpe_rot: float
    rpe_window: int
    records: int
    ate: ErrorStats
    segment_ate: ErrorStats
    segment_ate_aligned: ErrorStats
    rpe_distance: dict[float, ErrorStats]
    segments: int
    distance_m: float

    @property
    def ate_mean(self) -> float:
        return self.ate.mean

    @property
    def ate_max(self) -> float:
        return self.ate.max

    def figures(self) -> list[tuple[str, float]]:
        """The figures a report shows, as (label with unit, value): fault-robust ones first."""
        return [
            ("segment ATE mean [m]", self.segment_ate.mean),
            ("segment ATE aligned [m]", self.segment_ate_aligned.mean),
            *((f"RPE over {d:g} m [m]", s.mean) for d, s in self.rpe_distance.items()),
            ("full-run ATE mean [m]", self.ate_mean),
            ("full-run ATE max [m]", self.ate_max),
            (f"RPE over {self.rpe_window} records [m]", self.rpe_trans),
            (f"RPE over {self.rpe_window} records [rad]", self.rpe_rot),
        ]

    def fair_figures(self) -> dict[str, float]:
        """The fault-robust figures a check or a fleet table compares: the segment ATE and the RPE
        over each of :data:`RPE_DISTANCES`, by label."""
        every = dict(self.figures())
        return {label: every[label] for label in FAIR_FIGURES if label in every}

    def as_dict(self) -> dict[str, object]:
        return {
            "ate_mean": self.ate_mean,
            "ate_max": self.ate_max,
            "ate_final": self.ate_final,
            "rpe_trans": self.rpe_trans,
            "rpe_rot": self.rpe_rot,
            "rpe_window": self.rpe_window,
            "records": self.records,
            "ate": self.ate.as_dict(),
            "segment_ate": self.segment_ate.as_dict(),
            "segment_ate_aligned": self.segment_ate_aligned.as_dict(),
            **{f"rpe_{d:g}m": s.as_dict() for d, s in self.rpe_distance.items()},
            "segments": self.segments,
            "distance_m": self.distance_m,
        }
