"""Synthetic tricycle logs with known truth, in the exact text format of SPEC §2.

The robot is simulated in continuous time (exact arcs on a fine sub-step grid, with smoothly
varying speed and steering), then sampled at jittered ~25 Hz: quantised steering and traction
encoders (the traction counter starts near 2³² so it wraps), and a tracker that sees the sensor
pose with noise, gross outliers and latency. Independent of the symbolic model on purpose: it is
the yardstick the model is checked against. Deterministic for a given seed.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.io.files import atomic_write_text
from nlp_calib.io.logfile import COUNTER_MODULUS, LogHeader, format_log

TRAJECTORIES = ("s_curves", "straight", "no_reversals")

DEFAULT_TRUTH = {
    "k_steer": 0.55,
    "k_traction": 0.0105,
    "axis_length": 1.5,
    "steer_offset": -0.05,
    "sensor_x": 1.6,
    "sensor_y": 0.1,
    "sensor_theta": 0.05,
}
DEFAULT_GUESS = {
    "k_steer": 0.5,
    "k_traction": 0.01,
    "axis_length": 1.4,
    "steer_offset": 0.0,
    "sensor_x": 1.5,
    "sensor_y": 0.0,
    "sensor_theta": 0.0,
}


@dataclass(frozen=True)
class SimulationOptions:
    """What to simulate. Angles in rad, lengths in m, times in s.

    ``trajectory``: ``s_curves`` (turns, stops and reversals), ``straight`` (no steering) or
    ``no_reversals`` (turns and stops, always forward). ``truth`` and ``guess`` map parameter
    names to values (``guess`` goes into the log header as the initial guess).
    """

    records: int = 1500
    seed: int = 0
    trajectory: str = "s_curves"
    truth: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_TRUTH))
    guess: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_GUESS))
    steering_ticks: int = 8192
    traction_ticks: int = 5000
    rate_hz: float = 25.0
    jitter_s: float = 0.004
    substeps: int = 20
    max_speed: float = 0.6
    max_steer: float = 0.6
    stop_fraction: float = 0.15
    tracker_noise_xy: float = 0.002
    tracker_noise_theta: float = 0.002
    outlier_fraction: float = 0.0
    outlier_magnitude: float = 0.3
    latency_s: float = 0.0
    wrap_after_ticks: int = 20000

    def __post_init__(self) -> None:
        if self.trajectory not in TRAJECTORIES:
            raise ValueError(f"trajectory must be one of {TRAJECTORIES}, got {self.trajectory!r}")
        if self.records < 3:
            raise ValueError("records must be >= 3")
        missing = [k for k in DEFAULT_TRUTH if k not in self.truth or k not in self.guess]
        if missing:
            raise ValueError(f"truth and guess need values for {missing}")
        if not 0.0 <= self.outlier_fraction < 1.0 or not 0.0 <= self.stop_fraction < 1.0:
            raise ValueError("outlier_fraction and stop_fraction must lie in [0, 1)")
        if self.substeps < 1 or self.rate_hz <= 0 or self.jitter_s < 0 or self.latency_s < 0:
            raise ValueError("substeps >= 1, rate_hz > 0, jitter_s >= 0 and latency_s >= 0 are required")


@dataclass(frozen=True)
class SimulatedLog:
    """A simulated log: record arrays plus the header that describes them."""

    header: LogHeader
    time_ns: np.ndarray
    ticks: np.ndarray
    model_pose: np.ndarray
    T_world_sensor: np.ndarray
    T_world_base_true: np.ndarray
    options: SimulationOptions

    def text(self) -> str:
        return format_log(self.header, self.time_ns, self.ticks, self.model_pose, self.T_world_sensor)

    def truth_dict(self) -> dict[str, Any]:
        opts = asdict(self.options)
        return {
            "params": dict(self.options.truth),
            "options": opts,
            "records": int(self.time_ns.size),
        }


def _profiles(
    opts: SimulationOptions, rng: np.random.Generator, duration: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Knot times, front-wheel speeds and steering angles; linear between knots."""
    n_knots = int(duration / 1.5) + 3
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(1.0, 2.5, n_knots))])
    speed = rng.uniform(0.3, 1.0, t.size) * opts.max_speed
    if opts.trajectory == "s_curves":
        # Drive in one direction for a few knots, then reverse: reversals with realistic runs.
        direction = np.where((np.arange(t.size) // 6) % 2 == 0, 1.0, -1.0)
        speed *= direction
    stops = rng.random(t.size) < opts.stop_fraction
    speed[stops] = 0.0
    speed[0] = 0.0
    # A stop is held for a while (a second knot at zero speed), not just touched.
    hold = np.flatnonzero(stops)
    t = np.insert(
        t, hold + 1, t[hold] + rng.uniform(0.5, 1.0, hold.size) * np.diff(t)[np.minimum(hold, t.size - 2)]
    )
    speed = np.insert(speed, hold + 1, 0.0)
    steer = rng.uniform(-1.0, 1.0, t.size) * opts.max_steer
    steer[hold + 1 + np.arange(hold.size)] = steer[hold + np.arange(hold.size)]
    if opts.trajectory == "straight":
        steer[:] = 0.0
    return t, speed, steer


def _sample_times(opts: SimulationOptions, rng: np.random.Generator) -> np.ndarray:
    dt = 1.0 / opts.rate_hz + rng.normal(0.0, opts.jitter_s, opts.records - 1)
    dt = np.clip(dt, 0.25 / opts.rate_hz, None)
    return np.concatenate([[0.0], np.cumsum(dt)])


def _integrate(
    opts: SimulationOptions, knots: tuple[np.ndarray, np.ndarray, np.ndarray], t_fine: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Base poses and front-wheel distance on the fine grid (exact arcs per sub-step)."""
    kt, kv, ks = knots
    L = opts.truth["axis_length"]
    t_mid = 0.5 * (t_fine[1:] + t_fine[:-1])
    v = np.interp(t_mid, kt, kv)
    phi = np.interp(t_mid, kt, ks)
    d = v * np.diff(t_fine)
    ds = d * np.cos(phi)
    w = d * np.sin(phi) / L
    theta = np.concatenate([[0.0], np.cumsum(w)])
    small = np.abs(w) < 1e-9
    w_safe = np.where(small, 1.0, w)
    a = np.where(small, ds, ds * np.sin(w_safe) / w_safe)
    b = np.where(small, 0.5 * ds * w, ds * (1.0 - np.cos(w_safe)) / w_safe)
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    x = np.concatenate([[0.0], np.cumsum(c * a - s * b)])
    y = np.concatenate([[0.0], np.cumsum(s * a + c * b)])
    front = np.concatenate([[0.0], np.cumsum(d)])
    return np.stack([x, y, theta], axis=1), front, np.concatenate([[ks[0]], phi])


def _pose_at(t_fine: np.ndarray, poses: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, t_fine, poses[:, i]) for i in range(3)], axis=1)


def _sensor_pose(base: np.ndarray, mount: tuple[float, float, float]) -> np.ndarray:
    c, s = np.cos(base[:, 2]), np.sin(base[:, 2])
    mx, my, mth = mount
    return np.stack([base[:, 0] + c * mx - s * my, base[:, 1] + s * mx + c * my, base[:, 2] + mth], axis=1)


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def simulate(opts: SimulationOptions) -> SimulatedLog:
    """Simulate a drive and the log it would produce."""
    rng = np.random.default_rng(opts.seed)
    truth = opts.truth
    t_s = _sample_times(opts, rng)
    knots = _profiles(opts, rng, float(t_s[-1]) + opts.latency_s + 1.0)
    # Fine grid: sub-steps between samples, starting early enough to cover the latency.
    t0 = -opts.latency_s
    base_grid = np.concatenate([[t0], t_s]) if opts.latency_s > 0 else t_s
    frac = np.arange(opts.substeps) / opts.substeps
    t_fine = np.concatenate(
        [(base_grid[:-1, None] + np.diff(base_grid)[:, None] * frac).ravel(), base_grid[-1:]]
    )
    poses, front, phi = _integrate(opts, knots, t_fine - t0)

    base_at_samples = _pose_at(t_fine, poses, t_s)
    front_at_samples = np.interp(t_s, t_fine, front)
    phi_at_samples = np.interp(t_s, t_fine, phi)
    mount = (truth["sensor_x"], truth["sensor_y"], truth["sensor_theta"])
    tracker = _sensor_pose(_pose_at(t_fine, poses, t_s - opts.latency_s), mount)
    tracker[:, :2] += rng.normal(0.0, opts.tracker_noise_xy, (opts.records, 2))
    tracker[:, 2] += rng.normal(0.0, opts.tracker_noise_theta, opts.records)
    outliers = rng.random(opts.records) < opts.outlier_fraction
    tracker[outliers, :2] += rng.normal(0.0, opts.outlier_magnitude, (int(outliers.sum()), 2))
    tracker[outliers, 2] += rng.normal(0.0, opts.outlier_magnitude, int(outliers.sum()))
    tracker[:, 2] = _wrap(tracker[:, 2])

    s_max, t_max = opts.steering_ticks, opts.traction_ticks
    steer_ticks = np.mod(
        np.round((phi_at_samples - truth["steer_offset"]) / truth["k_steer"] * s_max / (2 * np.pi)),
        s_max,
    )
    traction_raw = np.floor(front_at_samples * t_max / truth["k_traction"]).astype(np.int64)
    traction_ticks = np.mod(traction_raw + (COUNTER_MODULUS - opts.wrap_after_ticks), COUNTER_MODULUS)
    ticks = np.stack([steer_ticks.astype(np.int64), traction_ticks], axis=1)

    guess = opts.guess
    header = LogHeader(
        kinematic_model="traction_drive_wheel",
        parameters={k: float(guess[k]) for k in ("k_steer", "k_traction", "axis_length", "steer_offset")},
        encoder_names=("steering", "traction_wheel"),
        encoder_max=(s_max, t_max),
        sensor_frame="laser",
        T_base_sensor=(
            float(guess["sensor_x"]),
            float(guess["sensor_y"]),
            float(guess["sensor_theta"]),
        ),
    )
    return SimulatedLog(
        header=header,
        time_ns=np.round(t_s * 1e9).astype(np.int64) + 1_700_000_000_000_000_000,
        ticks=ticks,
        model_pose=_vendor_odometry(header, ticks),
        T_world_sensor=tracker,
        T_world_base_true=base_at_samples,
        options=opts,
    )


def _vendor_odometry(header: LogHeader, ticks: np.ndarray) -> np.ndarray:
    """The robot's own first-order odometry with the header's parameters (``model_pose``)."""
    p = header.parameters
    s_max, t_max = header.encoder_max
    d_ticks = ((ticks[1:, 1] - ticks[:-1, 1] + COUNTER_MODULUS // 2) % COUNTER_MODULUS) - COUNTER_MODULUS // 2
    d = p["k_traction"] * d_ticks / t_max
    phi = p["k_steer"] * _wrap(2 * np.pi * ticks[:-1, 0] / s_max) + p["steer_offset"]
    theta = np.concatenate([[0.0], np.cumsum(d * np.sin(phi) / p["axis_length"])])
    step = d * np.cos(phi)
    x = np.concatenate([[0.0], np.cumsum(step * np.cos(theta[:-1]))])
    y = np.concatenate([[0.0], np.cumsum(step * np.sin(theta[:-1]))])
    return np.stack([x, y, theta], axis=1)


def truth_path(log_path: Path) -> Path:
    """Where the truth JSON of a simulated log lives: beside it, ``<name>.truth.json``."""
    return log_path.with_suffix(".truth.json")


def write_simulation(sim: SimulatedLog, out: str | Path) -> tuple[Path, Path]:
    """Write the log and its truth JSON (atomically); returns both paths."""
    log_path = Path(out)
    atomic_write_text(log_path, sim.text())
    tp = truth_path(log_path)
    atomic_write_text(tp, json.dumps(sim.truth_dict(), indent=2) + "\n")
    return log_path, tp
