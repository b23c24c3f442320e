"""A planar pose sensor (a laser, a tracker's planar pose): the original problem, unchanged.

Poses ``(x, y, theta)``; a window's measured motion ``z = t2v(T(p_a)⁻¹T(p_b))`` and the residual
``e = t2v(Z⁻¹·T⁻¹MT)`` (3 rows); the mount ``T_base_sensor = (sensor_x, sensor_y, sensor_theta)``,
perturbed on SE(2) from the left when all of it is free. Its start is the model's own planar
closed form (the wheels and the mount by hand-eye); its height, roll and pitch are the nominal
mount's where a source knows them (a bag's ``/tf_static``), else 0.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.logs import Log, LogHeader
from nlp_calib.models.base import SENSOR_PARAMS, SENSOR_REFERENCE, SENSOR_UNITS, KinematicModel, canonical
from nlp_calib.results.mount import SensorMount
from nlp_calib.sensors.base import BaseMotion, Reference, SensorDefaults, SensorStart
from nlp_calib.symbolic import se2


class PlanarPose(SensorDefaults):
    """A planar pose sensor (see the module docstring)."""

    kind: ClassVar[str] = "planar"
    label: ClassVar[str] = "planar pose sensor"
    group: ClassVar[str] = "SE(2)"
    params: ClassVar[tuple[str, ...]] = SENSOR_PARAMS
    #: The mount's pose components (URDF's) and the parameter each is.
    components: ClassVar[Mapping[str, str]] = MappingProxyType(
        {"x": "sensor_x", "y": "sensor_y", "yaw": "sensor_theta"}
    )
    units: ClassVar[Mapping[str, str]] = MappingProxyType(dict(SENSOR_UNITS))
    reference: ClassVar[Mapping[str, Reference]] = MappingProxyType(dict(SENSOR_REFERENCE))
    #: The lever arm: a drive without turning cannot determine it.
    turning: ClassVar[tuple[str, ...]] = SENSOR_PARAMS[:2]
    angles: ClassVar[tuple[str, ...]] = ("sensor_theta",)
    pose_rows: ClassVar[int] = 3
    z_rows: ClassVar[int] = 3
    error_rows: ClassVar[int] = 3
    #: Pose noise components sharing one variance, and the variances' names.
    noise_groups: ClassVar[tuple[tuple[int, ...], ...]] = ((0, 1), (2,))
    noise_names: ClassVar[tuple[str, ...]] = ("tracker_xy", "tracker_theta")
    planar_base: ClassVar[bool] = True

    # --- the error term ------------------------------------------------------------------------

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

    # --- numeric twins ---------------------------------------------------------------------------

    def heading(self, T_world_sensor: np.ndarray) -> np.ndarray:
        """The sensor's unwrapped heading at each pose (rad)."""
        return np.unwrap(T_world_sensor[:, 2])

    def floor_track(self, log: Log) -> np.ndarray:
        """Its poses as they are (x, y and the unwrapped heading)."""
        T = np.asarray(log.T_world_sensor, dtype=float)
        return np.column_stack([T[:, :2], np.unwrap(T[:, 2])])

    def planar_mount(self, params: Mapping[str, float]) -> tuple[float, float, float] | None:
        """The mount ``(x, y, yaw)`` in the base plane (m, m, rad) in ``params`` (0 where they hold
        none): what turns the tracker's track into the base's."""
        x, y, yaw = (float(params.get(self.components[c], 0.0)) for c in ("x", "y", "yaw"))
        return x, y, yaw

    def implausible(self, params: Mapping[str, float], given: Mapping[str, float] | None) -> str:
        """Nothing: every planar mount is one a robot can have (a mirror shows in the model's own
        parameters)."""
        return ""

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """Measured motions ``z`` ``(3, n)`` in the residual's rows: they are their own."""
        return np.asarray(z, dtype=float)

    def poses(self, log: Log) -> np.ndarray:
        return log.T_world_sensor

    def motion_of(self, z: np.ndarray) -> np.ndarray | None:
        """Each increment's travel and the size of its turn."""
        z = np.asarray(z, dtype=float)
        return np.column_stack([np.hypot(z[:, 0], z[:, 1]), np.abs(z[:, 2])])

    def jump_signal(self, log: Log) -> tuple[np.ndarray, int]:
        """The poses as a signal continuous in time, ``(x, y, θ unwrapped)``, and its position columns."""
        T = np.array(log.T_world_sensor, dtype=float)
        T[:, 2] = np.unwrap(T[:, 2])
        return T, 2

    def repaired(self, log: Log, bad: np.ndarray) -> Log:
        return log.with_poses_interpolated(bad)

    def heights(self, log: Log) -> np.ndarray | None:
        """The tracker's height where its source reports one (a bag's 3-D pose topic)."""
        return log.heights()

    # --- the start -----------------------------------------------------------------------------

    def initial(self, header: LogHeader) -> dict[str, float]:
        """The header's nominal mount."""
        return self.nominal(header)

    def nominal(self, header: LogHeader) -> dict[str, float]:
        """The mount the log's header gives (its ``T_base_sensor``)."""
        return dict(zip(self.params, header.T_base_sensor))

    def closed_form(
        self,
        model: KinematicModel,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: BaseMotion,
        known: Mapping[str, float],
    ) -> SensorStart:
        """The model's planar closed form: the wheels, and the mount by hand-eye."""
        return SensorStart(model.initial_guess(U, z[:3], base_motion))

    # --- the write-back ------------------------------------------------------------------------

    def canonical(
        self, model: KinematicModel, params: Mapping[str, float], fixed: Sequence[str]
    ) -> dict[str, float]:
        """The model's canonical form (its symmetries turn the planar mount round)."""
        return canonical(model, params, tuple(fixed))

    def mount_pose(
        self,
        params: Mapping[str, float],
        std: Mapping[str, float],
        frame: str,
        nominal: tuple[float, float, float] | None,
    ) -> SensorMount:
        """x, y and yaw calibrated; z, roll and pitch the nominal mount's (else 0)."""
        z, roll, pitch = nominal or (0.0, 0.0, 0.0)
        known = "from the nominal mount (/tf_static)" if nominal else "not known (0)"
        names = self.components
        pose = {"z": z, "roll": roll, "pitch": pitch, **{c: float(params[n]) for c, n in names.items()}}
        source = f"{known}, which planar driving cannot see"
        return SensorMount.on_base(
            self.kind,
            frame,
            pose,
            {c: std[n] for c, n in names.items()},
            dict.fromkeys(("z", "roll", "pitch"), source),
        )
