"""SE(2) in CasADi, on pose vectors ordered ``(x, y, theta)``.

Poses are kept as 3-vectors rather than 3x3 matrices: composition then costs one sin/cos pair
and the expression graph stays small. :func:`v2t` / :func:`t2v` convert to and from the
homogeneous matrix for callers that want it. Angles are wrapped onto ``(-pi, pi]`` only where a
result leaves the group (:func:`t2v`, :func:`between`), so derivatives stay continuous inside.
"""

from __future__ import annotations

from typing import TypeVar

import casadi as ca

Sym = TypeVar("Sym", ca.SX, ca.MX)

#: Below this |a| sinc uses its Taylor series; its error there is below a**6/5040 < 2e-16.
SINC_TAYLOR_THRESHOLD = 1e-2


def wrap_angle(theta: Sym) -> Sym:
    """Angle onto ``(-pi, pi]`` via ``atan2(sin, cos)`` (smooth away from the cut)."""
    return ca.atan2(ca.sin(theta), ca.cos(theta))


def v2t(v: Sym) -> Sym:
    """Homogeneous 3x3 matrix of the pose vector ``(x, y, theta)``."""
    c, s = ca.cos(v[2]), ca.sin(v[2])
    return ca.vertcat(
        ca.horzcat(c, -s, v[0]),
        ca.horzcat(s, c, v[1]),
        ca.horzcat(0, 0, 1),
    )


def t2v(T: Sym) -> Sym:
    """Pose vector ``(x, y, theta)`` of a homogeneous 3x3 matrix, angle wrapped."""
    return ca.vertcat(T[0, 2], T[1, 2], ca.atan2(T[1, 0], T[0, 0]))


def compose(a: Sym, b: Sym) -> Sym:
    """``a · b`` for pose vectors (angle not wrapped)."""
    c, s = ca.cos(a[2]), ca.sin(a[2])
    return ca.vertcat(
        a[0] + c * b[0] - s * b[1],
        a[1] + s * b[0] + c * b[1],
        a[2] + b[2],
    )


def inverse(a: Sym) -> Sym:
    """``a⁻¹`` for a pose vector."""
    c, s = ca.cos(a[2]), ca.sin(a[2])
    return ca.vertcat(-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2])


def between(a: Sym, b: Sym) -> Sym:
    """``t2v(a⁻¹ · b)``: the motion from ``a`` to ``b`` in ``a``'s frame, angle wrapped."""
    c, s = ca.cos(a[2]), ca.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return ca.vertcat(c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[2] - a[2]))


def boxplus(T: Sym, delta: Sym) -> Sym:
    """Left perturbation ``v2t(delta) · T``: the sensor pose's box-plus."""
    return compose(delta, T)


def conjugate(T_base_sensor: Sym, motion_base: Sym) -> Sym:
    """``T⁻¹ · M · T``: a base-link motion seen from the sensor frame."""
    return compose(inverse(T_base_sensor), compose(motion_base, T_base_sensor))


def sinc(a: Sym) -> Sym:
    """``sin(a)/a`` with a Taylor branch near 0, so neither branch ever evaluates 0/0."""
    small = ca.fabs(a) < SINC_TAYLOR_THRESHOLD
    a_safe = ca.if_else(small, 1.0, a)
    a2 = a * a
    return ca.if_else(small, 1.0 - a2 / 6.0 * (1.0 - a2 / 20.0), ca.sin(a_safe) / a_safe)


def arc(distance: Sym, dtheta: Sym) -> Sym:
    """Pose after travelling ``distance`` along a circular arc turning by ``dtheta``.

    ``(d·sin(w)/w, d·(1-cos(w))/w, w)``, written as ``d·sinc(w)`` and
    ``d·sin(w/2)·sinc(w/2)`` so that no term cancels or divides by zero as ``w -> 0``.
    """
    half = 0.5 * dtheta
    return ca.vertcat(distance * sinc(dtheta), distance * ca.sin(half) * sinc(half), dtheta)
