"""What the simulator asks of a model's drive, and the numpy pieces the drives share.

A drive turns speed and turning profiles into per-sub-step base increments and cumulative encoder
channels, quantises those channels into log ticks, and writes the log header and the robot's own
first-order odometry (``model_pose``). Drives are plain numpy, independent of the symbolic models
on purpose: the simulator is the yardstick the models are checked against.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol, runtime_checkable

import numpy as np

from nlp_calib.core import poses
from nlp_calib.core.numeric import COUNTER_MODULUS
from nlp_calib.logs import LogHeader

#: A pose ``(x, y, theta)`` a running integration continues from.
Pose = tuple[float, float, float]


class SimulationSettings(Protocol):
    """The simulation options a drive reads (see ``nlp_calib.simulation.SimulationOptions``)."""

    @property
    def truth(self) -> Mapping[str, float]: ...
    @property
    def guess(self) -> Mapping[str, float]: ...
    @property
    def encoder_ranges(self) -> Mapping[str, int]: ...
    @property
    def wrap_after_ticks(self) -> int: ...


class Drive(Protocol):
    """A model's simulated base; ``default_truth`` / ``default_guess`` map every parameter,
    ``default_ranges`` every encoder to its ``#joints_max_enc_values`` entry."""

    default_truth: Mapping[str, float]
    default_guess: Mapping[str, float]
    default_ranges: Mapping[str, int]

    def steps(
        self,
        opts: SimulationSettings,
        speed: np.ndarray,
        turn: np.ndarray,
        turn_end: np.ndarray,
        dt: np.ndarray,
        turn_start: float,
        carry: Mapping[str, float] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Per sub-step arc length and turn of the base (``speed`` and ``turn`` at each sub-step's
        middle), and the encoder channels at the sub-step ends (a steering angle: ``turn_end``, the
        turn at each end), preceded by their values at the start: at rest (``turn_start``) for the
        log's first sub-step, else ``carry``, the channels' last values of the sub-steps before."""
        ...

    def ticks(self, opts: SimulationSettings, channels: Mapping[str, np.ndarray]) -> np.ndarray:
        """The log's encoder readings ``(n, n_encoders)`` from the channels at the sample times."""
        ...

    def header(self, opts: SimulationSettings) -> LogHeader:
        """The log header: the guess as the initial values, the encoder ranges."""
        ...

    def vendor_odometry(self, header: LogHeader, ticks: np.ndarray, start: Pose | None = None) -> np.ndarray:
        """The robot's own first-order odometry with the header's parameters (``model_pose``), from
        ``start`` at the first record (None: the log's start, the origin)."""
        ...


@runtime_checkable
class VendorController(Protocol):
    """A drive whose robot's controller integrates its own odometry from its joints (what the
    vendor odometry simulator writes): ``vendor_truth``, a robot (the model's parameters in joint
    units) whose controller runs the wrong model ``vendor_model``."""

    vendor_truth: Mapping[str, float]
    vendor_model: Mapping[str, float]

    def odometry(self, joints: Mapping[str, np.ndarray], params: Mapping[str, float]) -> np.ndarray:
        """The base poses ``(n, 3)``, from the origin, that the controller integrates with its
        model ``params`` from the joints' angles (rad, by the model's joint map's names)."""
        ...


def running(step: np.ndarray, start: float | None = None) -> np.ndarray:
    """Running sum of ``step`` from ``start`` (one more element; None: from 0, the log's start).

    Summed in order, one addition per element, so a log made in blocks, each continuing from the
    last sum of the block before, holds the very numbers of a log made at once.
    """
    if start is None:
        return np.concatenate([[0.0], np.cumsum(step)])
    return np.cumsum(np.concatenate([[start], step]))


def integrate_base(ds: np.ndarray, w: np.ndarray, start: Pose | None = None) -> np.ndarray:
    """Base poses ``(n + 1, 3)`` from per-sub-step arcs of length ``ds`` turning by ``w``, from
    ``start`` (None: the origin)."""
    x0, y0, th0 = start if start is not None else (None, None, None)
    theta = running(w, th0)
    small = np.abs(w) < 1e-9
    w_safe = np.where(small, 1.0, w)
    a = np.where(small, ds, ds * np.sin(w_safe) / w_safe)
    b = np.where(small, 0.5 * ds * w, ds * (1.0 - np.cos(w_safe)) / w_safe)
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    x = running(c * a - s * b, x0)
    y = running(s * a + c * b, y0)
    return np.stack([x, y, theta], axis=1)


def arcs(base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each step between consecutive base poses ``(n, 3)`` as the exact arc that drives it (the
    inverse of :func:`integrate_base`): its length, signed by its direction of travel, and its turn."""
    step = poses.between(base[:-1], base[1:])
    turn, half = step[:, 2], 0.5 * step[:, 2]
    chord = np.hypot(step[:, 0], step[:, 1]) * np.sign(step[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        arc = chord * np.where(np.abs(half) > 1e-9, half / np.sin(half), 1.0 + half**2 / 6.0)
    return arc, turn


def counter(distance: np.ndarray, metres_per_tick: float, wrap_after: int) -> np.ndarray:
    """A uint32 wheel counter started ``wrap_after`` ticks below its wrap."""
    raw = np.floor(distance / metres_per_tick).astype(np.int64)
    return np.mod(raw + (COUNTER_MODULUS - wrap_after), COUNTER_MODULUS)


def first_order(step: np.ndarray, dtheta: np.ndarray, start: Pose | None = None) -> np.ndarray:
    """Poses of first-order (Euler) dead reckoning from ``start`` (None: the origin): move
    ``step`` along the heading, then turn."""
    x0, y0, th0 = start if start is not None else (None, None, None)
    theta = running(dtheta, th0)
    x = running(step * np.cos(theta[:-1]), x0)
    y = running(step * np.sin(theta[:-1]), y0)
    return np.stack([x, y, theta], axis=1)


def drive_header(
    opts: SimulationSettings, kinematic_model: str, header_names: Mapping[str, str]
) -> LogHeader:
    """A header with ``opts.guess`` as initial values (under ``header_names``) and the encoder ranges."""
    g = opts.guess
    return LogHeader(
        kinematic_model=kinematic_model,
        parameters={header: float(g[name]) for name, header in header_names.items()},
        encoder_names=tuple(opts.encoder_ranges),
        encoder_max=tuple(opts.encoder_ranges.values()),
        sensor_frame="laser",
        T_base_sensor=(float(g["sensor_x"]), float(g["sensor_y"]), float(g["sensor_theta"])),
    )
