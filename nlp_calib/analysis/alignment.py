"""Time alignment: how much later the tracker reports a pose than the encoders read it.

The lag is estimated the way any other parameter is: by the fit cost. For a lag the encoder
inputs are re-sampled at ``t - lag`` (the tracker's measurements stay untouched, so costs are
comparable) and the problem is solved; a parabola through the costs on a grid of lags around the
best one gives the estimate. Interpolating encoder readings at fractional sample offsets smooths
them slightly, which makes the raw cost ripple with the sample period; the parabola fit over
several periods averages that ripple out.

Not every grid point needs a fit: a coarse pass over the grid brackets the valley, then only the
neighbourhood of the best point is filled in, moving with it until the best point is also the
best of its whole neighbourhood. The estimate is the same parabola through the same costs as a
fit at every grid point would give, whenever the coarse pass finds the valley (a ripple shorter
than the neighbourhood cannot hide it).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.results.checks import LagEstimate

#: Grid points on each side of the best one that the parabola is fitted through.
HALF_WIDTH = 6
#: Every this many grid points the coarse pass fits one.
COARSE_STRIDE = 4


def lag_grid(search: tuple[float, float], step: float) -> np.ndarray:
    """Grid of candidate lags over ``search`` (inclusive) at ``step``."""
    lo, hi = search
    n = int(np.floor((hi - lo) / step + 1e-9)) + 1
    return lo + step * np.arange(n)


def refine_minimum(grid: np.ndarray, costs: np.ndarray, half_width: int = HALF_WIDTH) -> float:
    """Vertex of a least-squares parabola through the costs around the best grid point."""
    i = int(np.argmin(costs))
    lo, hi = max(0, i - half_width), min(grid.size, i + half_width + 1)
    if hi - lo < 3:
        return float(grid[i])
    a, b, _ = np.polyfit(grid[lo:hi], costs[lo:hi], 2)
    if a <= 0:
        return float(grid[i])
    vertex = -b / (2.0 * a)
    return float(np.clip(vertex, grid[lo], grid[hi - 1]))


def estimate_lag(fit_cost: Callable[[float], float], search: tuple[float, float], step: float) -> LagEstimate:
    """Minimise ``fit_cost(lag)`` over the grid (coarse pass, then the best point's neighbourhood),
    refined by a parabola. ``fit_cost`` returns NaN where the fit does not converge."""
    grid = lag_grid(search, step)
    costs = np.full(grid.size, np.nan)
    fitted = np.zeros(grid.size, dtype=bool)

    def fit(indices: np.ndarray) -> None:
        for i in indices[~fitted[indices]]:
            costs[i] = fit_cost(float(grid[i]))
            fitted[i] = True

    fit(np.unique(np.r_[np.arange(0, grid.size, COARSE_STRIDE), grid.size - 1]))
    while True:
        usable = fitted & np.isfinite(costs)
        if not usable.any():
            raise ProblemError(
                f"no lag in [{search[0]:g}, {search[1]:g}] s gave a fit that converged; check the initial "
                "guess (or use initial_guess: auto), or search around the lag the log's clocks allow"
            )
        best = int(np.flatnonzero(usable)[np.argmin(costs[usable])])
        around = np.arange(max(0, best - HALF_WIDTH), min(grid.size, best + HALF_WIDTH + 1))
        if fitted[around].all():
            break
        fit(around)
    keep = np.isfinite(costs[around])
    lag = refine_minimum(grid[around][keep], costs[around][keep])
    at_edge = best in (0, grid.size - 1)
    return LagEstimate(round(lag, 6), tuple(grid[fitted].tolist()), tuple(costs[fitted].tolist()), at_edge)
