"""What a kinematic model provides to the rest of the package.

A model is one small module: its parameter names, how raw encoder readings become per-interval
inputs (numeric, once per dataset), and the symbolic base-link increment those inputs produce.
The builder, both solvers, code generation and the reports use it only through this protocol.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol

import casadi as ca
import numpy as np

from nlp_calib.io.logfile import Dataset

#: The sensor mounting pose ``T_base_sensor`` closes every parameter vector, in this order.
SENSOR_PARAMS: tuple[str, str, str] = ("sensor_x", "sensor_y", "sensor_theta")

INTEGRATIONS = ("exact", "euler")
#: 1σ of rounding to whole ticks (uniform over one tick).
QUANTISATION = 1.0 / np.sqrt(12.0)
STEERING_SAMPLES = ("start", "end", "mean")


class KinematicModel(Protocol):
    """A wheeled base: parameters, encoder inputs and the symbolic SE(2) increment."""

    #: Name used in scenarios (``model:``).
    name: str
    #: ``#kinematic_model:`` values of logs this model reads.
    log_names: tuple[str, ...]
    #: Kinematic parameter names, in state order (the sensor pose follows them).
    kinematic_params: tuple[str, ...]
    #: Names of the per-interval inputs :meth:`inputs` returns, in row order.
    input_names: tuple[str, ...]
    #: Encoder names (``#joints_max_enc``) the model reads.
    encoders: tuple[str, ...]
    #: Kinematic parameters a log without turning cannot determine, and a note on what else.
    turning_params: tuple[str, ...]
    turning_note: str
    #: Plausible ranges, used to reject absurd initial guesses and as basin-study ranges.
    physical_ranges: Mapping[str, tuple[float, float]]

    def increment(self, k: ca.SX, u: ca.SX, integration: str) -> ca.SX:
        """Base-link motion ``(x, y, theta)`` over one interval for parameters ``k``, inputs ``u``."""
        ...

    def inputs(self, dataset: Dataset, steering_sample: str) -> np.ndarray:
        """Per-interval inputs, ``(len(input_names), n_records - 1)``, from the raw encoders."""
        ...

    def moving(self, inputs: np.ndarray) -> np.ndarray:
        """Boolean mask of intervals in which the encoders report motion."""
        ...

    def input_noise_std(
        self, dataset: Dataset, encoder_noise: Mapping[str, float] | None = None
    ) -> np.ndarray:
        """1σ noise of each input row, from each encoder's noise in ticks (default: quantisation)."""
        ...

    def canonical(self, params: Mapping[str, float], fixed: tuple[str, ...] = ()) -> dict[str, float]:
        """The same physical calibration in the model's canonical form (positive gains, wrapped
        angles); parameters in ``fixed`` are left as they are."""
        ...

    def initial_guess(
        self,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: Callable[[Mapping[str, float]], np.ndarray],
    ) -> dict[str, float]:
        """All parameters from horizon windows (inputs ``U``, sensor motions ``z``), no guess needed.

        ``base_motion(params)`` evaluates the windows' base motion ``(3, M)`` for given parameters.
        """
        ...


def param_names(model: KinematicModel) -> tuple[str, ...]:
    """The full state order: kinematic parameters then the sensor pose."""
    return (*model.kinematic_params, *SENSOR_PARAMS)
