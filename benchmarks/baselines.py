"""Baselines on the same objective and the same windows: the tricycle's robust cost written in numpy.

- :class:`NumpyTricycle` evaluates every window's residual and its analytic Jacobian (plain
  coordinates) in vectorised numpy, from prefix poses built with running sums, so a window of any
  length costs the same: the strongest numpy formulation we know. :func:`scipy_solve` hands it to
  ``scipy.optimize.least_squares`` with the Huber loss on each window's Mahalanobis norm, which is
  exactly the objective nlp_calib minimises (``Σ ρ(eᵀΩe)``).
- :func:`gtsam_solve` and :func:`ceres_solve` use their libraries' standard Python APIs: one custom
  factor / cost function per window (single-interval windows) with a Huber robust loss, evaluated
  by a scalar Python function.

Only the tricycle model (exact arc or Euler integration) is written here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def _arc(w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``sin(w)/w``, ``(1 - cos w)/w`` and their derivatives, with series near 0."""
    small = np.abs(w) < 1e-4
    ws = np.where(small, 1.0, w)
    s, c = np.sin(ws), np.cos(ws)
    w2 = w * w
    sx = np.where(small, 1 - w2 / 6 + w2 * w2 / 120, s / ws)
    sy = np.where(small, w / 2 - w * w2 / 24, (1 - c) / ws)
    dsx = np.where(small, -w / 3 + w * w2 / 30, (ws * c - s) / ws**2)
    dsy = np.where(small, 0.5 - w2 / 8, (ws * s - (1 - c)) / ws**2)
    return sx, sy, dsx, dsy


