"""What a sensor plug-in provides: the reference a robot's wheels are calibrated against.

A sensor is one file and one registry line (:data:`nlp_calib.sensors.SENSORS`). It owns, like a
kalibr sensor class, everything about itself that the rest of the package would otherwise decide
by asking which sensor it is:

- its **variables**: the mount's parameters, their units, the precision a calibration needs of
  each, those the drive never determines (``held``) and those only turning shows (``turning``),
  its angles (wrapped in the canonical form);
- its **error term**: the pose layout it measures, the measured motion ``z`` of a window and the
  residual comparing it with the model's prediction (symbolic, CasADi), the mount's box-plus, the
  noise model's groups; and the numeric twins the analyses need (headings, the residual's rows
  of a motion, its poses in a log, the signal its jump screen judges);
- its **start**: the mount's starting values, its closed-form start (with the physical sign) and
  the selection of the fit's windows that start implies;
- its **write-back**: the mount in a robot's terms (:class:`~nlp_calib.results.mount.SensorMount`:
  the joint of its frame on ``base_link``, each component's value and 1σ, what was calibrated and
  where each nominal component comes from: every hand-off file's one description of it), the
  canonical form of an estimate and what it says of itself in a result (``kind``, ``group``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, Literal, Protocol

import casadi as ca
import numpy as np

from nlp_calib.logs import Log, LogHeader
from nlp_calib.models.base import KinematicModel
from nlp_calib.models.clock import LAG_PARAM
from nlp_calib.results.mount import SensorMount

#: A reference precision: a fraction of the parameter's value, or an absolute amount in its unit.
Reference = tuple[Literal["relative", "absolute"], float]
#: The model's planar base motion ``(3, M)`` over windows, for given parameters.
BaseMotion = Callable[[Mapping[str, float]], np.ndarray]


@dataclass(frozen=True)
class SensorStart:
    """A sensor's start: every parameter's starting value (kinematic, then the mount's), what the
    fit's windows are selected by (a sensor's own record, None: no selection) and the windows the
    closed form left out, by reason (None: it selected none) and what it found worth saying."""

    params: dict[str, float]
    selection: object | None = None
    dropped: Mapping[str, int] | None = None
    #: What the start found worth saying (empty: nothing), e.g. that it gave way to the nominal robot.
    note: str = ""


class Sensor(Protocol):
    """A reference on the robot (see the module docstring)."""

    @property
    def kind(self) -> str: ...  # its registry name, as a scenario's ``sensor`` gives it
    @property
    def label(self) -> str: ...  # what it is, in words
    @property
    def group(self) -> str: ...  # the pose group it measures in: "SE(2)", "SE(3)"
    @property
    def params(self) -> tuple[str, ...]: ...
    @property
    def units(self) -> Mapping[str, str]: ...
    @property
    def components(self) -> Mapping[str, str]: ...  # the mount's pose components and their parameters
    @property
    def reference(self) -> Mapping[str, Reference]: ...
    @property
    def held(self) -> tuple[str, ...]: ...
    @property
    def turning(self) -> tuple[str, ...]: ...
    @property
    def angles(self) -> tuple[str, ...]: ...
    @property
    def pose_rows(self) -> int: ...
    @property
    def z_rows(self) -> int: ...
    @property
    def error_rows(self) -> int: ...
    @property
    def noise_groups(self) -> tuple[tuple[int, ...], ...]: ...
    @property
    def noise_names(self) -> tuple[str, ...]: ...
    @property
    def increment_noise_rows(self) -> tuple[int, ...]: ...  # z's row of each noise component, increments
    @property
    def weights(self) -> tuple[str, ...]: ...  # each error row's information weight by name (): by halves
    @property
    def length_unit(self) -> str: ...  # the unit its positions are in ("m", or "trajectory units")
    @property
    def planar_base(self) -> bool: ...  # whether the base's planar odometry and drift check apply
    @property
    def held_why(self) -> str: ...  # why ``held`` are held, in words
    @property
    def convention(self) -> str: ...  # what its parameters mean, where the names do not say it
    @property
    def lengths_unseen(self) -> str: ...  # why it determines no length, in words ("": it measures them)
    @property
    def lengths_from(self) -> str: ...  # what determines the lengths it does not, in words
    @property
    def roles(self) -> str: ...  # what each of its sensors determines, in words ("": one sensor)
    @property
    def per_log(self) -> tuple[str, ...]: ...  # its parameters each log has its own of, even when shared
    @property
    def clocks(self) -> tuple[str, ...]: ...  # its clocks' offsets (the clock block's keys)
    @property
    def beside_row(self) -> int | None: ...  # the row of z that is 1 on its second clock's windows

    # --- the error term (symbolic) -------------------------------------------------------------
    def residual(self, z: ca.SX, mount: ca.SX, M: ca.SX) -> ca.SX: ...
    def clock_weights(self, z: ca.SX) -> ca.SX: ...  # which of its clocks a window's z is on
    def predict(self, mount: ca.SX, M: ca.SX) -> ca.SX: ...
    def between(self, a: ca.SX, b: ca.SX) -> ca.SX: ...
    def between_jacobians(self, a: ca.SX, b: ca.SX) -> tuple[ca.SX, ca.SX]: ...
    def compose(self, pose: ca.SX, motion: ca.SX) -> ca.SX: ...
    def base_from_sensor(self, T_world_sensor: ca.SX, mount: ca.SX) -> ca.SX: ...
    def manifold(self, free: Sequence[str]) -> bool: ...
    def boxplus(self, free: Sequence[str], x: ca.SX, step: ca.SX, x_plus: ca.SX) -> None: ...

    # --- numeric twins ---------------------------------------------------------------------------
    def heading(self, T_world_sensor: np.ndarray) -> np.ndarray: ...
    def floor_track(self, log: Log) -> np.ndarray: ...  # (x, y, unwrapped heading) on the floor
    def planar_mount(
        self, params: Mapping[str, float]
    ) -> tuple[float, float, float] | None: ...  # (x, y, yaw)
    def implausible(self, params: Mapping[str, float], given: Mapping[str, float] | None) -> str: ...
    def tangent(self, z: np.ndarray) -> np.ndarray: ...
    def beside_mount(
        self, params: Mapping[str, float], std: Mapping[str, float], header: LogHeader
    ) -> SensorMount | None: ...  # a 2nd joint
    def screened(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...  # increments judged, as predicted
    def motion_of(self, z: np.ndarray) -> np.ndarray | None: ...  # per increment (distance, turn)
    def poses(self, log: Log) -> np.ndarray: ...
    def jump_signal(self, log: Log) -> tuple[np.ndarray, int]: ...
    def repaired(self, log: Log, bad: np.ndarray) -> Log: ...
    def heights(self, log: Log) -> np.ndarray | None: ...
    def level(self, params: Mapping[str, float], first_pose: np.ndarray) -> np.ndarray | None: ...
    def trajectory_scale(self, params: Mapping[str, float]) -> float: ...

    # --- the start -----------------------------------------------------------------------------
    def initial(self, header: LogHeader) -> dict[str, float]: ...
    def nominal(self, header: LogHeader) -> dict[str, float]: ...  # the mount a log's header gives
    @property
    def start_span_s(self) -> float | None: ...  # its start's windows (s); None: the residual's
    def closed_form(
        self,
        model: KinematicModel,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: BaseMotion,
        known: Mapping[str, float],
    ) -> SensorStart: ...
    def given(self, initial: Mapping[str, float]) -> SensorStart | None: ...
    def fit_windows(
        self, start: SensorStart, z: np.ndarray, base_turn: np.ndarray
    ) -> tuple[np.ndarray, dict[str, int]]: ...

    # --- the write-back ------------------------------------------------------------------------
    def canonical(
        self, model: KinematicModel, params: Mapping[str, float], fixed: Sequence[str]
    ) -> dict[str, float]: ...
    def mount_pose(
        self,
        params: Mapping[str, float],
        std: Mapping[str, float],
        frame: str,
        nominal: tuple[float, float, float] | None,
    ) -> SensorMount: ...


class SensorDefaults:
    """What most references share, for a new kind to inherit and override where it differs: no
    mount parameter held, no angle convention to state, no turning-only or angle parameter, no
    parameter of a log's own beside a shared mount, lengths
    measured in metres, no planar base pose, no group structure for the mount's perturbation, no
    repair of its poses, no height, no levelling, no scale, no nominal mount in a log's header, no
    given start, every window fitted, and the estimate as it is (no mirror images to fold)."""

    held: ClassVar[tuple[str, ...]] = ()
    held_why: ClassVar[str] = ""
    convention: str = ""
    turning: ClassVar[tuple[str, ...]] = ()
    angles: ClassVar[tuple[str, ...]] = ()
    lengths_unseen: ClassVar[str] = ""
    lengths_from: ClassVar[str] = "fit beside a reference that measures distance"
    roles: ClassVar[str] = ""
    #: The parameters each log of a fit of several has its own of with the mount shared (a gyro's
    #: bias, which changes with each power cycle); ``mounts: per_log`` gives each log all of them.
    per_log: ClassVar[tuple[str, ...]] = ()
    #: Each error row's information weight by name; (): translation rows, then rotation rows.
    weights: ClassVar[tuple[str, ...]] = ()
    #: Its clocks' offsets, each a parameter of the clock block (one per log): the reference's.
    clocks: ClassVar[tuple[str, ...]] = (LAG_PARAM,)
    #: With two clocks, the row of a window's ``z`` that is 1 where the window is on the second
    #: (:meth:`clock_weights`' second weight; None: one clock).
    beside_row: ClassVar[int | None] = None
    length_unit: str = "m"
    planar_base: ClassVar[bool] = False
    start_span_s: ClassVar[float | None] = None

    def manifold(self, free: Sequence[str]) -> bool:
        return False

    @property
    def increment_noise_rows(self) -> tuple[int, ...]:
        """The row of ``z`` each noise component (``noise_groups``' indices) lies on in a window whose
        ``z`` is a measured increment (its noise its own): its first rows."""
        groups: tuple[tuple[int, ...], ...] = self.noise_groups  # type: ignore[attr-defined]
        return tuple(range(sum(len(g) for g in groups)))

    def floor_track(self, log: Log) -> np.ndarray:
        """What it measured of the drive on the floor: its unwrapped heading (no position)."""
        sensor: Sensor = self  # type: ignore[assignment]  # a subclass implements the rest of Sensor
        heading = np.unwrap(sensor.heading(np.asarray(sensor.poses(log), dtype=float)))
        return np.column_stack([np.zeros((heading.size, 2)), heading])

    def boxplus(self, free: Sequence[str], x: ca.SX, step: ca.SX, x_plus: ca.SX) -> None:
        return None

    def planar_mount(self, params: Mapping[str, float]) -> tuple[float, float, float] | None:
        return None

    def implausible(self, params: Mapping[str, float], given: Mapping[str, float] | None) -> str:
        return ""

    def repaired(self, log: Log, bad: np.ndarray) -> Log:
        return log

    def clock_weights(self, z: ca.SX) -> ca.SX:
        """How much of each of :attr:`clocks`' offsets a window of measurement ``z`` is late by: its
        one clock's, whole."""
        return ca.DM.ones(len(self.clocks), 1)

    def beside_mount(
        self, params: Mapping[str, float], std: Mapping[str, float], header: LogHeader
    ) -> SensorMount | None:
        """The mount of a second sensor fitted beside the reference (its own joint; ``header``: the
        log's, :attr:`LogHeader.beside` the second sensor's): none."""
        return None

    def screened(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Which increments ``z`` ``(n, z_rows)`` the screen judges against the sensor's predicted
        motion, and their motions in its layout: all, as they are."""
        return np.ones(z.shape[0], dtype=bool), z

    def motion_of(self, z: np.ndarray) -> np.ndarray | None:
        """Per increment ``z`` ``(n, z_rows)``, how far its reference moved and turned ``(n, 2)``
        (NaN for an increment not the reference's), exactly 0 only where it read no motion at all:
        what a frozen reference's increments show. None: its increments cannot show one."""
        return None

    def heights(self, log: Log) -> np.ndarray | None:
        return None

    def level(self, params: Mapping[str, float], first_pose: np.ndarray) -> np.ndarray | None:
        return None

    def trajectory_scale(self, params: Mapping[str, float]) -> float:
        return 1.0

    def nominal(self, header: LogHeader) -> dict[str, float]:
        return {}

    def given(self, initial: Mapping[str, float]) -> SensorStart | None:
        return None

    def fit_windows(
        self, start: SensorStart, z: np.ndarray, base_turn: np.ndarray
    ) -> tuple[np.ndarray, dict[str, int]]:
        return np.ones(z.shape[1], dtype=bool), {}

    def canonical(
        self, model: KinematicModel, params: Mapping[str, float], fixed: Sequence[str]
    ) -> dict[str, float]:
        return dict(params)
