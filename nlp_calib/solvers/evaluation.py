"""Numeric access to a built problem over one data matrix: what the solvers call.

:class:`ProblemEvaluator` binds the mapped Functions of :mod:`nlp_calib.problem.functions` to the
data once; each call then only copies the parameter vector in and the sums out.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from nlp_calib.problem import ProblemFunctions, unpack_upper
from nlp_calib.solvers.backends import Backend, Buffered, pad_columns

#: H is called singular when its Jacobi-scaled condition number exceeds this.
SINGULAR_CONDITION = 1e12
#: Why a solver did not start: the objective is not a number at the initial guess.
NAN_START_REASON = (
    "the residual is NaN or infinite at the initial guess (e.g. a length of 0); check the data and "
    "the initial guess"
)
SINGULAR_REASON = (
    "singular normal matrix: some parameters are not determined by the data (see the observability warnings)"
)


def scaled_condition(H: np.ndarray) -> float:
    """Condition number of ``D^-1/2 H D^-1/2`` (``D = diag H``): insensitive to parameter units."""
    d = np.diag(H)
    if np.any(~np.isfinite(H)) or np.any(d <= 0):
        return float("inf")
    s = 1.0 / np.sqrt(d)
    eig = np.linalg.eigvalsh(H * s[:, None] * s[None, :])
    return float(eig[-1] / eig[0]) if eig[0] > 0 else float("inf")


def is_singular(H: np.ndarray) -> bool:
    """True when the normal matrix does not determine every free parameter."""
    return scaled_condition(H) > SINGULAR_CONDITION


@dataclass(frozen=True)
class NormalEquations:
    """Robust-weighted normal equations at one point: ``H = Σ w ρ' JᵀΩJ``, ``g = Σ w ρ' JᵀΩe``.

    ``cost`` is the objective ``Σ ρ(s) + prior``; ``chi2`` is ``Σ s``; ``inliers`` counts
    residuals with ``s <= delta²``. ``H`` and ``g`` include the priors.
    """

    H: np.ndarray
    g: np.ndarray
    cost: float
    chi2: float
    inliers: int


@dataclass(frozen=True)
class Priors:
    """Gaussian priors on free parameters: ``mean`` and ``sqrt_info = 1/std`` (0 = no prior)."""

    mean: np.ndarray
    sqrt_info: np.ndarray

    @property
    def active(self) -> bool:
        return bool(np.any(self.sqrt_info != 0.0))


class ProblemEvaluator:
    """The problem's Functions mapped over one data matrix, ready to call with a free vector."""

    def __init__(
        self,
        fns: ProblemFunctions,
        columns: np.ndarray,
        *,
        x_fixed: np.ndarray,
        omega: np.ndarray,
        delta: float,
        priors: Priors | None = None,
        backend: Backend | None = None,
    ) -> None:
        self.fns = fns
        self.backend = backend or Backend()
        self.n_residuals = int(columns.shape[1])
        self.n_padded = self.backend.padded(self.n_residuals)
        self.data = pad_columns(columns, self.n_padded)
        self.x_fixed = np.asarray(x_fixed, dtype=float)
        self.omega = np.asarray(omega, dtype=float)
        self.delta = float(delta)
        n = fns.n_free
        self.priors = priors or Priors(np.zeros(n), np.zeros(n))
        self._static: dict[str, np.ndarray | float] = {
            "x_fixed": self.x_fixed,
            "omega": self.omega,
            "delta": self.delta,
            "data": self.data,
        }
        self._normal = Buffered(self.mapped("normal_equations", reduce=True), self._static)
        self._cost = Buffered(self.mapped("cost", reduce=True), self._static)
        self._terms: Buffered | None = None
        self._prior = Buffered(fns.prior, {"mean": self.priors.mean, "sqrt_info": self.priors.sqrt_info})
        self._boxplus = Buffered(fns.boxplus)

    def mapped(self, name: str, *, reduce: bool, extra_mapped: tuple[str, ...] = ()) -> ca.Function:
        """The per-residual Function ``name`` mapped over the (padded) data columns."""
        return self.backend.map(self.fns.function(name), self.n_padded, ("data", *extra_mapped), reduce)

    def normal_equations(self, x: np.ndarray) -> NormalEquations:
        h_upper, g, cost, chi2, inliers = self._normal(x=x)
        H, cost_f = unpack_upper(h_upper, self.fns.n_free), float(cost[0])
        if self.priors.active:
            Hp, gp, cp, _, _ = self._prior(x=x)
            H, g, cost_f = H + Hp, g + gp, cost_f + float(cp[0])
        return NormalEquations(H=H, g=g, cost=cost_f, chi2=float(chi2[0]), inliers=round(float(inliers[0])))

    def cost(self, x: np.ndarray) -> float:
        (cost,) = self._cost(x=x)
        c = float(cost[0])
        if self.priors.active:
            c += float(self._prior(x=x)[2][0])
        return c

    def robust_terms(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per residual: error ``(3, n)``, ``s = eᵀΩe`` and the IRLS weight ρ'(s)."""
        e, s, w, _ = self.residual_terms(x)
        return e, s, w

    def residual_terms(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`robust_terms` plus each residual's score ``ρ'·JᵀΩe``, ``(n_free, n)``."""
        if self._terms is None:
            self._terms = Buffered(self.mapped("robust_terms", reduce=False), self._static)
        e, s, w, g = self._terms(x=x)
        n = self.n_residuals
        nf = self.fns.n_free
        return (
            e.reshape(3, -1, order="F")[:, :n],
            s.ravel()[:n],
            w.ravel()[:n],
            g.reshape(nf, -1, order="F")[:, :n],
        )

    def prior_information(self, x: np.ndarray) -> np.ndarray:
        """The priors' contribution ``J_pᵀJ_p`` to the normal matrix."""
        return self._prior(x=x)[0]

    def boxplus(self, x: np.ndarray, step: np.ndarray) -> np.ndarray:
        (x_next,) = self._boxplus(x=x, step=step)
        return x_next.ravel()

    def params(self, x: np.ndarray) -> np.ndarray:
        """Full parameter vector (free and fixed, in model order)."""
        return np.asarray(self.fns.assemble(x, self.x_fixed)).ravel()

    # --- IPOPT: Functions of (x, p) with the data passed as the parameter p -------------------

    def data_parameter(self) -> np.ndarray:
        """The NLP parameter vector ``p``: the padded data matrix, column-major."""
        return self.data.ravel(order="F")

    def nlp_functions(self, hessian: str = "exact") -> tuple[ca.Function, ca.Function, ca.Function]:
        """``f(x, p)``, ``grad_f(x, p) -> (f, grad)`` and ``hess_lag(x, p, lam_f, lam_g)``.

        Thin MX wrappers around the mapped Functions; nothing is differentiated here.
        """
        n = self.fns.n_free
        x = ca.MX.sym("x", n)
        p = ca.MX.sym("p", self.data.size)
        lam_f = ca.MX.sym("lam_f")
        lam_g = ca.MX.sym("lam_g", 0)
        data = ca.reshape(p, self.data.shape[0], self.data.shape[1])
        static = [ca.DM(self.x_fixed), ca.DM(self.omega), self.delta]
        prior = self.fns.prior(x, self.priors.mean, self.priors.sqrt_info)
        use_prior = self.priors.active
        cost = self.mapped("cost", reduce=True)(x, *static, data)
        cost_grad = self.mapped("cost_gradient", reduce=True)(x, *static, data)
        hess_name = "gauss_newton_hessian" if hessian == "gauss_newton" else "cost_hessian"
        hess = self.mapped(hess_name, reduce=True)(x, *static, data, lam_f)
        if use_prior:
            cost = cost + prior[2]
            cost_grad = [cost_grad[0] + prior[2], cost_grad[1] + prior[3]]
            hess = hess + ca.triu(lam_f * prior[4])
        f = ca.Function("f", [x, p], [cost], ["x", "p"], ["f"])
        grad_f = ca.Function("grad_f", [x, p], cost_grad, ["x", "p"], ["f", "grad_f_x"])
        hess_lag = ca.Function(
            "hess_lag",
            [x, p, lam_f, lam_g],
            [hess],
            ["x", "p", "lam_f", "lam_g"],
            ["hess_gamma_x_x"],
        )
        return f, grad_f, hess_lag
