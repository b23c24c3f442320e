"""A 3-D pose sensor on a planar base: a camera (AprilTags, visual odometry or SLAM poses).

Poses ``(x, y, z, qx, qy, qz, qw)``; a window's measured motion ``z = p_a⁻¹·p_b`` (7 rows) and the
residual ``e = Log((s·Z)⁻¹·X⁻¹·lift(M)·X)`` (6 rows, translation first) with ``X`` the mount
``(sensor_x, sensor_y, sensor_z, sensor_roll, sensor_pitch, sensor_yaw)`` (:mod:`.mount`) and
``s·Z`` the measured motion with its translation times ``scale`` (1 unless the scale is free).
``sensor_z`` is always held. Box-plus: translation and scale Euclidean; the rotation on SO(3)
from the left, ``R ⊞ δ = Exp(δ)·R`` in roll-pitch-yaw, when all three angles are free. A left
SE(3) perturbation would move the translation with every rotation step, so holding ``sensor_z``
would no longer hold a coordinate; Euclidean roll-pitch-yaw would lose a degree of freedom at
pitch ±90° (a camera looking straight down), where ``Exp(δ)·R`` does not. Its start is the
closed form of :mod:`.camera_start` (the floor normal, then the planar hand-eye, with the
physical sign), which also selects the fit's windows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.core import poses3d
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.logs import Log, LogHeader, planar_track
from nlp_calib.models.base import KinematicModel
from nlp_calib.results.mount import COMPONENTS, SensorMount
from nlp_calib.sensors.base import BaseMotion, Reference, SensorDefaults, SensorStart
from nlp_calib.sensors.camera_start import FIT_REASONS, CameraStart, camera_start, fit_selection
from nlp_calib.sensors.mount import (
    HELD_PARAMS,
    MOUNT_ANGLES,
    MOUNT_PARAMS,
    MOUNT_REFERENCE,
    MOUNT_UNITS,
    SCALE_PARAM,
    mirrored_mount,
    mount_rotation,
)
from nlp_calib.symbolic import se3

#: Why the height is held, in the result's words.
HELD_WHY = "planar driving cannot determine a 3-D sensor's height (give the measured one as known.sensor_z)"


#: A rotation (the sine of half its angle) no camera reads: the rounding of a quaternion's product
#: with its own inverse, a few times 1e-18, is below it by six orders, any real camera's noise
#: (1e-4 and more) above it by eight.
ROUNDING = 1e-12


class CameraPose(SensorDefaults):
    """A 3-D pose sensor (see the module docstring); ``scale_free``: poses known up to scale."""

    kind: ClassVar[str] = "3d"
    label: ClassVar[str] = "3-D sensor"
    group: ClassVar[str] = "SE(3)"
    held: ClassVar[tuple[str, ...]] = HELD_PARAMS
    #: The mount's pose components (URDF's) and the parameter each is.
    components: ClassVar[Mapping[str, str]] = MappingProxyType(dict(zip(COMPONENTS, MOUNT_PARAMS)))
    angles: ClassVar[tuple[str, ...]] = MOUNT_ANGLES
    error_rows: ClassVar[int] = 6
    z_rows: ClassVar[int] = 7
    pose_rows: ClassVar[int] = 7
    noise_groups: ClassVar[tuple[tuple[int, ...], ...]] = ((0, 1, 2), (3, 4, 5))
    noise_names: ClassVar[tuple[str, ...]] = ("tracker_xyz", "tracker_rotation")
    #: The lever arm, and roll and pitch: only turning shows the floor normal.
    turning: ClassVar[tuple[str, ...]] = ("sensor_x", "sensor_y", "sensor_roll", "sensor_pitch")
    planar_base: ClassVar[bool] = False
    #: The start's windows: a second of driving turns far more than one image interval, so their
    #: rotation axes show the floor normal above the pose noise.
    start_span_s: ClassVar[float | None] = 1.0
    held_why: ClassVar[str] = HELD_WHY
    reference: ClassVar[Mapping[str, Reference]] = MOUNT_REFERENCE

    def __init__(self, scale_free: bool) -> None:
        self.scale_free = scale_free
        self.params: tuple[str, ...] = (*MOUNT_PARAMS, *((SCALE_PARAM,) if scale_free else ()))
        self.units: Mapping[str, str] = MappingProxyType({n: MOUNT_UNITS[n] for n in self.params})
        self.length_unit = "trajectory units" if scale_free else "m"
        self.convention = (
            "URDF: fixed axes, R = Rz(yaw)·Ry(pitch)·Rx(roll); sensor_z held: planar driving cannot see it"
            + ("; scale: metres per trajectory unit" if scale_free else "")
        )

    def _pose_and_scale(self, mount: ca.SX) -> tuple[ca.SX, ca.SX]:
        return se3.mount(mount[0:6]), mount[6] if self.scale_free else 1.0

    # --- the error term ------------------------------------------------------------------------

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

    # --- numeric twins ---------------------------------------------------------------------------

    def planar_mount(self, params: Mapping[str, float]) -> tuple[float, float, float] | None:
        """None: a camera's poses lie in its own world frame, not the base's plane."""
        return None

    def implausible(self, params: Mapping[str, float], given: Mapping[str, float] | None) -> str:
        """Why the mount is likely the mirror image a camera's motion cannot tell from the robot (its
        image upside down while no ``given`` mount says so); "" when it is not."""
        return mirrored_mount(params, given)

    def floor_track(self, log: Log) -> np.ndarray:
        """Its 3-D poses levelled onto the floor (its world frame need not be level): the position
        in the floor's plane and the unwrapped heading about its normal."""
        T = planar_track(np.asarray(self.poses(log), dtype=float))
        return np.column_stack([T[:, :2], np.unwrap(T[:, 2])])

    def heading(self, T_world_sensor: np.ndarray) -> np.ndarray:
        """The camera's unwrapped rotation about the floor normal (the principal axis of its
        rotations relative to the first pose) at each pose (rad)."""
        q0 = T_world_sensor[0, 3:7]
        phi = poses3d.quat_to_rotvec(
            poses3d.quat_multiply(poses3d.quat_conjugate(q0), T_world_sensor[:, 3:7])
        )
        _, vecs = np.linalg.eigh(phi.T @ phi)
        return np.unwrap(phi @ vecs[:, -1])

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """Measured motions ``z`` ``(7, n)`` in the residual's rows: translation, then rotation vector."""
        return np.vstack([z[:3], poses3d.quat_to_rotvec(np.asarray(z[3:7]).T).T])

    def poses(self, log: Log) -> np.ndarray:
        return log.poses_3d()

    def motion_of(self, z: np.ndarray) -> np.ndarray | None:
        """Each 3-D increment's travel and the norm of its quaternion's vector part, 0 at
        :data:`ROUNDING` or less (the motion between two equal poses rounds to ~1e-18 there)."""
        z = np.asarray(z, dtype=float)
        turn = np.linalg.norm(z[:, 3:6], axis=1)
        return np.column_stack([np.linalg.norm(z[:, :3], axis=1), np.where(turn > ROUNDING, turn, 0.0)])

    def jump_signal(self, log: Log) -> tuple[np.ndarray, int]:
        """``(x, y, z)`` and the rotation accumulated about the world's axes
        (:func:`~nlp_calib.core.poses3d.turned`): a glitch in either departs from the path."""
        P = np.asarray(log.poses_3d(), dtype=float)
        return np.hstack([P[:, :3], poses3d.turned(P[:, 3:])]), 3

    def repaired(self, log: Log, bad: np.ndarray) -> Log:
        return log.with_poses_interpolated(bad)

    def heights(self, log: Log) -> np.ndarray | None:
        return log.heights()

    def level(self, params: Mapping[str, float], first_pose: np.ndarray) -> np.ndarray | None:
        """The trajectory's world turned onto the base's frame at the first pose: ``R_X·R(q_0)ᵀ``."""
        return np.asarray(mount_rotation(params) @ poses3d.quat_to_matrix(first_pose[3:7]).T)

    def trajectory_scale(self, params: Mapping[str, float]) -> float:
        """Metres per trajectory unit."""
        return float(params[SCALE_PARAM]) if self.scale_free else 1.0

    # --- the start -----------------------------------------------------------------------------

    def initial(self, header: LogHeader) -> dict[str, float]:
        """The held height at 0 and the scale at 1 unless the scenario gives them."""
        return {**dict.fromkeys(self.held, 0.0), **({SCALE_PARAM: 1.0} if self.scale_free else {})}

    def nominal(self, header: LogHeader) -> dict[str, float]:
        """None: a log's header gives a planar mount, not this one."""
        return {}

    def closed_form(
        self,
        model: KinematicModel,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: BaseMotion,
        known: Mapping[str, float],
    ) -> SensorStart:
        """The camera's closed-form start (:func:`~nlp_calib.sensors.camera_start.camera_start`)."""
        start = camera_start(model, U, z, base_motion, scale_free=self.scale_free, known=known)
        return SensorStart(start.params, start, None if start.selection is None else start.selection.counts())

    def given(self, initial: Mapping[str, float]) -> SensorStart | None:
        """A given mount as a start: its floor normal in the camera frame is the third row of its
        rotation (no windows were selected)."""
        R = mount_rotation(initial)
        return SensorStart(dict(initial), CameraStart(dict(initial), R[2], None), None)

    def fit_windows(
        self, start: SensorStart, z: np.ndarray, base_turn: np.ndarray
    ) -> tuple[np.ndarray, dict[str, int]]:
        """The fit's windows the start's floor normal and parameters keep (``FIT_REASONS``)."""
        if not isinstance(start.selection, CameraStart):
            return np.ones(z.shape[1], dtype=bool), {}
        selection = fit_selection(z, start.selection.normal, base_turn)
        counts = {r: n for r, n in selection.counts().items() if r in FIT_REASONS}
        return selection.kept(FIT_REASONS), counts

    # --- the write-back ------------------------------------------------------------------------

    def canonical(
        self, model: KinematicModel, params: Mapping[str, float], fixed: Sequence[str]
    ) -> dict[str, float]:
        """The start already has the physical signs (the model's symmetries turn a planar mount
        round): each free mount angle is only wrapped."""
        out = dict(params)
        out.update({n: float(wrap_angle(out[n])) for n in MOUNT_ANGLES if n not in fixed})
        return out

    def mount_pose(
        self,
        params: Mapping[str, float],
        std: Mapping[str, float],
        frame: str,
        nominal: tuple[float, float, float] | None,
    ) -> SensorMount:
        """All six numbers; the height as held."""
        names = self.components
        return SensorMount.on_base(
            self.kind,
            frame,
            {c: float(params[n]) for c, n in names.items()},
            {c: std[n] for c, n in names.items()},
            {"z": "held at the value given (known.sensor_z, 0 unless set), which planar driving cannot see"},
        )
