"""Symbolic Jacobians against central finite differences, on the manifold perturbation."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close, boxplus_numpy, parse_lines

from nlp_calib.models import get_model
from nlp_calib.problem import ProblemSpec, ResidualOptions, build, build_residual_data
from nlp_calib.simulation import SimulationOptions, simulate
from nlp_calib.solvers import ProblemEvaluator

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


def small_evaluator(horizon: int, kernel: str, **sim: object) -> tuple[ProblemEvaluator, np.ndarray]:
    """An interpreted evaluator on a short simulated log, and a point near its optimum."""
    fns = build(MODEL, ProblemSpec(horizon=horizon, kernel=kernel))
    log = parse_lines(simulate(SimulationOptions.of(records=120, seed=9, **sim)).text().splitlines())  # type: ignore[arg-type]
    data = build_residual_data(fns, log, ResidualOptions(horizon=horizon))
    ev = ProblemEvaluator(fns, data, x_fixed=np.zeros(0), omega=np.array([1.0, 1.0, 2.0]), delta=0.01)
    x = np.array(list(MODEL.drive.default_truth.values())) * (1.0 + 0.02 * np.arange(7) / 7)
    return ev, x


@pytest.mark.parametrize("horizon", [1, 4])
def test_cost_gradient_and_hessian_match_finite_differences(horizon: int) -> None:
    """The exact Hessian IPOPT gets, through the prefix jets for H > 1, against differences."""
    ev, x = small_evaluator(horizon, "pseudo_huber")
    cost, grad, hess = ev.cost_derivatives(x)
    assert cost == pytest.approx(ev.cost(x), rel=1e-12)
    g_fd, H_fd = np.zeros(7), np.zeros((7, 7))
    for i in range(7):
        d = np.zeros(7)
        d[i] = 1e-6 * max(abs(x[i]), 1e-2)
        g_fd[i] = (ev.cost(x + d) - ev.cost(x - d)) / (2 * d[i])
        H_fd[:, i] = (ev.cost_derivatives(x + d)[1] - ev.cost_derivatives(x - d)[1]) / (2 * d[i])
    assert_close(grad, g_fd, rtol=1e-5, atol=1e-6 * np.abs(grad).max(), what="gradient")
    assert_close(hess, H_fd, rtol=1e-4, atol=1e-5 * np.abs(H_fd).max(), what="hessian")


@pytest.mark.parametrize("horizon", [1, 3])
def test_normal_equations_are_irls_of_the_cost(horizon: int) -> None:
    """2·g of the normal equations is the manifold gradient of the robust cost."""
    ev, x = small_evaluator(horizon, "huber", outlier_fraction=0.05)
    ne = ev.normal_equations(x)
    g_fd = np.zeros(7)
    for i in range(7):
        d = np.zeros(7)
        d[i] = 1e-6 * max(abs(x[i]), 1e-2)
        g_fd[i] = (ev.cost(boxplus_numpy(x, d)) - ev.cost(boxplus_numpy(x, -d))) / (2 * d[i])
    # Differences straddle some residuals' kink at s = δ²: allow their O(step) error.
    assert_close(2 * ne.g.ravel(), g_fd, rtol=1e-5, atol=1e-6 * np.abs(g_fd).max())
    e, s, _ = ev.robust_terms(x)
    assert ne.chi2 == pytest.approx(float(np.sum(s)), rel=1e-12)
    assert_close(s, np.einsum("cw,c,cw->w", e, ev.omega, e), rtol=1e-12)
    assert ne.inliers == int(np.sum(s <= ev.delta**2)) and 0 < ne.inliers < s.size


def test_fixed_parameters_leave_the_decision_vector() -> None:
    fns = build(MODEL, ProblemSpec(fixed=("axis_length", "sensor_theta")))
    assert fns.free == ("k_steer", "k_traction", "steer_offset", "sensor_x", "sensor_y")
    assert fns.normal_equations.size_in("x") == (5, 1)
    assert fns.normal_equations.size_out("H_upper") == (15, 1)  # 5 x 5, upper triangle
    assert fns.cost_derivatives.size_out("hess_upper") == (15, 1)
    assert not fns.manifold_sensor
