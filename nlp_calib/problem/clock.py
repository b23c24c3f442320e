"""The reference's time offset inside the problem: each window's motion moved along the encoders' clock.

The encoders are read ``τ`` (``tracker_lag``) earlier than the reference stamps its poses. The
data are re-sampled at ``t − τ₀`` once per log (``τ₀``: the data's own offset, kept with the
windows); the problem then takes ``τ = τ₀ + δ`` as a parameter. Over a window from record ``a`` to
``b`` the robot moved, between the times the reference saw,

    M_τ = E_a(δ) · M · E_b(δ)⁻¹,     E_j(δ) = Δ(k, u_j(δ))

with ``M`` the model's motion over the window's intervals and ``E_j`` its motion over the ``δ``
before record ``j``: the model's increment on the inputs of that stretch, ``δ·ṙ_j`` for an
increment (``ṙ_j`` its rate at record ``j``: its two intervals' travel over their duration) and
the level itself for a level (an angle the model reads as it is). A negative ``δ`` moves along
the stretch after record ``j`` (the increment is then backwards, the exact inverse for the
model's arcs). This is
linear interpolation of the encoders at the shifted time, written symbolically: every consumer
of the problem's Functions (both solvers, the uncertainty, the observability, the refits and the
C export) sees the offset's Jacobian. It is exact to first order in ``δ`` for any drive; the
pipeline re-samples the data at each new estimate, so ``δ`` ends near zero.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from nlp_calib.core.numeric import wrap_angle
from nlp_calib.models.base import KinematicModel
from nlp_calib.symbolic import se2


def level_rows(model: KinematicModel) -> tuple[int, ...]:
    """The rows of ``model``'s inputs that are levels (see :attr:`KinematicModel.level_inputs`)."""
    return tuple(model.input_names.index(n) for n in model.level_inputs)


def stretch_inputs(rate: ca.SX, delta: ca.SX, levels: Sequence[int]) -> ca.SX:
    """The inputs of the ``delta`` seconds before a record whose rates (levels) are ``rate``."""
    return ca.vertcat(*[rate[i] if i in levels else rate[i] * delta for i in range(rate.numel())])


def shifted(
    model: KinematicModel,
    k: ca.SX,
    M: ca.SX,
    ends: tuple[ca.SX, ca.SX],
    delta: ca.SX,
    integration: str,
) -> ca.SX:
    """``E_a(δ)·M·E_b(δ)⁻¹`` (see the module docstring); ``ends`` the rates at the window's ends."""
    levels = level_rows(model)
    E_a, E_b = (model.increment(k, stretch_inputs(r, delta, levels), integration) for r in ends)
    return se2.compose(E_a, se2.compose(M, se2.inverse(E_b)))


def record_rates(inputs: np.ndarray, time_s: np.ndarray, levels: Sequence[int]) -> np.ndarray:
    """Each input's rate (per second; a level: its value) at each record of one log, ``(n_inputs,
    n_records)``: the travel of the two intervals around the record over their duration (one at
    the log's ends), a level the mean of its two intervals' along the shorter arc."""
    n_in, n = inputs.shape[0], time_s.size
    out = np.zeros((n_in, n))
    if n < 2:
        return out
    dt = np.diff(time_s)
    pad = np.zeros((n_in, 1))
    before, after = np.hstack([pad, inputs]), np.hstack([inputs, pad])
    span = np.concatenate([[0.0], dt]) + np.concatenate([dt, [0.0]])
    with np.errstate(divide="ignore", invalid="ignore"):
        rates = np.where(span > 0, (before + after) / span, 0.0)
    out[:] = rates
    for i in levels:
        first, last = (
            np.concatenate([[inputs[i, 0]], inputs[i]]),
            np.concatenate([inputs[i], [inputs[i, -1]]]),
        )
        out[i] = wrap_angle(first + 0.5 * wrap_angle(last - first))
    return out
