"""The NLP IPOPT solves, as CasADi callbacks on the evaluator: the same Functions Gauss-Newton calls.

IPOPT asks for the cost, its gradient and the Hessian of the Lagrangian at points of its own
choosing. Each is answered by the evaluator (so the windows' motion is integrated once per point,
by the same compiled code, and nothing is differentiated again): the gradient and the exact
Hessian by ``cost_derivatives`` (the cost by ``cost``), or the cost, the gradient and a
Gauss-Newton Hessian by the normal equations, mapped from the manifold perturbation to plain coordinates
(``J_plain = J·M⁻¹``, ``M = ∂(x ⊞ Δ)/∂Δ``): ``∇f = 2·M⁻ᵀg`` and ``∇²f ≈ 2·M⁻ᵀHM⁻¹`` (exact for
the priors). For Huber, the lifted form ``min Σ v·s + δ²(1/v − 1)`` over ``(x, v)`` adds one
variable per residual.

An exception raised inside a callback (an interrupt, a bug) is kept and re-raised once IPOPT
returns, rather than turned into an evaluation error IPOPT would try to work around.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import casadi as ca
import numpy as np

from nlp_calib.problem import upper_indices
from nlp_calib.solvers.evaluation import ProblemEvaluator


class Guard:
    """The first exception a callback raised; callbacks return NaN from then on."""

    def __init__(self) -> None:
        self.error: BaseException | None = None

    def reraise(self) -> None:
        if self.error is not None:
            error, self.error = self.error, None
            raise error


class NumpyCallback(ca.Callback):
    """A CasADi Function answered by a Python function of numpy arrays."""

    def __init__(
        self,
        name: str,
        ins: Sequence[tuple[str, ca.Sparsity]],
        outs: Sequence[tuple[str, ca.Sparsity]],
        fn: Callable[..., Sequence[np.ndarray | float]],
        guard: Guard,
    ) -> None:
        ca.Callback.__init__(self)
        self._ins, self._outs, self._fn, self._guard = list(ins), list(outs), fn, guard
        self.construct(name, {})

    def get_n_in(self) -> int:
        return len(self._ins)

    def get_n_out(self) -> int:
        return len(self._outs)

    def get_name_in(self, i: int) -> str:
        return self._ins[i][0]

    def get_name_out(self, i: int) -> str:
        return self._outs[i][0]

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return self._ins[i][1]

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return self._outs[i][1]

    def eval(self, args: list[ca.DM]) -> list[ca.DM]:
        if self._guard.error is None:
            try:
                values = self._fn(*[np.asarray(a.nonzeros()) for a in args])
                return [ca.DM(sp, np.ravel(v)) for (_, sp), v in zip(self._outs, values)]
            except BaseException as exc:
                self._guard.error = exc
        return [ca.DM(sp, np.nan) for _, sp in self._outs]


class NlpOracle:
    """``f``, ``grad_f`` and ``hess_lag`` of the (direct or lifted) NLP over ``evaluator``."""

    def __init__(self, evaluator: ProblemEvaluator, lifted: bool, exact: bool) -> None:
        self.ev = evaluator
        self.lifted = lifted
        self.exact = exact
        self.guard = Guard()
        n = evaluator.fns.n_free
        self.n_x = n + (evaluator.n_residuals if lifted else 0)
        x_sp, p_sp, scalar = ca.Sparsity.dense(self.n_x, 1), ca.Sparsity.dense(0, 1), ca.Sparsity.dense(1, 1)
        self.hess_sparsity = self._hess_sparsity()
        cb = self._callback
        self.f = cb("f", [("x", x_sp), ("p", p_sp)], [("f", scalar)], self._f)
        self.grad_f = cb(
            "grad_f", [("x", x_sp), ("p", p_sp)], [("f", scalar), ("grad_f_x", x_sp)], self._grad
        )
        self.hess_lag = cb(
            "hess_lag",
            [("x", x_sp), ("p", p_sp), ("lam_f", scalar), ("lam_g", p_sp)],
            [("hess_gamma_x_x", self.hess_sparsity)],
            self._hess,
        )

    def _callback(
        self,
        name: str,
        ins: list[tuple[str, ca.Sparsity]],
        outs: list[tuple[str, ca.Sparsity]],
        fn: Callable[..., Sequence[np.ndarray | float]],
    ) -> NumpyCallback:
        return NumpyCallback(name, ins, outs, fn, self.guard)

    # --- direct -------------------------------------------------------------------------------------

    def _split(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = self.ev.fns.n_free
        return v[:n], v[n:]

    def _plain(self, x: np.ndarray) -> np.ndarray:
        """``M⁻¹``: plain coordinates from the manifold perturbation."""
        return np.linalg.inv(self.ev.tangent_map(x))

    def _f(self, v: np.ndarray, _p: np.ndarray) -> Sequence[np.ndarray | float]:
        if not self.lifted and not self.exact:
            # The normal equations' cost: IPOPT asks for the gradient at the point it accepts next,
            # and they carry it (one pass over the windows for both, where a cost-only pass and
            # then the normal equations took two; the same objective, by the other Function).
            return [self.ev.normal_equations(v).cost]
        if not self.lifted:
            return [self.ev.cost(v)]
        x, w = self._split(v)
        _, s, _ = self.ev.robust_terms(x)
        d2 = self.ev.delta**2
        cost = float(np.sum(w * s + d2 * (1.0 / w - 1.0)))
        return [cost + (self.ev.prior_terms(x)[0] if self.ev.priors.active else 0.0)]

    def _grad(self, v: np.ndarray, _p: np.ndarray) -> Sequence[np.ndarray | float]:
        ev = self.ev
        x, w = self._split(v)
        if self.exact:
            cost, grad, _ = ev.cost_derivatives(x)
            return [cost, grad]
        Minv = self._plain(x)
        if not self.lifted:
            # 2·g is the cost's manifold gradient, the priors' included.
            ne = ev.normal_equations(x)
            return [ne.cost, 2.0 * Minv.T @ ne.g.ravel()]
        _, s, _, JtOe = ev.residual_terms(x)
        grad_x = 2.0 * Minv.T @ (JtOe @ w)
        prior_cost = 0.0
        if ev.priors.active:
            prior_cost, prior_grad, _ = ev.prior_terms(x)
            grad_x = grad_x + prior_grad
        d2 = ev.delta**2
        cost = float(np.sum(w * s + d2 * (1.0 / w - 1.0))) + prior_cost
        return [cost, np.concatenate([grad_x, s - d2 / w**2])]

    def _hess(
        self, v: np.ndarray, _p: np.ndarray, lam_f: np.ndarray, _lam_g: np.ndarray
    ) -> Sequence[np.ndarray | float]:
        ev = self.ev
        x, w = self._split(v)
        rows, cols = upper_indices(ev.fns.n_free)
        if self.exact:
            return [float(lam_f[0]) * ev.cost_derivatives(x)[2][rows, cols]]
        Minv = self._plain(x)
        # Gauss-Newton for the data, exact for the (linear) prior residuals.
        Hxx = 2.0 * Minv.T @ ev.normal_equations(x).H @ Minv
        values = [Hxx[rows, cols]]
        if self.lifted:
            _, _, _, JtOe = ev.residual_terms(x)
            # Column n + k: the x-rows of w_k's cross term, then its diagonal.
            cross = 2.0 * Minv.T @ JtOe
            diag = 2.0 * ev.delta**2 / w**3
            values.append(np.vstack([cross, diag[None, :]]).ravel(order="F"))
        return [float(lam_f[0]) * np.concatenate(values)]

    def _hess_sparsity(self) -> ca.Sparsity:
        """Upper triangle: ``x``'s block, and per lifted weight its column of cross terms and diagonal."""
        n = self.ev.fns.n_free
        rows, cols = (list(map(int, v)) for v in upper_indices(n))
        if self.lifted:
            for k in range(self.ev.n_residuals):
                rows += [*range(n), n + k]
                cols += [n + k] * (n + 1)
        return ca.Sparsity.triplet(self.n_x, self.n_x, rows, cols)
