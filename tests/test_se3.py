"""SE(3) expressions (symbolic/se3.py) and their numpy twins (core/poses3d.py) against an
independent reference: 4x4 homogeneous matrices, elementary rotations and a matrix exponential by
scaling and squaring of its power series."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from conftest import assert_close
from hypothesis import given, settings
from hypothesis import strategies as st

from nlp_calib.core import poses3d
from nlp_calib.symbolic import se3

coord = st.floats(-5.0, 5.0, allow_nan=False)
vec3 = st.tuples(coord, coord, coord)
# Rotation vectors of angle below π (where Log is unique), including tiny and exactly zero ones.
small = st.floats(-1e-3, 1e-3, allow_nan=False)
rotvec = st.one_of(
    st.tuples(small, small, small),
    st.tuples(*[st.floats(-1.7, 1.7, allow_nan=False)] * 3).filter(lambda v: np.linalg.norm(v) < 3.1),
)
angles = st.tuples(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5), st.floats(-3.1, 3.1))


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def expm(A: np.ndarray) -> np.ndarray:
    """Matrix exponential: scaling and squaring of a 20-term power series (independent of se3)."""
    n = max(0, int(np.ceil(np.log2(max(np.linalg.norm(A), 1e-300)))) + 1)
    B = A / 2.0**n
    out, term = np.eye(A.shape[0]), np.eye(A.shape[0])
    for k in range(1, 20):
        term = term @ B / k
        out = out + term
    for _ in range(n):
        out = out @ out
    return out


def twist(xi: np.ndarray) -> np.ndarray:
    T = np.zeros((4, 4))
    T[:3, :3], T[:3, 3] = skew(xi[3:]), xi[:3]
    return T


def matrix(p: np.ndarray) -> np.ndarray:
    """Homogeneous matrix of a pose vector, through the rotation vector (Rodrigues via expm)."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = quat_matrix(p[3:]), p[:3]
    return T


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation of a unit quaternion from its axis and angle (a different route than se3's)."""
    q = q / np.linalg.norm(q)
    angle = 2.0 * np.arctan2(np.linalg.norm(q[:3]), q[3])
    axis = q[:3] / np.linalg.norm(q[:3]) if np.linalg.norm(q[:3]) > 0 else np.zeros(3)
    return expm(skew(axis * angle))


def elementary(roll: float, pitch: float, yaw: float) -> np.ndarray:
    def rx(a: float) -> np.ndarray:
        return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])

    def ry(a: float) -> np.ndarray:
        return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])

    def rz(a: float) -> np.ndarray:
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    return rz(yaw) @ ry(pitch) @ rx(roll)


def pose_of(t: tuple, phi: tuple) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = expm(skew(np.array(phi))), t
    return np.concatenate([t, poses3d.matrix_to_quat(T[:3, :3])])


def fn(name: str, n_in: list[int], build) -> ca.Function:
    syms = [ca.SX.sym(f"a{i}", n) for i, n in enumerate(n_in)]
    return ca.Function(name, syms, [build(*syms)])


COMPOSE = fn("compose", [7, 7], se3.compose)
INVERSE = fn("inverse", [7], se3.inverse)
BETWEEN = fn("between", [7, 7], se3.between)
EXP = fn("exp", [6], se3.exp)
LOG = fn("log", [7], se3.log)
RPY_TO_QUAT = fn("rpy_to_quat", [3], se3.rpy_to_quat)
QUAT_TO_RPY = fn("quat_to_rpy", [4], se3.quat_to_rpy)
MATRIX_TO_QUAT = fn("matrix_to_quat", [9], lambda r: se3.matrix_to_quat(ca.reshape(r, 3, 3)))
CONJUGATE = fn("conjugate", [7, 3], lambda x, m: se3.conjugate(x, se3.lift(m)))


def call(f: ca.Function, *args: object) -> np.ndarray:
    return np.asarray(f(*args)).ravel()


