"""Front-tractor tricycle: the front wheel steers and drives (SPEC §3).

Parameters ``(k_steer, k_traction, axis_length, steer_offset)``; inputs per interval
``(traction_revolutions, steering_angle)``: the unwrapped traction increment divided by
``t_max``, and the steering encoder's angle ``wrap(2π·s/s_max)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import casadi as ca
import numpy as np

from nlp_calib.errors import ModelError
from nlp_calib.io.logfile import Dataset
from nlp_calib.models.base import STEERING_SAMPLES
from nlp_calib.symbolic import se2

STEERING_ENCODER = "steering"
TRACTION_ENCODER = "traction_wheel"


def _wrap(a: np.ndarray) -> np.ndarray:
    """Onto (-π, π], matching the encoder convention that ticks above s_max/2 are negative."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


class Tricycle:
    """Front-wheel-drive bicycle model of a tricycle; base link at the rear-axle midpoint."""

    name: str = "tricycle"
    log_names: tuple[str, ...] = ("traction_drive_wheel", "tricycle")
    kinematic_params: tuple[str, ...] = ("k_steer", "k_traction", "axis_length", "steer_offset")
    input_names: tuple[str, ...] = ("traction_revolutions", "steering_angle")
    physical_ranges: Mapping[str, tuple[float, float]] = MappingProxyType(
        {
            "k_steer": (0.01, 3.0),
            "k_traction": (1e-4, 10.0),
            "axis_length": (0.1, 10.0),
            "steer_offset": (-0.5, 0.5),
            "sensor_x": (-5.0, 5.0),
            "sensor_y": (-5.0, 5.0),
            "sensor_theta": (-np.pi, np.pi),
        }
    )

    def increment(self, k: ca.SX, u: ca.SX, integration: str) -> ca.SX:
        """``v = d·cos φ``, ``ω = d·sin φ / L``; exact arc or Euler ``(v, 0, ω)``."""
        k_steer, k_traction, axis_length, steer_offset = k[0], k[1], k[2], k[3]
        phi = k_steer * u[1] + steer_offset
        d = k_traction * u[0]
        v = d * ca.cos(phi)
        omega = d * ca.sin(phi) / axis_length
        if integration == "euler":
            return ca.vertcat(v, 0.0, omega)
        return se2.arc(v, omega)

    def inputs(self, dataset: Dataset, steering_sample: str) -> np.ndarray:
        """Rows: traction revolutions ``Δt/t_max`` and the steering angle sampled as asked."""
        header = dataset.header
        if steering_sample not in STEERING_SAMPLES:
            raise ModelError(f"steering_sample must be one of {STEERING_SAMPLES}, got {steering_sample!r}")
        for enc in (STEERING_ENCODER, TRACTION_ENCODER):
            if enc not in header.encoder_names:
                raise ModelError(
                    f"{dataset.path}: the tricycle model needs encoders {STEERING_ENCODER!r} and "
                    f"{TRACTION_ENCODER!r}; the log has {list(header.encoder_names)}"
                )
        s_max = header.encoder_max[header.encoder_index(STEERING_ENCODER)]
        t_max = header.encoder_max[header.encoder_index(TRACTION_ENCODER)]
        revs = dataset.increments(TRACTION_ENCODER) / float(t_max)
        angle = _wrap(2.0 * np.pi * dataset.encoder(STEERING_ENCODER) / float(s_max))
        if steering_sample == "start":
            steer = angle[:-1]
        elif steering_sample == "end":
            steer = angle[1:]
        else:
            steer = _wrap(angle[:-1] + 0.5 * _wrap(angle[1:] - angle[:-1]))
        return np.vstack([revs, steer])

    def moving(self, inputs: np.ndarray) -> np.ndarray:
        return np.asarray(inputs[0] != 0.0)

    def input_noise_std(self, dataset: Dataset) -> np.ndarray:
        """One tick of quantisation, uniform: ``tick/√12`` on each input."""
        header = dataset.header
        s_max = header.encoder_max[header.encoder_index(STEERING_ENCODER)]
        t_max = header.encoder_max[header.encoder_index(TRACTION_ENCODER)]
        return np.array([1.0 / t_max, 2.0 * np.pi / s_max]) / np.sqrt(12.0)
