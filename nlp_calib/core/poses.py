"""Numeric SE(2) on arrays of pose vectors ``(x, y, theta)``, one pose per row (numpy only).

The symbolic twins of these live in :mod:`nlp_calib.symbolic.se2`; these serve post-processing
(dead reckoning, trajectory errors, alignment), vectorised over thousands of poses.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.core.numeric import wrap_angle


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a · b`` row by row (angles not wrapped)."""
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack(
        [
            a[..., 0] + c * b[..., 0] - s * b[..., 1],
            a[..., 1] + s * b[..., 0] + c * b[..., 1],
            a[..., 2] + b[..., 2],
        ],
        axis=-1,
    )


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a⁻¹ · b`` row by row, angle wrapped."""
    return np.concatenate([moved(a, b), wrap_angle(b[..., 2] - a[..., 2])[..., None]], axis=-1)


def moved(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The translation of ``a⁻¹ · b`` row by row, ``(..., 2)``: :func:`between`'s, without its angle."""
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)


def accumulate(start: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Poses ``(n + 1, 3)`` of ``start · steps[0] · … · steps[n-1]``, in one vectorised pass.

    In SE(2) the heading is a running sum, so every step can be rotated into the world frame at
    once and the positions are a running sum too.
    """
    theta = start[2] + np.concatenate([[0.0], np.cumsum(steps[:, 2])])
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    dx = c * steps[:, 0] - s * steps[:, 1]
    dy = s * steps[:, 0] + c * steps[:, 1]
    x = start[0] + np.concatenate([[0.0], np.cumsum(dx)])
    y = start[1] + np.concatenate([[0.0], np.cumsum(dy)])
    return np.stack([x, y, theta], axis=1)


def align(est_xy: np.ndarray, ref_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation ``R`` (2×2) and translation ``t`` minimising ``Σ |R·est + t − ref|²``.

    The planar case of Umeyama's method without scale (a proper rotation: no reflection).
    """
    mu_r = ref_xy.mean(axis=0)
    return align_centred(est_xy, ref_xy - mu_r, mu_r)


def align_centred(
    est_xy: np.ndarray, ref_centred: np.ndarray, mu_r: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`align` with the reference's side given: its positions less their mean ``mu_r`` (the
    same arithmetic: one reference's side serves every estimate aligned to it)."""
    mu_e = est_xy.mean(axis=0)
    cov = ref_centred.T @ (est_xy - mu_e)
    U, _, Vt = np.linalg.svd(cov)
    D = np.diag([1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    return R, mu_r - R @ mu_e