def same_pose(a: np.ndarray, b: np.ndarray, atol: float = 1e-9) -> None:
    assert_close(matrix(a), matrix(b), atol=atol)


@given(vec3, rotvec, vec3, rotvec)
def test_compose_and_between_match_matrix_products(t1: tuple, r1: tuple, t2: tuple, r2: tuple) -> None:
    a, b = pose_of(t1, r1), pose_of(t2, r2)
    assert_close(matrix(call(COMPOSE, a, b)), matrix(a) @ matrix(b), atol=1e-9)
    assert_close(matrix(call(BETWEEN, a, b)), np.linalg.inv(matrix(a)) @ matrix(b), atol=1e-9)
    assert_close(matrix(call(INVERSE, a)) @ matrix(a), np.eye(4), atol=1e-9)
    same_pose(poses3d.compose(a, b), call(COMPOSE, a, b))
    same_pose(poses3d.between(a, b), call(BETWEEN, a, b))


@given(vec3, rotvec)
def test_exp_is_the_matrix_exponential_and_log_inverts_it(rho: tuple, phi: tuple) -> None:
    xi = np.array([*rho, *phi])
    T = call(EXP, xi)
    assert_close(matrix(T), expm(twist(xi)), atol=1e-9)
    assert abs(np.linalg.norm(T[3:]) - 1.0) < 1e-12
    assert_close(call(LOG, T), xi, atol=1e-9)


@given(rotvec)
def test_so3_numpy_twins_round_trip(phi: tuple) -> None:
    q = poses3d.rotvec_to_quat(np.array(phi))
    assert_close(poses3d.quat_to_matrix(q), expm(skew(np.array(phi))), atol=1e-12)
    assert_close(poses3d.quat_to_rotvec(q), phi, atol=1e-12)
    assert_close(poses3d.quat_to_rotvec(-q), phi, atol=1e-12)  # the double cover
    assert_close(call(LOG, np.concatenate([np.zeros(3), -q]))[3:], phi, atol=1e-12)


@given(angles)
def test_rpy_is_urdf_fixed_axes_and_round_trips(rpy: tuple) -> None:
    R = elementary(*rpy)
    q = call(RPY_TO_QUAT, rpy)
    assert_close(poses3d.quat_to_matrix(q), R, atol=1e-12)
    assert_close(poses3d.rpy_to_matrix(np.array(rpy)), R, atol=1e-12)
    assert_close(call(QUAT_TO_RPY, q), rpy, atol=1e-9)
    assert_close(poses3d.matrix_to_rpy(R), rpy, atol=1e-9)


@settings(max_examples=200)
@given(rotvec)
def test_matrix_to_quat_takes_every_pivot(phi: tuple) -> None:
    R = expm(skew(np.array(phi)))
    for q in (call(MATRIX_TO_QUAT, R.T.ravel()), poses3d.matrix_to_quat(R)):
        assert_close(poses3d.quat_to_matrix(q), R, atol=1e-12)
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12


@pytest.mark.parametrize("pivot", [np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])])
def test_matrix_to_quat_at_half_turns(pivot: np.ndarray) -> None:
    q = call(MATRIX_TO_QUAT, pivot.T.ravel())
    assert_close(poses3d.quat_to_matrix(q), pivot, atol=1e-15)


@given(vec3, rotvec, st.tuples(coord, coord, st.floats(-3.1, 3.1)))
def test_conjugate_of_a_lifted_planar_motion(t: tuple, phi: tuple, m: tuple) -> None:
    X = pose_of(t, phi)
    M = poses3d.from_planar(np.array(m))
    expected = np.linalg.inv(matrix(X)) @ matrix(M) @ matrix(X)
    assert_close(matrix(call(CONJUGATE, X, m)), expected, atol=1e-9)


def _derivatives(build, n: int) -> ca.Function:
    x = ca.SX.sym("x", n)
    y = build(x)
    return ca.Function("d", [x], [y, ca.jacobian(y, x), ca.hessian(ca.sumsqr(y), x)[0]])


