"""Whether several logs tell the same story: each log's own fit against their joint fit, in σ.

A joint fit of several logs (``datasets:``) assumes one robot: one set of parameters explains
every log. Each log's own fit should then agree with the joint fit within their uncertainty. The
joint fit contains the log's own data, so the two are correlated: for estimates combined by
their information, ``var(own − joint) = σ_own² − σ_joint²`` (two logs: the difference to the
joint fit in these units is exactly the difference between the two logs in units of
``√(σ_a² + σ_b²)``). The σ are the honest ones (the larger of the white-noise and the block
jackknife σ), each estimated from ten blocks: their difference is unreliable where the joint σ
comes close to the log's own (a parameter the other logs barely inform, or joint blocks that
disagree among themselves), so the variance of the difference is taken as at least the log's
share ``σ_own² / n_logs`` (below what logs of equal information give, ``σ_own²·(1 − 1/n)``).

The joint fit weighs each log by its white-noise information, not by its σ to believe: where a log's
block σ exceeds its white-noise σ (errors that vary along the drive), the joint estimate leans
towards it more than the σ to believe would. Given each log's white-noise σ, the joint estimate is
taken as the mean of the logs' own weighted by their white-noise information, ``W_j``, and the
variance of the difference is that of this estimator with the σ to believe:
``(1 − W_i)²·σ_i² + Σ_{j≠i} W_j²·σ_j²``, which is ``σ_own² − σ_joint²`` again where every log's σ to
believe is its white-noise σ.

A difference beyond :data:`~nlp_calib.results.checks.CONSISTENCY_SIGMAS` of that in any parameter
of any log says the logs do not come from one robot (or one of them is not what it seems): the
joint result is then not to be trusted, and the check names the parameter and the logs. The
threshold allows for the many comparisons (every parameter of every log) and for the jackknife σ
being itself estimated from ten blocks; the false-alarm rate it gives on pairs of simulated logs
of one robot is measured by ``benchmarks/fault_study.py``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from nlp_calib.results.checks import ConsistencyCheck


def compare_logs(
    names: tuple[str, ...],
    logs: Sequence[str],
    joint: np.ndarray,
    std_joint: np.ndarray,
    own: np.ndarray,
    std_own: np.ndarray,
    held: Sequence[set[str]] = (),
    white_own: np.ndarray | None = None,
) -> ConsistencyCheck:
    """The check of each log's own estimates ``own`` (n_logs, n_params) with their σ ``std_own``
    against the joint estimates ``joint`` with σ ``std_joint``; parameters a log's fit (or the
    joint fit: ``held[i]`` for log i) held are not compared. ``white_own``: each log's own
    white-noise σ, the joint fit's weights (see the module docstring)."""
    own, std_own = (
        np.atleast_2d(np.asarray(own, dtype=float)),
        np.atleast_2d(np.asarray(std_own, dtype=float)),
    )
    joint, std_joint = np.asarray(joint, dtype=float), np.asarray(std_joint, dtype=float)
    difference = std_own**2 - std_joint[None, :] ** 2
    if white_own is not None:
        difference = _weighted_variance(
            std_own, np.atleast_2d(np.asarray(white_own, dtype=float)), difference
        )
    # The difference of two estimated variances is unreliable where the joint fit is barely more
    # certain than the log's own: never less than the log's share of its own variance.
    var = np.maximum(difference, std_own**2 / max(own.shape[0], 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(np.isfinite(var) & (var > 0), (own - joint[None, :]) / np.sqrt(var), np.nan)
    for i, h in enumerate(held):
        z[i, [n in h for n in names]] = np.nan
    return ConsistencyCheck(tuple(names), tuple(logs), joint, own, z)


def _weighted_variance(believed: np.ndarray, white: np.ndarray, otherwise: np.ndarray) -> np.ndarray:
    """``var(own_i − joint)`` per log and parameter for a joint estimate weighted by the logs'
    white-noise information (``otherwise`` where a log gives a parameter no finite white σ, and for
    a parameter fewer than two logs have: a log's own mount)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        info = np.where(np.isfinite(white) & (white > 0), 1.0 / white**2, np.nan)
        W = info / np.nansum(info, axis=0)
    var_j = W**2 * believed**2
    total = np.nansum(var_j, axis=0)
    out = (1.0 - W) ** 2 * believed**2 + (total[None, :] - var_j)
    shared = np.sum(np.isfinite(info), axis=0) >= 2
    return np.where(np.isfinite(out) & shared[None, :], out, otherwise)
