"""Full-parameter Functions of a problem: one interval's motion, dead reckoning, odometry with
covariance, a window's motion, and SE(2) ``between`` with its Jacobians.

They take the full parameter vector (free and fixed, in model order) rather than the free one,
because trajectories, metrics, reports and the closed-form start evaluate a given calibration; a
problem with a mount per log takes one log's view of it (its own mount among the shared ones).
Poses and motions are in the sensor's layout (:mod:`nlp_calib.sensors`): ``(x, y, theta)``
for a planar sensor, ``(x, y, z, qx, qy, qz, qw)`` in the trajectory's own units for a 3-D one.
"""

from __future__ import annotations

import functools

import casadi as ca

from nlp_calib.models.base import KinematicModel
from nlp_calib.sensors import Sensor
from nlp_calib.symbolic import se2

_CSE = {"cse": True}


def fn(
    name: str, ins: list[ca.SX], in_names: list[str], outs: list[ca.SX], out_names: list[str]
) -> ca.Function:
    # Dense outputs: buffers bind numpy memory to stored non-zeros only. Common subexpression
    # elimination merges repeated sin/cos of the same angle (e.g. cos θ and cos(−θ)).
    return ca.Function(name, ins, [ca.densify(o) for o in outs], in_names, out_names, _CSE)


