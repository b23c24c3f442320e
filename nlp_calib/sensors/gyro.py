"""A gyro (an IMU's angular velocity) as the reference: the heading change the wheels predict
against the rate the gyro integrates.

The gyro's increments (:mod:`nlp_calib.logs.imu`) are its rates integrated over each of its
integration intervals, ``z = (∫ω_x, ∫ω_y, ∫ω_z, Δt)`` in the IMU's own frame (rad, and s). On a
planar base the body turns about the base's vertical alone, so a gyro tilted by ``R`` (the IMU's
roll and pitch on the base; its yaw turns nothing about the vertical) with a constant bias ``b``
(per axis) and a scale ``s`` reads ``ω = s·Rᵀ·(0, 0, θ̇) + b``. The residual is that relation over
the window, in the base's frame::

    e = R·(z_ω − b·Δt) − s·(0, 0, Δθ)          (3 rows, rad)

with ``Δθ`` the base's heading change the model predicts (its motion ``M``'s third row). Its
vertical row compares the heading changes; its two horizontal rows are what the tilt and the
horizontal biases show (the vertical rate leaking into the IMU's x and y axes): a gyro about one
axis alone would see the tilt only to second order. The scale is held at 1 unless the scenario
frees it (``sensor: {mount: gyro, scale: free}``): with a gyro alone it trades with every length
of the model.

A gyro measures no length: with it alone, what the wheels determine is their turning, so the
model's lengths are known only as ratios (each length over one of them: the model says which are
lengths); one known length (under the scenario's ``known``) or a second reference fixes the
rest. The fit's observability says so: the scale of the lengths is a direction the residuals do
not see.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.core.numeric import wrap_angle
from nlp_calib.logs import Log, LogHeader
from nlp_calib.models.base import KinematicModel
from nlp_calib.results.mount import SensorMount
from nlp_calib.sensors.base import BaseMotion, Reference, SensorDefaults, SensorStart
from nlp_calib.sensors.gyro_start import gyro_start

#: The gyro's bias on each of the IMU's axes (rad/s): one set per log (a gyro's bias changes with
#: each power cycle): in a fit of several logs each has its own, the tilt and scale shared.
BIAS_PARAMS: tuple[str, str, str] = ("gyro_bias_x", "gyro_bias_y", "gyro_bias_z")
#: The IMU's tilt on the base (URDF: R = Rz(yaw)·Ry(pitch)·Rx(roll); the yaw is not seen).
TILT_PARAMS: tuple[str, str] = ("imu_roll", "imu_pitch")
#: The gyro's scale factor (its reading per true rate), a parameter only when the scenario frees it.
SCALE_PARAM = "gyro_scale"
UNITS: Mapping[str, str] = MappingProxyType(
    {**dict.fromkeys(BIAS_PARAMS, "rad/s"), **dict.fromkeys(TILT_PARAMS, "rad"), SCALE_PARAM: "ratio"}
)
#: What a useful calibration must resolve: 0.005 °/s of bias (0.3 ° of heading a minute), 5 mrad
#: of tilt, 0.5 % of scale.
REFERENCE: Mapping[str, Reference] = MappingProxyType(
    {
        **dict.fromkeys(BIAS_PARAMS, ("absolute", 1e-4)),
        **dict.fromkeys(TILT_PARAMS, ("absolute", 0.005)),
        SCALE_PARAM: ("relative", 0.005),
    }
)


def tilt_rotation(roll: ca.SX, pitch: ca.SX) -> ca.SX:
    """``Ry(pitch)·Rx(roll)``: the IMU's frame turned onto the base's (its yaw turns nothing
    about the vertical)."""
    cr, sr, cp, sp = ca.cos(roll), ca.sin(roll), ca.cos(pitch), ca.sin(pitch)
    Rx = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, cr, -sr), ca.horzcat(0, sr, cr))
    Ry = ca.vertcat(ca.horzcat(cp, 0, sp), ca.horzcat(0, 1, 0), ca.horzcat(-sp, 0, cp))
    return ca.mtimes(Ry, Rx)


class Gyro(SensorDefaults):
    """A gyro (see the module docstring); ``scale_free``: its scale factor is fitted."""

    kind: ClassVar[str] = "gyro"
    label: ClassVar[str] = "gyro"
    group: ClassVar[str] = "rate"
    #: The mount's pose components (URDF's) the gyro determines and the parameter each is.
    components: ClassVar[Mapping[str, str]] = MappingProxyType({"roll": "imu_roll", "pitch": "imu_pitch"})
    reference: ClassVar[Mapping[str, Reference]] = REFERENCE
    #: The tilt shows only while the base turns (the vertical rate leaking into x and y).
    turning: ClassVar[tuple[str, ...]] = TILT_PARAMS
    angles: ClassVar[tuple[str, ...]] = TILT_PARAMS
    #: Its "pose" at a record: the rates integrated from the first record, and the time.
    pose_rows: ClassVar[int] = 4
    z_rows: ClassVar[int] = 4
    error_rows: ClassVar[int] = 3
    noise_groups: ClassVar[tuple[tuple[int, ...], ...]] = ((0, 1, 2),)
    noise_names: ClassVar[tuple[str, ...]] = ("gyro_angle",)
    lengths_unseen: ClassVar[str] = "a gyro measures turning, no length"
    lengths_from: ClassVar[str] = (
        "fit it beside a reference that measures distance (sensor: {mount: planar, beside: gyro}, "
        "with a lidar's scan: or a motions: file in the dataset; docs/imu.md)"
    )
    per_log: ClassVar[tuple[str, ...]] = BIAS_PARAMS

    def __init__(self, scale_free: bool) -> None:
        self.scale_free = scale_free
        self.params: tuple[str, ...] = (*BIAS_PARAMS, *TILT_PARAMS, *((SCALE_PARAM,) if scale_free else ()))
        self.units: Mapping[str, str] = MappingProxyType({n: UNITS[n] for n in self.params})
        self.convention = (
            "the gyro reads s·Rᵀ·ω_base + bias (IMU frame; R = Ry(imu_pitch)·Rx(imu_roll)); its yaw and "
            "position are not seen" + ("; gyro_scale fitted" if scale_free else "; gyro_scale held at 1")
        )

    def _parts(self, mount: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
        scale = mount[5] if self.scale_free else 1.0
        return mount[0:3], tilt_rotation(mount[3], mount[4]), scale

    # --- the error term ------------------------------------------------------------------------

    def residual(self, z: ca.SX, mount: ca.SX, M: ca.SX) -> ca.SX:
        bias, R, scale = self._parts(mount)
        return ca.mtimes(R, z[0:3] - bias * z[3]) - scale * ca.vertcat(0, 0, M[2])

    def predict(self, mount: ca.SX, M: ca.SX) -> ca.SX:
        """The rates a bias-free gyro integrates over the base's motion ``M`` (no time: 0)."""
        _, R, scale = self._parts(mount)
        return ca.vertcat(scale * M[2] * R[2, :].T, 0)

    def between(self, a: ca.SX, b: ca.SX) -> ca.SX:
        return b - a

    def between_jacobians(self, a: ca.SX, b: ca.SX) -> tuple[ca.SX, ca.SX]:
        """The noise lies on the integrated rates (3 components); the time is exact."""
        noise = ca.vertcat(ca.DM.eye(3), ca.DM.zeros(1, 3))
        return -noise, noise

    def compose(self, pose: ca.SX, motion: ca.SX) -> ca.SX:
        return pose + motion

    def base_from_sensor(self, T_world_sensor: ca.SX, mount: ca.SX) -> ca.SX:
        """The base's heading from the integrated rates (no position: a gyro measures none)."""
        bias, R, scale = self._parts(mount)
        turned = ca.mtimes(R, T_world_sensor[0:3] - bias * T_world_sensor[3])[2] / scale
        return ca.vertcat(0, 0, turned)

    # --- numeric twins ---------------------------------------------------------------------------

    def heading(self, T_world_sensor: np.ndarray) -> np.ndarray:
        """The rate integrated about the IMU's z axis (rad): its heading when mounted level."""
        return np.asarray(T_world_sensor[:, 2], dtype=float)

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """The integrated rates (the time row is no motion)."""
        return np.asarray(z, dtype=float)[:3]

    def poses(self, log: Log) -> np.ndarray:
        """The rates integrated from the first record over the one-interval increments, and the time."""
        inc = log.motions
        if inc is None or inc.z.shape[1] != self.z_rows:
            raise ValueError(
                f"{log.path}: a gyro needs a log of a gyro's increments (dataset: {{bag: …, imu: TOPIC}}, "
                "docs/imu.md)"
            )
        steps = np.zeros((max(log.n_records - 1, 0), 3))
        one = inc.single()
        steps[inc.first[one]] = inc.z[one, :3]
        summed = np.vstack([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
        return np.column_stack([summed, log.time_s])

    def motion_of(self, z: np.ndarray) -> np.ndarray | None:
        """None: a gyro cannot show itself frozen. Its rates read zero on every straight drive,
        and one that republishes its last rate repeats what a steady turn repeats too; what the
        wheels say of the turn is the calibration's to find, not a screen's to assume."""
        return None

    def jump_signal(self, log: Log) -> tuple[np.ndarray, int]:
        return self.poses(log)[:, :3], 0

    # --- the start -----------------------------------------------------------------------------

    def initial(self, header: LogHeader) -> dict[str, float]:
        return self.neutral()

    def neutral(self) -> dict[str, float]:
        """No bias, a level IMU, a true scale."""
        return {**dict.fromkeys(self.params, 0.0), **({SCALE_PARAM: 1.0} if self.scale_free else {})}

    def closed_form(
        self,
        model: KinematicModel,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: BaseMotion,
        known: Mapping[str, float],
    ) -> SensorStart:
        """The tilt and biases by linear least squares, the wheels' turning by damped Gauss-Newton
        steps on the heading (:func:`~nlp_calib.sensors.gyro_start.gyro_start`)."""
        params = gyro_start(model, z, base_motion, known)
        if self.scale_free:
            params[SCALE_PARAM] = float(known.get(SCALE_PARAM, 1.0))
        return SensorStart(params)

    # --- the write-back ------------------------------------------------------------------------

    def canonical(
        self, model: KinematicModel, params: Mapping[str, float], fixed: Sequence[str]
    ) -> dict[str, float]:
        """The tilt with its pitch within ±90° (roll + π, π − pitch is the same axis), wrapped."""
        out = dict(params)
        roll, pitch = out.get("imu_roll", 0.0), out.get("imu_pitch", 0.0)
        if abs(wrap_angle(pitch)) > np.pi / 2 and not set(TILT_PARAMS) & set(fixed):
            roll, pitch = roll + np.pi, np.pi - pitch
        out.update({n: float(wrap_angle(v)) for n, v in zip(TILT_PARAMS, (roll, pitch)) if n not in fixed})
        return out

    def mount_pose(
        self,
        params: Mapping[str, float],
        std: Mapping[str, float],
        frame: str,
        nominal: tuple[float, float, float] | None,
    ) -> SensorMount:
        """Roll and pitch calibrated; the position and yaw, which a gyro cannot see, 0 (the height
        the nominal mount's where a source knows it)."""
        height = nominal[0] if nominal else 0.0
        pose = {"x": 0.0, "y": 0.0, "z": height, "yaw": 0.0}
        pose.update({"roll": float(params["imu_roll"]), "pitch": float(params["imu_pitch"])})
        unseen = "not seen by a gyro on a planar base (0; give it in your URDF)"
        return SensorMount.on_base(
            self.kind,
            frame,
            pose,
            {"roll": std["imu_roll"], "pitch": std["imu_pitch"]},
            {c: unseen for c in ("x", "y", "z", "yaw")},
        )
