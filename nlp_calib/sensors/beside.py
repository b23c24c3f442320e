"""A gyro beside a reference that measures its own motion (a lidar's scan matches, a tracker's
planar poses, a motions file; a camera's 3-D poses, :mod:`.camera_beside`): both sensors'
residuals in one objective.

Each of the log's increments is one sensor's: the reference's motion ``(x, y, θ)`` between two of
its stamps, or the gyro's rates integrated over one of its intervals ``(∫ω, Δt)``. A window's
``z`` holds both layouts and a last row saying whose it is (0: the reference's, 1: the gyro's)::

    z = (z_reference (3; a camera's 7), z_gyro (4), gyro?)

and its residual has both sensors' rows, the other sensor's zero::

    e = ((1 − g)·e_reference (3 rows; a camera's 6), g·e_gyro (3 rows))

so each is weighted by its own noise (Ω's diagonal: the reference's translation and rotation,
then the gyro's angle, ``information: {gyro: …}``). The mount is both mounts in one block: the
reference's pose (``sensor_x, sensor_y, sensor_theta``) and the gyro's bias, tilt and scale.
The reference measures lengths, so the wheels' scale a gyro alone cannot see is determined; the
gyro adds its turning. The base's poses, figures and hand-off pose are the reference's; the
gyro's tilt is stated beside them (:meth:`Beside.mount_pose`, :meth:`Beside.gyro_pose`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.logs import Log, LogHeader
from nlp_calib.models.base import KinematicModel
from nlp_calib.models.clock import LAG_PARAM, LAG_REFERENCE
from nlp_calib.results.mount import SensorMount
from nlp_calib.sensors.base import BaseMotion, Sensor, SensorDefaults, SensorStart
from nlp_calib.sensors.gyro import Gyro
from nlp_calib.sensors.planar import PlanarPose

#: The rows of a planar reference's increment and of a gyro's in a window's ``z``; then the gyro row.
REFERENCE_ROWS, GYRO_ROWS = 3, 4
#: The gyro's clock offset: how late its driver stamps the rates (s; the reference's: ``tracker_lag``).
GYRO_LAG = "gyro_lag"
#: The IMU's link in the hand-off files where its messages name no frame.
IMU_FRAME = "imu_link"
#: Ω's rows, by the information weight each takes (``information: {translation, rotation, gyro}``).
WEIGHTS: tuple[str, ...] = ("translation", "translation", "rotation", "gyro", "gyro", "gyro")


def is_gyro(z: np.ndarray) -> np.ndarray:
    """Which windows of ``z`` ``(rows, n)`` are the gyro's (its last row)."""
    return np.asarray(z[-1] > 0.5)


