"""Pivots as draws: what a drive's turns on the spot say of the parameters, each on its own.

A base that pivots turns on the ground as the ground lets it: a skid-steer skids by a share that
holds over a whole pivot and differs from one pivot to the next, either way. Every window of one
pivot then shares one draw of that slip, a random effect per pivot that neither the white-noise σ
(independent windows) nor a blocked jackknife (a block holds a pivot or two) counts, and a fit that
leaves out the pivots the wheels disagree with keeps those that agree with it (those of one sign).
So each pivot is fitted on its own (the drive's windows off every pivot, and its own): the σ of
their mean over ``G`` pivots, and the estimate's distance from that mean in full (a fit that keeps
the pivots agreeing with it may sit anywhere among them), give the σ of the estimate as the law
the drive's pivots hold.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.results.faults import PIVOT_RADIUS_M


def pivot_intervals(steps: np.ndarray) -> np.ndarray:
    """Per interval, whether the base pivots over it: it turns, and travels less than
    :data:`PIVOT_RADIUS_M` per radian turned (``steps``: the model's base motion over each
    interval, rows of along, across and heading)."""
    travel, turned = np.hypot(steps[:, 0], steps[:, 1]), np.abs(steps[:, 2])
    return (turned > 0.0) & (travel < PIVOT_RADIUS_M * turned)


def pivot_windows(pivot: np.ndarray, starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """Per window (records ``starts[w]`` to ``stops[w]``), the pivot it crosses, numbered from 0 in
    the order they are driven (-1: none); a pivot is a run of consecutive ``pivot`` intervals, and
    runs that one window crosses are one pivot (the window shares both draws)."""
    pivot = np.asarray(pivot, dtype=bool)
    starts, stops = np.asarray(starts, dtype=np.intp), np.asarray(stops, dtype=np.intp)
    n, label = pivot.size, np.full(starts.size, -1)
    run = np.where(pivot, np.cumsum(np.diff(np.concatenate([[0], pivot.astype(int)])) == 1) - 1, -1)
    runs = int(run.max(initial=-1)) + 1
    if not runs or not starts.size:
        return label
    # Runs are numbered in driving order, so a window crosses every run from the one of its first
    # pivot interval to that of its last: a range, and runs joined by one window are a range too.
    at = np.arange(n)
    following = np.minimum.accumulate(np.where(pivot, at, n)[::-1])[::-1]
    preceding = np.maximum.accumulate(np.where(pivot, at, -1))
    first = np.where(starts < n, following[np.clip(starts, 0, n - 1)], n)
    last = np.where(stops > 0, preceding[np.clip(stops - 1, 0, n - 1)], -1)
    crosses = first < np.minimum(stops, n)
    lo, hi = run[first[crosses]], run[last[crosses]]
    edges = np.zeros(runs + 1)
    np.add.at(edges, lo, 1.0)
    np.add.at(edges, hi, -1.0)
    joined = np.cumsum(edges)[: runs - 1] > 0  # runs r and r + 1 crossed by one window
    label[crosses] = np.concatenate([[0], np.cumsum(~joined)])[lo]
    _, dense = np.unique(label, return_inverse=True)
    return np.where(label >= 0, dense - int(np.any(label < 0)), -1)


def pivots_std(params: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """The σ of ``estimate`` as the law ``G`` pivots hold, from each pivot's own fit (``params``,
    ``(G, n)``): the σ of their mean, ``s/√G`` (``s`` their scatter), and the estimate's distance
    from that mean in full, ``√(s²/G + (θ̂ − θ̄)²)``; NaN for fewer than two pivots."""
    G = params.shape[0]
    if G < 2:
        return np.full(np.shape(estimate), np.nan)
    mean = params.mean(axis=0)
    return np.sqrt(params.var(axis=0, ddof=1) / G + (estimate - mean) ** 2)
