"""The lag's re-sampling loop (``_LagFits.settle``) ends where the lag fitted on the encoders
re-sampled at τ is τ, also where the plain re-samplings alternate between two lags."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from nlp_calib.pipeline.align import BRACKET_STEPS, MAX_RESAMPLINGS, _LagFits, bracket, next_lag


class _Fits:
    """A lag's fits where the lag fitted on the encoders re-sampled at τ is ``fitted(τ)`` and its
    cost ``cost(τ)``; white-noise σ ``std`` (one free parameter, the lag, no second clock)."""

    column = 0
    beside = None

    def __init__(self, fitted: Callable[[float], float], cost: Callable[[float], float], std: float) -> None:
        self.fitted, self.cost, self.std, self.calls = fitted, cost, std, 0

    def fit(self, x: np.ndarray) -> tuple[float, np.ndarray, bool]:
        self.calls += 1
        return self.cost(float(x[0])), np.array([self.fitted(float(x[0]))]), True

    def beside_s(self, x: np.ndarray) -> None:
        return None

    def lag_std(self, x: np.ndarray, column: int | None = None) -> float:
        return self.std


def _settle(fits: _Fits, start: float) -> tuple[float, list[float]]:
    x, path, _, converged = _LagFits.settle(fits, np.array([start]))  # type: ignore[arg-type]
    assert converged
    return float(x[0]), path


@pytest.mark.parametrize(("slope", "root"), [(-1.0, 0.018), (-1.6, 0.0114), (-0.9, -0.03)])
def test_a_lag_whose_re_samplings_overshoot_each_other_settles_at_the_root(slope: float, root: float) -> None:
    """The lag fitted at τ is ``root + slope·(τ − root)``: at slope −1 the plain re-samplings
    alternate between two lags for ever, below it they part further each time, at −0.9 they close
    in by a tenth a step. Each ends within its tolerance (a quarter of the white σ, 1 ms) of the
    root: a lag where the fit stays."""
    std = 0.004
    fits = _Fits(lambda t: root + slope * (t - root), lambda t: 1.0 + (t - root) ** 2, std)
    lag, path = _settle(fits, 0.0)
    assert abs(lag - root) < 0.25 * std, (lag, path)
    assert fits.calls <= MAX_RESAMPLINGS + BRACKET_STEPS


def test_a_fitted_lag_that_jumps_across_the_lag_settles_on_the_cheaper_side_of_the_jump() -> None:
    """The lag fitted at τ jumps across τ at 20 ms (from 26 ms below it to 12 ms above): no lag
    stays. The loop closes in on the jump, to its tolerance (0.25 ms), and keeps the re-sampling
    of least cost (above the jump here), the fit from it made once more."""
    fits = _Fits(lambda t: 0.026 if t < 0.02 else 0.012, lambda t: 1.0 if t < 0.02 else 0.9, 0.001)
    lag, path = _settle(fits, 0.0)
    assert lag >= 0.02 and path[-1] == lag, path
    assert min(abs(p - 0.02) for p in path if p >= 0.02) < 0.00025, path


def test_the_cheapest_re_sampling_is_kept_over_the_root_once_the_fits_overshoot() -> None:
    """The lag fitted at τ overshoots τ (slope −1.2 about 18 ms) while the fits' cost is least
    at 0 (the encoders as logged, each re-sampling away from them costing more): the loop finds
    where it stays, and keeps the re-sampling at 0, the fit from it made again."""
    fits = _Fits(lambda t: 0.018 - 1.2 * (t - 0.018), lambda t: 1.0 + abs(t), 0.004)
    lag, path = _settle(fits, 0.0)
    assert lag == 0.0 and path[-1] == 0.0, path
    assert min(abs(p - 0.018) for p in path) < 0.001, path


def test_plain_re_samplings_that_close_in_are_kept() -> None:
    """The fitted lags closing in (a move each under :data:`SHRINK` of the last, either way) are
    followed as fitted, the secant only once they stop; the bracket is the last lag and the last
    before it moved the other way."""
    tried = [(0.0, 0.024), (0.024, 0.0155), (0.0155, 0.0205)]
    assert next_lag(tried) == 0.0205
    assert bracket(tried) == (2, 1)
    alternating = [(0.0, 0.0237), (0.0237, 0.0283), (0.0283, 0.0155)]
    lag = next_lag(alternating)
    assert 0.0237 < lag < 0.0283 and lag != 0.0155
