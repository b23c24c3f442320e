"""SE(2) expressions against homogeneous matrices computed independently in numpy."""

from __future__ import annotations

import casadi as ca
import numpy as np
from conftest import assert_close, mat, vec
from hypothesis import given, settings
from hypothesis import strategies as st

from nlp_calib.symbolic import se2

finite = st.floats(-10.0, 10.0, allow_nan=False)
angle = st.floats(-3.1, 3.1, allow_nan=False)
pose = st.tuples(finite, finite, angle)

a_sym, b_sym = ca.SX.sym("a", 3), ca.SX.sym("b", 3)
COMPOSE = ca.Function("compose", [a_sym, b_sym], [se2.compose(a_sym, b_sym)])
BETWEEN = ca.Function("between", [a_sym, b_sym], [se2.between(a_sym, b_sym)])
INVERSE = ca.Function("inverse", [a_sym], [se2.inverse(a_sym)])
V2T = ca.Function("v2t", [a_sym], [se2.v2t(a_sym)])
w_sym = ca.SX.sym("w")
SINC = ca.Function("sinc", [w_sym], [se2.sinc(w_sym), ca.jacobian(se2.sinc(w_sym), w_sym)])
d_sym = ca.SX.sym("d")
ARC = ca.Function(
    "arc",
    [d_sym, w_sym],
    [se2.arc(d_sym, w_sym), ca.jacobian(se2.arc(d_sym, w_sym), ca.vertcat(d_sym, w_sym))],
)


def wrap(t: float) -> float:
    return float(np.arctan2(np.sin(t), np.cos(t)))


@given(pose, pose)
def test_compose_matches_matrix_product(a: tuple, b: tuple) -> None:
    got = np.asarray(COMPOSE(a, b)).ravel()
    expected = vec(mat(a) @ mat(b))
    assert_close(got[:2], expected[:2], atol=1e-9)
    assert abs(wrap(got[2] - expected[2])) < 1e-12


@given(pose, pose)
def test_between_is_inverse_times_other(a: tuple, b: tuple) -> None:
    got = np.asarray(BETWEEN(a, b)).ravel()
    assert_close(got, vec(np.linalg.inv(mat(a)) @ mat(b)), atol=1e-9)
    assert -np.pi <= got[2] <= np.pi


@given(pose)
def test_inverse(a: tuple) -> None:
    assert_close(mat(np.asarray(INVERSE(a)).ravel()) @ mat(a), np.eye(3), atol=1e-9)


@given(pose)
def test_v2t_t2v_round_trip(a: tuple) -> None:
    T = np.asarray(V2T(a))
    assert_close(T, mat(a), atol=1e-15)
    t2v = ca.Function("t2v", [a_sym], [se2.t2v(se2.v2t(a_sym))])
    assert_close(np.asarray(t2v(a)).ravel(), a, atol=1e-12)


def test_sinc_at_exactly_zero_value_and_derivative() -> None:
    value, deriv = SINC(0.0)
    assert float(value) == 1.0
    assert float(deriv) == 0.0


@given(st.floats(-0.5, 0.5, allow_nan=False))
def test_sinc_is_smooth_across_the_taylor_switch(w: float) -> None:
    value, deriv = (float(v) for v in SINC(w))
    exact = np.sinc(w / np.pi)
    exact_deriv = (np.cos(w) * w - np.sin(w)) / w**2 if abs(w) > 1e-4 else -w / 3.0
    assert abs(value - exact) < 1e-15
    assert abs(deriv - exact_deriv) < 1e-8


@settings(max_examples=200)
@given(st.floats(-2.0, 2.0, allow_nan=False), st.floats(-1.0, 1.0, allow_nan=False))
def test_arc_matches_closed_form(d: float, w: float) -> None:
    got = np.asarray(ARC(d, w)[0]).ravel()
    if abs(w) > 1e-3:
        expected = [d * np.sin(w) / w, d * (1 - np.cos(w)) / w, w]
    else:
        expected = [d * (1 - w**2 / 6 + w**4 / 120), d * (w / 2 - w**3 / 24), w]
    assert_close(got, expected, atol=1e-12)


def test_arc_values_and_jacobian_finite_at_zero_turn() -> None:
    value, jac = ARC(0.7, 0.0)
    assert_close(np.asarray(value).ravel(), [0.7, 0.0, 0.0], atol=0.0)
    # d/dd = (1, 0, 0); d/dw = (0, d/2, 1) at w = 0.
    assert_close(np.asarray(jac), [[1.0, 0.0], [0.0, 0.35], [0.0, 1.0]], atol=1e-15)
