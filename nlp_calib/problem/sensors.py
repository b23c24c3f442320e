"""What a sensor measures and how its mount enters the residual: a planar pose or a 3-D one.

The problem is written once over a window's planar base motion ``M`` (see
:mod:`nlp_calib.problem.motion`); the sensor decides the rest: the parameters that close the
vector (its mount), the measured motion ``z`` and the residual ``e`` comparing it with the
prediction ``T⁻¹·M·T``, the tracker's pose layout and the perturbation its noise is modelled in,
and the box-plus of the mount.

- ``planar``: poses ``(x, y, theta)``; ``z = t2v(T(p_a)⁻¹T(p_b))``, ``e = t2v(Z⁻¹·T⁻¹MT)``
  (3 rows); the mount ``(sensor_x, sensor_y, sensor_theta)`` perturbed on SE(2) when all free.
- ``3d``: poses ``(x, y, z, qx, qy, qz, qw)``; ``z`` the relative pose ``p_a⁻¹·p_b`` (7 rows),
  ``e = Log((s·Z)⁻¹·X⁻¹·lift(M)·X)`` (6 rows, translation first) with ``X`` the mount
  ``(sensor_x, sensor_y, sensor_z, sensor_roll, sensor_pitch, sensor_yaw)`` and ``s·Z`` the
  measured motion with its translation times ``scale`` (1 unless the scale is free).
  ``sensor_z`` is always held. Box-plus: translation and scale Euclidean; the rotation on SO(3)
  from the left, ``R ⊞ δ = Exp(δ)·R`` in roll-pitch-yaw, when all three angles are free. A left
  SE(3) perturbation would move the translation with every rotation step, so holding
  ``sensor_z`` would no longer hold a coordinate; Euclidean roll-pitch-yaw would lose a degree of
  freedom at pitch ±90° (a camera looking straight down), where ``Exp(δ)·R`` does not.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import casadi as ca
import numpy as np

from nlp_calib.core import poses3d
from nlp_calib.core.errors import ProblemError
from nlp_calib.models.base import SENSOR_PARAMS
from nlp_calib.models.mount import HELD_PARAMS, MOUNT_ANGLES, MOUNT_PARAMS, SCALE_PARAM
from nlp_calib.symbolic import se2, se3

SENSORS = ("planar", "3d")
SCALES = ("fixed", "free")


class PlanarSensor:
    """A planar pose sensor (laser, planar tracker): the original problem, unchanged."""

    name = "planar"
    params: tuple[str, ...] = SENSOR_PARAMS
    held: tuple[str, ...] = ()
    error_rows = 3
    z_rows = 3
    pose_rows = 3
    #: Pose noise components sharing one variance, and the variances' names.
    noise_groups: tuple[tuple[int, ...], ...] = ((0, 1), (2,))
    noise_names: tuple[str, ...] = ("tracker_xy", "tracker_theta")
    #: Mount parameters a drive without turning cannot determine (the lever arm).
    turning: tuple[str, ...] = SENSOR_PARAMS[:2]

    def residual(self, z: ca.SX, mount: ca.SX, M: ca.SX) -> ca.SX:
        return se2.between(z, se2.conjugate(mount, M))

    def predict(self, mount: ca.SX, M: ca.SX) -> ca.SX:
        """The sensor's motion ``T⁻¹·M·T`` in the tracker's layout."""
        return se2.conjugate(mount, M)

    def between(self, a: ca.SX, b: ca.SX) -> ca.SX:
        return se2.between(a, b)

    def between_jacobians(self, a: ca.SX, b: ca.SX) -> tuple[ca.SX, ca.SX]:
        """``∂z/∂a`` and ``∂z/∂b``: the pose vectors are their own noise coordinates."""
        motion = se2.between(a, b)
        return ca.jacobian(motion, a), ca.jacobian(motion, b)

    def compose(self, pose: ca.SX, motion: ca.SX) -> ca.SX:
        return se2.compose(pose, motion)

    def base_from_sensor(self, T_world_sensor: ca.SX, mount: ca.SX) -> ca.SX:
        return se2.compose(T_world_sensor, se2.inverse(mount))

    def manifold(self, free: Sequence[str]) -> bool:
        """Whether the mount is perturbed on SE(2): all three components free."""
        return all(n in free for n in self.params)

    def boxplus(self, free: Sequence[str], x: ca.SX, step: ca.SX, x_plus: ca.SX) -> None:
        """Write the mount's box-plus into ``x_plus`` (Euclidean elsewhere)."""
        if self.manifold(free):
            idx = [free.index(n) for n in self.params]
            T_new = se2.boxplus(x[idx], step[idx])
            for j, i in enumerate(idx):
                x_plus[i] = T_new[j]

    def heading(self, T_world_sensor: np.ndarray) -> np.ndarray:
        """The sensor's unwrapped heading at each pose (rad)."""
        return np.unwrap(T_world_sensor[:, 2])

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """Measured motions ``z`` ``(3, n)`` in the residual's rows: they are their own."""
        return np.asarray(z, dtype=float)


