"""Trajectory errors of a calibration: standard figures and fair ones on logs with faults.

The calibrated sensor track is dead reckoning ``T_{k+1} = T_k · h_k(X)`` started from the
tracker's pose; each step ``h_k`` comes from the problem's ``predict`` Function, and the steps are
composed in one vectorised pass (linear in the number of records).

- **ATE** (full run): the track started at the first record, against every tracker position. A
  counter fault loses counts for good, so from the first fault on this figure measures the fault,
  not the calibration, and it can rank parameter sets wrongly.
- **Segment ATE**: the track restarted from the tracker after each fault, the fault's records left
  out; ``aligned``: the same after the best SE(2) alignment of each segment to the tracker (what
  ``evo_ape --align`` computes on each exported segment), pooled over the segments.
- **RPE over a distance** (1 m, 5 m): for every record, the record whose distance along the
  tracker's path is nearest that distance further on (within 10 %, pairs inside one segment, as
  ``evo_rpe --delta D --delta_unit m --all_pairs --pairs_from_reference`` chooses them); the
  error is the translation of ``(ref_i⁻¹·ref_j)⁻¹·(est_i⁻¹·est_j)``. Alignment does not change it.
- **RPE over a window** of records, as before.

Statistics are those evo reports: RMSE, mean, median, standard deviation, minimum and maximum.

A 3-D sensor's track (a camera's own trajectory) is scored the same way in 3-D: positions
``(x, y, z)`` in the trajectory's units, SE(3) alignment (Umeyama without scale), rotation errors
as angles.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nlp_calib.core import poses, poses3d
from nlp_calib.models.mount import SCALE_PARAM
from nlp_calib.problem import ProblemFunctions, over_columns
from nlp_calib.results.figures import RPE_DISTANCES, RPE_TOLERANCE, ErrorStats, TrajectoryMetrics


@dataclass(frozen=True)
class Geometry:
    """The pose algebra a track is scored in: composition, motions, the position's dimensions,
    the angle of a motion and the best rigid alignment of positions."""

    accumulate: Callable[[np.ndarray, np.ndarray], np.ndarray]
    between: Callable[[np.ndarray, np.ndarray], np.ndarray]
    dims: int
    angle: Callable[[np.ndarray], np.ndarray]
    align: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


PLANAR = Geometry(poses.accumulate, poses.between, 2, lambda rel: np.abs(rel[:, 2]), poses.align)
SPATIAL = Geometry(
    poses3d.accumulate,
    poses3d.between,
    3,
    lambda rel: np.linalg.norm(poses3d.quat_to_rotvec(rel[:, 3:7]), axis=1),
    poses3d.align,
)


def geometry(fns: ProblemFunctions) -> Geometry:
    """The geometry of the problem's tracker poses."""
    return SPATIAL if fns.sensor.pose_rows == 7 else PLANAR


