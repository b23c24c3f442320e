"""The non-negative least squares behind every noise estimate: the optimum, whatever the columns'
scales or rank (against an exhaustive search over every subset of free coordinates)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from nlp_calib.analysis.uncertainty import nnls_gram, nnls_small


def exhaustive(A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """The best point among every subset's unconstrained solution that is non-negative."""
    k = A.shape[1]
    best, best_cost = np.zeros(k), float(y @ y)
    for size in range(1, k + 1):
        for cols in itertools.combinations(range(k), size):
            sol = np.linalg.lstsq(A[:, cols], y, rcond=None)[0]
            if np.all(sol >= 0):
                x = np.zeros(k)
                x[list(cols)] = sol
                cost = float(np.sum((y - A @ x) ** 2))
                if cost < best_cost:
                    best, best_cost = x, cost
    return best, best_cost


@pytest.mark.parametrize("seed", range(6))
def test_the_active_set_reaches_the_exhaustive_optimum(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(60):
        k, m = int(rng.integers(1, 8)), int(rng.integers(1, 25))
        # Columns over twelve orders of magnitude, sometimes two equal (a rank-deficient problem).
        A = rng.normal(size=(m, k)) * np.exp(3.0 * rng.normal(size=k))
        if k > 1 and rng.random() < 0.25:
            A[:, 0] = A[:, -1]
        y = rng.normal(size=m) + (A @ np.abs(rng.normal(size=k)) if rng.random() < 0.5 else 0.0)
        x = nnls_small(A, y)
        want, cost = exhaustive(A, y)
        assert np.all(x >= 0)
        assert float(np.sum((y - A @ x) ** 2)) <= cost + 1e-10 * float(y @ y)
        if np.linalg.matrix_rank(A) == k and np.linalg.cond(A) < 1e4:
            np.testing.assert_allclose(x, want, rtol=1e-8, atol=1e-12 * np.abs(want).max(initial=1.0))


def test_a_problem_whose_unconstrained_optimum_is_negative_everywhere_gives_zero() -> None:
    A = np.eye(3)
    assert np.array_equal(nnls_gram(A.T @ A, -np.ones(3), 3.0), np.zeros(3))