def split_params(model: KinematicModel, sensor: Sensor, params: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Kinematic parameters, the sensor's mount (``T_base_sensor``, then the scale when free) and
    the time offsets (one per log, when the problem has them) of a full parameter vector."""
    nk, ns = len(model.kinematic_params), len(sensor.params)
    return params[:nk], params[nk : nk + ns], params[nk + ns :]


def base_motion(model: KinematicModel, k: ca.SX, U: ca.SX, integration: str) -> ca.SX:
    """Base motion over consecutive intervals ``Δr_0 ⋯ Δr_{H-1}`` (``U``: one interval's inputs
    per column). Conjugating it once by the mount equals composing the conjugated per-interval
    motions, at a fraction of the cost."""
    motion_base = model.increment(k, U[:, 0], integration)
    for j in range(1, U.shape[1]):
        motion_base = se2.compose(motion_base, model.increment(k, U[:, j], integration))
    return motion_base


def predict_motion(model: KinematicModel, sensor: Sensor, params: ca.SX, U: ca.SX, integration: str) -> ca.SX:
    """Sensor motion over consecutive intervals: ``T⁻¹ · Δr_0 ⋯ Δr_{H-1} · T``."""
    k, mount, _ = split_params(model, sensor, params)
    return sensor.predict(mount, base_motion(model, k, U, integration))


class TrajectoryFunctions:
    """Full-parameter Functions, built on first use; the host provides the layout attributes.

    ``predict`` (params, u) → sensor motion over one interval; ``interval_residual`` (params, u,
    z) → (e, ∂e/∂u) of one interval; ``integrate_step``
    (T_world_sensor, params, u) → T_world_sensor · predict; ``predict_window`` (params, U) with
    ``U`` one window's inputs, interval after interval; ``base_from_sensor`` (T_world_sensor,
    params) → T_world_base; ``odometry_step`` (state = [T_world_base, vec P], params, u,
    input_std) → the base pose and its covariance propagated over one interval; ``between``
    (a, b) → t2v(a⁻¹b) and ``between_jacobians``.
    """

    model: KinematicModel
    names: tuple[str, ...]
    #: The parameters these Functions take: one log's (its mount among them; see
    #: :meth:`ProblemFunctions.view`).
    view_names: tuple[str, ...]

    @property
    def integration(self) -> str:
        """How an interval's motion is integrated (see :data:`~nlp_calib.models.base.INTEGRATIONS`)."""
        raise NotImplementedError

    @property
    def horizon(self) -> int:
        """Intervals per window."""
        raise NotImplementedError

    @property
    def sensor(self) -> Sensor:
        """The host's sensor (see :mod:`~nlp_calib.sensors`)."""
        raise NotImplementedError

    @property
    def n_inputs(self) -> int:
        return len(self.model.input_names)

    @functools.cached_property
    def _full(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        """Full-parameter symbols: params, one interval's inputs and the sensor motion over it."""
        params = ca.SX.sym("params", len(self.view_names))
        u1 = ca.SX.sym("u", self.n_inputs)
        h1 = predict_motion(
            self.model, self.sensor, params, ca.reshape(u1, self.n_inputs, 1), self.integration
        )
        return params, u1, h1

    @functools.cached_property
    def interval_residual(self) -> ca.Function:
        """(params, u, z) → (e, de_du): one interval's residual against the tracker's motion ``z``
        and its derivative with respect to the interval's inputs (for checking encoder readings)."""
        params, u1, _ = self._full
        z = ca.SX.sym("z", self.sensor.z_rows)
        k, mount, _ = split_params(self.model, self.sensor, params)
        M1 = base_motion(self.model, k, ca.reshape(u1, self.n_inputs, 1), self.integration)
        e1 = self.sensor.residual(z, mount, M1)
        return fn(
            "interval_residual",
            [params, u1, z],
            ["params", "u", "z"],
            [e1, ca.jacobian(e1, u1)],
            ["e", "de_du"],
        )

    @functools.cached_property
    def predict(self) -> ca.Function:
        params, u1, h1 = self._full
        return fn("predict", [params, u1], ["params", "u"], [h1], ["motion"])

    @functools.cached_property
    def integrate_step(self) -> ca.Function:
        params, u1, h1 = self._full
        T_ws = ca.SX.sym("T_world_sensor", self.sensor.pose_rows)
        return fn(
            "integrate_step",
            [T_ws, params, u1],
            ["T_world_sensor", "params", "u"],
            [self.sensor.compose(T_ws, h1)],
            ["T_world_sensor_next"],
        )

    @functools.cached_property
    def carried(self) -> ca.Function:
        """(T_world_sensor, params, M) → the sensor's pose after the base moves by the planar motion
        ``M`` ``(x, y, θ)`` from where the sensor is at ``T_world_sensor``: ``T_world_sensor·T⁻¹MT``
        (a manoeuvre's tracker poses from its base path)."""
        params = self._full[0]
        T_ws = ca.SX.sym("T_world_sensor", self.sensor.pose_rows)
        M = ca.SX.sym("M", 3)
        mount = split_params(self.model, self.sensor, params)[1]
        return fn(
            "carried",
            [T_ws, params, M],
            ["T_world_sensor", "params", "M"],
            [self.sensor.compose(T_ws, self.sensor.predict(mount, M))],
            ["T_world_sensor_next"],
        )

    @functools.cached_property
    def base_from_sensor(self) -> ca.Function:
        params = self._full[0]
        T_ws = ca.SX.sym("T_world_sensor", self.sensor.pose_rows)
        T_base_sensor = split_params(self.model, self.sensor, params)[1]
        return fn(
            "base_from_sensor",
            [T_ws, params],
            ["T_world_sensor", "params"],
            [self.sensor.base_from_sensor(T_ws, T_base_sensor)],
            ["T_world_base"],
        )

    @functools.cached_property
    def odometry_step(self) -> ca.Function:
        """P' = F·P·Fᵀ + G·diag(σ_u²)·Gᵀ with F = ∂T'/∂T and G = ∂T'/∂u."""
        params, u1, _ = self._full
        state = ca.SX.sym("state", 12)
        T_wb, P = state[:3], ca.reshape(state[3:], 3, 3)
        input_std = ca.SX.sym("input_std", self.n_inputs)
        k_sym = split_params(self.model, self.sensor, params)[0]
        T_wb_next = se2.compose(T_wb, self.model.increment(k_sym, u1, self.integration))
        F, G = ca.jacobian(T_wb_next, T_wb), ca.jacobian(T_wb_next, u1)
        P_next = ca.mtimes([F, P, F.T]) + ca.mtimes([G, ca.diag(input_std**2), G.T])
        return fn(
            "odometry_step",
            [state, params, u1, input_std],
            ["state", "params", "u", "input_std"],
            [ca.vertcat(T_wb_next, ca.reshape(P_next, 9, 1))],
            ["state_next"],
        )

    @functools.cached_property
    def predict_window(self) -> ca.Function:
        params = self._full[0]
        U = ca.SX.sym("U", self.n_inputs * self.horizon)
        return fn(
            "predict_window",
            [params, U],
            ["params", "U"],
            [
                predict_motion(
                    self.model,
                    self.sensor,
                    params,
                    ca.reshape(U, self.n_inputs, self.horizon),
                    self.integration,
                )
            ],
            ["motion"],
        )

    @functools.cached_property
    def _pose_pair(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        a, b = ca.SX.sym("a", self.sensor.pose_rows), ca.SX.sym("b", self.sensor.pose_rows)
        return a, b, self.sensor.between(a, b)

    @functools.cached_property
    def between(self) -> ca.Function:
        a, b, motion = self._pose_pair
        return fn("between", [a, b], ["a", "b"], [motion], ["motion"])

    @functools.cached_property
    def between_jacobians(self) -> ca.Function:
        a, b, _ = self._pose_pair
        return fn(
            "between_jacobians",
            [a, b],
            ["a", "b"],
            list(self.sensor.between_jacobians(a, b)),
            ["dmotion_da", "dmotion_db"],
        )
