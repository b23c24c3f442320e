"""Closed-form pieces of a data-driven start that needs no guess at all (``initial_guess: auto``).

In SE(2) the sensor turns exactly as the base does (``h = T⁻¹·Δr·T`` keeps the angle), so the
measured heading changes alone fix the model's steering parameters; each model's
``initial_guess`` says how. With those, the base motion of every window is known up
to the traction scale, and the translations give the sensor pose and that scale in closed form,
as in hand-eye calibration ``AX = XB``:

    R_s·z_t = (R(ψ) − I)·t_s + k·u,

linear in ``(t_s, k)`` and in ``(cos θ_s, sin θ_s)``; minimising the stacked residual over the
unit circle is a 2x2 eigenproblem. Both steps are reweighted (Huber) so that outlier windows do
not steer the start. The result is refined by the usual solvers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HUBER_K = 3.0


@dataclass(frozen=True)
class HandEye:
    """Sensor pose ``(x, y, theta)`` and the traction scale from the hand-eye step."""

    T_base_sensor: tuple[float, float, float]
    scale: float


def huber_weights(r: np.ndarray) -> np.ndarray:
    """IRLS weights for residuals ``r`` with a threshold of 3 robust standard deviations."""
    sigma = 1.4826 * np.median(np.abs(r)) + 1e-12
    a = np.abs(r) / (HUBER_K * sigma)
    return np.where(a <= 1.0, 1.0, 1.0 / np.maximum(a, 1e-12))


def robust_lstsq(A: np.ndarray, y: np.ndarray, iterations: int = 8) -> np.ndarray:
    """Least squares ``A x ≈ y`` reweighted with :func:`huber_weights`."""
    w = np.ones(y.size)
    x = np.zeros(A.shape[1])
    for _ in range(iterations):
        sw = np.sqrt(w)
        x, *_ = np.linalg.lstsq(A * sw[:, None], y * sw, rcond=None)
        w = huber_weights(y - A @ x)
    return x


def hand_eye(psi: np.ndarray, u: np.ndarray, z: np.ndarray, iterations: int = 8) -> HandEye:
    """Sensor pose and scale from base rotations ``psi (M,)``, unit-scale base translations
    ``u (2, M)`` and measured sensor motions ``z (3, M)``."""
    c, s = np.cos(psi), np.sin(psi)
    M = psi.size
    A = np.zeros((2 * M, 5))
    # (R(ψ) − I)·t_s
    A[0::2, 0], A[0::2, 1] = c - 1.0, -s
    A[1::2, 0], A[1::2, 1] = s, c - 1.0
    # + k·u
    A[0::2, 2], A[1::2, 2] = u[0], u[1]
    # − R_s·z_t, written in (cos θ_s, sin θ_s)
    A[0::2, 3], A[0::2, 4] = -z[0], z[1]
    A[1::2, 3], A[1::2, 4] = -z[1], -z[0]
    w = np.ones(2 * M)
    q = np.zeros(5)
    for _ in range(iterations):
        sw = np.sqrt(w)[:, None]
        A1, A2 = A[:, :3] * sw, A[:, 3:] * sw
        pinv = np.linalg.pinv(A1)
        # A2 less its projection on A1's columns, without the (2M x 2M) projection matrix.
        B = A2.T @ (A2 - A1 @ (pinv @ A2))
        _, vecs = np.linalg.eigh(B)
        g = vecs[:, 0]
        p = -pinv @ (A2 @ g)
        if p[2] < 0:  # the traction scale is positive: pick the sign of the eigenvector
            g, p = -g, -p
        q = np.concatenate([p, g])
        r = (A @ q).reshape(M, 2)
        w = np.repeat(huber_weights(np.linalg.norm(r, axis=1)), 2)
    return HandEye(T_base_sensor=(float(q[0]), float(q[1]), float(np.arctan2(q[4], q[3]))), scale=float(q[2]))