@pytest.mark.parametrize(
    ("name", "build", "n", "at"),
    [
        ("exp", se3.exp, 6, np.zeros(6)),
        ("log", se3.log, 7, np.array([0, 0, 0, 0, 0, 0, 1.0])),
        ("so3_exp", se3.so3_exp, 3, np.zeros(3)),
        ("so3_log", se3.so3_log, 4, np.array([0, 0, 0, 1.0])),
    ],
)
def test_values_and_derivatives_are_finite_and_exact_at_exactly_zero_angle(name, build, n, at) -> None:
    """At zero angle the series branch must give the identity's value, the identity Jacobian of the
    chart (no 0/0, no square root's derivative at 0) and a finite Hessian."""
    value, J, H = (np.asarray(v) for v in _derivatives(build, n)(at))
    assert np.all(np.isfinite(value)) and np.all(np.isfinite(J)) and np.all(np.isfinite(H)), name
    eps = 1e-7
    for k in range(n):
        step = np.zeros(n)
        step[k] = eps
        fd = (
            np.asarray(_derivatives(build, n)(at + step)[0])
            - np.asarray(_derivatives(build, n)(at - step)[0])
        ) / (2 * eps)
        assert_close(J[:, k], fd.ravel(), atol=1e-8, what=f"{name} column {k}")


@settings(max_examples=100)
@given(st.floats(1e-4, 0.05), st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1))
def test_series_and_closed_forms_agree_across_the_switch(angle: float, axis: tuple) -> None:
    """Values and Jacobians are continuous where the Taylor branch hands over (θ = 1e-2)."""
    phi = angle * np.array(axis) / np.linalg.norm(axis)
    xi = np.concatenate([[0.3, -0.2, 0.1], phi])
    T = expm(twist(xi))
    assert_close(matrix(call(EXP, xi)), T, atol=1e-14)
    d = _derivatives(se3.exp, 6)
    J = np.asarray(d(xi)[1])
    eps = 1e-6
    fd = np.stack(
        [
            (np.asarray(d(xi + eps * e)[0]) - np.asarray(d(xi - eps * e)[0])).ravel() / (2 * eps)
            for e in np.eye(6)
        ],
        1,
    )
    assert_close(J, fd, atol=1e-8)
    assert_close(call(LOG, call(EXP, xi)), xi, atol=1e-14)


def test_retract_moves_position_in_the_parent_and_rotation_on_the_right() -> None:
    a = pose_of((1.0, 2.0, 3.0), (0.3, -0.2, 0.5))
    delta = np.array([0.01, -0.02, 0.03, 0.002, 0.001, -0.003])
    f = fn("retract", [7, 6], se3.retract)
    got = matrix(call(f, a, delta))
    expected = matrix(a) @ expm(twist(np.r_[0, 0, 0, delta[3:]]))
    expected[:3, 3] = matrix(a)[:3, 3] + delta[:3]
    assert_close(got, expected, atol=1e-12)


def test_rpy_boxplus_is_a_left_rotation() -> None:
    rpy = np.array([-2.0, 0.1, -1.5])
    delta = np.array([0.01, -0.02, 0.03])
    f = fn("boxplus", [3, 3], se3.rpy_boxplus)
    assert_close(elementary(*call(f, rpy, delta)), expm(skew(delta)) @ elementary(*rpy), atol=1e-12)


def test_accumulate_matches_repeated_products() -> None:
    rng = np.random.default_rng(0)
    steps = np.stack([pose_of(tuple(rng.normal(size=3)), tuple(0.3 * rng.normal(size=3))) for _ in range(5)])
    start = pose_of((1, 0, 0), (0, 0, 0.4))
    track = poses3d.accumulate(start, steps)
    T = matrix(start)
    for k in range(5):
        T = T @ matrix(steps[k])
        same_pose(track[k + 1], np.concatenate([T[:3, 3], poses3d.matrix_to_quat(T[:3, :3])]))


