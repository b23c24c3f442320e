"""A calibration in the robot stack's terms: the controller's parameters with their 1σ.

The model maps its parameters onto its ros2_control controller's; each derived value's 1σ is
propagated to first order from the parameters' covariance (their σ to believe with the
white-noise correlation, as ``result.json`` reports them), with the map's Jacobian taken by
central differences.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from nlp_calib.models import KinematicModel
from nlp_calib.results.handoff import ControllerParams, Placement


def _values(
    model: KinematicModel, names: Sequence[str], p: np.ndarray, ranges: Mapping[str, float]
) -> np.ndarray:
    _, parameters, _, _ = model.controller(dict(zip(names, map(float, p))), ranges)
    return np.array(list(parameters.values()))


def controller_params(
    model: KinematicModel,
    names: Sequence[str],
    params: np.ndarray,
    std: np.ndarray,
    correlation: np.ndarray,
    ranges: Mapping[str, float],
) -> ControllerParams:
    """``model``'s controller parameters at ``params`` (in ``names`` order) with their 1σ."""
    values = dict(zip(names, map(float, params)))
    controller, parameters, places, assumes = model.controller(values, ranges)
    finite = np.where(np.isfinite(std), std, 0.0)
    cov = np.nan_to_num(correlation) * np.outer(finite, finite)
    jac = np.zeros((len(parameters), len(names)))
    for j in range(len(names)):
        h = 1e-6 * max(abs(float(params[j])), float(finite[j]), 1e-9)
        up, down = params.copy(), params.copy()
        up[j] += h
        down[j] -= h
        jac[:, j] = (_values(model, names, up, ranges) - _values(model, names, down, ranges)) / (2.0 * h)
    sd = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", jac, cov, jac), 0.0, None))
    units = dict(model.units)
    elsewhere = tuple(
        Placement(n, values[n], float(std[list(names).index(n)]), units.get(n, ""), where)
        for n, where in places.items()
    )
    return ControllerParams(controller, parameters, dict(zip(parameters, map(float, sd))), elsewhere, assumes)
