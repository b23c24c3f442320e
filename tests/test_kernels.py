"""Robust kernels: values against their closed forms, weights against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close

from nlp_calib.symbolic.kernels import KERNELS, kernel_function

DELTA = 0.3
S = np.array([0.0, 1e-6, 0.05, DELTA**2, 0.2, 1.0, 25.0])


def closed_form(kernel: str, s: np.ndarray, d: float) -> np.ndarray:
    if kernel == "none":
        return s
    if kernel == "huber":
        return np.where(s <= d * d, s, 2 * d * np.sqrt(s) - d * d)
    if kernel == "cauchy":
        return d * d * np.log(1 + s / (d * d))
    return 2 * d * d * (np.sqrt(1 + s / (d * d)) - 1)


@pytest.mark.parametrize("kernel", sorted(KERNELS))
def test_kernel_values_and_weights(kernel: str) -> None:
    f = kernel_function(kernel)
    rho = np.array([float(f(s, DELTA)[0]) for s in S])
    weight = np.array([float(f(s, DELTA)[1]) for s in S])
    assert_close(rho, closed_form(kernel, S, DELTA), rtol=1e-12, atol=1e-15, what=kernel)
    h = 1e-7
    s_fd = S[S > 2 * h]
    fd = (closed_form(kernel, s_fd + h, DELTA) - closed_form(kernel, s_fd - h, DELTA)) / (2 * h)
    inside = ~np.isclose(s_fd, DELTA**2)  # Huber's weight jumps exactly at the threshold
    assert_close(weight[S > 2 * h][inside], fd[inside], rtol=1e-5, what=kernel)
    assert weight[0] == pytest.approx(1.0)  # every kernel behaves like least squares near 0


def test_weights_are_finite_at_zero() -> None:
    for kernel in KERNELS:
        rho, weight = kernel_function(kernel)(0.0, DELTA)
        assert np.isfinite(float(rho)) and np.isfinite(float(weight))
