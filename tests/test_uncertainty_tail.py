"""Which windows beyond a robust kernel's threshold the noise explains (nlp_calib.analysis.uncertainty)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from nlp_calib.analysis.uncertainty import (
    EXPLAINED_Z,
    _Kernel,
    _Window,
    bounds_prior,
    chi2_point,
    expected_kernel_terms,
    range_std,
)


@pytest.mark.parametrize(("k", "point"), [(1, 10.828), (3, 16.266), (6, 22.458), (9, 27.877)])
def test_the_chi_square_point_is_the_tables(k: int, point: float) -> None:
    """χ²(k)'s 99.9 % points as the tables give them (Wilson-Hilferty: within 4 % from k = 1 on)."""
    assert float(chi2_point(np.array([k]), EXPLAINED_Z)[0]) == pytest.approx(point, rel=0.04)


def test_a_window_is_explained_by_its_rows_noise_not_by_the_kernels_threshold() -> None:
    """Six rows of unit noise (Ω 1): a squared residual of 12 is the noise's (beyond δ = 3, within
    χ²(6)'s 99.9 % point), one of 30 is not; with the noise's variance four times larger, 30 is too.
    Rows of no noise (another sensor's) count for nothing."""
    rows = 9
    coef = np.zeros((3, rows, 2))
    coef[:, :6, 0] = 1.0  # six rows of the first group's noise, three of the other's (none)
    e2 = np.zeros((3, rows))
    e2[0, :6], e2[1, :6], e2[2, :6] = 2.0, 5.0, 5.0
    window = _Window(np.arange(3), coef, np.zeros((3, rows)), e2, np.zeros((3, 4)))
    omega = np.ones(rows)
    assert window.explained(np.array([1.0, 0.0]), omega).tolist() == [True, False, False]
    assert window.explained(np.array([4.0, 0.0]), omega).tolist() == [True, True, True]
    # Noise on rows of unequal weight: fewer effective degrees of freedom (1.1), a wider tail: 60
    # lies beyond six equal rows' point (10.5 × 22.46 / 6 = 39) but within this one's (about 111).
    unequal = np.ones(rows)
    unequal[0] = 100.0
    e2_one = np.zeros((1, rows))
    e2_one[0, 0] = 0.6  # 60 in Ω's units, on the heavily weighted row
    one = _Window(np.arange(1), coef[:1], np.zeros((1, rows)), e2_one, np.zeros((1, 4)))
    assert one.explained(np.array([0.1, 0.0]), unequal).tolist() == [True]