class NumpyTricycle:
    """Residuals ``e (N, 3)`` and Jacobians ``J (N, 3, 7)`` of windows ``starts < stops`` over
    intervals with inputs ``U (2, n)`` (revolutions, steering angle) and tracker motions ``z (N, 3)``;
    window motions from prefix poses (``prefix``), or composed interval by interval.
    Parameters ``(k_steer, k_traction, axis_length, steer_offset, sensor_x, sensor_y, sensor_theta)``."""

    def __init__(
        self,
        U: np.ndarray,
        starts: np.ndarray,
        stops: np.ndarray,
        z: np.ndarray,
        exact: bool,
        prefix: bool = True,
    ) -> None:
        self.r, self.a = U[0], U[1]
        self.starts, self.stops = starts, stops
        self.z = z
        self.exact = exact
        self.prefix = prefix

    def evaluate(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ks, kt, L, off, tx, ty, tth = p
        r, a = self.r, self.a
        phi = ks * a + off
        d = kt * r
        cphi, sphi = np.cos(phi), np.sin(phi)
        v, w = d * cphi, d * sphi / L
        dv = np.stack([-d * sphi * a, r * cphi, np.zeros_like(r), -d * sphi], axis=1)  # (n, 4)
        dw = np.stack([d * cphi * a / L, r * sphi / L, -w / L, d * cphi / L], axis=1)
        if self.exact:
            sx, sy, dsx, dsy = _arc(w)
            dpx = sx[:, None] * dv + (v * dsx)[:, None] * dw
            dpy = sy[:, None] * dv + (v * dsy)[:, None] * dw
            step = np.stack([v * sx, v * sy], axis=1)  # (n, 2)
            dstep = np.stack([dpx, dpy], axis=1)  # (n, 2, 4)
        else:
            step = np.stack([v, np.zeros_like(v)], axis=1)
            dstep = np.stack([dv, np.zeros_like(dv)], axis=1)
        if self.prefix:
            Mp, dMp, Mth, dMth = self._prefix_windows(step, dstep, w, dw)
        else:
            Mp, dMp, Mth, dMth = self._composed_windows(step, dstep, w, dw)
        # Sensor motion S = T⁻¹·M·T, then e = t2v(Z⁻¹·S).
        cm, sm = np.cos(Mth), np.sin(Mth)
        q = Mp + np.stack([(cm - 1) * tx - sm * ty, sm * tx + (cm - 1) * ty], axis=1)
        dq_k = dMp + np.stack([-sm * tx - cm * ty, cm * tx - sm * ty], axis=1)[:, :, None] * dMth[:, None, :]
        ct, st = math.cos(tth), math.sin(tth)
        Sp = np.stack([ct * q[:, 0] + st * q[:, 1], -st * q[:, 0] + ct * q[:, 1]], axis=1)
        dSp_k = np.stack([ct * dq_k[:, 0] + st * dq_k[:, 1], -st * dq_k[:, 0] + ct * dq_k[:, 1]], axis=1)
        dq_t = np.stack([np.stack([cm - 1, -sm], axis=1), np.stack([sm, cm - 1], axis=1)], axis=1)  # (N,2,2)
        rotT = np.array([[ct, st], [-st, ct]])
        dSp_t = np.einsum("ij,wjk->wik", rotT, dq_t)
        dSp_th = np.stack([-st * q[:, 0] + ct * q[:, 1], -ct * q[:, 0] - st * q[:, 1]], axis=1)
        z = self.z
        cz, sz = np.cos(z[:, 2]), np.sin(z[:, 2])
        dd = Sp - z[:, :2]
        e = np.stack(
            [cz * dd[:, 0] + sz * dd[:, 1], -sz * dd[:, 0] + cz * dd[:, 1], _wrap(Mth - z[:, 2])], axis=1
        )
        J = np.zeros((e.shape[0], 3, 7))
        rz = np.stack([np.stack([cz, sz], axis=1), np.stack([-sz, cz], axis=1)], axis=1)  # (N,2,2)
        J[:, :2, :4] = rz @ dSp_k
        J[:, :2, 4:6] = rz @ dSp_t
        J[:, :2, 6] = (rz @ dSp_th[:, :, None])[:, :, 0]
        J[:, 2, :4] = dMth
        return e, J

    def _prefix_windows(
        self, step: np.ndarray, dstep: np.ndarray, w: np.ndarray, dw: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each window's motion ``M = P_a⁻¹·P_b`` from prefix poses built with running sums."""
        # Prefix poses: θ and p after each interval, with their derivatives (running sums).
        theta = np.concatenate([[0.0], np.cumsum(w)])
        dtheta = np.concatenate([np.zeros((1, 4)), np.cumsum(dw, axis=0)])
        c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
        moved = np.stack([c * step[:, 0] - s * step[:, 1], s * step[:, 0] + c * step[:, 1]], axis=1)
        dmoved = (
            np.stack(
                [
                    c[:, None] * dstep[:, 0] - s[:, None] * dstep[:, 1],
                    s[:, None] * dstep[:, 0] + c[:, None] * dstep[:, 1],
                ],
                axis=1,
            )
            + np.stack([-moved[:, 1], moved[:, 0]], axis=1)[:, :, None] * dtheta[:-1, None, :]
        )
        pos = np.concatenate([np.zeros((1, 2)), np.cumsum(moved, axis=0)])
        dpos = np.concatenate([np.zeros((1, 2, 4)), np.cumsum(dmoved, axis=0)])
        A, B = self.starts, self.stops
        # Window motion M = P_a⁻¹·P_b and its derivative.
        ca_, sa = np.cos(theta[A]), np.sin(theta[A])
        dp = pos[B] - pos[A]
        Mp = np.stack([ca_ * dp[:, 0] + sa * dp[:, 1], -sa * dp[:, 0] + ca_ * dp[:, 1]], axis=1)
        ddp = dpos[B] - dpos[A]
        dMp = np.stack(
            [
                ca_[:, None] * ddp[:, 0] + sa[:, None] * ddp[:, 1],
                -sa[:, None] * ddp[:, 0] + ca_[:, None] * ddp[:, 1],
            ],
            axis=1,
        )
        dMp = dMp + np.stack([Mp[:, 1], -Mp[:, 0]], axis=1)[:, :, None] * dtheta[A][:, None, :]
        Mth = theta[B] - theta[A]
        dMth = dtheta[B] - dtheta[A]
        return Mp, dMp, Mth, dMth

    def _composed_windows(
        self, step: np.ndarray, dstep: np.ndarray, w: np.ndarray, dw: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each window's motion composed interval by interval (vectorised over the windows)."""
        A, n = self.starts, self.starts.size
        length = self.stops - A
        Mp, dMp = np.zeros((n, 2)), np.zeros((n, 2, 4))
        Mth, dMth = np.zeros(n), np.zeros((n, 4))
        for h in range(int(length.max(initial=0))):
            live = h < length
            j = np.where(live, A + h, A)
            c, s = np.cos(Mth), np.sin(Mth)
            st, dst = step[j] * live[:, None], dstep[j] * live[:, None, None]
            moved = np.stack([c * st[:, 0] - s * st[:, 1], s * st[:, 0] + c * st[:, 1]], axis=1)
            dMp = (
                dMp
                + np.stack(
                    [
                        c[:, None] * dst[:, 0] - s[:, None] * dst[:, 1],
                        s[:, None] * dst[:, 0] + c[:, None] * dst[:, 1],
                    ],
                    axis=1,
                )
                + np.stack([-moved[:, 1], moved[:, 0]], axis=1)[:, :, None] * dMth[:, None, :]
            )
            Mp = Mp + moved
            Mth = Mth + w[j] * live
            dMth = dMth + dw[j] * live[:, None]
        return Mp, dMp, Mth, dMth


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.arctan2(np.sin(a), np.cos(a))


def scipy_solve(
    model: NumpyTricycle, p0: np.ndarray, omega: np.ndarray, delta: float, tol: float = 1e-10
) -> Any:
    """``least_squares`` on the objective ``½ Σ ρ(eᵀΩe)`` written as a sum of squares: each window
    contributes ``r = √(ρ(s)/s)·√Ω·e`` (so ``‖r‖² = ρ(s)``), with its analytic Jacobian."""
    from scipy.optimize import least_squares

    sqrt_omega = np.sqrt(omega)
    d2 = delta * delta
    cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def terms(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = p.tobytes()
        if key not in cache:
            cache.clear()
            e, J = model.evaluate(p)
            s = np.maximum(np.einsum("wc,c,wc->w", e, omega, e), 1e-300)
            out = s > d2
            g = np.where(out, 2 * delta / np.sqrt(s) - d2 / s, 1.0)
            dg = np.where(out, -delta * s**-1.5 + d2 / s**2, 0.0)
            root = np.sqrt(g)
            we = sqrt_omega * e
            ds = 2 * np.einsum("wc,c,wci->wi", e, omega, J)
            jac = root[:, None, None] * sqrt_omega[None, :, None] * J + (
                we[:, :, None] * (dg / (2 * root))[:, None, None] * ds[:, None, :]
            )
            cache[key] = ((root[:, None] * we).ravel(), jac.reshape(-1, J.shape[2]))
        return cache[key]

    return least_squares(
        lambda p: terms(p)[0],
        p0,
        jac=lambda p: terms(p)[1],
        method="trf",
        x_scale="jac",
        ftol=tol,
        xtol=tol,
        gtol=tol,
    )


def _window_1(p: np.ndarray, r: float, a: float, z: np.ndarray, exact: bool) -> tuple[np.ndarray, np.ndarray]:
    """One single-interval window's residual and plain Jacobian in scalar Python (what a
    per-factor API calls; the same algebra as :class:`NumpyTricycle`)."""
    ks, kt, L, off, tx, ty, tth = (float(v) for v in p)
    phi = ks * a + off
    d = kt * r
    cphi, sphi = math.cos(phi), math.sin(phi)
    v, w = d * cphi, d * sphi / L
    dv = (-d * sphi * a, r * cphi, 0.0, -d * sphi)
    dw = (d * cphi * a / L, r * sphi / L, -w / L, d * cphi / L)
    if exact and abs(w) >= 1e-4:
        sw, cw = math.sin(w), math.cos(w)
        sx, sy = sw / w, (1 - cw) / w
        dsx, dsy = (w * cw - sw) / w**2, (w * sw - (1 - cw)) / w**2
    elif exact:
        sx, sy, dsx, dsy = 1 - w * w / 6, w / 2 - w**3 / 24, -w / 3, 0.5 - w * w / 8
    else:
        sx, sy, dsx, dsy = 1.0, 0.0, 0.0, 0.0
    mx, my = v * sx, v * sy
    cm, sm = math.cos(w), math.sin(w)
    qx, qy = mx + (cm - 1) * tx - sm * ty, my + sm * tx + (cm - 1) * ty
    ct, st = math.cos(tth), math.sin(tth)
    cz, sz = math.cos(z[2]), math.sin(z[2])
    ex, ey = ct * qx + st * qy - z[0], -st * qx + ct * qy - z[1]
    e = np.array([cz * ex + sz * ey, -sz * ex + cz * ey, math.atan2(math.sin(w - z[2]), math.cos(w - z[2]))])
    J = np.zeros((3, 7))
    for i in range(4):
        dqx = sx * dv[i] + v * dsx * dw[i] + (-sm * tx - cm * ty) * dw[i]
        dqy = sy * dv[i] + v * dsy * dw[i] + (cm * tx - sm * ty) * dw[i]
        gx, gy = ct * dqx + st * dqy, -st * dqx + ct * dqy
        J[0, i], J[1, i], J[2, i] = cz * gx + sz * gy, -sz * gx + cz * gy, dw[i]
    for j, (ax, ay) in enumerate(((cm - 1, sm), (-sm, cm - 1))):  # ∂q/∂(tx, ty)
        gx, gy = ct * ax + st * ay, -st * ax + ct * ay
        J[0, 4 + j], J[1, 4 + j] = cz * gx + sz * gy, -sz * gx + cz * gy
    gx, gy = -st * qx + ct * qy, -ct * qx - st * qy
    J[0, 6], J[1, 6] = cz * gx + sz * gy, -sz * gx + cz * gy
    return e, J


def gtsam_solve(
    U: np.ndarray,
    z: np.ndarray,
    p0: np.ndarray,
    omega: np.ndarray,
    delta: float,
    exact: bool,
    tol: float = 1e-10,
) -> np.ndarray:
    """GTSAM's Levenberg-Marquardt: a CustomFactor per window on one 7-vector, Huber noise model."""
    import gtsam

    key = 0
    noise = gtsam.noiseModel.Robust.Create(
        gtsam.noiseModel.mEstimator.Huber.Create(delta),
        gtsam.noiseModel.Diagonal.Sigmas(1.0 / np.sqrt(omega)),
    )
    graph = gtsam.NonlinearFactorGraph()
    for k in range(z.shape[0]):

        def error(factor: Any, values: Any, H: Any, k: int = k) -> np.ndarray:
            e, J = _window_1(values.atVector(key), U[0, k], U[1, k], z[k], exact)
            if H is not None:
                H[0] = J
            return e

        graph.add(gtsam.CustomFactor(noise, [key], error))
    values = gtsam.Values()
    values.insert(key, np.asarray(p0, dtype=float))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(tol)
    params.setAbsoluteErrorTol(0.0)
    params.setMaxIterations(200)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    return np.asarray(result.atVector(key))


def ceres_solve(
    U: np.ndarray,
    z: np.ndarray,
    p0: np.ndarray,
    omega: np.ndarray,
    delta: float,
    exact: bool,
    tol: float = 1e-10,
) -> np.ndarray:
    """Ceres through pyceres: a Python CostFunction per window, ``HuberLoss(delta)``, dense QR."""
    import pyceres

    sqrt_omega = np.sqrt(omega)

    class Window(pyceres.CostFunction):
        def __init__(self, k: int) -> None:
            super().__init__()
            self.k = k
            self.set_num_residuals(3)
            self.set_parameter_block_sizes([7])

        def Evaluate(self, parameters: Any, residuals: Any, jacobians: Any) -> bool:
            e, J = _window_1(parameters[0], U[0, self.k], U[1, self.k], z[self.k], exact)
            residuals[:] = sqrt_omega * e
            if jacobians is not None and jacobians[0] is not None:
                jacobians[0][:] = (sqrt_omega[:, None] * J).ravel()
            return True

    x = np.asarray(p0, dtype=float).copy()
    problem = pyceres.Problem()
    functions = [Window(k) for k in range(z.shape[0])]
    for f in functions:
        problem.add_residual_block(f, pyceres.HuberLoss(delta), [x])
    options = pyceres.SolverOptions()
    options.linear_solver_type = pyceres.LinearSolverType.DENSE_QR
    options.function_tolerance = tol
    options.gradient_tolerance = tol
    options.parameter_tolerance = tol
    options.max_num_iterations = 200
    summary = pyceres.SolverSummary()
    pyceres.solve(options, problem, summary)
    return x
