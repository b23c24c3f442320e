"""Whether several logs tell one robot's story: each log's own fit against the other logs', in σ.

A joint fit of several logs (``datasets:``) assumes one robot: one set of parameters explains
every log. Each log's own fit is compared with the fit of the other logs together (the joint fit
with that log left out, as the jackknife over the logs fits it), on the parameters the log
determines on its own (:func:`determined`: a finite σ within
:data:`~nlp_calib.results.checks.WEAK` times the precision a calibration needs; a straight run says
nothing of how the robot turns). The two fits share no data, so the σ of their difference is
``√(σ_own² + σ_others²)``, both honest (the larger of the white-noise and the block jackknife σ):
the log's own, and the other logs' own combined by their information (a lower bound on what they
determine together, so the test errs towards agreement).

Logs of one robot still differ beyond that σ when a parameter moves with the driving (an
effective length that depends on the path, a mount that seems to shift with the direction of
turning): a model limit, not another robot. So a difference is said to set the logs apart only
when it is also beyond ``apart``, the loosest a calibration is said to be known to (``WEAK``
times the precision it needs: 5 % of a length or gain, 5 cm of the sensor's position, 25 mrad of
an angle); within it, the parameter is named as moving between the logs, and the joint σ takes in
the jackknife over the logs (:meth:`~nlp_calib.results.run.Checks.spreads`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from nlp_calib.models import KinematicModel, reference_scales
from nlp_calib.models.base import Reference
from nlp_calib.results.checks import WEAK, ConsistencyCheck


def determined(
    model: KinematicModel,
    names: tuple[str, ...],
    values: np.ndarray,
    std: np.ndarray,
    sensor: Mapping[str, Reference] | None = None,
    needed: np.ndarray | None = None,
) -> np.ndarray:
    """Per parameter: whether an estimate ``values`` with σ ``std`` determines it to the precision a
    calibration needs (finite, at most :data:`WEAK` times its reference precision; ``sensor``: the
    sensor's precisions of its mount; ``needed``: the drive's, where known)."""
    std = np.asarray(std, dtype=float)
    if needed is None:
        needed = reference_scales(model, names, np.asarray(values, dtype=float), sensor)
    with np.errstate(invalid="ignore"):
        return np.isfinite(std) & (std <= WEAK * np.asarray(needed, dtype=float))


def combined_others(std_own: np.ndarray) -> np.ndarray:
    """For each log (row), the σ of the other logs' estimates combined by their information
    (``1/σ² = Σ 1/σ_j²`` over the others with a finite, non-zero σ; NaN when none has one)."""
    with np.errstate(divide="ignore"):
        info = np.where(np.isfinite(std_own) & (std_own > 0), 1.0 / std_own**2, 0.0)
    others = info.sum(axis=0)[None, :] - info
    with np.errstate(divide="ignore"):
        return np.where(others > 0, 1.0 / np.sqrt(others), np.nan)


def compare_logs(
    names: tuple[str, ...],
    logs: Sequence[str],
    joint: np.ndarray,
    own: tuple[np.ndarray, np.ndarray],
    others: np.ndarray,
    known: np.ndarray,
    apart: np.ndarray,
    units: tuple[str, ...] = (),
) -> ConsistencyCheck:
    """The check of each log's own estimates and honest σ ``own = (estimates, σ)`` (n_logs, n_params)
    against the other logs' fit ``others`` (same shape), where the log determines a parameter on its
    own (``known``, same shape); ``apart``: per parameter, the difference beyond which logs are not
    one robot's."""
    estimates, std = (np.atleast_2d(np.asarray(a, dtype=float)) for a in own)
    others = np.atleast_2d(np.asarray(others, dtype=float))
    var = std**2 + combined_others(std) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(np.asarray(known, dtype=bool) & (var > 0), (estimates - others) / np.sqrt(var), np.nan)
    return ConsistencyCheck(
        tuple(names),
        tuple(logs),
        np.asarray(joint, dtype=float),
        estimates,
        others,
        z,
        np.asarray(apart, dtype=float),
        units,
    )