def steps(fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """The predicted sensor motion ``h_k`` of every interval, ``(n_intervals, pose rows)``."""
    n = inputs.shape[1]
    if n == 0:
        return np.zeros((0, fns.sensor.pose_rows))
    return over_columns(
        fns.predict, np.ravel(np.asarray(params, dtype=float)), np.asarray(inputs, dtype=float)
    )[0].T


def in_metres(fns: ProblemFunctions, params: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """``poses`` (or motions) with their translations in metres: times the ``scale`` of
    ``params`` when the trajectory's scale is free (as they are otherwise)."""
    if SCALE_PARAM not in fns.names or SCALE_PARAM not in fns.sensor.params:
        return poses
    out = np.array(poses, dtype=float)
    out[:, :3] *= float(np.ravel(params)[fns.names.index(SCALE_PARAM)])
    return out


def integrate(
    fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray, T_world_sensor_0: np.ndarray
) -> np.ndarray:
    """Dead-reckoned sensor poses ``(n_intervals + 1, pose rows)`` from ``T_world_sensor_0``."""
    return geometry(fns).accumulate(np.asarray(T_world_sensor_0, dtype=float), steps(fns, params, inputs))


def segments(n_records: int, bad_intervals: np.ndarray | None) -> list[tuple[int, int]]:
    """Record ranges ``[a, b)`` with no bad interval inside (at least two records each)."""
    if bad_intervals is None or not np.any(bad_intervals):
        return [(0, n_records)] if n_records >= 2 else []
    out, a = [], 0
    for k in np.flatnonzero(bad_intervals):
        if k + 1 - a >= 2:
            out.append((a, int(k) + 1))
        a = int(k) + 1
    if n_records - a >= 2:
        out.append((a, n_records))
    return out


def restarted(
    step: np.ndarray, T_ref: np.ndarray, parts: list[tuple[int, int]], g: Geometry = PLANAR
) -> np.ndarray:
    """Poses dead-reckoned within each part from the reference's pose at its start (NaN outside
    the parts)."""
    out = np.full(T_ref.shape, np.nan)
    for a, b in parts:
        out[a:b] = g.accumulate(T_ref[a], step[a : b - 1])
    return out


def path_distance(T_ref: np.ndarray, g: Geometry = PLANAR) -> np.ndarray:
    """Distance travelled along the reference's positions up to each record (m)."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(T_ref[:, : g.dims], axis=0), axis=1))])


def distance_pairs(dist: np.ndarray, delta: float, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """For each index ``i``, the ``j > i`` whose ``dist[j] − dist[i]`` is nearest ``delta``, kept
    when within ``tol`` (``dist`` is non-decreasing)."""
    n = dist.size
    if n < 2:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    i = np.arange(n - 1)
    target = dist[i] + delta
    j_hi = np.clip(np.searchsorted(dist, target, side="left"), i + 1, n - 1)
    j_lo = np.clip(j_hi - 1, i + 1, n - 1)
    # Among equal distances the first index wins, as an argmin over j > i does.
    better_lo = np.abs(dist[j_lo] - target) <= np.abs(dist[j_hi] - target)
    j = np.where(better_lo, j_lo, j_hi)
    first = np.searchsorted(dist, dist[j], side="left")
    j = np.maximum(first, i + 1)
    keep = np.abs(dist[j] - target) <= tol
    return i[keep], j[keep]


def rpe_by_distance(
    T_est: np.ndarray, T_ref: np.ndarray, parts: list[np.ndarray], delta: float, g: Geometry = PLANAR
) -> ErrorStats:
    """Translation error over ``delta`` metres of the reference's path, pairs inside each part
    (an array of record indices; the path runs through them in order)."""
    errors = []
    for idx in parts:
        i, j = distance_pairs(path_distance(T_ref[idx], g), delta, RPE_TOLERANCE * delta)
        ref = g.between(T_ref[idx[i]], T_ref[idx[j]])
        est = g.between(T_est[idx[i]], T_est[idx[j]])
        errors.append(np.linalg.norm(g.between(ref, est)[:, : g.dims], axis=1))
    return ErrorStats.of(np.concatenate(errors) if errors else np.zeros(0))


def aligned_errors(T_est: np.ndarray, T_ref: np.ndarray, g: Geometry = PLANAR) -> np.ndarray:
    """Position errors after the best rigid alignment (SE(2), or SE(3)) of the estimate's
    positions to the reference."""
    d = g.dims
    if T_est.shape[0] < 2 or not np.all(np.isfinite(T_est[:, :d])):
        return np.linalg.norm(T_est[:, :d] - T_ref[:, :d], axis=1)  # NaN where the track is
    R, t = g.align(T_est[:, :d], T_ref[:, :d])
    return np.linalg.norm(T_est[:, :d] @ R.T + t - T_ref[:, :d], axis=1)


def trajectory_metrics(
    fns: ProblemFunctions,
    params: np.ndarray,
    inputs: np.ndarray,
    T_world_sensor: np.ndarray,
    *,
    start: int = 0,
    stop: int | None = None,
    rpe_window: int = 25,
    bad_intervals: np.ndarray | None = None,
    bad_records: np.ndarray | None = None,
) -> TrajectoryMetrics:
    """Metrics of the tracks over records ``start:stop`` (interval ``k`` joins records k, k+1).

    ``bad_intervals`` (per interval) and ``bad_records`` (per record) mark faults in the same
    indexing as ``inputs`` and ``T_world_sensor``; they shape the fair figures only.
    """
    stop = T_world_sensor.shape[0] if stop is None else stop
    if stop - start < 2:
        raise ValueError(f"need at least 2 records to score a trajectory, got {stop - start}")
    g = geometry(fns)
    # A trajectory known up to scale is scored in metres, by each parameter set's own scale.
    ref = in_metres(fns, params, np.asarray(T_world_sensor[start:stop], dtype=float))
    step = in_metres(fns, params, steps(fns, params, inputs[:, start : stop - 1]))
    track = g.accumulate(ref[0], step)
    bad_i = None if bad_intervals is None else np.asarray(bad_intervals[start : stop - 1], dtype=bool)
    good = np.ones(stop - start, dtype=bool)
    if bad_records is not None:
        good &= ~np.asarray(bad_records[start:stop], dtype=bool)
    # A bad tracker pose is the tracker's error, not the calibration's: left out of every figure.
    err = np.linalg.norm(track[good, : g.dims] - ref[good, : g.dims], axis=1)
    W = min(rpe_window, stop - start - 1)
    pair = good[:-W] & good[W:]
    rel = g.between(g.between(ref[:-W][pair], ref[W:][pair]), g.between(track[:-W][pair], track[W:][pair]))
    parts = segments(stop - start, bad_i)
    seg_track = restarted(step, ref, parts, g)
    scored = np.zeros(stop - start, dtype=bool)
    for a, b in parts:
        scored[a:b] = True
    scored &= good
    seg_err = np.linalg.norm(seg_track[scored, : g.dims] - ref[scored, : g.dims], axis=1)
    # A bad tracker pose is left out of the path too, as it is of the exported files.
    scored_parts = [a + np.flatnonzero(good[a:b]) for a, b in parts]
    aligned = [aligned_errors(seg_track[idx], ref[idx], g) for idx in scored_parts]
    rpe = {d: rpe_by_distance(seg_track, ref, scored_parts, d, g) for d in RPE_DISTANCES}
    ate = ErrorStats.of(err)
    return TrajectoryMetrics(
        ate_final=float(err[-1]) if err.size else float("nan"),
        rpe_trans=ErrorStats.of(np.linalg.norm(rel[:, : g.dims], axis=1)).mean,
        rpe_rot=ErrorStats.of(g.angle(rel)).mean,
        rpe_window=int(W),
        records=int(stop - start),
        ate=ate,
        segment_ate=ErrorStats.of(seg_err),
        segment_ate_aligned=ErrorStats.of(np.concatenate(aligned) if aligned else np.zeros(0)),
        rpe_distance=rpe,
        segments=len(parts),
        distance_m=float(path_distance(ref[good], g)[-1]) if good.any() else 0.0,
    )
