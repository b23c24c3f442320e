"""SE(3) in CasADi, on pose vectors ordered ``(x, y, z, qx, qy, qz, qw)``.

Conventions (the same as :mod:`nlp_calib.core.poses3d`, their numeric twins):

- quaternions are Hamilton and ordered ``(qx, qy, qz, qw)``, as TUM files and ROS messages write
  them; ``q`` and ``−q`` are the same rotation;
- a pose vector is the translation followed by the unit quaternion of the rotation; ``a · b``
  maps ``b``'s frame into ``a``'s (``t = t_a + R_a·t_b``, ``q = q_a ⊗ q_b``);
- a tangent vector ``ξ = (ρ, φ)`` is translation first, rotation second (as jaxlie orders it),
  ``φ`` the rotation vector (axis times angle); :func:`exp` and :func:`log` are the group's
  exponential and logarithm (``ρ = V(φ)⁻¹·t``), not a translation-plus-rotation-vector chart;
- roll, pitch and yaw follow URDF (fixed axes): ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``.

Poses stay vectors (composition is a quaternion product and a rotation) so the expression graphs
stay small. Every function that divides by an angle has a Taylor branch below
:data:`TAYLOR_THRESHOLD` written in the squared angle, so no branch ever computes 0/0 or a square
root's derivative at 0: values and derivatives are exact at exactly zero angle.
"""

from __future__ import annotations

from typing import TypeVar

import casadi as ca

Sym = TypeVar("Sym", ca.SX, ca.MX)

#: Below this rotation angle (rad) the series are used; their truncation error there is below 1e-16.
TAYLOR_THRESHOLD = 1e-2


def _small(theta2: Sym, threshold: float = TAYLOR_THRESHOLD) -> Sym:
    return theta2 < threshold * threshold


def _safe_sqrt(theta2: Sym, small: Sym) -> Sym:
    """``sqrt(theta2)`` where it is used, 1 in the series branch (keeps its derivative finite)."""
    return ca.sqrt(ca.if_else(small, 1.0, theta2))


# --- quaternions ----------------------------------------------------------------------------------


