"""The named :class:`casadi.Function` objects of one calibration problem, written once.

This is the only place where residuals, their Jacobians and Hessians are written. Solvers, code
generation, metrics and reports all call the Functions built here.

:class:`ProblemFunctions` builds the residual, its manifold Jacobian and box-plus when it is
created; every other Function is derived from those same expressions the first time a consumer
asks for it (a run that never uses IPOPT never builds a Hessian).

Per-residual Functions take one column of the data matrix and give one residual's contribution;
the evaluation backend maps them over the data (``Function.map``) with the sums taken inside the
map. A data column is ``[u_0 … u_{H-1}, z, w]``: the model inputs of the ``H`` intervals of a
horizon window, the measured sensor motion ``z = t2v(T(p_k)⁻¹T(p_{k+H}))`` and a weight ``w``
(1 for a residual, 0 for padding). The decision vector ``x`` holds the free parameters only;
fixed ones enter as ``x_fixed``, so fixing a parameter changes the Functions, not the solvers.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.models.base import INTEGRATIONS, SENSOR_PARAMS, KinematicModel, param_names
from nlp_calib.symbolic import se2
from nlp_calib.symbolic.kernels import KERNELS, kernel_function

_CSE = {"cse": True}
#: Inputs of every per-residual Function that takes the robust kernel's settings.
COMMON_INPUTS = ("x", "x_fixed", "omega", "delta", "data")
#: The per-residual Functions, by name (what a backend may be asked to map).
PER_RESIDUAL = (
    "residual",
    "residual_jacobian",
    "normal_equations",
    "cost",
    "cost_gradient",
    "cost_hessian",
    "gauss_newton_hessian",
    "robust_terms",
    "huber_lifted",
    "sensitivities",
)


@dataclass(frozen=True)
class ProblemSpec:
    """What determines the symbolic problem (and therefore the compiled code)."""

    horizon: int = 1
    integration: str = "exact"
    kernel: str = "huber"
    fixed: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.horizon < 1:
            raise ProblemError(f"the horizon must be >= 1 interval, got {self.horizon}")
        if self.integration not in INTEGRATIONS:
            raise ProblemError(
                f"integration must be one of {', '.join(INTEGRATIONS)}, got {self.integration!r}"
            )
        if self.kernel not in KERNELS:
            raise ProblemError(f"unknown robust kernel {self.kernel!r}; valid kernels: {', '.join(KERNELS)}")


def predict_motion(model: KinematicModel, params: ca.SX, U: ca.SX, integration: str) -> ca.SX:
    """Sensor motion over consecutive intervals: ``T⁻¹ · Δr_0 ⋯ Δr_{H-1} · T``.

    ``U`` holds one interval's inputs per column. Conjugating the composed base motion once
    equals composing the conjugated per-interval motions, at a fraction of the cost.
    """
    k, T_base_sensor = _split_params(model, params)
    motion_base = model.increment(k, U[:, 0], integration)
    for j in range(1, U.shape[1]):
        motion_base = se2.compose(motion_base, model.increment(k, U[:, j], integration))
    return se2.conjugate(T_base_sensor, motion_base)


def _split_params(model: KinematicModel, params: ca.SX) -> tuple[ca.SX, ca.SX]:
    nk = len(model.kinematic_params)
    return params[:nk], params[nk : nk + 3]


def _fn(
    name: str, ins: list[ca.SX], in_names: list[str], outs: list[ca.SX], out_names: list[str]
) -> ca.Function:
    # Dense outputs: buffers bind numpy memory to stored non-zeros only. Common subexpression
    # elimination merges repeated sin/cos of the same angle (e.g. cos θ and cos(−θ)).
    return ca.Function(name, ins, [ca.densify(o) for o in outs], in_names, out_names, _CSE)


class ProblemFunctions:
    """The Functions of one problem (model + :class:`ProblemSpec`), with the layout facts callers need.

    Built at once: ``residual`` (x, x_fixed, data) → e; ``residual_jacobian`` → (e, J) with
    J = ∂e(x ⊞ Δ)/∂Δ; ``boxplus`` (x, step) → x ⊞ step. Derived on first use, per residual
    (inputs ``x, x_fixed, omega, delta, data``): ``normal_equations`` → (H_upper, g, cost, chi2,
    inliers) with H = w·ρ'·JᵀΩJ (upper triangle, column by column, see :func:`unpack_upper`) and
    g = w·ρ'·JᵀΩe; ``cost``; ``cost_gradient`` → (cost, grad) in plain coordinates;
    ``cost_hessian`` → upper triangle of ∇²(λ·cost) and ``gauss_newton_hessian`` its Gauss-Newton
    approximation ``λ·2·w·ρ'·JᵀΩJ``; ``robust_terms`` → (e, s, weight, score = w·ρ'·JᵀΩe);
    ``huber_lifted`` → the Black–Rangarajan term; ``sensitivities`` (x, x_fixed, data) →
    (∂e/∂data, J). Whole-problem: ``tangent_map`` x → ∂(x ⊞ Δ)/∂Δ at Δ = 0; ``prior`` → (H, g,
    cost, grad, hess) of Gaussian priors; ``assemble`` (x, x_fixed) → params. Full-parameter:
    ``predict`` (params, u) → sensor motion over one interval; ``interval_residual`` (params, u,
    z) → (e, ∂e/∂u) of one interval; ``integrate_step``
    (T_world_sensor, params, u) → T_world_sensor · predict; ``predict_window`` (params, data);
    ``between`` (a, b) → t2v(a⁻¹b) and ``between_jacobians``; ``base_from_sensor``
    (T_world_sensor, params) → T_world_base; ``odometry_step`` (state = [T_world_base, vec P],
    params, u, input_std) → the base pose and its covariance propagated over one interval.
    """

    def __init__(self, model: KinematicModel, spec: ProblemSpec) -> None:
        names = param_names(model)
        unknown = [n for n in spec.fixed if n not in names]
        if unknown:
            raise ProblemError(f"cannot fix unknown parameter(s) {unknown}; parameters are {list(names)}")
        self.spec = spec
        self.model = model
        self.names = names
        self.free = tuple(n for n in names if n not in spec.fixed)
        self.fixed = tuple(n for n in names if n in spec.fixed)
        if not self.free:
            raise ProblemError("every parameter is fixed; nothing to estimate")
        n_in, H = len(model.input_names), spec.horizon
        self.data_rows = n_in * H + 3 + 1

        free, fixed = self.free, self.fixed
        self._x = x = ca.SX.sym("x", len(free))
        self._x_fixed = x_fixed = ca.SX.sym("x_fixed", len(fixed))
        self._omega = ca.SX.sym("omega", 3)
        self._delta = ca.SX.sym("delta")
        self._data = data = ca.SX.sym("data", self.data_rows)
        self._params = ca.vertcat(
            *[x[free.index(n)] if n in free else x_fixed[fixed.index(n)] for n in names]
        )
        self._U = ca.reshape(data[: n_in * H], n_in, H)
        z = data[n_in * H : n_in * H + 3]
        self._w = data[-1]

        # Box-plus: Euclidean for kinematic parameters; left SE(2) perturbation of the sensor pose
        # when all of it is free (a partly fixed pose has no group structure left to respect).
        step = ca.SX.sym("step", len(free))
        x_plus = ca.SX(step + x)
        if self.manifold_sensor:
            idx = [free.index(n) for n in SENSOR_PARAMS]
            T_new = se2.boxplus(x[idx], step[idx])
            for j, i in enumerate(idx):
                x_plus[i] = T_new[j]
        self.boxplus = ca.Function("boxplus", [x, step], [x_plus], ["x", "step"], ["x_next"], _CSE)
        # dx(x ⊞ Δ)/dΔ at Δ = 0 maps plain-coordinate Jacobians onto the manifold perturbation.
        self._M = ca.substitute(ca.jacobian(x_plus, step), step, ca.DM.zeros(len(free)))

        self._e = se2.between(z, predict_motion(model, self._params, self._U, spec.integration))
        self._J_plain = ca.jacobian(self._e, x)
        self._J = ca.mtimes(self._J_plain, self._M)
        self.residual = _fn("residual", [x, x_fixed, data], ["x", "x_fixed", "data"], [self._e], ["e"])
        self.residual_jacobian = _fn(
            "residual_jacobian", [x, x_fixed, data], ["x", "x_fixed", "data"], [self._e, self._J], ["e", "J"]
        )

    # --- layout facts ---------------------------------------------------------------------------

    @property
    def n_free(self) -> int:
        return len(self.free)

    @property
    def n_inputs(self) -> int:
        return len(self.model.input_names)

    @property
    def manifold_sensor(self) -> bool:
        """True when the sensor pose is perturbed on SE(2) (all three components free)."""
        return all(n in self.free for n in SENSOR_PARAMS)

    def function(self, name: str) -> ca.Function:
        """The per-residual Function ``name`` (one of :data:`PER_RESIDUAL`), built if needed."""
        if name not in PER_RESIDUAL:
            raise KeyError(f"{name!r} is not a per-residual Function; they are {', '.join(PER_RESIDUAL)}")
        f: ca.Function = getattr(self, name)
        return f

    # --- derived on first use -------------------------------------------------------------------

    @functools.cached_property
    def _robust(self) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
        """``s = eᵀΩe``, ρ(s), ρ'(s), the inlier flag and the weighted cost ``w·ρ``."""
        e, omega, delta = self._e, self._omega, self._delta
        s = ca.dot(e, omega * e)
        rho, weight = kernel_function(self.spec.kernel)(s, delta)
        inlier = ca.if_else(s <= delta * delta, 1.0, 0.0)
        return s, rho, weight, inlier, self._w * rho

    def _common(self) -> tuple[list[ca.SX], list[str]]:
        return [self._x, self._x_fixed, self._omega, self._delta, self._data], list(COMMON_INPUTS)

    @functools.cached_property
    def normal_equations(self) -> ca.Function:
        s, _, weight, inlier, cost = self._robust
        J, e, w = self._J, self._e, self._w
        Omega = ca.diag(self._omega)
        # Only the upper triangle of the symmetric JᵀΩJ: fewer operations per residual and per sum.
        JtOJ = ca.mtimes([J.T, Omega, J])
        H_upper = ca.vertcat(*[JtOJ[i, j] for j in range(self.n_free) for i in range(j + 1)])
        ins, in_names = self._common()
        return _fn(
            "normal_equations",
            ins,
            in_names,
            [w * weight * H_upper, w * weight * ca.mtimes([J.T, Omega, e]), cost, w * s, w * inlier],
            ["H_upper", "g", "cost", "chi2", "inliers"],
        )

    @functools.cached_property
    def cost(self) -> ca.Function:
        ins, in_names = self._common()
        return _fn("cost", ins, in_names, [self._robust[4]], ["cost"])

    @functools.cached_property
    def cost_gradient(self) -> ca.Function:
        cost = self._robust[4]
        ins, in_names = self._common()
        return _fn("cost_gradient", ins, in_names, [cost, ca.gradient(cost, self._x)], ["cost", "grad"])

    @functools.cached_property
    def _lam_f(self) -> ca.SX:
        return ca.SX.sym("lam_f")

    @functools.cached_property
    def cost_hessian(self) -> ca.Function:
        hess = ca.triu(
            ca.hessian(self._lam_f * self._robust[4], self._x)[0]
        )  # IPOPT reads the upper triangle
        ins, in_names = self._common()
        return ca.Function(
            "cost_hessian", [*ins, self._lam_f], [ca.triu(ca.densify(hess))], [*in_names, "lam_f"], ["hess"]
        )

    @functools.cached_property
    def gauss_newton_hessian(self) -> ca.Function:
        weight, Jp, w = self._robust[2], self._J_plain, self._w
        hess = self._lam_f * 2.0 * w * weight * ca.mtimes([Jp.T, ca.diag(self._omega), Jp])
        ins, in_names = self._common()
        return ca.Function(
            "gauss_newton_hessian",
            [*ins, self._lam_f],
            [ca.triu(ca.densify(hess))],
            [*in_names, "lam_f"],
            ["hess"],
            _CSE,
        )

    @functools.cached_property
    def robust_terms(self) -> ca.Function:
        s, _, weight, _, _ = self._robust
        J, e, w = self._J, self._e, self._w
        ins, in_names = self._common()
        return _fn(
            "robust_terms",
            ins,
            in_names,
            [e, s, weight, w * weight * ca.mtimes([J.T, ca.diag(self._omega), e])],
            ["e", "s", "weight", "score"],
        )

    @functools.cached_property
    def huber_lifted(self) -> ca.Function:
        s, delta = self._robust[0], self._delta
        w_lift = ca.SX.sym("w_lift")
        lifted = self._w * (w_lift * s + delta * delta * (1.0 / w_lift - 1.0))
        ins, in_names = self._common()
        return _fn("huber_lifted", [*ins, w_lift], [*in_names, "w_lift"], [lifted], ["cost"])

    @functools.cached_property
    def sensitivities(self) -> ca.Function:
        return _fn(
            "sensitivities",
            [self._x, self._x_fixed, self._data],
            ["x", "x_fixed", "data"],
            [ca.jacobian(self._e, self._data), self._J],
            ["de_ddata", "J"],
        )

    @functools.cached_property
    def tangent_map(self) -> ca.Function:
        return _fn("tangent_map", [self._x], ["x"], [self._M], ["M"])

    @functools.cached_property
    def prior(self) -> ca.Function:
        """Gaussian priors on free parameters: r = sqrt_info · (x - mean), r = 0 where sqrt_info = 0."""
        x, n = self._x, self.n_free
        mean = ca.SX.sym("mean", n)
        sqrt_info = ca.SX.sym("sqrt_info", n)
        r_prior = sqrt_info * (x - mean)
        J_prior = ca.mtimes(ca.jacobian(r_prior, x), self._M)
        cost_prior = ca.dot(r_prior, r_prior)
        return _fn(
            "prior",
            [x, mean, sqrt_info],
            ["x", "mean", "sqrt_info"],
            [
                ca.mtimes(J_prior.T, J_prior),
                ca.mtimes(J_prior.T, r_prior),
                cost_prior,
                ca.gradient(cost_prior, x),
                ca.hessian(cost_prior, x)[0],
            ],
            ["H", "g", "cost", "grad", "hess"],
        )

    @functools.cached_property
    def assemble(self) -> ca.Function:
        return _fn("assemble", [self._x, self._x_fixed], ["x", "x_fixed"], [self._params], ["params"])

    @functools.cached_property
    def _full(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        """Full-parameter symbols: params, one interval's inputs and the sensor motion over it."""
        params = ca.SX.sym("params", len(self.names))
        u1 = ca.SX.sym("u", self.n_inputs)
        h1 = predict_motion(self.model, params, ca.reshape(u1, self.n_inputs, 1), self.spec.integration)
        return params, u1, h1

    @functools.cached_property
    def interval_residual(self) -> ca.Function:
        """(params, u, z) → (e, de_du): one interval's residual against the tracker's motion ``z``
        and its derivative with respect to the interval's inputs (for checking encoder readings)."""
        params, u1, h1 = self._full
        z = ca.SX.sym("z", 3)
        e1 = se2.between(z, h1)
        return _fn(
            "interval_residual",
            [params, u1, z],
            ["params", "u", "z"],
            [e1, ca.jacobian(e1, u1)],
            ["e", "de_du"],
        )

    @functools.cached_property
    def predict(self) -> ca.Function:
        params, u1, h1 = self._full
        return _fn("predict", [params, u1], ["params", "u"], [h1], ["motion"])

    @functools.cached_property
    def integrate_step(self) -> ca.Function:
        params, u1, h1 = self._full
        T_ws = ca.SX.sym("T_world_sensor", 3)
        return _fn(
            "integrate_step",
            [T_ws, params, u1],
            ["T_world_sensor", "params", "u"],
            [se2.compose(T_ws, h1)],
            ["T_world_sensor_next"],
        )

    @functools.cached_property
    def base_from_sensor(self) -> ca.Function:
        params = self._full[0]
        T_ws = ca.SX.sym("T_world_sensor", 3)
        T_base_sensor = _split_params(self.model, params)[1]
        return _fn(
            "base_from_sensor",
            [T_ws, params],
            ["T_world_sensor", "params"],
            [se2.compose(T_ws, se2.inverse(T_base_sensor))],
            ["T_world_base"],
        )

    @functools.cached_property
    def odometry_step(self) -> ca.Function:
        """P' = F·P·Fᵀ + G·diag(σ_u²)·Gᵀ with F = ∂T'/∂T and G = ∂T'/∂u."""
        params, u1, _ = self._full
        state = ca.SX.sym("state", 12)
        T_wb, P = state[:3], ca.reshape(state[3:], 3, 3)
        input_std = ca.SX.sym("input_std", self.n_inputs)
        k_sym, _ = _split_params(self.model, params)
        T_wb_next = se2.compose(T_wb, self.model.increment(k_sym, u1, self.spec.integration))
        F, G = ca.jacobian(T_wb_next, T_wb), ca.jacobian(T_wb_next, u1)
        P_next = ca.mtimes([F, P, F.T]) + ca.mtimes([G, ca.diag(input_std**2), G.T])
        return _fn(
            "odometry_step",
            [state, params, u1, input_std],
            ["state", "params", "u", "input_std"],
            [ca.vertcat(T_wb_next, ca.reshape(P_next, 9, 1))],
            ["state_next"],
        )

    @functools.cached_property
    def predict_window(self) -> ca.Function:
        params = self._full[0]
        U = ca.reshape(self._data[: self.n_inputs * self.spec.horizon], self.n_inputs, self.spec.horizon)
        return _fn(
            "predict_window",
            [params, self._data],
            ["params", "data"],
            [predict_motion(self.model, params, U, self.spec.integration)],
            ["motion"],
        )

    @functools.cached_property
    def _pose_pair(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        a, b = ca.SX.sym("a", 3), ca.SX.sym("b", 3)
        return a, b, se2.between(a, b)

    @functools.cached_property
    def between(self) -> ca.Function:
        a, b, motion = self._pose_pair
        return _fn("between", [a, b], ["a", "b"], [motion], ["motion"])

    @functools.cached_property
    def between_jacobians(self) -> ca.Function:
        a, b, motion = self._pose_pair
        return _fn(
            "between_jacobians",
            [a, b],
            ["a", "b"],
            [ca.jacobian(motion, a), ca.jacobian(motion, b)],
            ["dmotion_da", "dmotion_db"],
        )


def build(model: KinematicModel, spec: ProblemSpec) -> ProblemFunctions:
    """The Functions of the problem described by ``model`` and ``spec``."""
    return ProblemFunctions(model, spec)


@functools.cache
def _upper_indices(n: int) -> tuple[np.ndarray, np.ndarray]:
    cols, rows = zip(*[(j, i) for j in range(n) for i in range(j + 1)]) if n else ((), ())
    return np.array(rows, dtype=np.intp), np.array(cols, dtype=np.intp)


def unpack_upper(h_upper: np.ndarray, n: int) -> np.ndarray:
    """The symmetric ``n x n`` matrix whose upper triangle is stored column by column."""
    rows, cols = _upper_indices(n)
    H = np.empty((n, n))
    H[rows, cols] = np.ravel(h_upper)
    H[cols, rows] = np.ravel(h_upper)
    return H
