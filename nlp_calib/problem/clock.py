"""The reference's time offset inside the problem: each window's motion moved along the encoders' clock.

The encoders are read ``τ`` (``tracker_lag``) earlier than the reference stamps its poses. The
data are re-sampled at ``t − τ₀`` once per log (``τ₀``: the data's own offset, kept with the
windows); the problem then takes ``τ = τ₀ + δ`` as a parameter. Over a window from record ``a`` to
``b`` the robot moved, between the times the reference saw,

    M_τ = E_a(δ) · M · E_b(δ)⁻¹,     E_j(δ) = δ·ξ_j  (to first order in δ)

with ``M`` the model's motion over the window's intervals and ``E_j`` its motion over the ``δ``
before record ``j``: ``ξ_j`` is the base's velocity there, the model's increment per second of a
stretch whose inputs move at their rates at record ``j`` (an increment: its two intervals' travel
over their duration; a level, an angle the model reads as it is: its value). A negative ``δ``
moves along the stretch after record ``j``. This is the encoders read at the shifted time,
written symbolically, to first order (products of the two ends' small motions dropped): every
consumer of the problem's Functions (both solvers, the uncertainty, the observability, the refits
and the C export) sees the offset's Jacobian at ``δ = 0``. The rates at a record are the samples'
either side of it (:func:`record_rates`, :meth:`~nlp_calib.logs.log.JointStream.slopes`), not the
interval's after it: a reading's own noise has then no weight in its rate, which a window that ends
on it would otherwise meet in the offset's derivative (a biased offset). The pipeline re-samples the
data at each new estimate, so ``δ`` ends near zero.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from nlp_calib.core.numeric import wrap_angle
from nlp_calib.models.base import KinematicModel


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
    """``E_a(δ)·M·E_b(δ)⁻¹`` to first order in ``δ`` (see the module docstring); ``ends`` the rates
    at the window's ends."""
    a, b = (delta * velocity(model, k, r, integration) for r in ends)
    # E_a·M·E_b⁻¹ to first order in the small motions a and b (their products dropped).
    c, s = ca.cos(M[2]), ca.sin(M[2])
    return ca.vertcat(
        M[0] + a[0] - a[2] * M[1] - c * b[0] + s * b[1],
        M[1] + a[1] + a[2] * M[0] - s * b[0] - c * b[1],
        M[2] + a[2] - b[2],
    )


def velocity(model: KinematicModel, k: ca.SX, rate: ca.SX, integration: str) -> ca.SX:
    """The base's velocity ``(v_x, v_y, ω)`` at a record whose inputs' rates (levels) are ``rate``:
    the model's increment per second of the stretch, its derivative in the stretch's length."""
    t = ca.SX.sym("t")
    step = model.increment(k, stretch_inputs(rate, t, level_rows(model)), integration)
    return ca.substitute(ca.jacobian(step, t), t, ca.DM(0.0))


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
