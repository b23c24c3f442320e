"""Trajectory errors of a calibration: standard figures and fair ones on logs with faults.

The calibrated sensor track is dead reckoning ``T_{k+1} = T_k · h_k(X)`` started from the
tracker's pose; each step ``h_k`` comes from the problem's ``predict`` Function, and the steps are
composed in one vectorised pass (linear in the number of records).

- **ATE** (full run): the track started at the first record, against every tracker position. A
  counter fault loses counts for good, so from the first fault on this figure measures the fault,
  not the calibration, and it can rank parameter sets wrongly. Over records that do not connect (a
  gap in time, a reference of its own increments missing some or leaving one out as its fault,
  several logs end to end) there is none: the track would chain what does not connect.
- **Segment ATE**: the track restarted from the tracker after each fault, the fault's records left
  out; ``aligned``: the same after the best SE(2) alignment of each segment to the tracker (what
  ``evo_ape --align`` computes on each exported segment), pooled over the segments.
- **RPE over a distance** (1 m, 5 m): for every record, the record whose distance along the
  tracker's path is nearest that distance further on (within 10 %, pairs inside one segment, as
  ``evo_rpe --delta D --delta_unit m --all_pairs --pairs_from_reference`` chooses them); the
  error is the translation of ``(ref_i⁻¹·ref_j)⁻¹·(est_i⁻¹·est_j)``. Alignment does not change it.
- **RPE over a window** of records, as before, each pair inside one fault-free part.

Statistics are those evo reports: RMSE, mean, median, standard deviation, minimum and maximum.

A 3-D sensor's track (a camera's own trajectory) is scored the same way in 3-D: positions
``(x, y, z)`` in the trajectory's units, SE(3) alignment (Umeyama without scale), rotation errors
as angles.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from nlp_calib.core import poses, poses3d
from nlp_calib.problem import ProblemFunctions, over_columns
from nlp_calib.results.figures import RPE_DISTANCES, RPE_TOLERANCE, ErrorStats, TrajectoryMetrics


@dataclass(frozen=True)
class Geometry:
    """The pose algebra a track is scored in: composition, motions, the position's dimensions,
    the angle of a motion, the best rigid alignment of positions, a motion's translation alone
    (``between``'s first ``dims`` columns, the same arithmetic: the RPE over a distance needs no
    angle) and the alignment to positions already centred (``align``'s arithmetic, the reference's
    side given: ``(est, ref − mean, mean)``)."""

    accumulate: Callable[[np.ndarray, np.ndarray], np.ndarray]
    between: Callable[[np.ndarray, np.ndarray], np.ndarray]
    dims: int
    angle: Callable[[np.ndarray], np.ndarray]
    align: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
    moved: Callable[[np.ndarray, np.ndarray], np.ndarray]
    align_centred: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


PLANAR = Geometry(
    poses.accumulate,
    poses.between,
    2,
    lambda rel: np.abs(rel[:, 2]),
    poses.align,
    poses.moved,
    poses.align_centred,
)
SPATIAL = Geometry(
    poses3d.accumulate,
    poses3d.between,
    3,
    lambda rel: np.linalg.norm(poses3d.quat_to_rotvec(rel[:, 3:7]), axis=1),
    poses3d.align,
    poses3d.moved,
    poses3d.align_centred,
)

#: A gyro's "poses": its rates integrated from the first record (and the time), added up; its
#: "positions" the three integrated rates (rad), aligned by an offset alone. Its predicted steps
#: carry no bias (a window's motion has no duration), so its track drifts by the bias.
RATE = Geometry(
    lambda T0, steps: T0 + np.vstack([np.zeros((1, T0.size)), np.cumsum(steps, axis=0)]),
    lambda a, b: b - a,
    3,
    lambda rel: np.zeros(rel.shape[0]),
    lambda est, ref: (np.eye(est.shape[1]), ref.mean(axis=0) - est.mean(axis=0)),
    lambda a, b: (b - a)[:, :3],
    lambda est, ref_centred, mu_r: (np.eye(est.shape[1]), mu_r - est.mean(axis=0)),
)


#: The geometry of a pose group's poses.
GEOMETRIES = {"SE(2)": PLANAR, "SE(3)": SPATIAL, "rate": RATE}


def geometry(fns: ProblemFunctions) -> Geometry:
    """The geometry of the problem's tracker poses (its sensor's pose group)."""
    return GEOMETRIES[fns.sensor.group]


def steps(fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """The predicted sensor motion ``h_k`` of every interval, ``(n_intervals, pose rows)``;
    ``params`` is one log's view (:meth:`ProblemFunctions.view`), or one per interval (a column each)."""
    n = inputs.shape[1]
    if n == 0:
        return np.zeros((0, fns.sensor.pose_rows))
    P = np.asarray(params, dtype=float)
    h = over_columns(fns.predict, P if P.ndim == 2 else np.ravel(P), np.asarray(inputs, dtype=float))[0].T
    return h[:, : fns.sensor.pose_rows]  # a sensor beside the reference predicts rows of its own after them