def _huber_three_rows(delta: float, mean_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Huber's mean slope E[ρ' + 2ρ''·s/3] and mean square pull E[ρ'²·s] over three rows of noise
    whose squares sum to ``mean_s`` on average, in closed form: s = c·χ²(3), c = mean_s/3; within
    δ the slope is 1 and the pull² s, beyond it δ/√s·(1 − 1/3) and δ²."""
    c = mean_s / 3.0
    t = delta**2 / c
    below = np.vectorize(math.erf)(np.sqrt(t / 2.0)) - np.sqrt(2.0 * t / np.pi) * np.exp(-t / 2.0)
    below5 = below - (t / 2.0) ** 1.5 * np.exp(-t / 2.0) / (0.75 * np.sqrt(np.pi))  # χ²(5)'s
    # E[1/√s; s > δ²] = √(2/π)·exp(−t/2)/√c for three rows.
    slope = below + (2.0 / 3.0) * delta * np.sqrt(2.0 / np.pi) * np.exp(-t / 2.0) / np.sqrt(c)
    return slope, 3.0 * c * below5 + delta**2 * (1.0 - below)


def test_the_kernels_expected_terms_are_the_closed_forms() -> None:
    """Huber's on three rows at scales from well within δ to far beyond it: the slope within 2e-5,
    the pull's mean square within 5e-5 of its value, and what a window's own pull adds beyond the
    slope (b − a², 0.0018 at unit noise and δ = 3) within 1e-5."""
    delta = 3.0
    mean_s = np.geomspace(0.3, 300.0, 400)
    slope, spread = expected_kernel_terms("huber", delta, mean_s, np.full(mean_s.size, 3))
    exact_slope, exact_spread = _huber_three_rows(delta, mean_s)
    assert np.abs(slope - exact_slope).max() < 2e-5
    assert np.abs(spread / exact_spread - 1.0).max() < 5e-5
    own, exact_own = spread / mean_s - slope**2, exact_spread / mean_s - exact_slope**2
    assert np.abs(own - exact_own).max() < 1e-5
    assert exact_own[np.argmin(np.abs(mean_s - 3.0))] == pytest.approx(0.0018, abs=2e-4)  # at unit noise
    # A quadratic kernel's: 1 and the mean itself.
    ones, same = expected_kernel_terms("none", delta, mean_s, np.full(mean_s.size, 3))
    assert ones.tolist() == [1.0] * mean_s.size and same.tolist() == mean_s.tolist()


def test_the_kernels_expected_slope_is_its_derivatives_mean() -> None:
    """Cauchy's on six rows of unit noise: the slope, computed as E[ρ'·s]/E[s], is the mean of its
    definition ρ' + 2ρ''·s/6 over 400,000 draws (ρ' = 1/(1 + s/δ²), ρ'' = −ρ'²/δ²), and the mean
    square pull E[ρ'²·s] too, within their sampling noise."""
    delta = 2.0
    s = (np.random.default_rng(5).normal(size=(400_000, 6)) ** 2).sum(axis=1)
    weight = 1.0 / (1.0 + s / delta**2)
    definition = weight - 2.0 * weight**2 / delta**2 * s / 6.0
    slope, spread = expected_kernel_terms("cauchy", delta, np.array([6.0]), np.array([6]))
    assert float(slope[0]) == pytest.approx(definition.mean(), abs=4 * definition.std() / np.sqrt(s.size))
    pull2 = weight**2 * s
    assert float(spread[0]) == pytest.approx(pull2.mean(), abs=4 * pull2.std() / np.sqrt(s.size))


def test_the_kernels_slopes_follow_the_noise_not_the_windows_residuals() -> None:
    """Over windows of three rows of unit noise, the mean slope and the pulls' mean square over the
    residuals' are the noise's (the closed form at a mean of 3) whatever each window's own residual
    was; a window beyond the threshold the noise does not explain is left out (here, one of twice
    the noise: the means lie between the two scales')."""
    kernel = _Kernel("huber", 3.0)
    # Per window: Σ Ω·known, Σ Ω·coef per group (the second group none), rows of noise.
    kernel.noise.append(np.array([[0.0, 3.0, 0.0, 3.0]] * 9 + [[0.0, 6.0, 0.0, 3.0]]))
    a, b = kernel.slopes(np.array([9]), np.array([1.0, 0.0]))
    slope, spread = _huber_three_rows(3.0, np.array([3.0]))
    assert a[0] == pytest.approx(float(slope[0]), abs=2e-5)
    assert b[0] == pytest.approx(float(spread[0]) / 3.0, abs=5e-5)
    assert (a[1], b[1]) == (1.0, 1.0)  # no window carries the second group
    both, _ = kernel.slopes(np.zeros(0, dtype=int), np.array([1.0, 0.0]))
    wider, _ = _huber_three_rows(3.0, np.array([6.0]))
    assert both[0] == pytest.approx((9 * float(slope[0]) + float(wider[0])) / 10, abs=2e-5)
    assert _Kernel("none", 3.0).slopes(np.zeros(0, dtype=int), np.array([1.0, 0.0]))[0].tolist() == [1.0, 1.0]


def test_a_pinned_parameters_bounds_weigh_it_infinitely_and_say_nothing() -> None:
    """Bounds that meet (a lag pinned where no fit converged) hold the parameter exactly: an infinite
    prior weight, computed without numpy's division warning reaching the user's terminal."""
    std = range_std(np.array([0.5, -np.inf, 0.0]), np.array([3.5, np.inf, 0.0]), 3)
    assert std[0] == pytest.approx(3.0 / math.sqrt(12.0)) and math.isinf(std[1]) and std[2] == 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        weight = bounds_prior(std, 2.0, 3)
    assert weight[0] == pytest.approx(2.0 * 12.0 / 9.0) and weight[1] == 0.0 and math.isinf(weight[2])
