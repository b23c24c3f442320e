"""The odometry's noise per metre driven and per radian turned, as a filter's process noise takes it.

Each interval's increment covariance from the calibrated inputs' noise (``G·diag(σ_u²)·Gᵀ``, in
the base frame at the interval's start, :mod:`nlp_calib.analysis.odometry`) is split, component
by component (along, across, heading), into a variance per metre driven and one per radian turned
(non-negative least squares on the intervals' |distance| and |turn|): what AMCL's ``odom_alpha``
or a hand-written EKF's process noise ask for. Those rates are then checked on the drift segments
themselves: each segment's covariance grown from them as a filter grows it (``P' = F·P·Fᵀ + Q``,
the heading's noise carried by the distance still to drive), with the reference's own variances,
must hold :data:`~nlp_calib.analysis.odometry.COVERED` of the segments' errors within 2σ, else all
rates are raised by one factor until it does: at least the drift the windows show.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.analysis.odometry import COVERED, Drift
from nlp_calib.analysis.uncertainty import nnls_small
from nlp_calib.core import poses
from nlp_calib.problem import ProblemFunctions
from nlp_calib.problem.windows import over_columns
from nlp_calib.results.handoff import NoiseRates


def _increments(
    fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray, noise: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each interval's base increment ``(n, 3)`` and its covariance's diagonal ``(n, 3)`` in the
    base frame at its start, from each input's 1σ per interval ``noise``."""
    if inputs.shape[1] == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    step = over_columns(fns.odometry_step, np.zeros(12), np.ravel(params), inputs, noise)[0]
    P = step[3:].reshape(3, 3, -1, order="F")
    return step[:3].T, np.stack([P[0, 0], P[1, 1], P[2, 2]], axis=1)


def fit_rates(increments: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """``(2, 3)``: each component's variance per metre and per radian (rows) whose sum over an
    interval's |distance| and |turn| best gives its variance (non-negative least squares)."""
    A = np.c_[np.hypot(increments[:, 0], increments[:, 1]), np.abs(increments[:, 2])]
    scale = np.maximum(np.max(A, axis=0), 1e-12) if A.size else np.ones(2)
    out = np.zeros((2, 3))
    for c in range(3):
        if A.size:
            out[:, c] = nnls_small(A / scale, variances[:, c]) / scale
    return out


def _sums(values: np.ndarray) -> np.ndarray:
    """Cumulative sums with a leading zero, so ``s[j] − s[i]`` sums rows ``i`` to ``j − 1``."""
    return np.concatenate([np.zeros((1, *values.shape[1:])), np.cumsum(values, axis=0)])


def grown_covariances(increments: np.ndarray, rates: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """The covariance ``(S, 3, 3)`` of each span ``(i, j)``'s motion, in the base frame at ``i``,
    grown from each interval's ``Q = diag(rates·(|distance|, |turn|))`` added at its end and
    carried to ``j`` (a heading error turns the rest of the span): by cumulative sums of
    ``Q``'s world-frame terms against the end's position, one pass for every span."""
    track = poses.accumulate(np.zeros(3), increments)
    A = np.c_[np.hypot(increments[:, 0], increments[:, 1]), np.abs(increments[:, 2])]
    q = A @ rates  # (n, 3): along, across, heading per interval
    th = track[:-1, 2]
    c, s = np.cos(th), np.sin(th)
    xx, yy, xy = (
        c * c * q[:, 0] + s * s * q[:, 1],
        s * s * q[:, 0] + c * c * q[:, 1],
        c * s * (q[:, 0] - q[:, 1]),
    )
    e, x, y = q[:, 2], track[1:, 0], track[1:, 1]
    S = _sums(np.stack([xx, yy, xy, e, x * e, y * e, x * x * e, y * y * e, x * y * e], axis=1))
    i, j = spans[:, 0], spans[:, 1]
    a, b, cxy, E, XE, YE, XXE, YYE, XYE = (S[j] - S[i]).T
    xj, yj = track[j, 0], track[j, 1]
    C = np.zeros((spans.shape[0], 3, 3))
    C[:, 0, 0] = a + yj * yj * E - 2.0 * yj * YE + YYE
    C[:, 1, 1] = b + xj * xj * E - 2.0 * xj * XE + XXE
    C[:, 0, 1] = C[:, 1, 0] = cxy - (xj * yj * E - xj * YE - yj * XE + XYE)
    C[:, 0, 2] = C[:, 2, 0] = -(yj * E - YE)
    C[:, 1, 2] = C[:, 2, 1] = xj * E - XE
    C[:, 2, 2] = E
    ci, si = np.cos(track[i, 2]), np.sin(track[i, 2])
    R = np.zeros((spans.shape[0], 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = ci, si, -si, ci, 1.0
    return R @ C @ np.swapaxes(R, 1, 2)


def _ratios(
    drift: Drift, increments: np.ndarray, rates: np.ndarray, known: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """Each segment error's size in its σ ``(S, 3)``: the grown covariance turned into the
    reference's axes at the segment's start, beside the reference's own variances and the readings'
    noise (``known``: those variances and the readings' 1σ per input)."""
    reference_var, floor = known
    C = grown_covariances(increments, rates, drift.spans)
    turn = drift.start_headings
    c, s = np.cos(turn), np.sin(turn)
    R = np.zeros((turn.size, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    P = R @ C @ np.swapaxes(R, 1, 2) + np.einsum("k,skij->sij", reference_var, drift.terms)
    P = P + drift.known(floor)
    sigma = np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2), 0.0, None))
    return np.abs(drift.errors) / np.maximum(sigma, 1e-300)


def _three(v: np.ndarray) -> tuple[float, float, float]:
    return float(v[0]), float(v[1]), float(v[2])


def noise_rates(
    fns: ProblemFunctions,
    params: np.ndarray,
    inputs: np.ndarray,
    noise: np.ndarray,
    checked: tuple[Drift, np.ndarray, np.ndarray],
) -> NoiseRates:
    """The rates from each input's 1σ per interval ``noise`` (its random walk) over ``inputs``,
    checked (and raised where they fall short) on ``checked``: the drift segments over the same
    records, the reference's own position and heading variances and the readings' 1σ per input
    (their rounding, which does not add up per metre)."""
    drift, reference_var, floor = checked
    known = (reference_var, floor)
    increments, variances = _increments(fns, params, inputs, noise)
    rates = fit_rates(increments, variances)
    if drift.spans.shape[0] == 0:
        return NoiseRates(_three(rates[0]), _three(rates[1]), None, 0, 1.0)
    raised = 1.0
    for _ in range(8):
        ratio = _ratios(drift, increments, raised * rates, known)
        need = float(np.quantile(ratio, COVERED)) / 2.0
        if need <= 1.0 + 1e-6 or not np.any(rates):
            break
        raised *= need * need
    coverage = float(np.mean(_ratios(drift, increments, raised * rates, known) <= 2.0))
    return NoiseRates(
        _three(raised * rates[0]),
        _three(raised * rates[1]),
        coverage,
        int(drift.spans.shape[0]),
        raised,
    )