class Mount3D:
    """A 3-D pose sensor (a camera) on a planar base; ``scale_free``: poses known up to scale."""

    name = "3d"
    held: tuple[str, ...] = HELD_PARAMS
    error_rows = 6
    z_rows = 7
    pose_rows = 7
    noise_groups: tuple[tuple[int, ...], ...] = ((0, 1, 2), (3, 4, 5))
    noise_names: tuple[str, ...] = ("tracker_xyz", "tracker_rotation")
    #: The lever arm, and roll and pitch: only turning shows the floor normal.
    turning: tuple[str, ...] = ("sensor_x", "sensor_y", "sensor_roll", "sensor_pitch")

    def __init__(self, scale_free: bool) -> None:
        self.scale_free = scale_free
        self.params: tuple[str, ...] = (*MOUNT_PARAMS, *((SCALE_PARAM,) if scale_free else ()))

    def _pose_and_scale(self, mount: ca.SX) -> tuple[ca.SX, ca.SX]:
        return se3.mount(mount[0:6]), mount[6] if self.scale_free else 1.0

    def residual(self, z: ca.SX, mount: ca.SX, M: ca.SX) -> ca.SX:
        X, scale = self._pose_and_scale(mount)
        measured = ca.vertcat(scale * z[0:3], z[3:7])
        return se3.log(se3.between(measured, se3.conjugate(X, se3.lift(M))))

    def predict(self, mount: ca.SX, M: ca.SX) -> ca.SX:
        """The camera's motion in the trajectory's own units (translation divided by the scale)."""
        X, scale = self._pose_and_scale(mount)
        h = se3.conjugate(X, se3.lift(M))
        return ca.vertcat(h[0:3] / scale, h[3:7])

    def between(self, a: ca.SX, b: ca.SX) -> ca.SX:
        return se3.between(a, b)

    def between_jacobians(self, a: ca.SX, b: ca.SX) -> tuple[ca.SX, ca.SX]:
        """``∂z/∂n`` for each pose moved by its noise ``n`` (see :func:`~nlp_calib.symbolic.se3.retract`)."""
        na, nb = ca.SX.sym("na", 6), ca.SX.sym("nb", 6)
        motion = se3.between(se3.retract(a, na), se3.retract(b, nb))
        zero = [ca.DM.zeros(6), ca.DM.zeros(6)]
        da, db = ca.substitute([ca.jacobian(motion, na), ca.jacobian(motion, nb)], [na, nb], zero)
        return da, db

    def compose(self, pose: ca.SX, motion: ca.SX) -> ca.SX:
        return se3.compose(pose, motion)

    def base_from_sensor(self, T_world_sensor: ca.SX, mount: ca.SX) -> ca.SX:
        """The base's pose in the trajectory's world frame and units."""
        X, scale = self._pose_and_scale(mount)
        X_units = ca.vertcat(X[0:3] / scale, X[3:7])
        return se3.compose(T_world_sensor, se3.inverse(X_units))

    def manifold(self, free: Sequence[str]) -> bool:
        """Whether the mount's rotation is perturbed on SO(3): all three angles free."""
        return all(n in free for n in MOUNT_ANGLES)

    def boxplus(self, free: Sequence[str], x: ca.SX, step: ca.SX, x_plus: ca.SX) -> None:
        if self.manifold(free):
            idx = [free.index(n) for n in MOUNT_ANGLES]
            rpy = se3.rpy_boxplus(x[idx], step[idx])
            for j, i in enumerate(idx):
                x_plus[i] = rpy[j]

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """Measured motions ``z`` ``(7, n)`` in the residual's rows: translation, then rotation vector."""
        return np.vstack([z[:3], poses3d.quat_to_rotvec(np.asarray(z[3:7]).T).T])

    def heading(self, T_world_sensor: np.ndarray) -> np.ndarray:
        """The camera's unwrapped rotation about the floor normal (the principal axis of its
        rotations relative to the first pose) at each pose (rad)."""
        q0 = T_world_sensor[0, 3:7]
        phi = poses3d.quat_to_rotvec(
            poses3d.quat_multiply(poses3d.quat_conjugate(q0), T_world_sensor[:, 3:7])
        )
        _, vecs = np.linalg.eigh(phi.T @ phi)
        return np.unwrap(phi @ vecs[:, -1])


Sensor = PlanarSensor | Mount3D


@functools.cache
def sensor_for(kind: str, scale: str) -> Sensor:
    """The sensor of a problem: ``kind`` one of :data:`SENSORS`, ``scale`` one of :data:`SCALES`."""
    if kind not in SENSORS:
        raise ProblemError(f"sensor must be one of {', '.join(SENSORS)}, got {kind!r}")
    if scale not in SCALES:
        raise ProblemError(f"scale must be one of {', '.join(SCALES)}, got {scale!r}")
    if kind == "planar":
        if scale == "free":
            raise ProblemError(
                "a free scale needs a 3-D sensor (sensor: 3d); planar tracker poses are metric"
            )
        return PlanarSensor()
    return Mount3D(scale == "free")
