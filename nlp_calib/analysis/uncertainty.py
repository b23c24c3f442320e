"""Parameter covariance at the optimum, with the noise propagated through the correlated residuals.

Horizon windows share data: windows that meet share a tracker pose, windows that overlap share
encoder intervals. Treating their residuals as independent (the classical ``σ²·H⁻¹``) is wrong
both ways: tracker noise largely cancels along a chain of windows (consecutive errors
telescope), input noise is counted several times. So the covariance is propagated from the
sources instead, to first order:

- each tracker pose carries white noise ``diag(σ_t², σ_t², σ_θ²)``;
- each interval's model inputs carry white noise ``diag(σ_u²)`` (encoder quantisation by default).

A residual is ``e_w ≈ E_w^a n_a + E_w^b n_b + Σ_j F_w^j m_j`` (``E = ∂e/∂z·∂z/∂p`` and
``F = ∂e/∂u``, both symbolic), the Gauss-Newton estimate moves by ``−H⁻¹ Σ_w L_w e_w`` with
``L_w = ρ'_w J_wᵀΩ``, so ``Cov = M H⁻¹ S H⁻¹ Mᵀ`` with ``S = Σ_p K_p Σ_p K_pᵀ + Σ_j Q_j Σ_u Q_jᵀ``,
``K_p`` and ``Q_j`` summing ``L_w E_w`` and ``L_w F_w`` over the windows that touch pose ``p`` or
interval ``j``. Every interval ``j`` of a window moves its motion through the window's end alone:
``F_w^j = ∂e_w/∂end · D_j`` with ``D_j`` the interval's own map (see
:mod:`nlp_calib.problem.motion`), so ``Q_j = (Σ_{w ∋ j} L_w ∂e_w/∂end)·D_j`` and the input
noise a window collects, ``Σ_j D_j Σ_u D_jᵀ``, are differences of running sums: the cost is
linear in the number of windows whatever their length. The tracker's variances are estimated
from the squared residuals by non-negative least squares (method of moments, corrected for the
fitted degrees of freedom); the input noise is given. ``M`` maps the manifold perturbation to
plain parameter coordinates.

Assumptions: white tracker-pose noise explains the residuals beyond the given input noise (no
timing error or slowly varying model error), and the problem is close to linear within a few σ.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from nlp_calib.models import reference_scales
from nlp_calib.problem import ResidualData
from nlp_calib.solvers import ProblemEvaluator

#: The per-residual Functions the estimate evaluates, per residual (not summed).
FUNCTIONS = ("robust_terms", "sensitivities")


@dataclass(frozen=True)
class Uncertainty:
    """Covariance of the free parameters (plain coordinates) and the noise it was built from.

    ``std`` and ``correlation`` cover all parameters in model order; fixed ones have std 0 and
    correlation 0 with the rest. ``noise`` holds the estimated 1σ of each source.
    """

    names: tuple[str, ...]
    free: tuple[str, ...]
    covariance: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    noise: dict[str, float]
    dof: int

    def std_dict(self) -> dict[str, float]:
        return {n: float(s) for n, s in zip(self.names, self.std)}


def nnls_small(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Non-negative least squares for a handful of unknowns (exhaustive active sets)."""
    k = A.shape[1]
    best, best_cost = np.zeros(k), float(y @ y)
    for size in range(1, k + 1):
        for cols in itertools.combinations(range(k), size):
            sol, *_ = np.linalg.lstsq(A[:, cols], y, rcond=None)
            if np.all(sol >= 0):
                full = np.zeros(k)
                full[list(cols)] = sol
                r = A @ full - y
                if r @ r < best_cost:
                    best, best_cost = full, float(r @ r)
    return best


