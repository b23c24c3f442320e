"""The numbers behind a run's figures and trajectory files, carried in the result.

Computed once, in the analyse stage (:mod:`nlp_calib.pipeline.analyse`), from the same Functions
the solvers and the metrics use; the outputs only draw and format them, so a report can be
written from a stored result alone.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from nlp_calib.results.figures import ErrorStats
from nlp_calib.results.handoff import NoiseRates


@dataclass(frozen=True)
class Track:
    """A labelled sensor track ``(n, 3)`` over the used records; ``solver`` is None for the initial
    guess; ``ate_mean`` is its full-run ATE (m)."""

    label: str
    solver: str | None
    T_world_sensor: np.ndarray
    ate_mean: float
    converged: bool = True


@dataclass(frozen=True)
class SegmentFigures:
    """One solver's figures on one fault-free segment (what ``evo`` reproduces on its TUM files)."""

    solver: str
    segment: int
    poses: int
    ate: ErrorStats
    aligned: ErrorStats
    rpe: tuple[ErrorStats, ...]


@dataclass(frozen=True)
class TrackSeries:
    """The tracker's poses and the dead-reckoned tracks over the used records.

    ``good`` marks the tracker poses not flagged bad; ``parts`` are the fault-free segments
    ``[p, q)`` (indices into the tracks); ``restarted`` holds each solver's track restarted from
    the tracker at the start of every part (what the segment ATE scores); ``faults`` are
    ``(index, kind)``; ``holdout_start`` the index of the first record kept out of the fit;
    ``tracker_z`` the tracker's height at each record where the source has one (None: planar);
    ``level``: for a 3-D sensor, the rotation ``(3, 3)`` from the tracker's world frame to the
    base's frame at the first record (floor plane x-y, x forward), in which figures draw the tracks.
    """

    time_s: np.ndarray
    tracker: np.ndarray
    good: np.ndarray
    parts: tuple[tuple[int, int], ...]
    tracks: tuple[Track, ...]
    restarted: Mapping[str, np.ndarray]
    faults: tuple[tuple[int, str], ...]
    holdout_start: int | None
    segments: tuple[SegmentFigures, ...]
    tracker_z: np.ndarray | None = None
    level: np.ndarray | None = None


@dataclass(frozen=True)
class ResidualSeries:
    """Per-window errors ``(3, n)`` at the initial guess and at each solver's estimate, with the
    kernel's per-component thresholds and the windows' start times."""

    time_s: np.ndarray
    before: np.ndarray
    after: Mapping[str, np.ndarray]
    inliers_before: int
    inliers_after: Mapping[str, int]
    thresholds: np.ndarray
    kernel: str
    delta: float
    solvers_agree: bool


@dataclass(frozen=True)
class ModelCheckSeries:
    """The log's vendor odometry against our base-link model with the header's parameters:
    ``ours`` integrated as the fit integrates (``integration``), ``first_order`` the same motions
    integrated first-order (Euler), as a robot's own odometry usually is (None: not computed)."""

    time_s: np.ndarray
    vendor: np.ndarray
    ours: np.ndarray
    integration: str
    params: Mapping[str, float]
    first_order: np.ndarray | None = None


@dataclass(frozen=True)
class OdometryTrack:
    """Base-link poses ``(n, 3)`` ordered ``(x, y, theta)`` and covariances ``(n, 3, 3)``.

    ``reference``: the base poses the tracker implies with the calibrated mount; ``covariance``:
    the one noise model's (``rates``, grown from the start as a filter grows it, each end's
    reading's rounding beside it); ``input_noise``: each model input's 1σ per interval that shaped
    the rates (calibrated on the drift against the tracker: a random walk beside ``quantisation``,
    the encoders' resolution, which rounds each reading and does not add up); ``coverage``: the
    share of that drift, over segments, within the rates' 2σ (None: no segment to judge it by)."""

    time_s: np.ndarray
    T_world_base: np.ndarray
    covariance: np.ndarray
    reference: np.ndarray | None = None
    input_noise: Mapping[str, float] = field(default_factory=dict)
    quantisation: Mapping[str, float] = field(default_factory=dict)
    coverage: float | None = None
    #: The same noise per metre driven and per radian turned (None: not computed).
    rates: NoiseRates | None = None
    #: Why no covariance is stated ("": one is): the drift is no noise a filter can use.
    undetermined: str = ""

    def csv(self) -> str:
        """One row per record: time, pose and the upper triangle of the covariance (empty where
        none is stated)."""
        head = "time_s,x,y,theta,var_x,cov_xy,cov_xtheta,var_y,cov_ytheta,var_theta"
        P = self.covariance
        upper = [P[:, i, j] for i in range(3) for j in range(i, 3)]
        cols = np.column_stack([self.time_s, self.T_world_base, *upper])
        shown = 4 if self.undetermined else cols.shape[1]
        rows = (
            ",".join([*(f"{v:.10g}" for v in row[:shown]), *[""] * (cols.shape[1] - shown)]) for row in cols
        )
        return head + "\n" + "\n".join(rows) + "\n"


@dataclass(frozen=True)
class FaultSpan:
    """A fault's time span (s) and kind, for figures over time."""

    first_s: float
    last_s: float
    kind: str


@dataclass(frozen=True)
class RunSeries:
    """Everything a log's figures and trajectory files show; ``model_check`` is None when the log
    carries no vendor odometry."""

    tracks: TrackSeries
    residuals: ResidualSeries
    fault_spans: tuple[FaultSpan, ...]
    holdout_start_s: float | None
    model_check: ModelCheckSeries | None
