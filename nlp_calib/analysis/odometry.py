"""Calibrated odometry of the base link with its covariance, propagated interval by interval.

``T' = T·Δr(u)`` and ``P' = F·P·Fᵀ + G·diag(σ_u²)·Gᵀ`` with ``F = ∂T'/∂T`` and ``G = ∂T'/∂u``
the symbolic Jacobians of the model's increment (the problem's ``odometry_step``), folded over
the intervals with ``mapaccum``. ``σ_u`` is the encoders' noise on the model inputs.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.problem import ProblemFunctions


def propagate(
    fns: ProblemFunctions,
    params: np.ndarray,
    inputs: np.ndarray,
    T_world_base_0: np.ndarray,
    input_std: np.ndarray,
    P0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Poses ``(n + 1, 3)`` and covariances ``(n + 1, 3, 3)`` over the ``n`` intervals of ``inputs``."""
    n = inputs.shape[1]
    P_start = np.zeros((3, 3)) if P0 is None else np.asarray(P0, dtype=float)
    state0 = np.concatenate([np.asarray(T_world_base_0, dtype=float), P_start.ravel(order="F")])
    states = np.empty((n + 1, 12))
    states[0] = state0
    if n:
        fold = fns.odometry_step.mapaccum("odometry", n)
        reps = np.repeat(np.asarray(params, dtype=float).reshape(-1, 1), n, axis=1)
        sig = np.repeat(np.asarray(input_std, dtype=float).reshape(-1, 1), n, axis=1)
        states[1:] = np.asarray(fold(state0, reps, inputs, sig)).T
    return states[:, :3], states[:, 3:].reshape(-1, 3, 3, order="F")
