"""Parameter covariance at the optimum from the robust-weighted normal matrix.

``Cov = σ² · M H⁻¹ Mᵀ`` with ``H = Σ ρ'·JᵀΩJ`` (manifold Jacobians), ``M`` the tangent map to
plain parameter coordinates, and ``σ² = Σ ρ'·s / (m − n)`` the residual variance (``m`` scalar
residuals, ``n`` free parameters). This assumes independent residuals whose scale is right up to
the common factor σ², and a locally linear problem.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlp_calib.solvers.evaluation import ProblemEvaluator


@dataclass(frozen=True)
class Uncertainty:
    """Covariance of the free parameters (plain coordinates) and derived figures.

    ``std`` and ``correlation`` cover all parameters in model order; fixed ones have std 0 and
    correlation 0 with the rest.
    """

    names: tuple[str, ...]
    free: tuple[str, ...]
    covariance: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    sigma2: float
    dof: int

    def std_dict(self) -> dict[str, float]:
        return {n: float(s) for n, s in zip(self.names, self.std)}


def estimate(evaluator: ProblemEvaluator, x: np.ndarray) -> Uncertainty:
    """Covariance of the estimate ``x`` (free parameters) of ``evaluator``'s problem."""
    fns = evaluator.fns
    ne = evaluator.normal_equations(x)
    _, s, weight = evaluator.robust_terms(x)
    n = fns.n_free
    dof = max(3 * evaluator.n_residuals - n, 1)
    sigma2 = float(np.sum(weight * s) / dof)
    M = np.asarray(fns.tangent_map(x))
    try:
        H_inv = np.linalg.inv(ne.H)
    except np.linalg.LinAlgError:
        H_inv = np.full_like(ne.H, np.inf)
    cov = sigma2 * M @ H_inv @ M.T
    names = fns.names
    idx = [names.index(f) for f in fns.free]
    full = np.zeros((len(names), len(names)))
    full[np.ix_(idx, idx)] = cov
    std = np.sqrt(np.clip(np.diag(full), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = full / np.outer(std, std)
    corr[~np.isfinite(corr)] = 0.0
    for i in idx:
        corr[i, i] = 1.0
    return Uncertainty(
        names=names,
        free=fns.free,
        covariance=cov,
        std=std,
        correlation=corr,
        sigma2=sigma2,
        dof=dof,
    )