def test_accumulate_is_compose_step_by_step_to_the_bit() -> None:
    """The sequential pass written on floats gives the array compose's doubles, step after step."""
    rng = np.random.default_rng(3)
    steps = np.r_[
        "1", 0.1 * rng.normal(size=(500, 3)), poses3d.rotvec_to_quat(0.05 * rng.normal(size=(500, 3)))
    ]
    start = np.r_[rng.normal(size=3), poses3d.rotvec_to_quat(rng.normal(size=3))]
    expected = np.empty((501, 7))
    expected[0] = start
    for k in range(500):
        expected[k + 1] = poses3d.compose(expected[k], steps[k])
    expected[:, 3:] /= np.linalg.norm(expected[:, 3:], axis=1, keepdims=True)
    assert poses3d.accumulate(start, steps).tobytes() == expected.tobytes()


def test_accumulate_is_compose_step_by_step_across_its_blocks() -> None:
    """The positions are summed a block of steps at a time: each block goes on from the last
    one's end to the bit, over more than two blocks and a part of one."""
    rng = np.random.default_rng(5)
    n = 2 * poses3d._BLOCK + 37
    steps = np.c_[0.1 * rng.normal(size=(n, 3)), poses3d.rotvec_to_quat(0.05 * rng.normal(size=(n, 3)))]
    start = np.r_[rng.normal(size=3), poses3d.rotvec_to_quat(rng.normal(size=3))]
    expected = np.empty((n + 1, 7))
    expected[0] = start
    for k in range(n):
        expected[k + 1] = poses3d.compose(expected[k], steps[k])
    expected[:, 3:] /= np.linalg.norm(expected[:, 3:], axis=1, keepdims=True)
    assert poses3d.accumulate(start, steps).tobytes() == expected.tobytes()


def test_moved_is_betweens_translation_to_the_bit() -> None:
    """The RPE's translations skip the rotation's product: the same doubles as ``between``'s."""
    rng = np.random.default_rng(6)
    a = np.c_[rng.normal(size=(1000, 3)), poses3d.rotvec_to_quat(rng.normal(size=(1000, 3)))]
    b = np.c_[rng.normal(size=(1000, 3)), poses3d.rotvec_to_quat(rng.normal(size=(1000, 3)))]
    assert poses3d.moved(a, b).tobytes() == np.ascontiguousarray(poses3d.between(a, b)[:, :3]).tobytes()


def test_turned_is_an_unwrapped_angle_along_a_fixed_axis() -> None:
    axis = np.array([0.0, -np.sqrt(0.75), 0.5])  # the floor normal as a camera 30° down sees it
    angle = np.linspace(0.0, 9.0, 400)  # more than a turn and a half
    q = poses3d.rotvec_to_quat(np.outer(np.mod(angle + np.pi, 2 * np.pi) - np.pi, axis))
    assert np.allclose(poses3d.turned(q), np.outer(angle, axis), atol=1e-12)


def test_between_at_runs_from_one_pose_to_the_other_on_the_shorter_arc() -> None:
    rng = np.random.default_rng(4)
    a = np.r_[rng.normal(size=3), poses3d.rotvec_to_quat(rng.normal(size=3))]
    step = np.r_[rng.normal(size=3), poses3d.rotvec_to_quat(np.array([0.0, 0.0, 0.8]))]
    b = poses3d.compose(a, step)
    s = np.array([[0.0], [0.25], [1.0]])
    out = poses3d.between_at(np.tile(a, (3, 1)), np.tile(b, (3, 1)), s)
    assert np.allclose(out[0], a) and np.allclose(poses3d.between(b, out[2])[3:6], 0.0, atol=1e-12)
    assert np.allclose(out[1, :3], a[:3] + 0.25 * (b[:3] - a[:3]))
    assert np.allclose(poses3d.quat_to_rotvec(poses3d.between(a, out[1])[3:]), [0.0, 0.0, 0.2])
