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
    run = np.cumsum(np.diff(np.concatenate([[0], pivot.astype(int)])) == 1) - 1
    run = np.where(pivot, run, -1)
    root = np.arange(int(run.max()) + 1 if run.size else 0)

    def find(r: int) -> int:
        while root[r] != r:
            r = int(root[r])
        return r

    first = np.full(starts.size, -1)
    for w, (a, b) in enumerate(zip(starts, stops)):
        crossed = np.unique(run[a:b][run[a:b] >= 0])
        if crossed.size:
            first[w] = crossed[0]
            roots = [find(int(r)) for r in crossed]
            root[roots] = min(roots)
    label = np.array([find(int(r)) if r >= 0 else -1 for r in first], dtype=int)
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
