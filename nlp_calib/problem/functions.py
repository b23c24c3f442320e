"""The named :class:`casadi.Function` objects of one calibration problem, written once.

This is the only place where residuals, their Jacobians and the robust terms are written.
Solvers, code generation, metrics and reports all call the Functions built here.

A residual compares a horizon window's predicted sensor motion with the tracker's:
``e = t2v(Z⁻¹·T⁻¹·M·T)`` with ``Z = T(p_a)⁻¹T(p_b)`` the tracker's motion from record ``a`` to
``b``, ``M`` the base motion the model predicts over the intervals between them and ``T`` the
sensor mounting pose. Where ``M`` and ``∂M/∂x`` come from is :mod:`nlp_calib.problem.motion`'s
business (directly from one interval's inputs when ``H = 1``, from prefix poses otherwise); what
the sensor measures (a planar pose, or a 3-D one: ``e = Log((s·Z)⁻¹·T⁻¹·lift(M)·T)``, 6 rows) is
:mod:`nlp_calib.sensors`'; every per-residual Function here is built once on top of both.

Per-residual Functions take two mapped inputs: ``motion`` (the window's motion data, see
:class:`~nlp_calib.problem.motion.MotionSymbols`) and ``data = [z, w]`` (the tracker's motion
``z``, :attr:`ProblemFunctions.data_rows` − 1 rows, and the residual's weight ``w``: 1, or 0 for
padding); the evaluation backend maps them
over the windows with the sums taken inside the map. The decision vector ``x`` holds the free
parameters only; fixed ones enter as ``x_fixed``, so fixing a parameter changes the Functions,
not the solvers.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.core.ranges import Range, check_choice, check_range
from nlp_calib.models.base import INTEGRATIONS, KinematicModel, Reference, reference
from nlp_calib.models.clock import LAG_PARAM, LAG_REFERENCE, LAG_UNIT
from nlp_calib.problem import clock
from nlp_calib.problem import motion as motion_sources
from nlp_calib.problem.blocks import BLOCK_KINDS, by_definition
from nlp_calib.problem.trajectory import TrajectoryFunctions, base_motion, fn, split_params
from nlp_calib.results.layout import CLOCK, HELD, MODEL, MOUNT, BlockSpec, Layout
from nlp_calib.sensors import Sensor, sensor_for
from nlp_calib.symbolic.kernels import KERNELS, kernel_function

_CSE = {"cse": True}
#: Inputs of every per-residual Function that takes the robust kernel's settings.
COMMON_INPUTS = ("x", "x_fixed", "omega", "delta", "motion", "data")
#: The per-residual Functions, by name (what a backend maps over the windows).
PER_RESIDUAL = ("normal_equations", "cost", "cost_derivatives", "robust_terms", "sensitivities")
#: Those whose outputs are summed over the windows (the others give one block per window).
SUMMED = ("normal_equations", "cost", "cost_derivatives")
#: Their mapped inputs: the rest (parameters, kernel settings) are the same for every window.
WINDOW_INPUTS = ("motion", "data")
#: Rows of a planar problem's ``data``: the tracker's motion ``z`` and the weight ``w`` (any
#: problem: :attr:`ProblemFunctions.data_rows`).
DATA_ROWS = 4
#: The order of the motion's derivatives each per-residual Function needs.
ORDER = {
    "normal_equations": 1,
    "cost": 0,
    "cost_derivatives": 2,
    "robust_terms": 1,
    "sensitivities": 1,
    "end_sensitivity": 0,
}
#: The prefix scan's step of each order.
STEPS = {0: "prefix_value_step", 1: "prefix_step", 2: "prefix_hessian_step"}


#: ``horizon``: each window composes H steps symbolically, so building the problem costs time and
#: memory in proportion to H; the accuracy study's trajectory error flattens by H = 25.
HORIZON = Range(1, 200, integer=True)
#: Time offsets in one problem (one per log).
LAGS = Range(0, 10_000, integer=True)
#: Sensor mounts in one problem: one shared by every log, or one per log.
MOUNTS = Range(1, 10_000, integer=True)


@dataclass(frozen=True)
class ProblemSpec:
    """What determines the symbolic problem (and therefore the compiled code)."""

    horizon: int = 1
    integration: str = "exact"
    kernel: str = "huber"
    fixed: tuple[str, ...] = ()
    #: What the tracker measures: ``planar`` poses or ``3d`` ones (see :mod:`~nlp_calib.sensors`).
    sensor: str = "planar"
    #: ``free``: 3-D poses known up to scale (monocular visual odometry): ``scale`` is estimated.
    scale: str = "fixed"
    #: Time offsets (``tracker_lag``) in the problem, one per log (see :mod:`~nlp_calib.problem.clock`);
    #: 0: the data's clock is taken as it is.
    lags: int = 0
    #: Sensor mounts: 1, shared by every log; or one per log of a joint fit (``sensor_x_1``, …), each
    #: window's chosen by which log it belongs to, every log sharing the kinematic parameters.
    mounts: int = 1
    #: With a mount per log, its parameters every log shares nonetheless (a gyro's tilt beside each
    #: log's own bias: the sensor's ``per_log`` alone are each log's own); none: the whole mount.
    shared: tuple[str, ...] = ()
    #: Logs in the problem, and the registered block kinds it has beyond the built-in ones (see
    #: :mod:`~nlp_calib.problem.blocks`; their per-log parameters one per log).
    logs: int = 1
    blocks: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        sensor = sensor_for(self.sensor, self.scale)
        if unknown := [b for b in self.blocks if b not in BLOCK_KINDS]:
            raise ProblemError(f"blocks {unknown}: not registered ({', '.join(BLOCK_KINDS) or 'none are'})")
        if self.shared and (self.mounts == 1 or not set(self.shared) < set(sensor.params)):
            raise ProblemError(
                f"shared {list(self.shared)}: with a mount per log, some of the mount's parameters "
                f"({', '.join(sensor.params)}), not all"
            )
        check_range("lags", self.lags, LAGS)
        check_range("mounts", self.mounts, MOUNTS)
        if self.mounts > 1 and self.lags and self.lags != self.mounts:
            raise ProblemError(f"{self.mounts} mounts (one per log) but {self.lags} time offsets")
        # One offset fitted for several logs would have no return check (the alignment re-samples
        # one log at its own lag): a shared clock's lag is given (``alignment.tracker_lag: 0.03``).
        if self.logs > 1 and self.lags not in (0, self.logs):
            raise ProblemError(f"{self.logs} logs but {self.lags} time offsets (one per log, or none)")
        check_range("horizon", self.horizon, HORIZON)
        check_choice("integration", self.integration, INTEGRATIONS)
        check_choice("kernel", self.kernel, KERNELS)


@dataclass(frozen=True)
class _Symbols:
    """The problem's symbols: free and fixed parameters, the information weights, the robust
    kernel's threshold, a window's data, the full parameter vector and ``M`` = ∂(x ⊞ Δ)/∂Δ at 0."""

    x: ca.SX
    x_fixed: ca.SX
    omega: ca.SX
    delta: ca.SX
    data: ca.SX
    params: ca.SX
    M: ca.SX


class ProblemFunctions(TrajectoryFunctions):
    """The Functions of one problem (model + :class:`ProblemSpec`), with the layout facts callers need.

    Per residual (inputs ``x, x_fixed, omega, delta, motion, data``, derived on first use; the
    ``motion`` data of :data:`ORDER`'s order, see :meth:`motion_rows`): ``normal_equations`` →
    (H_upper, g, cost, chi2, inliers) with H = w·ρ'·JᵀΩJ (upper triangle, column by column, see
    :func:`unpack_upper`) and g = w·ρ'·JᵀΩe, J = ∂e(x ⊞ Δ)/∂Δ; ``cost`` → w·ρ;
    ``cost_derivatives`` → (cost, gradient, upper triangle of the Hessian) of w·ρ in plain
    coordinates; ``robust_terms`` → (e, s = eᵀΩe, ρ'(s), w·JᵀΩe); ``sensitivities`` (x, x_fixed,
    motion, data) → (J, ∂e/∂z, ∂e/∂end) for the noise propagation, ``end_sensitivity`` its
    ``∂e/∂end`` alone (on the motion's values). Prefix problems (``prefix``)
    add the scans' steps (:data:`STEPS`, see :meth:`step`) and ``interval_sensitivity`` (see
    :mod:`nlp_calib.problem.motion`). Whole-problem: ``boxplus`` (x, step) → x ⊞ step;
    ``tangent_map`` x → ∂(x ⊞ Δ)/∂Δ at Δ = 0; ``prior`` → (H, g, cost, grad, hess) of Gaussian
    priors; ``assemble`` (x, x_fixed) → params. The residual as defined, on one window's inputs
    ``[u_0 … u_{H-1}, z, w]`` (the C export, and the reference the tests hold the windows to):
    ``residual`` → e and ``residual_jacobian`` → (e, J). Full-parameter Functions: see
    :class:`~nlp_calib.problem.trajectory.TrajectoryFunctions`.
    """

    def __init__(self, model: KinematicModel, spec: ProblemSpec) -> None:
        sensor = sensor_for(spec.sensor, spec.scale)
        layout = problem_layout(model, sensor, spec)
        names = layout.names
        unknown = [n for n in spec.fixed if n not in names]
        if unknown:
            raise ProblemError(f"cannot fix unknown parameter(s) {unknown}; parameters are {list(names)}")
        self.spec = spec
        self.model = model
        self.names = names
        held = {*spec.fixed, *layout.status(HELD)}
        #: Every parameter in its block, with its log and status (see :mod:`nlp_calib.results.layout`).
        self.layout = layout.with_status(dict.fromkeys(spec.fixed, HELD))
        #: One log's parameters as the full-parameter Functions take them (see :meth:`view`).
        self.view_names = (*model.kinematic_params, *sensor.params, *layout.block(CLOCK))
        self.free = tuple(n for n in names if n not in held)
        self.fixed = tuple(n for n in names if n in held)
        if not self.free:
            raise ProblemError("every parameter is fixed; nothing to estimate")
        free, fixed = self.free, self.fixed
        x = ca.SX.sym("x", len(free))
        x_fixed = ca.SX.sym("x_fixed", len(fixed))
        params = ca.vertcat(*[x[free.index(n)] if n in free else x_fixed[fixed.index(n)] for n in names])
        # Box-plus: Euclidean for kinematic parameters; the sensor's own for its mount (planar: a
        # left SE(2) perturbation when all of it is free; a partly fixed pose has no group
        # structure left to respect).
        step = ca.SX.sym("step", len(free))
        x_plus = ca.SX(step + x)
        for i in range(spec.mounts):
            sensor.boxplus(self.mount_view(free, i), x, step, x_plus)
        self.boxplus = ca.Function("boxplus", [x, step], [x_plus], ["x", "step"], ["x_next"], _CSE)
        # dx(x ⊞ Δ)/dΔ at Δ = 0 maps plain-coordinate Jacobians onto the manifold perturbation.
        tangent = ca.substitute(ca.jacobian(x_plus, step), step, ca.DM.zeros(len(free)))
        omega, delta = ca.SX.sym("omega", sensor.error_rows), ca.SX.sym("delta")
        self._sym = _Symbols(x, x_fixed, omega, delta, ca.SX.sym("data", self.data_rows), params, tangent)
        self._windows: dict[int, tuple[motion_sources.MotionSymbols, ca.SX, ca.SX]] = {}
        self._steps: dict[int, ca.Function] = {}

    # --- layout facts ---------------------------------------------------------------------------

    @property
    def horizon(self) -> int:
        return self.spec.horizon

    @property
    def integration(self) -> str:
        return self.spec.integration

    @functools.cached_property
    def kinematic_columns(self) -> list[int]:
        """Places of the free kinematic parameters in ``x`` (the columns of a prefix Jacobian)."""
        return [self.free.index(n) for n in self.model.kinematic_params if n in self.free]

    @property
    def n_free(self) -> int:
        return len(self.free)

    def mount_names(self, log: int) -> tuple[str, ...]:
        """The names of log ``log``'s mount among :attr:`names` (the shared mount's, for one)."""
        return self.layout.block(MOUNT, log)

    def mount_view(self, names: tuple[str, ...], log: int) -> tuple[str, ...]:
        """``names`` with log ``log``'s mount under the sensor's own names and every other mount's
        out of the sensor's sight (what its box-plus and manifold test read)."""
        if self.spec.mounts == 1:
            return names
        mine = set(self.mount_names(log))
        others = set(self.layout.block(MOUNT)) - mine
        return tuple(self.layout.key(n) if n in mine else f"\0{n}" if n in others else n for n in names)

    @property
    def own_poses(self) -> bool:
        """Whether each log has a mount pose of its own (a pose component among a log's own
        parameters), not only parameters of its own beside a shared pose (a gyro's bias)."""
        pose = set(self.sensor.components.values())
        return any(p.log is not None and p.key in pose for p in self.layout.parameters if p.block == MOUNT)

    def mount_keys(self, log: int) -> dict[str, str]:
        """Log ``log``'s mount: each of its names among :attr:`names` and the sensor's name for it."""
        return {n: self.layout.key(n) for n in self.mount_names(log)}

    def view(self, params: np.ndarray, log: int) -> np.ndarray:
        """Log ``log``'s parameters in :attr:`view_names` order from the full vector ``params``
        (what the full-parameter Functions take): the shared ones and its own mount."""
        if self.spec.mounts == 1 and not self.spec.blocks:
            return np.asarray(params, dtype=float)
        named = dict(zip(self.names, np.ravel(np.asarray(params, dtype=float))))
        own = {key: named[n] for n, key in self.mount_keys(log).items()}
        return np.array([own[n] if n in own else named[n] for n in self.view_names])

    def view_dict(self, params: Mapping[str, float], log: int) -> dict[str, float]:
        """:meth:`view` of named values (any names; the other logs' mounts left out)."""
        if self.spec.mounts == 1:
            return dict(params)
        own = self.mount_keys(log)
        every = set(self.layout.block(MOUNT))
        return {own.get(n, n): float(v) for n, v in params.items() if n in own or n not in every}

    def full_dict(self, views: Sequence[Mapping[str, float]]) -> dict[str, float]:
        """Named values over :attr:`names` from one view per mount (the shared ones from the first)."""
        out = dict(views[0])
        if self.spec.mounts > 1:
            for i, v in reversed(list(enumerate(views))):
                out.update({n: float(v[key]) for n, key in self.mount_keys(i).items() if key in v})
            for p in self.sensor.params:
                if p not in self.names:
                    out.pop(p, None)
        return out

    @property
    def sensor(self) -> Sensor:
        """What the tracker measures and how the mount enters (see :mod:`~nlp_calib.sensors`)."""
        return sensor_for(self.spec.sensor, self.spec.scale)

    @property
    def manifold_sensor(self) -> bool:
        """True when the sensor's mount (every log's) is perturbed on its group (see
        :mod:`~nlp_calib.sensors`)."""
        return all(self.sensor.manifold(self.mount_view(self.free, i)) for i in range(self.spec.mounts))

    @property
    def data_rows(self) -> int:
        """Rows of a window's ``data = [z, clock, w]`` (``clock``: :attr:`clock_rows`)."""
        return self.sensor.z_rows + self.clock_rows + 1

    @property
    def clock_rows(self) -> int:
        """Rows of a window's clock data: the inputs' rates at its first and last record and the
        offset its log's data were re-sampled at (when the problem has a time offset, see
        :mod:`~nlp_calib.problem.clock`), then which log it belongs to (:attr:`select_rows`)."""
        return (2 * self.n_inputs + 1 if self.spec.lags else 0) + self.select_rows

    @property
    def select_rows(self) -> int:
        """Rows saying which log a window belongs to, one per log: with a time offset or a mount
        per log (none otherwise)."""
        if self.spec.lags:
            return self.spec.lags
        if self.spec.mounts > 1:
            return self.spec.mounts
        own = any(BLOCK_KINDS[b].per_log for b in self.spec.blocks)
        return self.spec.logs if own and self.spec.logs > 1 else 0

    @property
    def weight_row(self) -> int:
        """The row of a window's weight in its ``data``."""
        return self.data_rows - 1

    @property
    def error_rows(self) -> int:
        """Rows of a residual ``e`` (and of ``omega``)."""
        return self.sensor.error_rows

    @property
    def prefix(self) -> bool:
        """True when windows take their motion from prefix poses (horizon > 1)."""
        return self.spec.horizon > 1

    def motion_rows(self, order: int) -> int:
        """Rows of a window's motion data for Functions of derivative ``order`` (see :data:`ORDER`)."""
        return self._source.rows(order)

    def function(self, name: str) -> ca.Function:
        """The per-residual Function ``name`` (one of :data:`PER_RESIDUAL`), built if needed."""
        if name not in PER_RESIDUAL:
            raise KeyError(f"{name!r} is not a per-residual Function; they are {', '.join(PER_RESIDUAL)}")
        f: ca.Function = getattr(self, name)
        return f

    # --- the residual, from the window's motion ---------------------------------------------------

    @functools.cached_property
    def _source(self) -> motion_sources.MotionSource:
        k = split_params(self.model, self.sensor, self._sym.params)[0]
        kinematic = fn("kinematic", [self._sym.x, self._sym.x_fixed], ["x", "x_fixed"], [k], ["k"])
        return motion_sources.MotionSource(
            self.model,
            kinematic,
            self._sym.x,
            self._sym.x_fixed,
            self.kinematic_columns,
            self.n_inputs,
            self.spec.integration,
            self.prefix,
        )

    def _window(self, order: int) -> tuple[motion_sources.MotionSymbols, ca.SX, ca.SX]:
        """The motion data, the perturbation ``h`` of ``x`` and the residual ``e(h)`` at ``order``."""
        if order in self._windows:
            return self._windows[order]
        h = ca.SX.sym("h", self.n_free)
        mo = self._source.window(h, order)
        # The motion's kinematic dependence comes with its data (prefix jets); the mount's and the
        # clock's is direct.
        params_h = ca.substitute(self._sym.params, self._sym.x, self._sym.x + h)
        e = self._residual(self._sym.data, params_h, mo.M)
        self._windows[order] = (mo, h, e)
        return mo, h, e

    def _residual(self, data: ca.SX, params: ca.SX, M: ca.SX) -> ca.SX:
        """The residual of a window's ``data`` for ``params`` and base motion ``M`` (before the clock)."""
        at = {n: i for i, n in enumerate(self.names)}
        k = params[: len(self.model.kinematic_params)]
        z_rows, n_in = self.sensor.z_rows, self.n_inputs
        first = z_rows + (2 * n_in + 1 if self.spec.lags else 0)
        select = data[first : first + self.select_rows]
        M = self._blocks(params, select, at, M)
        if self.spec.lags:
            ends = data[z_rows : z_rows + n_in], data[z_rows + n_in : z_rows + 2 * n_in]
            resampled = data[z_rows + 2 * n_in]
            delta = ca.dot(select, self._lags(params, data[0:z_rows], at)) - resampled
            M = clock.shifted(self.model, k, M, ends, delta, self.spec.integration)
        return self.sensor.residual(data[0:z_rows], self._mount(params, select, at), M)

    def _blocks(self, params: ca.SX, select: ca.SX, at: Mapping[str, int], M: ca.SX) -> ca.SX:
        """The base motion ``M`` through each registered block's transform, with the window's
        values of its parameters (a per-log one: its log's own, by the window's log rows)."""
        for kind in self.spec.blocks:
            values: dict[str, ca.SX] = {}
            for p in self.layout.parameters:
                if p.block == kind:
                    mine = params[at[p.name]] if p.log is None else select[p.log] * params[at[p.name]]
                    values[p.key] = values.get(p.key, 0) + mine
            M = BLOCK_KINDS[kind].transform(M, values)
        return M

    def _lags(self, params: ca.SX, z: ca.SX, at: Mapping[str, int]) -> ca.SX:
        """Each log's time offset for a window of measurement ``z``: its sensor's clocks' offsets
        (the clock block's, that log's own) weighted by which clock the window is on."""
        weights = self.sensor.clock_weights(z)
        of = {(p.log or 0, p.key): at[p.name] for p in self.layout.parameters if p.block == CLOCK}
        return ca.vertcat(
            *[
                sum(weights[c] * params[of[(i, key)]] for c, key in enumerate(self.sensor.clocks))
                for i in range(self.spec.lags)
            ]
        )

    def _mount(self, params: ca.SX, select: ca.SX, at: Mapping[str, int]) -> ca.SX:
        """The window's mount in the sensor's order: a shared parameter as it is, a log's own picked
        by the window's one-hot log row (exact for any mount)."""
        names = [{key: n for n, key in self.mount_keys(i).items()} for i in range(self.spec.mounts)]
        rows = []
        for key in self.sensor.params:
            own = [at[by[key]] for by in names]
            one = len(set(own)) == 1
            rows.append(params[own[0]] if one else sum(select[i] * params[j] for i, j in enumerate(own)))
        return ca.vertcat(*rows)

    def _at_zero(self, mo: motion_sources.MotionSymbols, h: ca.SX, exprs: list[ca.SX]) -> list[ca.SX]:
        """``exprs`` at ``h = 0`` (and the motion's end unperturbed)."""
        out = ca.substitute(exprs, [h], [ca.DM.zeros(h.numel())])
        if mo.end_zero is not None:
            out = ca.substitute(out, [mo.end], [mo.end_zero])
        return out

    def _linear(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        """Motion data, ``e`` and the manifold Jacobian ``J`` (first order)."""
        mo, h, e_h = self._window(1)
        e, J_plain = self._at_zero(mo, h, [e_h, ca.jacobian(e_h, h)])
        return mo.data, e, ca.mtimes(J_plain, self._sym.M)

    def _robust(self, e: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
        """``s = eᵀΩe``, the weighted cost ``w·ρ(s)``, ρ'(s) and the inlier flag."""
        w, omega, delta = self._sym.data[self.weight_row], self._sym.omega, self._sym.delta
        s = ca.dot(e, omega * e)
        rho, weight = kernel_function(self.spec.kernel)(s, delta)
        return s, w * rho, weight, ca.if_else(s <= delta * delta, 1.0, 0.0)

    def _ins(self, motion: ca.SX) -> tuple[list[ca.SX], list[str]]:
        return [
            self._sym.x,
            self._sym.x_fixed,
            self._sym.omega,
            self._sym.delta,
            motion,
            self._sym.data,
        ], list(COMMON_INPUTS)

    @functools.cached_property
    def normal_equations(self) -> ca.Function:
        motion, e, J = self._linear()
        s, cost, weight, inlier = self._robust(e)
        w = self._sym.data[self.weight_row]
        Omega = ca.diag(self._sym.omega)
        # Only the upper triangle of the symmetric JᵀΩJ: fewer operations per residual and per sum.
        JtOJ = ca.mtimes([J.T, Omega, J])
        H_upper = ca.vertcat(*[JtOJ[i, j] for i, j in motion_sources.pairs(self.n_free)])
        ins, in_names = self._ins(motion)
        return fn(
            "normal_equations",
            ins,
            in_names,
            [w * weight * H_upper, w * weight * ca.mtimes([J.T, Omega, e]), cost, w * s, w * inlier],
            ["H_upper", "g", "cost", "chi2", "inliers"],
        )

    @functools.cached_property
    def cost(self) -> ca.Function:
        mo, h, e_h = self._window(0)
        (e,) = self._at_zero(mo, h, [e_h])
        ins, in_names = self._ins(mo.data)
        return fn("cost", ins, in_names, [self._robust(e)[1]], ["cost"])

    @functools.cached_property
    def cost_derivatives(self) -> ca.Function:
        mo, h, e_h = self._window(2)
        cost_h = self._robust(e_h)[1]
        hess, grad = ca.hessian(cost_h, h)
        upper = ca.vertcat(*[hess[i, j] for i, j in motion_sources.pairs(self.n_free)])
        cost, grad, upper = self._at_zero(mo, h, [cost_h, grad, upper])
        ins, in_names = self._ins(mo.data)
        return fn("cost_derivatives", ins, in_names, [cost, grad, upper], ["cost", "grad", "hess_upper"])

    @functools.cached_property
    def robust_terms(self) -> ca.Function:
        motion, e, J = self._linear()
        s, _, weight, _ = self._robust(e)
        ins, in_names = self._ins(motion)
        return fn(
            "robust_terms",
            ins,
            in_names,
            [
                e,
                s,
                weight,
                self._sym.data[self.weight_row] * ca.mtimes([J.T, ca.diag(self._sym.omega), e]),
            ],
            ["e", "s", "weight", "JtOe"],
        )

    @functools.cached_property
    def sensitivities(self) -> ca.Function:
        mo, h, e_h = self._window(1)
        J_plain, de_dz, de_dend = self._at_zero(
            mo,
            h,
            [
                ca.jacobian(e_h, h),
                ca.jacobian(e_h, self._sym.data[0 : self.sensor.z_rows]),
                ca.jacobian(e_h, mo.end),
            ],
        )
        return fn(
            "sensitivities",
            [self._sym.x, self._sym.x_fixed, mo.data, self._sym.data],
            ["x", "x_fixed", "motion", "data"],
            [ca.mtimes(J_plain, self._sym.M), de_dz, de_dend],
            ["J", "de_dz", "de_dend"],
        )

    @functools.cached_property
    def interval_coordinates(self) -> np.ndarray:
        """The free coordinates the prefix poses and :attr:`interval_sensitivity` depend on (the
        kinematic ones; none without prefix poses): at two points equal in these, both are the
        same to the bit."""
        if not self.prefix:
            return np.zeros(0, dtype=np.intp)
        uses = [
            f.which_depends("x", [f.name_out(0)], 1, False) for f in (self.interval_sensitivity, self.step(0))
        ]
        return np.flatnonzero(np.any(uses, axis=0))

    @functools.cached_property
    def end_sensitivity(self) -> ca.Function:
        """:attr:`sensitivities`' ``de_dend`` alone, on the motion's values (order 0): at ``h = 0``
        the jets' derivative rows drop out of it, so it is the same arithmetic on a fifth of the
        instructions and the scan of values alone (the inputs' noise share, once per parameter)."""
        mo, h, e_h = self._window(ORDER["end_sensitivity"])
        (de_dend,) = self._at_zero(mo, h, [ca.jacobian(e_h, mo.end)])
        return fn(
            "end_sensitivity",
            [self._sym.x, self._sym.x_fixed, mo.data, self._sym.data],
            ["x", "x_fixed", "motion", "data"],
            [de_dend],
            ["de_dend"],
        )

    # --- prefix scans -----------------------------------------------------------------------------

    def step(self, order: int) -> ca.Function:
        """The prefix scan's step for motion data of ``order`` (prefix problems)."""
        if order not in self._steps:
            self._steps[order] = self._source.step(order)
        return self._steps[order]

    @functools.cached_property
    def interval_sensitivity(self) -> ca.Function:
        return self._source.interval_sensitivity()

    # --- whole problem --------------------------------------------------------------------------

    @functools.cached_property
    def tangent_map(self) -> ca.Function:
        return fn("tangent_map", [self._sym.x], ["x"], [self._sym.M], ["M"])

    @functools.cached_property
    def prior(self) -> ca.Function:
        """Gaussian priors on free parameters: r = sqrt_info · (x - mean), r = 0 where sqrt_info = 0."""
        x, n = self._sym.x, self.n_free
        mean = ca.SX.sym("mean", n)
        sqrt_info = ca.SX.sym("sqrt_info", n)
        r_prior = sqrt_info * (x - mean)
        J_prior = ca.mtimes(ca.jacobian(r_prior, x), self._sym.M)
        cost_prior = ca.dot(r_prior, r_prior)
        return fn(
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
        return fn(
            "assemble", [self._sym.x, self._sym.x_fixed], ["x", "x_fixed"], [self._sym.params], ["params"]
        )

    # --- the residual as defined, on one window's inputs -------------------------------------------

    @property
    def column_rows(self) -> int:
        """Rows of one window's column ``[u_0 … u_{H-1}, data]`` (see :meth:`ResidualData.columns`)."""
        return self.n_inputs * self.spec.horizon + self.data_rows

    @functools.cached_property
    def _reference(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        column = ca.SX.sym("data", self.column_rows)
        n_in, H = self.n_inputs, self.spec.horizon
        U = ca.reshape(column[: n_in * H], n_in, H)
        k = split_params(self.model, self.sensor, self._sym.params)[0]
        M = base_motion(self.model, k, U, self.spec.integration)
        e = self._residual(column[n_in * H :], self._sym.params, M)
        return column, e, ca.mtimes(ca.jacobian(e, self._sym.x), self._sym.M)

    @functools.cached_property
    def residual(self) -> ca.Function:
        column, e, _ = self._reference
        return fn("residual", [self._sym.x, self._sym.x_fixed, column], ["x", "x_fixed", "data"], [e], ["e"])

    @functools.cached_property
    def residual_jacobian(self) -> ca.Function:
        column, e, J = self._reference
        return fn(
            "residual_jacobian",
            [self._sym.x, self._sym.x_fixed, column],
            ["x", "x_fixed", "data"],
            [e, J],
            ["e", "J"],
        )


_BUILT: dict[tuple[int, ProblemSpec], ProblemFunctions] = {}


def build(model: KinematicModel, spec: ProblemSpec) -> ProblemFunctions:
    """The Functions of the problem described by ``model`` and ``spec`` (built once per process:
    they hold no data, and the compiled backend keeps what it compiled for them)."""
    key = (id(model), spec)  # the entry keeps the model alive, so its id stays its own
    if key not in _BUILT:
        _BUILT[key] = ProblemFunctions(model, spec)
    return _BUILT[key]


@functools.cache
def upper_indices(n: int) -> tuple[np.ndarray, np.ndarray]:
    cols, rows = zip(*[(j, i) for j in range(n) for i in range(j + 1)]) if n else ((), ())
    return np.array(rows, dtype=np.intp), np.array(cols, dtype=np.intp)


def unpack_upper(h_upper: np.ndarray, n: int) -> np.ndarray:
    """The symmetric ``n x n`` matrix whose upper triangle is stored column by column."""
    rows, cols = upper_indices(n)
    H = np.empty((n, n))
    H[rows, cols] = np.ravel(h_upper)
    H[cols, rows] = np.ravel(h_upper)
    return H


def problem_layout(model: KinematicModel, sensor: Sensor, spec: ProblemSpec) -> Layout:
    """The parameters of ``model`` measured by ``sensor`` as ``spec`` lays them out: the model's,
    the mount (one per log with ``spec.mounts`` > 1: its ``spec.shared`` parameters first, once,
    then each log's own), then a clock offset per log (``spec.lags``); the mount's parameters the
    sensor never determines held."""
    kinematic = tuple(model.kinematic_params)
    turn = (-2.0 * np.pi, 2.0 * np.pi)
    ranges = {**model.physical_ranges, **dict.fromkeys((*model.angle_params, *sensor.angles), turn)}
    mount = [
        BlockSpec(
            MOUNT,
            keys,
            sensor.units,
            per_log=own,
            ranges=ranges,
            precision=_precision(model, keys, sensor.reference),
        )
        for keys, own in (
            (spec.shared, False),
            (tuple(k for k in sensor.params if k not in spec.shared), spec.mounts > 1),
        )
        if keys
    ]
    blocks = [
        BlockSpec(MODEL, kinematic, model.units, ranges=ranges, precision=_precision(model, kinematic)),
        *mount,
    ]
    if spec.lags:
        clocks = sensor.clocks
        needed = dict.fromkeys(clocks, LAG_REFERENCE[LAG_PARAM])
        clock = BlockSpec(CLOCK, clocks, dict.fromkeys(clocks, LAG_UNIT), True, precision=needed)
        blocks.append(clock)
    kinds = {b: BLOCK_KINDS[b] for b in spec.blocks}
    blocks += [kind.spec(b) for b, kind in kinds.items()]
    own = any(kind.per_log for kind in kinds.values())
    layout = Layout.of(blocks, max(spec.lags, spec.mounts, spec.logs if own else 1), tuple(model.headline))
    held = {p.name for p in layout.parameters if p.block == MOUNT and p.key in sensor.held}
    held |= {p.name for p in layout.parameters if p.block in kinds and by_definition(p.block, p.key, p.log)}
    return layout.with_status(dict.fromkeys(held, HELD))


def _precision(
    model: KinematicModel, keys: Sequence[str], sensor: Mapping[str, Reference] | None = None
) -> dict[str, tuple[str, float]]:
    """What a calibration must resolve of each of ``keys`` (:func:`~nlp_calib.models.base.reference`)."""
    return {k: reference(model, k, sensor) for k in keys}
