"""The simulator's drives: how speed and turning move a base and what its encoders read.

Plain numpy, independent of the symbolic models on purpose (the simulator is the yardstick they
are checked against). Each drive turns the speed and turning profiles of :mod:`nlp_calib.simulate`
into per-sub-step base increments and cumulative encoder channels, quantises those channels into
log ticks, and writes the log header and the robot's own first-order odometry (``model_pose``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Protocol

import numpy as np

from nlp_calib.io.logfile import LogHeader
from nlp_calib.numeric import COUNTER_MODULUS, wrap_angle, wrapped_difference

if TYPE_CHECKING:
    from nlp_calib.simulate import SimulationOptions

DEFAULT_TRUTH: dict[str, dict[str, float]] = {
    "tricycle": {
        "k_steer": 0.55,
        "k_traction": 0.0105,
        "axis_length": 1.5,
        "steer_offset": -0.05,
        "sensor_x": 1.6,
        "sensor_y": 0.1,
        "sensor_theta": 0.05,
    },
    "diff_drive": {
        "k_left": 4.9e-4,
        "k_right": 5.1e-4,
        "baseline": 0.55,
        "sensor_x": 0.3,
        "sensor_y": -0.05,
        "sensor_theta": 0.08,
    },
}
DEFAULT_GUESS: dict[str, dict[str, float]] = {
    "tricycle": {
        "k_steer": 0.5,
        "k_traction": 0.01,
        "axis_length": 1.4,
        "steer_offset": 0.0,
        "sensor_x": 1.5,
        "sensor_y": 0.0,
        "sensor_theta": 0.0,
    },
    "diff_drive": {
        "k_left": 5e-4,
        "k_right": 5e-4,
        "baseline": 0.5,
        "sensor_x": 0.25,
        "sensor_y": 0.0,
        "sensor_theta": 0.0,
    },
}
#: Curvature (1/m) per unit of the turning profile for the differential drive.
_DIFF_CURVATURE = 1.5


def integrate_base(ds: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Base poses ``(n + 1, 3)`` from per-sub-step arcs of length ``ds`` turning by ``w``."""
    theta = np.concatenate([[0.0], np.cumsum(w)])
    small = np.abs(w) < 1e-9
    w_safe = np.where(small, 1.0, w)
    a = np.where(small, ds, ds * np.sin(w_safe) / w_safe)
    b = np.where(small, 0.5 * ds * w, ds * (1.0 - np.cos(w_safe)) / w_safe)
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    x = np.concatenate([[0.0], np.cumsum(c * a - s * b)])
    y = np.concatenate([[0.0], np.cumsum(s * a + c * b)])
    return np.stack([x, y, theta], axis=1)


def _cumulative(step: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(step)])


def _counter(distance: np.ndarray, metres_per_tick: float, wrap_after: int) -> np.ndarray:
    """A uint32 wheel counter started ``wrap_after`` ticks below its wrap."""
    raw = np.floor(distance / metres_per_tick).astype(np.int64)
    return np.mod(raw + (COUNTER_MODULUS - wrap_after), COUNTER_MODULUS)


