"""Builds every named :class:`casadi.Function` of a calibration problem, once (SPEC §3-§6).

This is the only place where residuals, their Jacobians and Hessians are written. Solvers,
code generation, metrics and reports all call the Functions built here.

All problem Functions are *per residual*: one column of the data matrix in, one residual's
contribution out. The evaluation backend maps them over the data (``Function.map``) with the
sums taken inside the map. A data column is ``[u_0 … u_{H-1}, z, w]``: the model inputs of the
``H`` intervals of a horizon window, the measured sensor motion ``z = t2v(T(p_k)⁻¹T(p_{k+H}))``
and a weight ``w`` (1 for a residual, 0 for padding).

The decision vector ``x`` holds the free parameters only; fixed ones enter as ``x_fixed``, so
fixing a parameter changes the Functions, not the solvers.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from nlp_calib.models.base import INTEGRATIONS, SENSOR_PARAMS, KinematicModel, param_names
from nlp_calib.symbolic import se2
from nlp_calib.symbolic.kernels import KERNELS, kernel_function

_CSE = {"cse": True}


@dataclass(frozen=True)
class ProblemSpec:
    """What determines the symbolic problem (and therefore the compiled code)."""

    horizon: int = 1
    integration: str = "exact"
    kernel: str = "huber"
    fixed: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.horizon < 1:
            raise ValueError(f"horizon must be >= 1, got {self.horizon}")
        if self.integration not in INTEGRATIONS:
            raise ValueError(f"integration must be one of {INTEGRATIONS}, got {self.integration!r}")
        if self.kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {sorted(KERNELS)}, got {self.kernel!r}")


@dataclass(frozen=True)
class ProblemFunctions:
    """The built Functions of one problem, with the layout facts callers need.

    Per-residual Functions (inputs named ``x, x_fixed, omega, delta, data``):
    ``residual`` → e; ``residual_jacobian`` → (e, J) with J = ∂e(x ⊞ Δ)/∂Δ; ``normal_equations`` →
    (H_upper, g, cost, chi2, inliers) with H = w·ρ'·JᵀΩJ (upper triangle, column by column,
    see :func:`unpack_upper`), g = w·ρ'·JᵀΩe; ``cost``; ``cost_gradient`` →
    (cost, grad) in plain coordinates; ``cost_hessian`` → upper triangle of ∇²(λ·cost) and
    ``gauss_newton_hessian`` its Gauss-Newton approximation ``λ·2·w·ρ'·JᵀΩJ`` (plain coordinates);
    ``robust_terms`` → (e, s, weight, score = w·ρ'·JᵀΩe); ``huber_lifted`` → the Black–Rangarajan term.
    Whole-problem Functions: ``boxplus`` (x, step) → x ⊞ step; ``tangent_map`` x → ∂(x ⊞ Δ)/∂Δ
    at Δ = 0 (maps manifold covariances to plain coordinates); ``prior`` → (H, g, cost) of Gaussian
    priors; ``assemble`` (x, x_fixed) → params. Full-parameter Functions: ``predict``
    (params, u) → sensor motion over one interval; ``integrate_step`` (T_world_sensor, params, u)
    → T_world_sensor · predict; ``predict_window`` (params, data) → sensor motion over a data
    column's window; ``between`` (a, b) → t2v(a⁻¹b) and ``between_jacobians``.
    Odometry: ``base_from_sensor`` (T_world_sensor, params) → T_world_sensor·T_base_sensor⁻¹;
    ``odometry_step`` (state = [T_world_base, vec P], params, u, input_std) →
    state_next, the base pose and its covariance propagated over one interval.
    Noise propagation: ``sensitivities`` (x, x_fixed, data) → (∂e/∂data, J), per residual.
    """

    spec: ProblemSpec
    model: KinematicModel
    names: tuple[str, ...]
    free: tuple[str, ...]
    fixed: tuple[str, ...]
    data_rows: int
    residual: ca.Function
    residual_jacobian: ca.Function
    normal_equations: ca.Function
    cost: ca.Function
    cost_gradient: ca.Function
    cost_hessian: ca.Function
    gauss_newton_hessian: ca.Function
    robust_terms: ca.Function
    huber_lifted: ca.Function
    boxplus: ca.Function
    tangent_map: ca.Function
    prior: ca.Function
    assemble: ca.Function
    predict: ca.Function
    integrate_step: ca.Function
    base_from_sensor: ca.Function
    odometry_step: ca.Function
    predict_window: ca.Function
    between: ca.Function
    sensitivities: ca.Function
    between_jacobians: ca.Function

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

    def per_residual(self) -> dict[str, ca.Function]:
        """The Functions the backend maps over the data, by name."""
        return {
            f.name(): f
            for f in (
                self.residual,
                self.residual_jacobian,
                self.normal_equations,
                self.cost,
                self.cost_gradient,
                self.cost_hessian,
                self.gauss_newton_hessian,
                self.robust_terms,
                self.huber_lifted,
                self.sensitivities,
            )
        }


def _split_params(model: KinematicModel, params: ca.SX) -> tuple[ca.SX, ca.SX]:
    nk = len(model.kinematic_params)
    return params[:nk], params[nk : nk + 3]


def predict_motion(model: KinematicModel, params: ca.SX, U: ca.SX, integration: str) -> ca.SX:
    """Sensor motion over consecutive intervals: ``T⁻¹ · Δr_0 ⋯ Δr_{H-1} · T`` (SPEC §4).

    ``U`` holds one interval's inputs per column. Conjugating the composed base motion once
    equals composing the conjugated per-interval motions, at a fraction of the cost.
    """
    k, T_base_sensor = _split_params(model, params)
    motion_base = model.increment(k, U[:, 0], integration)
    for j in range(1, U.shape[1]):
        motion_base = se2.compose(motion_base, model.increment(k, U[:, j], integration))
    return se2.conjugate(T_base_sensor, motion_base)


def build(model: KinematicModel, spec: ProblemSpec) -> ProblemFunctions:
    """Build all Functions of the problem described by ``model`` and ``spec``."""
    names = param_names(model)
    unknown = [n for n in spec.fixed if n not in names]
    if unknown:
        raise ValueError(f"cannot fix unknown parameter(s) {unknown}; parameters are {list(names)}")
    free = tuple(n for n in names if n not in spec.fixed)
    fixed = tuple(n for n in names if n in spec.fixed)
    if not free:
        raise ValueError("every parameter is fixed; nothing to estimate")
    n_in, H = len(model.input_names), spec.horizon
    data_rows = n_in * H + 3 + 1

    x = ca.SX.sym("x", len(free))
    x_fixed = ca.SX.sym("x_fixed", len(fixed))
    omega = ca.SX.sym("omega", 3)
    delta = ca.SX.sym("delta")
    data = ca.SX.sym("data", data_rows)
    params = ca.vertcat(*[x[free.index(n)] if n in free else x_fixed[fixed.index(n)] for n in names])
    U = ca.reshape(data[: n_in * H], n_in, H)
    z = data[n_in * H : n_in * H + 3]
    w = data[-1]

    # Box-plus: Euclidean for kinematic parameters; left SE(2) perturbation of the sensor pose
    # when all of it is free (a partly fixed pose has no group structure left to respect).
    step = ca.SX.sym("step", len(free))
    x_plus = ca.SX(step + x)
    if all(n in free for n in SENSOR_PARAMS):
        idx = [free.index(n) for n in SENSOR_PARAMS]
        T_new = se2.boxplus(x[idx], step[idx])
        for j, i in enumerate(idx):
            x_plus[i] = T_new[j]
    boxplus = ca.Function("boxplus", [x, step], [x_plus], ["x", "step"], ["x_next"], _CSE)
    # dx(x ⊞ Δ)/dΔ at Δ = 0 maps plain-coordinate Jacobians onto the manifold perturbation.
    M = ca.substitute(ca.jacobian(x_plus, step), step, ca.DM.zeros(len(free)))

    e = se2.between(z, predict_motion(model, params, U, spec.integration))
    J_plain = ca.jacobian(e, x)
    J = ca.mtimes(J_plain, M)
    Omega = ca.diag(omega)
    s = ca.dot(e, omega * e)
    kernel = kernel_function(spec.kernel)
    rho, weight = kernel(s, delta)
    inlier = ca.if_else(s <= delta * delta, 1.0, 0.0)
    cost = w * rho
    grad = ca.gradient(cost, x)
    lam_f = ca.SX.sym("lam_f")
    hess = ca.triu(ca.hessian(lam_f * cost, x)[0])  # IPOPT reads the upper triangle
    w_lift = ca.SX.sym("w_lift")
    lifted = w * (w_lift * s + delta * delta * (1.0 / w_lift - 1.0))

    common_in = [x, x_fixed, omega, delta, data]
    common_names = ["x", "x_fixed", "omega", "delta", "data"]

    def fn(
        name: str, ins: list[ca.SX], in_names: list[str], outs: list[ca.SX], out_names: list[str]
    ) -> ca.Function:
        # Dense outputs: buffers bind numpy memory to stored non-zeros only. Common subexpression
        # elimination merges repeated sin/cos of the same angle (e.g. cos θ and cos(−θ)).
        return ca.Function(name, ins, [ca.densify(o) for o in outs], in_names, out_names, _CSE)

    # Only the upper triangle of the symmetric JᵀΩJ: fewer operations per residual and per sum.
    JtOJ = ca.mtimes([J.T, Omega, J])
    H_upper = ca.vertcat(*[JtOJ[i, j] for j in range(len(free)) for i in range(j + 1)])
    normal = fn(
        "normal_equations",
        common_in,
        common_names,
        [
            w * weight * H_upper,
            w * weight * ca.mtimes([J.T, Omega, e]),
            cost,
            w * s,
            w * inlier,
        ],
        ["H_upper", "g", "cost", "chi2", "inliers"],
    )

    # Gaussian priors on free parameters: r = sqrt_info · (x - mean), r = 0 where sqrt_info = 0.
    mean = ca.SX.sym("mean", len(free))
    sqrt_info = ca.SX.sym("sqrt_info", len(free))
    r_prior = sqrt_info * (x - mean)
    J_prior = ca.mtimes(ca.jacobian(r_prior, x), M)
    cost_prior = ca.dot(r_prior, r_prior)

    params_sym = ca.SX.sym("params", len(names))
    u1 = ca.SX.sym("u", n_in)
    h1 = predict_motion(model, params_sym, ca.reshape(u1, n_in, 1), spec.integration)
    T_ws = ca.SX.sym("T_world_sensor", 3)
    a, b = ca.SX.sym("a", 3), ca.SX.sym("b", 3)

    # Odometry with covariance: P' = F·P·Fᵀ + G·diag(σ_u²)·Gᵀ, F = ∂T'/∂T and G = ∂T'/∂u.
    state = ca.SX.sym("state", 12)
    T_wb, P = state[:3], ca.reshape(state[3:], 3, 3)
    input_std = ca.SX.sym("input_std", n_in)
    k_sym, _ = _split_params(model, params_sym)
    T_wb_next = se2.compose(T_wb, model.increment(k_sym, u1, spec.integration))
    F, G = ca.jacobian(T_wb_next, T_wb), ca.jacobian(T_wb_next, u1)
    P_next = ca.mtimes([F, P, F.T]) + ca.mtimes([G, ca.diag(input_std**2), G.T])

    return ProblemFunctions(
        spec=spec,
        model=model,
        names=names,
        free=free,
        fixed=fixed,
        data_rows=data_rows,
        residual=fn("residual", [x, x_fixed, data], ["x", "x_fixed", "data"], [e], ["e"]),
        residual_jacobian=fn(
            "residual_jacobian", [x, x_fixed, data], ["x", "x_fixed", "data"], [e, J], ["e", "J"]
        ),
        normal_equations=normal,
        cost=fn("cost", common_in, common_names, [cost], ["cost"]),
        cost_gradient=fn("cost_gradient", common_in, common_names, [cost, grad], ["cost", "grad"]),
        cost_hessian=ca.Function(
            "cost_hessian",
            [*common_in, lam_f],
            [ca.triu(ca.densify(hess))],
            [*common_names, "lam_f"],
            ["hess"],
        ),
        gauss_newton_hessian=ca.Function(
            "gauss_newton_hessian",
            [*common_in, lam_f],
            [ca.triu(ca.densify(lam_f * 2.0 * w * weight * ca.mtimes([J_plain.T, Omega, J_plain])))],
            [*common_names, "lam_f"],
            ["hess"],
            _CSE,
        ),
        robust_terms=fn(
            "robust_terms",
            common_in,
            common_names,
            [e, s, weight, w * weight * ca.mtimes([J.T, Omega, e])],
            ["e", "s", "weight", "score"],
        ),
        huber_lifted=fn("huber_lifted", [*common_in, w_lift], [*common_names, "w_lift"], [lifted], ["cost"]),
        boxplus=boxplus,
        tangent_map=fn("tangent_map", [x], ["x"], [M], ["M"]),
        prior=fn(
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
        ),
        assemble=fn("assemble", [x, x_fixed], ["x", "x_fixed"], [params], ["params"]),
        predict=fn("predict", [params_sym, u1], ["params", "u"], [h1], ["motion"]),
        integrate_step=fn(
            "integrate_step",
            [T_ws, params_sym, u1],
            ["T_world_sensor", "params", "u"],
            [se2.compose(T_ws, h1)],
            ["T_world_sensor_next"],
        ),
        base_from_sensor=fn(
            "base_from_sensor",
            [T_ws, params_sym],
            ["T_world_sensor", "params"],
            [se2.compose(T_ws, se2.inverse(_split_params(model, params_sym)[1]))],
            ["T_world_base"],
        ),
        odometry_step=fn(
            "odometry_step",
            [state, params_sym, u1, input_std],
            ["state", "params", "u", "input_std"],
            [ca.vertcat(T_wb_next, ca.reshape(P_next, 9, 1))],
            ["state_next"],
        ),
        predict_window=fn(
            "predict_window",
            [params_sym, data],
            ["params", "data"],
            [predict_motion(model, params_sym, U, spec.integration)],
            ["motion"],
        ),
        between=fn("between", [a, b], ["a", "b"], [se2.between(a, b)], ["motion"]),
        sensitivities=fn(
            "sensitivities",
            [x, x_fixed, data],
            ["x", "x_fixed", "data"],
            [ca.jacobian(e, data), J],
            ["de_ddata", "J"],
        ),
        between_jacobians=fn(
            "between_jacobians",
            [a, b],
            ["a", "b"],
            [ca.jacobian(se2.between(a, b), a), ca.jacobian(se2.between(a, b), b)],
            ["dmotion_da", "dmotion_db"],
        ),
    )


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
