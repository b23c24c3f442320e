"""Trajectory metrics: ATE, hold-out ATE and RPE of the integrated sensor track.

The calibrated sensor trajectory is dead reckoning ``T_{k+1} = T_k · h_k(X)`` started from the
tracker's pose at the first record of the evaluated range; it is computed by folding the
problem's ``integrate_step`` Function over the intervals (``mapaccum``), not by a Python loop.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from nlp_calib.problem import ProblemFunctions


@dataclass(frozen=True)
class TrajectoryMetrics:
    """Position errors (m) of a dead-reckoned sensor track against the tracker.

    ``ate_*``: absolute trajectory error over the range; ``rpe_trans`` / ``rpe_rot``: mean
    relative pose error over windows of ``rpe_window`` records (m, rad).
    """

    ate_mean: float
    ate_max: float
    ate_final: float
    rpe_trans: float
    rpe_rot: float
    rpe_window: int
    records: int

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)


def integrate(
    fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray, T_world_sensor_0: np.ndarray
) -> np.ndarray:
    """Dead-reckoned sensor poses ``(n_intervals + 1, 3)`` from ``T_world_sensor_0``."""
    n = inputs.shape[1]
    out = np.empty((n + 1, 3))
    out[0] = T_world_sensor_0
    if n:
        fold = fns.integrate_step.mapaccum("integrate", n)
        P = np.repeat(np.asarray(params, dtype=float).reshape(-1, 1), n, axis=1)
        out[1:] = np.asarray(fold(np.asarray(T_world_sensor_0, dtype=float), P, inputs)).T
    return out


def trajectory_metrics(
    fns: ProblemFunctions,
    params: np.ndarray,
    inputs: np.ndarray,
    T_world_sensor: np.ndarray,
    *,
    start: int = 0,
    stop: int | None = None,
    rpe_window: int = 25,
) -> TrajectoryMetrics:
    """Metrics of the track integrated over records ``start:stop`` (interval ``k`` joins records k, k+1)."""
    stop = T_world_sensor.shape[0] if stop is None else stop
    if stop - start < 2:
        raise ValueError(f"need at least 2 records to score a trajectory, got {stop - start}")
    track = integrate(fns, params, inputs[:, start : stop - 1], T_world_sensor[start])
    truth = T_world_sensor[start:stop]
    err = np.linalg.norm(track[:, :2] - truth[:, :2], axis=1)
    W = min(rpe_window, stop - start - 1)
    m = track.shape[0] - W
    between = fns.between.map(m)
    est = np.asarray(between(track[:-W].T, track[W:].T))
    ref = np.asarray(between(truth[:-W].T, truth[W:].T))
    diff = np.asarray(between(ref, est))
    return TrajectoryMetrics(
        ate_mean=float(err.mean()),
        ate_max=float(err.max()),
        ate_final=float(err[-1]),
        rpe_trans=float(np.linalg.norm(diff[:2], axis=0).mean()),
        rpe_rot=float(np.abs(diff[2]).mean()),
        rpe_window=int(W),
        records=int(stop - start),
    )