def _first_order(step: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    theta = np.concatenate([[0.0], np.cumsum(dtheta)])
    x = np.concatenate([[0.0], np.cumsum(step * np.cos(theta[:-1]))])
    y = np.concatenate([[0.0], np.cumsum(step * np.sin(theta[:-1]))])
    return np.stack([x, y, theta], axis=1)


def _header(
    opts: SimulationOptions,
    model: str,
    kinematic: tuple[str, ...],
    encoders: tuple[str, ...],
    ranges: tuple[int, ...],
) -> LogHeader:
    g = opts.guess
    return LogHeader(
        kinematic_model=model,
        parameters={k: float(g[k]) for k in kinematic},
        encoder_names=encoders,
        encoder_max=ranges,
        sensor_frame="laser",
        T_base_sensor=(float(g["sensor_x"]), float(g["sensor_y"]), float(g["sensor_theta"])),
    )


class Drive(Protocol):
    def steps(
        self, opts: SimulationOptions, speed: np.ndarray, turn: np.ndarray, dt: np.ndarray, turn_start: float
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]: ...

    def ticks(self, opts: SimulationOptions, channels: Mapping[str, np.ndarray]) -> np.ndarray: ...

    def header(self, opts: SimulationOptions) -> LogHeader: ...

    def vendor_odometry(self, header: LogHeader, ticks: np.ndarray) -> np.ndarray: ...


class TricycleDrive:
    """Front wheel drives at ``speed`` and steers to ``turn`` (rad); encoders: steering, traction."""

    def steps(
        self, opts: SimulationOptions, speed: np.ndarray, turn: np.ndarray, dt: np.ndarray, turn_start: float
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        d = speed * dt
        ds, w = d * np.cos(turn), d * np.sin(turn) / opts.truth["axis_length"]
        return ds, w, {"front": _cumulative(d), "phi": np.concatenate([[turn_start], turn])}

    def ticks(self, opts: SimulationOptions, channels: Mapping[str, np.ndarray]) -> np.ndarray:
        t = opts.truth
        s_max, t_max = opts.steering_ticks, opts.traction_ticks
        steer = np.mod(
            np.round((channels["phi"] - t["steer_offset"]) / t["k_steer"] * s_max / (2 * np.pi)), s_max
        )
        traction = _counter(channels["front"], t["k_traction"] / t_max, opts.wrap_after_ticks)
        return np.stack([steer.astype(np.int64), traction], axis=1)

    def header(self, opts: SimulationOptions) -> LogHeader:
        return _header(
            opts,
            "traction_drive_wheel",
            ("k_steer", "k_traction", "axis_length", "steer_offset"),
            ("steering", "traction_wheel"),
            (opts.steering_ticks, opts.traction_ticks),
        )

    def vendor_odometry(self, header: LogHeader, ticks: np.ndarray) -> np.ndarray:
        p = header.parameters
        s_max, t_max = header.encoder_max
        d = p["k_traction"] * wrapped_difference(ticks[:, 1]) / t_max
        phi = p["k_steer"] * wrap_angle(2 * np.pi * ticks[:-1, 0] / s_max) + p["steer_offset"]
        return _first_order(d * np.cos(phi), d * np.sin(phi) / p["axis_length"])


class DiffDriveDrive:
    """Base moves at ``speed``, curvature ``1.5·turn`` per metre; encoders: left and right wheel."""

    def steps(
        self, opts: SimulationOptions, speed: np.ndarray, turn: np.ndarray, dt: np.ndarray, turn_start: float
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        ds = speed * dt
        w = ds * _DIFF_CURVATURE * turn
        half = 0.5 * opts.truth["baseline"] * w
        return ds, w, {"left": _cumulative(ds - half), "right": _cumulative(ds + half)}

    def ticks(self, opts: SimulationOptions, channels: Mapping[str, np.ndarray]) -> np.ndarray:
        t = opts.truth
        left = _counter(channels["left"], t["k_left"], opts.wrap_after_ticks)
        right = _counter(channels["right"], t["k_right"], 2 * opts.wrap_after_ticks)
        return np.stack([left, right], axis=1)

    def header(self, opts: SimulationOptions) -> LogHeader:
        return _header(
            opts,
            "differential_drive",
            ("k_left", "k_right", "baseline"),
            ("left_wheel", "right_wheel"),
            (opts.wheel_ticks, opts.wheel_ticks),
        )

    def vendor_odometry(self, header: LogHeader, ticks: np.ndarray) -> np.ndarray:
        p = header.parameters
        d_l = p["k_left"] * wrapped_difference(ticks[:, 0])
        d_r = p["k_right"] * wrapped_difference(ticks[:, 1])
        return _first_order(0.5 * (d_l + d_r), (d_r - d_l) / p["baseline"])


DRIVES: dict[str, Drive] = {"tricycle": TricycleDrive(), "diff_drive": DiffDriveDrive()}
