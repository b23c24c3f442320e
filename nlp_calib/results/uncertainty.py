"""The white-noise covariance of an estimate (computed by :mod:`nlp_calib.analysis.uncertainty`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Uncertainty:
    """Covariance of the free parameters (plain coordinates) and the noise it was built from.

    ``std`` and ``correlation`` cover all parameters in model order; fixed ones have std 0 and
    correlation 0 with the rest. ``noise`` holds the estimated 1σ of each source.
    """

    names: tuple[str, ...]
    free: tuple[str, ...]
    covariance: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    noise: dict[str, float]
    dof: int
    #: Free parameters the data leave undetermined, known only as well as the bounds of a
    #: parameter they move with allow (a tracker lag within its search).
    bounded: tuple[str, ...] = ()
    #: Free parameters whose σ the residuals' own scores set, beyond the noise model's (an error of
    #: each window's own that the poses' noise, cancelling along a chain, does not carry).
    residual_floor: tuple[str, ...] = ()

    def std_dict(self) -> dict[str, float]:
        return {n: float(s) for n, s in zip(self.names, self.std)}