def _pseudo_inverse(H: np.ndarray, scale: np.ndarray, rcond: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of ``H`` on the subspace the data determine, and a mask of the parameters in the rest.

    The eigen-analysis runs in reference units (``scale``), where an undetermined direction
    stands out cleanly whatever the parameters' units.
    """
    lam, V = np.linalg.eigh(H * np.outer(scale, scale))
    keep = lam > rcond * max(float(lam[-1]), 1e-300)
    inv = (V[:, keep] / lam[keep]) @ V[:, keep].T * np.outer(scale, scale)
    undetermined = (V[:, ~keep] ** 2).sum(axis=1) > 1e-3
    return inv, undetermined


def not_available(evaluator: ProblemEvaluator) -> Uncertainty:
    """No uncertainty at all (NaN) for an estimate where the residual is NaN or infinite."""
    fns = evaluator.fns
    n = len(fns.names)
    free = np.array([name in fns.free for name in fns.names])
    corr = np.full((n, n), np.nan)
    corr[~free, :] = 0.0
    corr[:, ~free] = 0.0
    np.fill_diagonal(corr, 1.0)
    return Uncertainty(
        names=fns.names,
        free=fns.free,
        covariance=np.full((fns.n_free, fns.n_free), np.nan),
        std=np.where(free, np.nan, 0.0),
        correlation=corr,
        noise={},
        dof=0,
    )


def _accumulate(n: int, index: np.ndarray, values: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``out[i] += Σ values[w]`` over the ``w`` with ``index[w] == i`` (``values`` ``(N, ...)``)."""
    out = np.zeros((n, *values.shape[1:])) if out is None else out
    flat = values.reshape(values.shape[0], -1)
    target = out.reshape(n, -1)
    for k in range(flat.shape[1]):
        target[:, k] += np.bincount(index, weights=flat[:, k], minlength=n)
    return out


def estimate(
    evaluator: ProblemEvaluator, x: np.ndarray, data: ResidualData, input_noise_std: np.ndarray
) -> Uncertainty:
    """Covariance of the estimate ``x`` fitted to ``data``, given the inputs' 1σ noise."""
    fns = evaluator.fns
    ne = evaluator.normal_equations(x)
    if not (np.isfinite(ne.cost) and np.all(np.isfinite(ne.H))):
        return not_available(evaluator)
    n, N, n_in = fns.n_free, evaluator.n_residuals, fns.n_inputs
    e, s, weight = evaluator.robust_terms(x)
    sens = evaluator.sensitivities(x)
    de_dend = sens.de_dend  # (N, 3, m)
    m = de_dend.shape[2]
    n_int = data.inputs.shape[1]
    poses = data.T_world_sensor
    a_idx, b_idx = data.starts, data.stops
    Da, Db = (
        np.asarray(v).reshape(3, N, 3).transpose(1, 0, 2)
        for v in fns.between_jacobians.map(N)(poses[a_idx].T, poses[b_idx].T)
    )
    Ea, Eb = sens.de_dz @ Da, sens.de_dz @ Db  # (N, 3, 3)

    # Input noise is known (encoder resolution, or set by the user); the tracker's two variances
    # follow from the squared residuals by the method of moments, on inliers only. Estimating the
    # input noise the same way is ill-posed: its share of the residuals is small, its effect on the
    # parameters is not (it does not telescope), so residual noise would masquerade as it.
    Sigma_in = np.asarray(input_noise_std, dtype=float) ** 2
    D = sens.D if sens.D is not None else np.broadcast_to(np.eye(n_in), (n_int, n_in, n_in))
    # The input noise each window's end collects, Σ_j D_j Σ_u D_jᵀ over its intervals.
    running = np.zeros((n_int + 1, m, m))
    np.cumsum(np.einsum("jki,i,jli->jkl", D, Sigma_in, D), axis=0, out=running[1:])
    S_end = running[b_idx] - running[a_idx]
    known = np.einsum("wck,wkl,wcl->wc", de_dend, S_end, de_dend)
    use = s <= evaluator.delta**2 if fns.spec.kernel != "none" else np.ones(N, dtype=bool)
    E2 = Ea**2 + Eb**2  # (N, 3, 3): per residual component c, pose component k
    coef = np.concatenate([E2[:, :, :2].sum(axis=2, keepdims=True), E2[:, :, 2:3]], axis=2)  # (N, 3, 2)
    mm = 3 * int(use.sum())
    dof = max(mm - n, 1)
    var = nnls_small(coef[use].reshape(-1, 2), (e.T[use] ** 2 - known[use]).ravel()) * (mm / dof)
    Sigma_pose = np.array([var[0], var[0], var[1]])

    Omega = evaluator.omega
    L = weight[:, None, None] * np.einsum("wci,c->wic", sens.J, Omega)  # (N, n, 3)
    K = _accumulate(poses.shape[0], a_idx, L @ Ea)
    _accumulate(poses.shape[0], b_idx, L @ Eb, K)
    # Σ over the windows containing interval j of L_w ∂e_w/∂end: +at the first interval, −after the last.
    G = L @ de_dend  # (N, n, m)
    C = _accumulate(n_int + 1, a_idx, G)
    _accumulate(n_int + 1, b_idx, -G, C)
    Q = np.cumsum(C, axis=0)[:n_int] @ D  # (n_int, n, n_in)
    meat = np.einsum("pik,k,pjk->ij", K, Sigma_pose, K) + np.einsum("jik,k,jlk->il", Q, Sigma_in, Q)
    # Residuals beyond the kernel threshold are not explained by the noise model; their bounded
    # but non-zero pull is counted as it is, from their own scores.
    if not use.all():
        g_out = np.einsum("wic,cw->iw", L[~use], e[:, ~use])
        meat = meat + g_out @ g_out.T
    if evaluator.priors.active:
        meat = meat + evaluator.prior_information(x)
    free_values = np.asarray(fns.assemble(x, evaluator.x_fixed)).ravel()[
        [fns.names.index(f) for f in fns.free]
    ]
    bread_inv, undetermined = _pseudo_inverse(ne.H, reference_scales(fns.model, fns.free, free_values))
    M = np.asarray(fns.tangent_map(x))
    cov = M @ bread_inv @ meat @ bread_inv @ M.T
    # A parameter the data do not determine has no finite variance; say so instead of a number.
    lost = np.abs(M) @ undetermined > 0
    cov[lost, :] = np.inf
    cov[:, lost] = np.inf
    names = fns.names
    idx = [names.index(f) for f in fns.free]
    full = np.zeros((len(names), len(names)))
    full[np.ix_(idx, idx)] = cov
    std = np.sqrt(np.clip(np.diag(full), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = np.where(np.isfinite(full), full, 0.0) / np.outer(std, std)
    corr[~np.isfinite(corr)] = 0.0
    for i in idx:
        corr[i, i] = 1.0
    noise = {"tracker_xy": float(np.sqrt(var[0])), "tracker_theta": float(np.sqrt(var[1]))}
    noise.update({f"input_{name}": float(np.sqrt(v)) for name, v in zip(fns.model.input_names, Sigma_in)})
    return Uncertainty(
        names=names, free=fns.free, covariance=cov, std=std, correlation=corr, noise=noise, dof=dof
    )