def scale_free(fns: ProblemFunctions) -> bool:
    """Whether the trajectory's poses are in metres only by a parameter (its scale)."""
    return fns.sensor.length_unit != "m"


def in_metres(fns: ProblemFunctions, params: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """``poses`` (or motions) with their translations in metres: times the sensor's scale at
    ``params`` when its poses are known only up to scale (as they are otherwise)."""
    if not scale_free(fns):
        return poses
    out = np.array(poses, dtype=float)
    P = np.asarray(params, dtype=float)
    first = P[:, 0] if P.ndim == 2 else np.ravel(P)  # one view per interval: the first log's scale
    out[:, :3] *= fns.sensor.trajectory_scale(dict(zip(fns.view_names, map(float, first))))
    return out


def integrate(
    fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray, T_world_sensor_0: np.ndarray
) -> np.ndarray:
    """Dead-reckoned sensor poses ``(n_intervals + 1, pose rows)`` from ``T_world_sensor_0``."""
    return geometry(fns).accumulate(np.asarray(T_world_sensor_0, dtype=float), steps(fns, params, inputs))


def first_order(motion: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Planar poses from ``start`` dead-reckoned first-order (Euler: along the heading by the arc's
    length, then turned) from exact per-interval motions ``(n, 3)``: how a robot's own odometry
    usually integrates the same wheel travel, so the two compare like with like."""
    dx, dy, dth = (np.asarray(motion, dtype=float)[:, i] for i in range(3))
    half = 0.5 * dth
    chord = np.hypot(dx, dy) * np.sign(dx)
    safe = np.where(np.abs(half) > 1e-9, half, 1.0)
    arc = np.where(np.abs(half) > 1e-9, chord * half / np.sin(safe), chord)
    theta = float(start[2]) + np.concatenate([[0.0], np.cumsum(dth)])
    x = float(start[0]) + np.concatenate([[0.0], np.cumsum(arc * np.cos(theta[:-1]))])
    y = float(start[1]) + np.concatenate([[0.0], np.cumsum(arc * np.sin(theta[:-1]))])
    return np.stack([x, y, theta], axis=1)


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


def lengths(v: np.ndarray) -> np.ndarray:
    """Each row's Euclidean length: ``np.linalg.norm(v, axis=1)``'s arithmetic (squares summed
    left to right, then the root: the same bits), a column at a time (the reduction over a row of
    two or three took several times the CPU)."""
    out = v[:, 0] * v[:, 0]
    for k in range(1, v.shape[1]):
        out += v[:, k] * v[:, k]
    return np.sqrt(out, out=out)


def path_distance(T_ref: np.ndarray, g: Geometry = PLANAR) -> np.ndarray:
    """Distance travelled along the reference's positions up to each record (m)."""
    return np.concatenate([[0.0], np.cumsum(lengths(np.diff(T_ref[:, : g.dims], axis=0)))])


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
    # The first index of each run of equal distances, a running maximum (a second binary search
    # over every record found the same index at several times the CPU; a NaN distance, which the
    # search puts in one run, is never kept).
    starts = np.maximum.accumulate(np.where(np.r_[True, dist[1:] != dist[:-1]], np.arange(n), 0))
    j = np.maximum(starts[j], i + 1)
    keep = np.abs(dist[j] - target) <= tol
    return i[keep], j[keep]


#: Record pairs ``(i, j)`` of one part at a distance along the reference's path, with the
#: translation of the reference's motion ``ref_i⁻¹·ref_j`` between them.
Pairs = tuple[np.ndarray, np.ndarray, np.ndarray]


def rpe_pairs(
    T_ref: np.ndarray, parts: list[np.ndarray], deltas: Sequence[float], g: Geometry = PLANAR
) -> dict[float, list[Pairs]]:
    """For each of ``deltas`` (m), the pairs inside each part (an array of record indices; the path
    runs through them in order) that the RPE over that distance compares."""
    out: dict[float, list[Pairs]] = {d: [] for d in deltas}
    for idx in parts:
        dist = path_distance(T_ref[idx], g)
        for delta in deltas:
            i, j = distance_pairs(dist, delta, RPE_TOLERANCE * delta)
            out[delta].append((idx[i], idx[j], g.moved(T_ref[idx[i]], T_ref[idx[j]])))
    return out


#: Motions compared at a time: at 10^6 records, the temporaries of every pair at once were ~200 MB.
CHUNK = 1 << 16


def _motion_errors(
    g: Geometry, track: np.ndarray, first: np.ndarray, window: int, ref: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The translation's length and the angle of ``ref⁻¹·(a⁻¹·b)`` per pair of the ``track``'s
    records ``first`` and ``first + window``, :data:`CHUNK` pairs at a time (each pair's arithmetic
    is the one pass's)."""
    d = g.dims
    size, angles = np.zeros(first.size), np.zeros(first.size)
    for lo in range(0, first.size, CHUNK):
        rows, i = slice(lo, lo + CHUNK), first[lo : lo + CHUNK]
        rel = g.between(ref[rows], g.between(track[i], track[i + window]))
        size[rows], angles[rows] = lengths(rel[:, :d]), g.angle(rel)
    return size, angles


def rpe_of(T_est: np.ndarray, pairs: list[Pairs], g: Geometry = PLANAR) -> ErrorStats:
    """Translation error of the estimate's motions against the reference's over ``pairs``."""
    # The translation of ``ref⁻¹·est`` is the difference of the two translations turned by the
    # reference's rotation: its length is the difference's.
    errors = []
    for i, j, ref in pairs:
        for lo in range(0, i.size, CHUNK):
            rows = slice(lo, lo + CHUNK)
            errors.append(lengths(g.moved(T_est[i[rows]], T_est[j[rows]]) - ref[rows]))
    return ErrorStats.of(np.concatenate(errors) if errors else np.zeros(0))


def aligned_errors(T_est: np.ndarray, T_ref: np.ndarray, g: Geometry = PLANAR) -> np.ndarray:
    """Position errors after the best rigid alignment (SE(2), or SE(3)) of the estimate's
    positions to the reference."""
    return _aligned(T_est, T_ref, centred(T_ref, g), g)


def centred(T_ref: np.ndarray, g: Geometry = PLANAR) -> tuple[np.ndarray, np.ndarray]:
    """The reference's side of an alignment: its positions less their mean, and the mean."""
    mu_r = T_ref[:, : g.dims].mean(axis=0)
    return T_ref[:, : g.dims] - mu_r, mu_r


def _aligned(
    T_est: np.ndarray, T_ref: np.ndarray, side: tuple[np.ndarray, np.ndarray], g: Geometry
) -> np.ndarray:
    """:func:`aligned_errors` with the reference's side of the alignment given (:func:`centred`)."""
    d = g.dims
    if T_est.shape[0] < 2 or not np.all(np.isfinite(T_est[:, :d])):
        return lengths(T_est[:, :d] - T_ref[:, :d])  # NaN where the track is
    R, t = g.align_centred(T_est[:, :d], *side)
    # A :data:`CHUNK` of rows at a time: the product of every row at once is one BLAS call whose
    # threads cost several times the CPU at 10^6 rows (each row's arithmetic is the same).
    out = np.empty(T_est.shape[0])
    for lo in range(0, out.size, CHUNK):
        rows = slice(lo, lo + CHUNK)
        out[rows] = lengths(T_est[rows, :d] @ R.T + t - T_ref[rows, :d])
    return out


@dataclass(frozen=True)
class Positions:
    """The reference's poses as every parameter set's figures read them, gathered once: the
    positions of the ``good`` records (the full run's), of the ``scored`` ones (the segments') and
    each scored part's poses (``parts``, the aligned errors'); and the rows a track's figures read
    (``good_rows``, ``part_rows``): a slice where they run without a gap, so that a track's rows are
    read in place, not copied (the same values in the same layout)."""

    good: np.ndarray
    scored: np.ndarray
    parts: list[np.ndarray]
    good_rows: slice | np.ndarray
    part_rows: list[slice | np.ndarray]
    #: Each scored part's side of the alignment (:func:`centred`).
    sides: list[tuple[np.ndarray, np.ndarray]]


def _rows(idx: np.ndarray) -> slice | np.ndarray:
    """The record indices ``idx`` (increasing) as a slice where they run without a gap."""
    if idx.size and idx[-1] - idx[0] + 1 == idx.size:
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


@dataclass(frozen=True)
class Reference:
    """The reference's side of the figures over a stretch of records, shared by every parameter
    set scored there (none when the trajectory's scale is free: its poses then depend on it):
    its poses ``T`` (in metres), the records ``good`` to score, the ``window`` of the windowed RPE
    with the record ``pair`` mask and the reference's motions ``rel`` over it, the fault-free
    ``parts``, the records ``scored`` in them, each part's scored records, the RPE ``pairs`` over
    each distance and the distance travelled."""

    T: np.ndarray
    good: np.ndarray
    window: int
    pair: np.ndarray
    rel: np.ndarray
    parts: list[tuple[int, int]]
    scored: np.ndarray
    scored_parts: list[np.ndarray]
    pairs: dict[float, list[Pairs]]
    distance_m: float
    #: The reference's poses as the figures read them.
    at: Positions
    #: Whether the records connect end to end (no gap, missing increment or log's end between
    #: them): a full-run track over records that do not chains what does not connect.
    connected: bool = True


def reference(
    g: Geometry,
    T_ref: np.ndarray,
    rpe_window: int,
    bad_intervals: np.ndarray | None,
    bad_records: np.ndarray | None,
    breaks: np.ndarray | None = None,
) -> Reference:
    """The reference's side of the figures over all of ``T_ref`` (masks in its indexing;
    ``breaks``: the intervals across which the records do not connect)."""
    n = T_ref.shape[0]
    bad_i = None if bad_intervals is None else np.asarray(bad_intervals, dtype=bool)
    good = np.ones(n, dtype=bool)
    if bad_records is not None:
        good &= ~np.asarray(bad_records, dtype=bool)
    W = min(rpe_window, n - 1)
    # A window's pair of records lies within one fault-free part, as the RPE over a distance's.
    crossed = np.zeros(n, dtype=np.int64)
    if bad_i is not None:
        crossed[1:] = np.cumsum(bad_i)
    pair = good[:-W] & good[W:] & (crossed[W:] == crossed[:-W])
    parts = segments(n, bad_i)
    scored = np.zeros(n, dtype=bool)
    for a, b in parts:
        scored[a:b] = True
    scored &= good
    # A bad tracker pose is left out of the path too, as it is of the exported files.
    scored_parts = [a + np.flatnonzero(good[a:b]) for a, b in parts]
    connected = breaks is None or not np.any(breaks)
    # Over records that do not connect, a full-run track chains them: no full-run figure.
    full = good if connected else np.zeros_like(good)
    good_rows, part_rows = _rows(np.flatnonzero(full)), [_rows(idx) for idx in scored_parts]
    # Rows without a gap are read in place, not copied; a part's poses in the layout of the copy
    # the alignment's sums read (a C-ordered block: the same order of sums, the same bits).
    poses_of_parts = [np.ascontiguousarray(T_ref[r]) for r in part_rows]
    at = Positions(
        T_ref[good_rows, : g.dims],
        T_ref[_rows(np.flatnonzero(scored)), : g.dims],
        poses_of_parts,
        good_rows,
        part_rows,
        [centred(T_r, g) for T_r in poses_of_parts],
    )
    return Reference(
        T=T_ref,
        good=good,
        window=int(W),
        pair=pair,
        rel=g.between(T_ref[:-W][pair], T_ref[W:][pair]),
        parts=parts,
        scored=scored,
        scored_parts=scored_parts,
        pairs=rpe_pairs(T_ref, scored_parts, RPE_DISTANCES, g),
        distance_m=float(path_distance(T_ref[good], g)[-1]) if good.any() else 0.0,
        at=at,
        connected=connected,
    )


def _mean(errors: np.ndarray) -> float:
    """``ErrorStats.of(errors).mean`` without the statistics nobody reads (a median's partition)."""
    return float(errors.mean()) if errors.size else float("nan")


def scored(
    fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray, ref: Reference
) -> TrajectoryMetrics:
    """The figures of ``params`` against ``ref`` (``inputs``: the intervals between its records)."""
    g = geometry(fns)
    T = ref.T
    step = in_metres(fns, params, steps(fns, params, inputs))
    track = g.accumulate(T[0], step)
    # A bad tracker pose is the tracker's error, not the calibration's: left out of every figure.
    # Over records that do not connect, a full-run track chains them: no full-run figure.
    err = lengths(track[ref.at.good_rows, : g.dims] - ref.at.good)
    W, pair = ref.window, ref.pair
    rel_trans, rel_rot = _motion_errors(g, track, np.flatnonzero(pair), W, ref.rel)
    # One part over every record restarts where the track starts: the same poses.
    whole = ref.parts == [(0, T.shape[0])]
    seg_track = track if whole else restarted(step, T, ref.parts, g)
    ate = ErrorStats.of(err)
    if whole and ref.connected:
        # The one part's scored records are the good ones: the full run's errors, not taken again.
        segment_ate = ate
    else:
        segment_ate = ErrorStats.of(lengths(seg_track[ref.scored, : g.dims] - ref.at.scored))
    at = ref.at
    aligned = [_aligned(seg_track[r], T_r, side, g) for r, T_r, side in zip(at.part_rows, at.parts, at.sides)]
    rpe = {d: rpe_of(seg_track, ref.pairs[d], g) for d in RPE_DISTANCES}
    return TrajectoryMetrics(
        ate_final=float(err[-1]) if err.size else float("nan"),
        rpe_trans=_mean(rel_trans),
        rpe_rot=_mean(rel_rot),
        rpe_window=W,
        records=int(T.shape[0]),
        ate=ate,
        segment_ate=segment_ate,
        segment_ate_aligned=ErrorStats.of(np.concatenate(aligned) if aligned else np.zeros(0)),
        rpe_distance=rpe,
        segments=len(ref.parts),
        distance_m=ref.distance_m,
    )


def trajectory_metrics(
    fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray, T_world_sensor: np.ndarray, **where: Any
) -> TrajectoryMetrics:
    """Metrics of the tracks of ``params`` (``where``: the records and faults, as
    :func:`each_metrics` takes them)."""
    return each_metrics(fns, [params], inputs, T_world_sensor, **where)[0]


def each_metrics(
    fns: ProblemFunctions,
    param_sets: Sequence[np.ndarray],
    inputs: np.ndarray,
    T_world_sensor: np.ndarray,
    *,
    start: int = 0,
    stop: int | None = None,
    rpe_window: int = 25,
    bad_intervals: np.ndarray | None = None,
    bad_records: np.ndarray | None = None,
    breaks: np.ndarray | None = None,
) -> list[TrajectoryMetrics]:
    """Metrics of the tracks of each parameter set over records ``start:stop`` (interval ``k``
    joins records k, k+1), the reference's side computed once (once per set when the trajectory's
    scale is free). A parameter set is one log's view, or one view per interval (a column each).

    ``bad_intervals`` (per interval) and ``bad_records`` (per record) mark faults in the same
    indexing as ``inputs`` and ``T_world_sensor``; they shape the fair figures only. ``breaks``
    (per interval) marks where the records do not connect: with any, no full-run figure.
    """
    stop = T_world_sensor.shape[0] if stop is None else stop
    if stop - start < 2:
        raise ValueError(f"need at least 2 records to score a trajectory, got {stop - start}")
    g = geometry(fns)
    bad_i = None if bad_intervals is None else bad_intervals[start : stop - 1]
    bad_r = None if bad_records is None else bad_records[start:stop]
    cut = None if breaks is None else breaks[start : stop - 1]
    T = np.asarray(T_world_sensor[start:stop], dtype=float)
    out: list[TrajectoryMetrics] = []
    ref: Reference | None = None
    for params in param_sets:
        if ref is None or scale_free(fns):
            # A trajectory known up to scale is scored in metres, by each parameter set's own scale.
            ref = reference(g, in_metres(fns, params, T), rpe_window, bad_i, bad_r, cut)
        P = np.asarray(params, dtype=float)
        out.append(
            scored(fns, P[:, start : stop - 1] if P.ndim == 2 else P, inputs[:, start : stop - 1], ref)
        )
    return out