class Beside(SensorDefaults):
    """A planar reference's own motions and a gyro's integrated rates in one problem (see the
    module docstring); ``scale_free``: the gyro's scale factor is fitted (a reference that
    measures lengths determines it)."""

    kind: ClassVar[str] = "planar_gyro"
    label: ClassVar[str] = "planar motions beside a gyro"
    group: ClassVar[str] = "SE(2)"
    pose_rows: ClassVar[int] = 3
    z_rows: ClassVar[int] = REFERENCE_ROWS + GYRO_ROWS + 1
    error_rows: ClassVar[int] = 6
    noise_groups: ClassVar[tuple[tuple[int, ...], ...]] = ((0, 1), (2,), (3, 4, 5))
    noise_names: ClassVar[tuple[str, ...]] = ("tracker_xy", "tracker_theta", "gyro_angle")
    weights: ClassVar[tuple[str, ...]] = WEIGHTS
    clocks: ClassVar[tuple[str, ...]] = (LAG_PARAM, GYRO_LAG)
    per_log: ClassVar[tuple[str, ...]] = Gyro.per_log
    turning: ClassVar[tuple[str, ...]] = (*PlanarPose.turning, *Gyro.turning)
    angles: ClassVar[tuple[str, ...]] = (*PlanarPose.angles, *Gyro.angles)

    def __init__(self, scale_free: bool) -> None:
        self.reference_sensor: Sensor = self._reference()
        self.gyro = Gyro(scale_free)
        ref, gyro = self.reference_sensor, self.gyro
        self.params: tuple[str, ...] = (*ref.params, *gyro.params)
        self.units: Mapping[str, str] = MappingProxyType({**ref.units, **gyro.units})
        self.components: Mapping[str, str] = MappingProxyType(dict(ref.components))
        # Each clock's offset is read to 2 ms as the reference's is: a relative precision made a
        # gyro_lag estimated near 0 "not determined" (1 % of −0.17 ms: 1.7 µs).
        clocks = dict.fromkeys(self.clocks, LAG_REFERENCE[LAG_PARAM])
        self.reference = MappingProxyType({**ref.reference, **gyro.reference, **clocks})
        self.convention = f"{ref.label}: its pose on the base; {gyro.convention}"

    @staticmethod
    def _reference() -> Sensor:
        """The reference the gyro is beside."""
        return PlanarPose()

    @property
    def _rows(self) -> int:
        return int(self.reference_sensor.z_rows)

    @property
    def beside_row(self) -> int:  # type: ignore[override]  # the layout's, from its reference
        """The row of ``z`` that is 1 on a gyro's window (on the gyro's clock)."""
        return self._rows + GYRO_ROWS

    @property
    def roles(self) -> str:  # type: ignore[override]  # a class's words computed from its two sensors
        """What each sensor determines, as the pre-flight says it."""
        ref, gyro = self.reference_sensor, self.gyro
        mount = ", ".join(p for p in ref.params if p not in ref.held)
        held = f"; {', '.join(ref.held)} is held: {ref.held_why}" if ref.held else ""
        return (
            f"the {ref.label} determines the wheels' lengths, its mount ({mount}) and its clock offset "
            f"({LAG_PARAM}); the gyro beside it its biases and tilt ({', '.join(gyro.params)}) and its "
            f"clock offset ({GYRO_LAG}), and with the {ref.label} the wheels' turning{held}"
        )

    @property
    def increment_noise_rows(self) -> tuple[int, ...]:
        """The reference's noise on its rows, the gyro's on its integrated rates (after a camera's
        seven rows, not its six components: the gyro's third would fall on its time row)."""
        k = sum(len(g) for g in self.reference_sensor.noise_groups)
        return (*range(k), *range(self._rows, self._rows + 3))

    def _mounts(self, mount: ca.SX) -> tuple[ca.SX, ca.SX]:
        n = len(self.reference_sensor.params)
        return mount[:n], mount[n:]

    # --- the error term ------------------------------------------------------------------------

    def residual(self, z: ca.SX, mount: ca.SX, M: ca.SX) -> ca.SX:
        ref, gyro = self._mounts(mount)
        n = self._rows
        g = z[n + GYRO_ROWS]
        e_ref = self.reference_sensor.residual(z[:n], ref, M)
        e_gyro = self.gyro.residual(z[n : n + GYRO_ROWS], gyro, M)
        return ca.vertcat((1 - g) * e_ref, g * e_gyro)

    def clock_weights(self, z: ca.SX) -> ca.SX:
        """A reference's window is on its clock (``tracker_lag``), a gyro's on the gyro's (``gyro_lag``)."""
        g = z[self.beside_row]
        return ca.vertcat(1 - g, g)

    def predict(self, mount: ca.SX, M: ca.SX) -> ca.SX:
        """Both sensors' motions in the layout of ``z`` (the poses, figures and odometry are the
        reference's: its rows)."""
        ref, gyro = self._mounts(mount)
        return ca.vertcat(self.reference_sensor.predict(ref, M), self.gyro.predict(gyro, M), 0)

    def between(self, a: ca.SX, b: ca.SX) -> ca.SX:
        """The reference's motion from pose ``a`` to ``b``, in the layout of ``z``."""
        return ca.vertcat(self.reference_sensor.between(a, b), ca.DM.zeros(GYRO_ROWS + 1, 1))

    def between_jacobians(self, a: ca.SX, b: ca.SX) -> tuple[ca.SX, ca.SX]:
        """The reference's, in the layout of ``z`` over both sensors' noise (the reference's pose
        noise, then the gyro's integrated angle: none at a pose)."""
        da, db = self.reference_sensor.between_jacobians(a, b)

        def padded(d: ca.SX) -> ca.SX:
            return ca.diagcat(d, ca.DM.zeros(GYRO_ROWS + 1, 3))

        return padded(da), padded(db)

    def compose(self, pose: ca.SX, motion: ca.SX) -> ca.SX:
        return self.reference_sensor.compose(pose, motion[: self._rows])

    def base_from_sensor(self, T_world_sensor: ca.SX, mount: ca.SX) -> ca.SX:
        return self.reference_sensor.base_from_sensor(T_world_sensor, self._mounts(mount)[0])

    def manifold(self, free: Sequence[str]) -> bool:
        return self.reference_sensor.manifold(free)

    def boxplus(self, free: Sequence[str], x: ca.SX, step: ca.SX, x_plus: ca.SX) -> None:
        self.reference_sensor.boxplus(free, x, step, x_plus)

    # --- numeric twins ---------------------------------------------------------------------------

    def heading(self, T_world_sensor: np.ndarray) -> np.ndarray:
        return self.reference_sensor.heading(T_world_sensor)

    def floor_track(self, log: Log) -> np.ndarray:
        """The reference's positions and heading (was the gyro's heading alone: a drive of 0 m)."""
        return self.reference_sensor.floor_track(log)

    def planar_mount(self, params: Mapping[str, float]) -> tuple[float, float, float] | None:
        return self.reference_sensor.planar_mount(params)

    def implausible(self, params: Mapping[str, float], given: Mapping[str, float] | None) -> str:
        return self.reference_sensor.implausible(params, given)

    def heights(self, log: Log) -> np.ndarray | None:
        return self.reference_sensor.heights(log)

    def level(self, params: Mapping[str, float], first_pose: np.ndarray) -> np.ndarray | None:
        return self.reference_sensor.level(params, first_pose)

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """Each window's measured motion in the residual's rows (the other sensor's rows zero)."""
        z = np.asarray(z, dtype=float)
        g, n, e = is_gyro(z), self._rows, self.reference_sensor.error_rows
        out = np.zeros((self.error_rows, z.shape[1]))
        out[:e, ~g] = self.reference_sensor.tangent(z[:n, ~g])
        out[e:, g] = z[n : n + 3, g]
        return out

    def screened(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reference's increments, judged against its predicted motion (the gyro's are not)."""
        return ~is_gyro(np.asarray(z).T), np.asarray(z)[:, : self._rows]

    def motion_of(self, z: np.ndarray) -> np.ndarray | None:
        """The reference's increments' motions (its own sensor's word); the gyro's are NaN."""
        z = np.asarray(z, dtype=float)
        motion = self.reference_sensor.motion_of(z[:, : self._rows])
        if motion is None:
            return None
        return np.where(is_gyro(z.T)[:, None], np.nan, motion)

    def poses(self, log: Log) -> np.ndarray:
        """The reference's poses composed from its one-interval increments (the log's own)."""
        return log.T_world_sensor

    def jump_signal(self, log: Log) -> tuple[np.ndarray, int]:
        """The reference's poses as its signal, then the gyro's rates integrated to each record."""
        signal, positions = self.reference_sensor.jump_signal(log)
        turned = np.zeros((log.n_records, 3))
        inc = log.motions
        if inc is not None and inc.n:
            g = is_gyro(inc.z.T)
            np.add.at(turned, inc.last[g], inc.z[g, self._rows : self._rows + 3])
        return np.column_stack([signal, np.cumsum(turned, axis=0)]), positions

    # --- the start -----------------------------------------------------------------------------

    def initial(self, header: LogHeader) -> dict[str, float]:
        return {**self.reference_sensor.initial(header), **self.gyro.initial(header)}

    def nominal(self, header: LogHeader) -> dict[str, float]:
        return self.reference_sensor.nominal(header)

    def closed_form(
        self,
        model: KinematicModel,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: BaseMotion,
        known: Mapping[str, float],
    ) -> SensorStart:
        """The reference's closed form on its windows (the wheels and its mount), then the gyro's
        tilt and biases on the gyro's windows with those wheels."""
        g, n = is_gyro(z), self._rows

        def on(keep: np.ndarray) -> BaseMotion:
            return lambda params: np.asarray(base_motion(params))[:, keep]

        ref = self.reference_sensor.closed_form(model, U[:, ~g], z[:n, ~g], on(~g), known)
        if not g.any():
            # The start's windows the reference's alone (a camera's second of driving, its
            # ``start_span_s``): the gyro starts unbiased and level, the fit finds it.
            return SensorStart({**self.gyro.neutral(), **ref.params}, ref.selection, ref.dropped, ref.note)
        wheels = {k: ref.params[k] for k in model.kinematic_params}
        z_gyro = z[n : n + GYRO_ROWS, g]
        gyro = self.gyro.closed_form(model, U[:, g], z_gyro, on(g), {**wheels, **known})
        own = {k: v for k, v in gyro.params.items() if k in self.gyro.params}
        return SensorStart({**ref.params, **own}, ref.selection, ref.dropped, ref.note)

    def fit_windows(
        self, start: SensorStart, z: np.ndarray, base_turn: np.ndarray
    ) -> tuple[np.ndarray, dict[str, int]]:
        """The reference's selection on its windows; every gyro window fitted."""
        g = is_gyro(z)
        keep = np.ones(z.shape[1], dtype=bool)
        kept, counts = self.reference_sensor.fit_windows(
            start, z[: self._rows, ~g], np.asarray(base_turn)[~g]
        )
        keep[~g] = kept
        return keep, counts

    # --- the write-back ------------------------------------------------------------------------

    def canonical(
        self, model: KinematicModel, params: Mapping[str, float], fixed: Sequence[str]
    ) -> dict[str, float]:
        out = self.reference_sensor.canonical(model, params, fixed)
        return self.gyro.canonical(model, out, fixed)

    def mount_pose(
        self,
        params: Mapping[str, float],
        std: Mapping[str, float],
        frame: str,
        nominal: tuple[float, float, float] | None,
    ) -> SensorMount:
        """The reference's joint (x, y and yaw calibrated)."""
        return self.reference_sensor.mount_pose(params, std, frame, nominal)

    def beside_mount(
        self, params: Mapping[str, float], std: Mapping[str, float], header: LogHeader
    ) -> SensorMount | None:
        """The IMU's joint (roll and pitch calibrated) on its messages' frame (``imu_link`` where
        they name none), its height the nominal mount's where the source knows it."""
        gyro = header.beside
        if gyro is None:
            return self.gyro.mount_pose(params, std, IMU_FRAME, None)
        return self.gyro.mount_pose(params, std, gyro.sensor_frame, gyro.sensor_z_roll_pitch)
