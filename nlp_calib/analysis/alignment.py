"""Time alignment: how much later the tracker reports a pose than the encoders read it.

The lag is estimated the way any other parameter is: by the fit cost. For each lag on a grid
the encoder inputs are re-sampled at ``t - lag`` (the tracker's measurements stay untouched, so
costs are comparable), the problem is solved, and a parabola through the costs around the best
grid point gives the estimate. Interpolating encoder readings at fractional sample offsets
smooths them slightly, which makes the raw cost ripple with the sample period; the parabola
fit over several periods averages that ripple out.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LagEstimate:
    """The estimated lag (s) and the cost curve it came from."""

    lag_s: float
    grid_s: tuple[float, ...]
    costs: tuple[float, ...]

    def as_dict(self) -> dict[str, object]:
        return {"lag_s": self.lag_s, "grid_s": list(self.grid_s), "costs": list(self.costs)}


def lag_grid(search: tuple[float, float], step: float) -> np.ndarray:
    """Grid of candidate lags over ``search`` (inclusive) at ``step``."""
    lo, hi = search
    n = int(np.floor((hi - lo) / step + 1e-9)) + 1
    return lo + step * np.arange(n)


def refine_minimum(grid: np.ndarray, costs: np.ndarray, half_width: int = 6) -> float:
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
    """Minimise ``fit_cost(lag)`` over the grid, refined by a parabola."""
    grid = lag_grid(search, step)
    costs = np.array([fit_cost(float(lag)) for lag in grid])
    finite = np.isfinite(costs)
    if not finite.any():
        return LagEstimate(0.0, tuple(grid.tolist()), tuple(costs.tolist()))
    lag = refine_minimum(grid[finite], costs[finite])
    return LagEstimate(round(lag, 6), tuple(grid.tolist()), tuple(costs.tolist()))
