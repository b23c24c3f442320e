"""The seed documents' calibration method, in plain numpy: the baseline the benchmarks beat.

Single-step residuals, first-order (Euler) bicycle increments, homogeneous 3x3 matrices, a
central-difference Jacobian per sample in a Python loop (the sensor pose perturbed on the left),
Huber weights and undamped Gauss-Newton with a small diagonal loading, exactly as the seed
documents describe it. Written independently of nlp_calib on purpose.
"""

from __future__ import annotations

import numpy as np


def v2t(v: np.ndarray) -> np.ndarray:
    c, s = np.cos(v[2]), np.sin(v[2])
    return np.array([[c, -s, v[0]], [s, c, v[1]], [0.0, 0.0, 1.0]])


def t2v(T: np.ndarray) -> np.ndarray:
    return np.array([T[0, 2], T[1, 2], np.arctan2(T[1, 0], T[0, 0])])


def error(x: np.ndarray, revs: float, steer: float, Z: np.ndarray) -> np.ndarray:
    """e = t2v(Z⁻¹ · T⁻¹ Δr T) for one sample (Euler increment)."""
    k_steer, k_traction, axis_length, steer_offset = x[:4]
    phi = k_steer * steer + steer_offset
    d = k_traction * revs
    delta_r = v2t(np.array([d * np.cos(phi), 0.0, d * np.sin(phi) / axis_length]))
    T = v2t(x[4:7])
    h = np.linalg.inv(T) @ delta_r @ T
    return t2v(np.linalg.inv(Z) @ h)


def boxplus(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
    out = x.copy()
    out[:4] += dx[:4]
    out[4:7] = t2v(v2t(dx[4:7]) @ v2t(x[4:7]))
    return out


def calibrate(
    x0: np.ndarray,
    inputs: np.ndarray,
    Z: list[np.ndarray],
    iterations: int = 10,
    eps: float = 1e-7,
    delta: float = 0.05,
) -> tuple[np.ndarray, float]:
    """``iterations`` Gauss-Newton steps; returns the estimate and the last chi²."""
    x = x0.copy()
    chi2 = 0.0
    for _ in range(iterations):
        H = np.zeros((7, 7))
        b = np.zeros(7)
        chi2 = 0.0
        for k in range(inputs.shape[1]):
            revs, steer = inputs[0, k], inputs[1, k]
            e = error(x, revs, steer, Z[k])
            J = np.zeros((3, 7))
            for i in range(7):
                d = np.zeros(7)
                d[i] = eps
                J[:, i] = (
                    error(boxplus(x, d), revs, steer, Z[k]) - error(boxplus(x, -d), revs, steer, Z[k])
                ) / (2 * eps)
            s = float(e @ e)
            w = 1.0 if s <= delta * delta else delta / np.sqrt(s)
            H += w * J.T @ J
            b += w * J.T @ e
            chi2 += s
        dx = np.linalg.solve(H + 1e-3 * np.eye(7), -b)
        x = boxplus(x, dx)
    return x, chi2
