"""Symbolic Jacobians against central finite differences, on the manifold perturbation."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close, boxplus_numpy

from nlp_calib.models import get_model
from nlp_calib.problem import ProblemSpec, build

MODEL = get_model("tricycle")


def random_state(
    rng: np.random.Generator, horizon: int, straight: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    x = np.array(
        [
            rng.uniform(0.3, 0.8),
            rng.uniform(0.008, 0.012),
            rng.uniform(1.0, 2.0),
            rng.uniform(-0.1, 0.1),
            rng.uniform(0.5, 2.0),
            rng.uniform(-0.3, 0.3),
            rng.uniform(-0.5, 0.5),
        ]
    )
    revs = rng.uniform(-3.0, 3.0, horizon)
    steer = np.zeros(horizon) if straight else rng.uniform(-1.5, 1.5, horizon)
    u = np.column_stack([revs, steer]).ravel()
    z = rng.normal(0.0, 0.05, 3)
    return x, np.concatenate([u, z, [1.0]])


@pytest.mark.parametrize("integration", ["exact", "euler"])
@pytest.mark.parametrize("horizon", [1, 4])
def test_manifold_jacobian_matches_central_differences(integration: str, horizon: int) -> None:
    fns = build(MODEL, ProblemSpec(horizon=horizon, integration=integration))
    rng = np.random.default_rng(11 + horizon)
    for trial in range(20):
        x, data = random_state(rng, horizon, straight=(trial % 5 == 0))
        if trial % 5 == 0:
            x[3] = 0.0  # steer_offset 0 with straight inputs: exactly zero turn
        e, J = (np.asarray(v) for v in fns.residual_jacobian(x, [], data))
        eps = 1e-6
        J_fd = np.zeros_like(J)
        for i in range(7):
            d = np.zeros(7)
            d[i] = eps
            ep = np.asarray(fns.residual(boxplus_numpy(x, d), [], data)).ravel()
            em = np.asarray(fns.residual(boxplus_numpy(x, -d), [], data)).ravel()
            J_fd[:, i] = (ep - em) / (2 * eps)
        scale = np.maximum(np.abs(J), np.abs(J).max() * 1e-3)
        rel = np.abs(J - J_fd) / scale
        assert rel.max() <= 1e-6, f"trial {trial}: max relative error {rel.max():.2e}\n{J}\n{J_fd}"
        assert np.all(np.isfinite(e))


def test_cost_gradient_and_hessian_match_finite_differences() -> None:
    fns = build(MODEL, ProblemSpec(horizon=3, kernel="pseudo_huber"))
    rng = np.random.default_rng(5)
    omega, delta = np.array([1.0, 1.0, 2.0]), 0.05
    for _ in range(10):
        x, data = random_state(rng, 3)
        _, grad = (np.asarray(v).ravel() for v in fns.cost_gradient(x, [], omega, delta, data))
        hess = np.asarray(fns.cost_hessian(x, [], omega, delta, data, 1.0))
        eps = 1e-6
        g_fd = np.zeros(7)
        H_fd = np.zeros((7, 7))
        for i in range(7):
            d = np.zeros(7)
            d[i] = eps
            g_fd[i] = (
                float(fns.cost(x + d, [], omega, delta, data))
                - float(fns.cost(x - d, [], omega, delta, data))
            ) / (2 * eps)
            gp = np.asarray(fns.cost_gradient(x + d, [], omega, delta, data)[1]).ravel()
            gm = np.asarray(fns.cost_gradient(x - d, [], omega, delta, data)[1]).ravel()
            H_fd[:, i] = (gp - gm) / (2 * eps)
        assert_close(grad, g_fd, rtol=1e-6, atol=1e-8 * np.abs(grad).max(), what="gradient")
        assert_close(hess, np.triu(H_fd), rtol=1e-5, atol=1e-6 * np.abs(H_fd).max(), what="hessian")


def test_normal_equations_are_irls_of_the_cost() -> None:
    """2·g of the normal equations is the manifold gradient of the robust cost."""
    fns = build(MODEL, ProblemSpec(horizon=2, kernel="huber"))
    rng = np.random.default_rng(8)
    omega, delta = np.ones(3), 0.02
    x, data = random_state(rng, 2)
    _, g, _, chi2, inliers = fns.normal_equations(x, [], omega, delta, data)
    g = np.asarray(g)
    eps = 1e-7
    g_fd = np.zeros(7)
    for i in range(7):
        d = np.zeros(7)
        d[i] = eps
        g_fd[i] = (
            float(fns.cost(boxplus_numpy(x, d), [], omega, delta, data))
            - float(fns.cost(boxplus_numpy(x, -d), [], omega, delta, data))
        ) / (2 * eps)
    assert_close(2 * g.ravel(), g_fd, rtol=1e-6)
    e = np.asarray(fns.residual(x, [], data)).ravel()
    assert float(chi2) == pytest.approx(e @ e)
    assert float(inliers) == (1.0 if e @ e <= delta**2 else 0.0)


def test_fixed_parameters_leave_the_decision_vector() -> None:
    fns = build(MODEL, ProblemSpec(fixed=("axis_length", "sensor_theta")))
    assert fns.free == ("k_steer", "k_traction", "steer_offset", "sensor_x", "sensor_y")
    assert fns.normal_equations.size_in("x") == (5, 1)
    assert fns.normal_equations.size_out("H_upper") == (15, 1)  # 5 x 5, upper triangle
    assert not fns.manifold_sensor