def quat_multiply(a: Sym, b: Sym) -> Sym:
    """Hamilton product ``a ⊗ b``."""
    ax, ay, az, aw = a[0], a[1], a[2], a[3]
    bx, by, bz, bw = b[0], b[1], b[2], b[3]
    return ca.vertcat(
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def quat_conjugate(q: Sym) -> Sym:
    """The inverse rotation of a unit quaternion."""
    return ca.vertcat(-q[0], -q[1], -q[2], q[3])


def rotate(q: Sym, v: Sym) -> Sym:
    """``R(q)·v`` as ``v + 2w(u×v) + 2u×(u×v)`` (``u`` the vector part): no matrix built."""
    u, w = q[0:3], q[3]
    uv = ca.cross(u, v)
    return v + 2.0 * w * uv + 2.0 * ca.cross(u, uv)


def quat_to_matrix(q: Sym) -> Sym:
    """Rotation matrix of a unit quaternion."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        ca.horzcat(2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        ca.horzcat(2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )


def matrix_to_quat(R: Sym) -> Sym:
    """Unit quaternion of a rotation matrix, by the largest of the four pivots (Shepperd), so that
    no branch in use divides by a small number; ``qw >= 0`` where the ``w`` pivot is taken."""
    t = [
        1 + R[0, 0] - R[1, 1] - R[2, 2],
        1 - R[0, 0] + R[1, 1] - R[2, 2],
        1 - R[0, 0] - R[1, 1] + R[2, 2],
        1 + R[0, 0] + R[1, 1] + R[2, 2],
    ]
    yz, zx, xy = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    xy_, xz_, yz_ = R[0, 1] + R[1, 0], R[0, 2] + R[2, 0], R[1, 2] + R[2, 1]
    s = [0.5 / ca.sqrt(ca.fmax(tk, 1e-12)) for tk in t]
    candidates = [
        ca.vertcat(0.25 / s[0], xy_ * s[0], xz_ * s[0], yz * s[0]),
        ca.vertcat(xy_ * s[1], 0.25 / s[1], yz_ * s[1], zx * s[1]),
        ca.vertcat(xz_ * s[2], yz_ * s[2], 0.25 / s[2], xy * s[2]),
        ca.vertcat(yz * s[3], zx * s[3], xy * s[3], 0.25 / s[3]),
    ]
    out = candidates[3]
    best = t[3]
    for tk, qk in zip(t[:3], candidates[:3]):
        take = tk > best
        out = ca.if_else(take, qk, out)
        best = ca.if_else(take, tk, best)
    return out


# --- SO(3) -------------------------------------------------------------------------------------------


def so3_exp(phi: Sym) -> Sym:
    """``Exp(φ)`` as a unit quaternion ``(sin(θ/2)/θ·φ, cos(θ/2))``, ``θ = |φ|``."""
    theta2 = ca.dot(phi, phi)
    small = _small(theta2)
    theta = _safe_sqrt(theta2, small)
    half_sinc = ca.if_else(
        small, 0.5 * (1.0 - theta2 / 24.0 * (1.0 - theta2 / 80.0)), ca.sin(0.5 * theta) / theta
    )
    cos_half = ca.if_else(small, 1.0 - theta2 / 8.0 * (1.0 - theta2 / 48.0), ca.cos(0.5 * theta))
    return ca.vertcat(half_sinc * phi, cos_half)


def so3_log(q: Sym) -> Sym:
    """``Log(q)``: the rotation vector of angle in ``[0, π]`` (``q`` and ``−q`` give the same).

    ``φ = 2·atan2(s, |w|)/s · sign(w) · v`` with ``v`` the vector part and ``s = |v|``; for small
    ``s`` the series ``(2/w)(1 − r/3 + r²/5 − r³/7)``, ``r = s²/w²``.
    """
    v, w = q[0:3], q[3]
    s2 = ca.dot(v, v)
    small = _small(s2, 0.5 * TAYLOR_THRESHOLD)
    s = _safe_sqrt(s2, small)
    w_series = ca.if_else(small, w, 1.0)
    r = s2 / (w_series * w_series)
    series = 2.0 / w_series * (1.0 - r * (1.0 / 3.0 - r * (1.0 / 5.0 - r / 7.0)))
    sign = ca.if_else(w < 0, -1.0, 1.0)
    closed = 2.0 * ca.atan2(s, ca.fabs(w)) / s * sign
    return ca.if_else(small, series, closed) * v


def hat(phi: Sym) -> Sym:
    """The skew matrix ``[φ]×`` with ``[φ]×·v = φ × v``."""
    return ca.vertcat(
        ca.horzcat(0, -phi[2], phi[1]),
        ca.horzcat(phi[2], 0, -phi[0]),
        ca.horzcat(-phi[1], phi[0], 0),
    )


# --- roll, pitch, yaw (URDF) ------------------------------------------------------------------------


def rpy_to_quat(rpy: Sym) -> Sym:
    """``qz(yaw) ⊗ qy(pitch) ⊗ qx(roll)``: the quaternion of ``Rz(yaw)·Ry(pitch)·Rx(roll)``."""
    cr, sr = ca.cos(0.5 * rpy[0]), ca.sin(0.5 * rpy[0])
    cp, sp = ca.cos(0.5 * rpy[1]), ca.sin(0.5 * rpy[1])
    cy, sy = ca.cos(0.5 * rpy[2]), ca.sin(0.5 * rpy[2])
    return ca.vertcat(
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def matrix_to_rpy(R: Sym) -> Sym:
    """``(roll, pitch, yaw)`` of ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``, pitch in ``[−π/2, π/2]``
    (roll and yaw are not separable at pitch ±π/2: gimbal lock)."""
    roll = ca.atan2(R[2, 1], R[2, 2])
    pitch = ca.atan2(-R[2, 0], ca.sqrt(R[2, 1] * R[2, 1] + R[2, 2] * R[2, 2]))
    yaw = ca.atan2(R[1, 0], R[0, 0])
    return ca.vertcat(roll, pitch, yaw)


def quat_to_rpy(q: Sym) -> Sym:
    """``(roll, pitch, yaw)`` of a unit quaternion."""
    return matrix_to_rpy(quat_to_matrix(q))


def rpy_boxplus(rpy: Sym, delta: Sym) -> Sym:
    """Left SO(3) perturbation in roll-pitch-yaw: the angles of ``Exp(δ)·R(rpy)`` (``δ`` about the
    parent frame's axes)."""
    return quat_to_rpy(quat_multiply(so3_exp(delta), rpy_to_quat(rpy)))


# --- SE(3) --------------------------------------------------------------------------------------------


def compose(a: Sym, b: Sym) -> Sym:
    """``a · b`` for pose vectors."""
    return ca.vertcat(a[0:3] + rotate(a[3:7], b[0:3]), quat_multiply(a[3:7], b[3:7]))


def inverse(a: Sym) -> Sym:
    """``a⁻¹`` for a pose vector."""
    qi = quat_conjugate(a[3:7])
    return ca.vertcat(-rotate(qi, a[0:3]), qi)


def between(a: Sym, b: Sym) -> Sym:
    """``a⁻¹ · b``: the motion from ``a`` to ``b`` in ``a``'s frame."""
    return compose(inverse(a), b)


def exp(xi: Sym) -> Sym:
    """``Exp(ξ)`` for ``ξ = (ρ, φ)``: translation ``V(φ)·ρ``, rotation ``Exp(φ)``, with
    ``V = I + (1 − cos θ)/θ²·[φ]× + (θ − sin θ)/θ³·[φ]×²``."""
    rho, phi = xi[0:3], xi[3:6]
    theta2 = ca.dot(phi, phi)
    small = _small(theta2)
    theta = _safe_sqrt(theta2, small)
    a = ca.if_else(small, 0.5 - theta2 / 24.0 * (1.0 - theta2 / 30.0), (1.0 - ca.cos(theta)) / theta2)
    b = ca.if_else(
        small, (1.0 - theta2 / 20.0 * (1.0 - theta2 / 42.0)) / 6.0, (theta - ca.sin(theta)) / (theta2 * theta)
    )
    cross = ca.cross(phi, rho)
    t = rho + a * cross + b * ca.cross(phi, cross)
    return ca.vertcat(t, so3_exp(phi))


def log(a: Sym) -> Sym:
    """``Log(a) = (V(φ)⁻¹·t, φ)``, ``φ = Log(q)``, with
    ``V⁻¹ = I − ½[φ]× + (1 − (θ/2)·cot(θ/2))/θ²·[φ]×²``."""
    phi = so3_log(a[3:7])
    t = a[0:3]
    theta2 = ca.dot(phi, phi)
    small = _small(theta2)
    theta = _safe_sqrt(theta2, small)
    half = 0.5 * theta
    c = ca.if_else(
        small,
        (1.0 + theta2 / 60.0 * (1.0 + theta2 / 42.0)) / 12.0,
        (1.0 - half * ca.cos(half) / ca.sin(half)) / theta2,
    )
    cross = ca.cross(phi, t)
    return ca.vertcat(t - 0.5 * cross + c * ca.cross(phi, cross), phi)


def lift(m: Sym) -> Sym:
    """The planar motion ``(x, y, theta)`` as a pose vector: ``z = 0``, rotation about z."""
    half = 0.5 * m[2]
    return ca.vertcat(m[0], m[1], 0.0, 0.0, 0.0, ca.sin(half), ca.cos(half))


def mount(params: Sym) -> Sym:
    """The pose vector of a mount ``(x, y, z, roll, pitch, yaw)``."""
    return ca.vertcat(params[0:3], rpy_to_quat(params[3:6]))


def conjugate(T_base_sensor: Sym, motion_base: Sym) -> Sym:
    """``T⁻¹ · M · T``: a base motion (a pose vector) seen from the sensor frame."""
    return compose(inverse(T_base_sensor), compose(motion_base, T_base_sensor))


def retract(a: Sym, delta: Sym) -> Sym:
    """``a`` moved by ``δ = (δt, δφ)``: position in the parent frame, rotation on the right
    (``t + δt``, ``q ⊗ Exp(δφ)``); the perturbation a tracker's pose noise is modelled in."""
    return ca.vertcat(a[0:3] + delta[0:3], quat_multiply(a[3:7], so3_exp(delta[3:6])))
