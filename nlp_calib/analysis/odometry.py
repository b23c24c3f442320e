"""Calibrated odometry of the base link with its covariance, propagated interval by interval.

``T' = T·Δr(u)`` and ``P' = F·P·Fᵀ + G·diag(σ_u²)·Gᵀ`` with ``F = ∂T'/∂T`` and ``G = ∂T'/∂u``
the symbolic Jacobians of the model's increment (the problem's ``odometry_step``), folded over
the intervals with ``mapaccum``. ``σ_u`` is the encoders' noise on the model inputs.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from nlp_calib.analysis.uncertainty import nnls_small
from nlp_calib.core import poses
from nlp_calib.core.numeric import PIECE_SIZES, pieces, robust_spread, wrap_angle
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
        folded = _folded(fns.odometry_step, state0, (params, input_std), inputs)
        states[1:] = folded.T
    return states[:, :3], states[:, 3:].reshape(-1, 3, 3, order="F")


#: Lengths of the folds the intervals are folded with, one after the other (a length repeated), each
#: state written straight into numpy memory bound to the fold's buffer (whole, through CasADi's
#: matrices, 10^6 intervals took ~400 MB of Python floats); each length built once.
FOLD_LENGTHS = PIECE_SIZES


def _folded(
    step: ca.Function, state0: np.ndarray, same: tuple[np.ndarray, np.ndarray], inputs: np.ndarray
) -> np.ndarray:
    """``step`` folded from ``state0`` over the columns of ``inputs`` (``same``: the parameters and
    the inputs' 1σ, the same for every interval), each state ``(rows, n)``: a fold's last state
    starts the next, so the arithmetic is one fold's."""
    n = inputs.shape[1]
    out = np.empty((state0.size, n), order="F")
    params, std = (np.asarray(v, dtype=float).reshape(-1, 1) for v in same)
    bound: dict[int, tuple[ca.FunctionBuffer, Callable[[], None], list[np.ndarray]]] = {}
    state = np.array(state0, dtype=float)
    lo = 0
    for length in pieces(n, FOLD_LENGTHS):
        if length not in bound:
            bound[length] = _bound_fold(step, length, params, std)
        buf, call, held = bound[length]
        hi = lo + length
        held[0][:] = state
        held[2].reshape(length, -1)[:] = inputs[:, lo:hi].T
        res = out[:, lo:hi].reshape(-1, order="F")  # a view: a block of a column-major array's columns
        buf.set_res(0, res.data)
        call()
        state = out[:, hi - 1]
        lo = hi
    return out


def _bound_fold(
    step: ca.Function, length: int, params: np.ndarray, std: np.ndarray
) -> tuple[ca.FunctionBuffer, Callable[[], None], list[np.ndarray]]:
    """The fold of ``length`` intervals with a buffer bound to numpy memory: the state, the
    parameters, the inputs and their 1σ (the step's order), the parameters and 1σ filled."""
    fold = _fold(step, length)
    if not all(fold.sparsity_in(i).is_dense() for i in range(4)) or not fold.sparsity_out(0).is_dense():
        raise ValueError("the odometry step's arguments must be dense to fold in numpy memory")
    buf, call = fold.buffer()
    held = [
        np.zeros(fold.nnz_in(0)),
        np.ravel(np.repeat(params, length, axis=1), order="F"),
        np.zeros(fold.nnz_in(2)),
        np.ravel(np.repeat(std, length, axis=1), order="F"),
    ]
    for i, a in enumerate(held):
        buf.set_arg(i, a.data)
    return buf, call, held


@functools.lru_cache(maxsize=8)
def _fold(step: ca.Function, n: int) -> ca.Function:
    """``step`` folded over ``n`` intervals, built once per length."""
    return step.mapaccum("odometry", n)


#: Segment lengths (records) over which the odometry's drift is compared with the tracker's.
DRIFT_LENGTHS = (25, 100, 400)


def _unit_covariances(
    fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray, T_world_base_0: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The dead-reckoned base track ``(n + 1, 3)`` and, for each input row at unit noise, the
    covariance of every pose from the start ``(n_inputs, n + 1, 3, 3)``: the covariance is linear in
    each input's variance, so any noise level's is a weighted sum of these."""
    n_in = inputs.shape[0]
    covs = []
    track = np.zeros((inputs.shape[1] + 1, 3))
    for k in range(n_in):
        track, cov = propagate(fns, params, inputs, T_world_base_0, np.eye(n_in)[k])
        covs.append(cov)
    return track, np.stack(covs)


def _start_jacobian(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``∂(T_a ⊕ M)/∂T_a`` in world axes, for ``T_a ⊕ M`` at ``b`` (rows of poses: one per row):
    the start's error carried along."""
    F = np.broadcast_to(np.eye(3), (*a.shape[:-1], 3, 3)).copy()
    F[..., 0, 2], F[..., 1, 2] = -(b[..., 1] - a[..., 1]), b[..., 0] - a[..., 0]
    return F


def _turned(C: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """Covariances ``C`` ``(len(turn), …, 3, 3)`` in world axes turned by ``turn``."""
    c, s = np.cos(turn), np.sin(turn)
    R = np.zeros((turn.size, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    extra = (slice(None),) + (None,) * (C.ndim - 3)
    return R[extra] @ C @ np.swapaxes(R, -1, -2)[extra]


def _grown(P: np.ndarray, est: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """``P_j − F·P_i·Fᵀ`` with ``F = ∂T_j/∂T_i``: what poses ``j`` gained since poses ``i``;
    ``(len(i), …, 3, 3)`` for ``P`` ``(…, poses, 3, 3)``."""
    F = _start_jacobian(est[i], est[j])
    Pi, Pj = np.moveaxis(P[..., i, :, :], -3, 0), np.moveaxis(P[..., j, :, :], -3, 0)
    extra = (slice(None),) + (None,) * (Pi.ndim - 3)
    return Pj - F[extra] @ Pi @ np.swapaxes(F, -1, -2)[extra]


def running_sums(values: np.ndarray) -> np.ndarray:
    """Cumulative sums with a leading zero, so ``s[j] − s[i]`` sums rows ``i`` to ``j − 1``."""
    return np.concatenate([np.zeros((1, *values.shape[1:])), np.cumsum(values, axis=0)])


def grown_variances(increments: np.ndarray, q: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """The covariance ``(S, 3, 3)`` of each span ``(i, j)``'s motion, in the base frame at ``i``,
    grown from each interval's ``diag(q)`` (``q`` ``(n, 3)``: along, across, heading, in the base
    frame at its start) added at its end and carried to ``j`` (a heading error turns the rest of
    the span): by cumulative sums of its world-frame terms against the end's position, one pass
    for every span."""
    track = poses.accumulate(np.zeros(3), increments)
    th = track[:-1, 2]
    c, s = np.cos(th), np.sin(th)
    xx, yy, xy = (
        c * c * q[:, 0] + s * s * q[:, 1],
        s * s * q[:, 0] + c * c * q[:, 1],
        c * s * (q[:, 0] - q[:, 1]),
    )
    e, x, y = q[:, 2], track[1:, 0], track[1:, 1]
    S = running_sums(np.stack([xx, yy, xy, e, x * e, y * e, x * x * e, y * y * e, x * y * e], axis=1))
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


def one_arc_errors(
    fns: ProblemFunctions, params: np.ndarray, inputs: np.ndarray, fine: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """Each interval's increment as the model integrates it, one arc on the inputs over the whole
    interval, less the increment its joints' own samples integrate to (``fine``: the inputs
    between those samples, and where the intervals' ends fall among them), ``(n, 3)`` in the base
    frame at its start: a drive that changes inside an interval (reverses, or swings its turn one
    way then the other) is not one arc, and that error is the model's, not the wheels' noise."""
    u, at = fine
    zero = np.zeros(inputs.shape[0])
    coarse = propagate(fns, params, inputs, np.zeros(3), zero)[0]
    track = propagate(fns, params, u, np.zeros(3), zero)[0]
    a, b = poses.between(coarse[:-1], coarse[1:]), poses.between(track[at[:-1]], track[at[1:]])
    return np.c_[a[:, :2] - b[:, :2], wrap_angle(a[:, 2] - b[:, 2])]


def segment_covariance(
    P: np.ndarray, est: np.ndarray, i: np.ndarray, j: np.ndarray, turn: np.ndarray
) -> np.ndarray:
    """The covariance of poses ``j`` dead-reckoned from poses ``i`` (their covariance taken away),
    in world axes turned by ``turn``."""
    return _turned(_grown(P, est, i, j), turn)


def readings_covariance(
    P: np.ndarray, est: np.ndarray, i: np.ndarray, j: np.ndarray, turn: np.ndarray
) -> np.ndarray:
    """The covariance of segments ``i → j`` from one reading's noise at each end, at unit noise
    (``P`` as :func:`segment_covariance`'s): a position read at ``i`` enters the first interval only, one
    read at ``j`` the last (those between enter one interval up and the next down, and cancel):
    the first interval's gain carried to ``j`` and the last's."""
    first = _grown(P, est, i, i + 1)
    F = _start_jacobian(est[i + 1], est[j])
    extra = (slice(None),) + (None,) * (first.ndim - 3)
    carried = F[extra] @ first @ np.swapaxes(F, -1, -2)[extra]
    return _turned(carried + _grown(P, est, j - 1, j), turn)


def _tracker_terms(start: np.ndarray, end: np.ndarray, levers: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The error's covariance per unit variance of the tracker's position and of its heading, at
    both ends of segments restarted from the tracker (rows of poses): ``(rows, 2, 3, 3)``. The base
    poses are the tracker's through the mount, so its heading's noise moves the base's position
    too, by the lever from the sensor to the base (``levers``: at the start and the end, world
    axes): across a forward mount's lever (the demo's tracker 1.6 m ahead: 3 mm at 2 mrad)."""
    F = _start_jacobian(start, end)[:, None]
    units = []
    for lever in levers:
        v = np.c_[-lever[:, 1], lever[:, 0], np.ones(lever.shape[0])]
        heading = v[:, :, None] * v[:, None, :]
        units.append(np.stack([np.broadcast_to(np.diag([1.0, 1.0, 0.0]), heading.shape), heading], axis=1))
    return F @ units[0] @ np.swapaxes(F, -1, -2) + units[1]


def restarted(
    reference: np.ndarray, track: np.ndarray, spans: np.ndarray, lever: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each span ``(i, j)``'s error ``(S, 3)`` (world axes) when the odometry ``track`` is restarted
    from the ``reference`` base poses at ``i``, and the reference's own noise terms of it
    ``(S, 2, 3, 3)`` (:func:`_tracker_terms`; ``lever`` ``(n, 2)`` as :func:`segment_drift`'s)."""
    i, j = spans[:, 0], spans[:, 1]
    again = poses.compose(reference[i], poses.between(track[i], track[j]))
    errors = np.c_[again[:, :2] - reference[j, :2], wrap_angle(again[:, 2] - reference[j, 2])]
    return errors, _tracker_terms(reference[i], again, (lever[i], lever[j]))


@dataclass(frozen=True)
class Drift:
    """Segments of the odometry against a reference: each error ``(S, 3)``, each input's unit-noise
    covariance of it ``(S, n_inputs, 3, 3)``, and the reference's own noise terms ``(S, 2, 3, 3)``
    (per unit variance of its position and of its heading, see :func:`_tracker_terms`); each
    segment's first and last record ``(S, 2)``, the reference's heading at its start ``(S,)`` and
    each input's unit-noise covariance of its two ends' readings ``(S, n_inputs, 3, 3)`` (see
    :func:`readings_covariance`: a resolution's rounding, which does not add up along a drive);
    ``arcs``: the one-arc integration's errors' covariance of each ``(S, 3, 3)``
    (:func:`one_arc_errors`, squared, grown as a random walk's; None: none known)."""

    errors: np.ndarray
    covs: np.ndarray
    terms: np.ndarray
    spans: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=int))
    start_headings: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reads: np.ndarray | None = None
    arcs: np.ndarray | None = None

    def known(self, floor: np.ndarray) -> np.ndarray:
        """The errors' covariance ``(S, 3, 3)`` from a reading noise of ``floor`` (1σ per input),
        and the one-arc integration's (``arcs``): known, so no noise is fitted to them."""
        out = np.zeros((self.errors.shape[0], 3, 3)) if self.arcs is None else self.arcs
        if self.reads is None:
            return out
        return out + np.einsum("k,skij->sij", np.asarray(floor, dtype=float) ** 2, self.reads)


def segment_drift(
    fns: ProblemFunctions,
    params: np.ndarray,
    inputs: np.ndarray,
    T_world_base: np.ndarray,
    parts: Sequence[tuple[int, int]],
    good: np.ndarray,
    lengths: Sequence[int] = DRIFT_LENGTHS,
    lever: np.ndarray | None = None,
    arc: np.ndarray | None = None,
) -> Drift:
    """The odometry against the reference base poses over segments of ``lengths`` records inside
    each fault-free part (half-overlapping, ends at good reference poses), each restarted from the
    reference at its start; ``lever`` ``(n, 2)``: the base's position less the sensor's at each
    record (world axes; None: none), through which the reference's heading noise reaches the
    base's position; ``arc`` ``(n - 1, 3)``: each interval's one-arc integration error
    (:func:`one_arc_errors`; None: none known), its square grown over each segment."""
    lever = np.zeros((T_world_base.shape[0], 2)) if lever is None else np.asarray(lever, dtype=float)
    errors, covs, terms, spans, headings, reads, arcs = [], [], [], [], [], [], []
    for a, b in parts:
        if b - a < 2:
            continue
        ref = T_world_base[a:b]
        est, P = _unit_covariances(fns, params, inputs[:, a : b - 1], ref[0])
        for L in dict.fromkeys(lengths):
            i = np.arange(0, b - a - L, max(L // 2, 1))
            i = i[good[a + i] & good[a + i + L]]
            j = i + L
            error, term = restarted(ref, est, np.c_[i, j], lever[a:])
            errors.append(error)
            covs.append(segment_covariance(P, est, i, j, ref[i, 2] - est[i, 2]))
            reads.append(readings_covariance(P, est, i, j, ref[i, 2] - est[i, 2]))
            terms.append(term)
            spans.append(np.c_[a + i, a + j])
            headings.append(ref[i, 2])
            if arc is not None:
                arcs.append(_arcs_grown(est, arc[a : b - 1], np.c_[i, j], ref[i, 2]))
    n_in = inputs.shape[0]
    if not errors:
        return Drift(np.zeros((0, 3)), np.zeros((0, n_in, 3, 3)), np.zeros((0, 2, 3, 3)))
    stacked = (np.concatenate(errors), np.concatenate(covs), np.concatenate(terms))
    where = (np.concatenate(spans).astype(int), np.concatenate(headings))
    return Drift(*stacked, *where, np.concatenate(reads), np.concatenate(arcs) if arcs else None)


def _arcs_grown(track: np.ndarray, arc: np.ndarray, spans: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """The one-arc errors ``arc``' squares grown over each span ``(i, j)`` of ``track``
    (:func:`grown_variances`), in world axes at the reference's ``heading`` at ``i`` (as the
    segments' errors are)."""
    C = grown_variances(poses.between(track[:-1], track[1:]), arc**2, spans)
    return _turned(C, heading)


#: How many σ of its predicted variance a segment's error may lie out before the moments leave it
#: out of their fit (5σ: a false alarm in 10⁶ Gaussian errors). A mean of squares is ruled by its
#: largest: one reference pose the fault checks missed (a tracker that held a stale pose until the
#: base drove off, then jumped 2.5 rad) made a motion capture's heading noise 88 mrad.
FAR_OUT = 5.0


def _far_by_length(drift: Drift) -> np.ndarray:
    """Which segments' errors lie over :data:`FAR_OUT` robust σ (1.4826 median absolute deviations)
    of those of their own length from their median, in any component."""
    lengths = drift.spans[:, 1] - drift.spans[:, 0]
    far = np.zeros(lengths.size, dtype=bool)
    for length in np.unique(lengths):
        on = lengths == length
        centre, scale = robust_spread(drift.errors[on])
        far[on] = np.any(np.abs(drift.errors[on] - centre) > FAR_OUT * np.maximum(scale, 1e-12), axis=1)
    return far


def _steps_itself(reference: np.ndarray, a: int, b: int) -> bool:
    """Whether the reference's own increment over one of the intervals ``[a, b)`` departs from the
    mean of its neighbours' by over :data:`FAR_OUT` robust σ of every interval's such departure,
    in any component: the reference stepped there (the wheels slipping do not move it so)."""
    d = np.diff(np.asarray(reference, dtype=float), axis=0)
    d[:, 2] = wrap_angle(d[:, 2])
    if d.shape[0] < 3:
        return False
    bent = d[1:-1] - 0.5 * (d[:-2] + d[2:])  # row m: interval m + 1
    scale = robust_spread(bent)[1]
    at = bent[max(a - 1, 0) : max(b - 1, 1)]
    return bool(np.any(np.abs(at) > FAR_OUT * np.maximum(scale, 1e-12)))


def reference_step(drift: Drift, reference: np.ndarray) -> tuple[int, int] | None:
    """The intervals ``[a, b)`` (records ``a`` to ``b``) a step of the ``reference`` (its base
    poses ``(n, 3)``) lies in, where the fault checks missed one (a tracker that held a wrong pose,
    then relocked on its target): the intervals two far-out segments (:func:`_far_by_length`) or
    more all cross, every segment across them far out, and over which the reference's own
    increments step (:func:`_steps_itself`). One event, not a drift: a random walk's rates grown
    to cover it are 10³ too wide, a noise per interval fitted with it as large as the motion.
    None: no such step."""
    far = _far_by_length(drift)
    if np.count_nonzero(far) < 2:
        return None
    i, j = drift.spans[far, 0], drift.spans[far, 1]
    crossed = np.zeros(int(j.max()) + 1, dtype=int)
    np.add.at(crossed, i, 1)
    np.add.at(crossed, j, -1)
    k = int(np.argmax(np.cumsum(crossed)))
    across = (i <= k) & (k < j)
    a, b = int(i[across].max()), int(j[across].min())
    every = (drift.spans[:, 0] <= a) & (drift.spans[:, 1] >= b)
    if np.count_nonzero(across) < 2 or not np.all(far[every]) or not _steps_itself(reference, a, b):
        return None
    return a, b


def weights(y: np.ndarray, predicted: np.ndarray, far_out: float | None = FAR_OUT) -> np.ndarray:
    """Each squared error's weight ``y`` in a fit of variances: the inverse of its prediction (a
    χ² with one degree of freedom spreads as its expectation), 0 for one over ``far_out`` σ of
    it where such errors are a few: no more than the 1 − :data:`COVERED` the covering steps need
    not hold (more are the drift itself, a model's error: kept; None: none left out). Only the fit
    leaves them out: the covering steps count every segment."""
    floored = np.maximum(predicted, 1e-6 * float(np.max(predicted)))
    far = y > (np.inf if far_out is None else far_out**2) * floored
    if np.count_nonzero(far) > (1.0 - COVERED) * y.size:
        far[:] = False
    return np.where(far, 0.0, 1.0 / floored)


def moments(
    A: np.ndarray, y: np.ndarray, known: np.ndarray, predicted: np.ndarray, far_out: float | None = FAR_OUT
) -> np.ndarray:
    """Non-negative variances ``x`` with ``A·x + known ≈ y`` (squared errors), each equation
    weighted as :func:`weights` gives (far out ones left out), refined a few times."""
    var = np.zeros(A.shape[1])
    for _ in range(4):
        w = weights(y, predicted, far_out)
        var = nnls_small(A * w[:, None], (y - known) * w)
        predicted = A @ var + known
    return var


#: How much the squared errors' misfit (in their own variances) may grow when the odometry's
#: noise is raised from what fits best: 2σ of a parameter.
ALLOWED = 4.0


class _Profile:
    """The squared errors' misfit with the inputs' variances ``scale·share`` (each input an equal
    share of the predicted drift), the reference's refitted, in the variances of the best fit's
    predictions; ``y``: the squared errors less what the readings' known noise explains."""

    def __init__(
        self,
        A: np.ndarray,
        y: np.ndarray,
        n_in: int,
        predicted: np.ndarray,
        top: float,
        far_out: float | None,
    ) -> None:
        self.A, self.y, self.n_in, self.top = A, y, n_in, top
        self.w = weights(y, predicted, far_out)
        self.share = 1.0 / np.maximum(np.mean(A[:, :n_in], axis=0), 1e-300)

    def fit(self, scale: float, least: np.ndarray) -> np.ndarray:
        inputs = np.maximum(scale * self.share, least)
        rest = (self.y - self.A[:, : self.n_in] @ inputs) * self.w
        return np.r_[inputs, nnls_small(self.A[:, self.n_in :] * self.w[:, None], rest)]

    def misfit(self, x: np.ndarray) -> float:
        return 0.5 * float(np.sum(((self.y - self.A @ x) * self.w) ** 2))


def _largest(profile: _Profile, least: np.ndarray) -> np.ndarray:
    """The variances with the largest input noise (along the equal shares, never below ``least``)
    whose misfit stays within :data:`ALLOWED` of the best: the most the segments allow the
    odometry to drift, the reference taking the rest."""
    scales = np.r_[0.0, profile.top * np.logspace(-8, 2, 51)]
    misfits = np.array([profile.misfit(profile.fit(s, least)) for s in scales])
    best = float(misfits.min())
    ok = np.flatnonzero(misfits <= best + ALLOWED)
    lo = float(scales[ok[-1]])
    if ok[-1] == scales.size - 1:
        return profile.fit(lo, least)
    hi = float(scales[ok[-1] + 1])
    for _ in range(12):  # between the grid's last allowed scale and its first not
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if profile.misfit(profile.fit(mid, least)) <= best + ALLOWED else (lo, mid)
    return profile.fit(lo, least)


def _diagonals(C: np.ndarray) -> np.ndarray:
    """The diagonals of covariances ``(S, …, 3, 3)`` stacked component by component: ``(3·S, …)``."""
    d = np.diagonal(C, axis1=-2, axis2=-1)
    return np.concatenate([d[..., c] for c in range(3)])


def drift_noise(
    drift: Drift,
    floor: np.ndarray,
    credited: tuple[bool, bool] = (True, True),
    far_out: float | None = FAR_OUT,
) -> tuple[np.ndarray, np.ndarray]:
    """Each input's 1σ noise per interval whose propagated covariance (a random walk: slip,
    jitter) explains the observed drift beside the readings' own noise ``floor`` (the encoders'
    quantisation, counted once at each end of a segment: it does not add up along a drive), and
    the reference's own position and heading variances (those ``credited``; the others 0): the
    method of moments, the squared errors against the unit covariances' diagonals and the
    reference's noise terms. A reference's noise and the wheels' over short segments look alike,
    so the best fit's split is unstable (a drift under the reference's noise goes either way); the
    inputs get the largest noise the segments allow (within :data:`ALLOWED` of the best fit's
    misfit), at least the best fit's: a filter must not trust the wheels beyond what the data show
    of them. An input with no floor is exact (an interval's duration) and keeps no noise.
    ``far_out``: the errors the moments leave out (:func:`weights`; None: none)."""
    floor = np.asarray(floor, dtype=float)
    noisy = floor > 0
    n_in = int(noisy.sum())
    errors = drift.errors
    if errors.shape[0] < 3 * (n_in + 2) or n_in == 0:
        return floor, np.zeros(2)
    terms = np.flatnonzero(credited)
    A = _diagonals(np.concatenate([drift.covs[:, noisy], drift.terms[:, terms]], axis=1))
    y = np.concatenate([errors[:, c] ** 2 for c in range(3)])
    known = _diagonals(drift.known(floor))
    start = np.repeat([max(float(np.mean(errors[:, c] ** 2)), 1e-300) for c in range(3)], len(errors))
    point = moments(A, y, known, start, far_out)
    predicted = np.maximum(A @ point + known, 1e-300)
    var = _largest(_Profile(A, y - known, n_in, predicted, float(np.mean(y)), far_out), point[:n_in])
    noise = np.zeros_like(floor)
    noise[noisy] = np.sqrt(var[:n_in])
    reference = np.zeros(2)
    reference[terms] = var[n_in:]
    return noise, reference


def _sigmas(drift: Drift, noise: np.ndarray, floor: np.ndarray, reference_var: np.ndarray) -> np.ndarray:
    """Each segment error's 1σ ``(S, 3)`` with ``noise``, the readings' ``floor`` and the
    reference's variances."""
    weights = np.concatenate([np.asarray(noise, dtype=float) ** 2, reference_var])
    P = np.einsum("k,skij->sij", weights, np.concatenate([drift.covs, drift.terms], axis=1))
    P = P + drift.known(floor)
    return np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2), 0.0, None))


def drift_coverage(
    drift: Drift, noise: np.ndarray, floor: np.ndarray, reference_var: np.ndarray, k: float = 2.0
) -> float | None:
    """The share of segment errors (each component) within ``k`` σ of the odometry's propagated
    covariance with ``noise`` and the readings' ``floor`` (and the reference's own noise,
    ``reference_var``: zero against truth); None without a segment to judge it by."""
    if drift.errors.shape[0] == 0:
        return None
    return float(np.mean(np.abs(drift.errors) <= k * _sigmas(drift, noise, floor, reference_var)))


#: The share of segment errors within 2σ a calibrated noise must reach: a Gaussian's.
COVERED = 0.95


def covered_margin(samples: float) -> float:
    """Two binomial σ of the share of ``samples`` independent errors within 2σ about
    :data:`COVERED`: how far a share counted on them strays from it by sampling alone."""
    return 2.0 * float(np.sqrt(COVERED * (1.0 - COVERED) / max(samples, 1.0)))


def beyond_motion(inputs: np.ndarray, noise: np.ndarray) -> tuple[int, ...]:
    """The inputs (rows of ``inputs``, one column per interval) whose calibrated noise per interval
    ``noise`` reaches the scale of their own values over the drive (the 95th percentile of the
    nonzero ones): a random walk that large is not the readings' noise but an error of the model
    or the clocks that the drift segments show, and a covariance grown from it none a filter can
    use (on the real log with the seed formulation, 1.8 traction revolutions per 8 ms interval)."""
    out = []
    for k, row in enumerate(np.abs(np.asarray(inputs, dtype=float))):
        moving = row[row > 0]
        if moving.size and float(noise[k]) >= float(np.quantile(moving, 0.95)):
            out.append(k)
    return tuple(out)


def beyond_motion_words(
    names: Sequence[str], units: Mapping[str, str], noise: np.ndarray, beyond: Sequence[int]
) -> str:
    """Why no covariance is stated for the inputs ``beyond`` (:func:`beyond_motion`) of ``noise``."""
    said = ", ".join(f"{names[k]} {float(noise[k]):.3g} {units.get(names[k], '')}".rstrip() for k in beyond)
    return (
        "the drift against the reference calibrates a noise per interval as large as the inputs' own "
        f"values ({said}): the model's or the clocks' error, not noise a filter can use"
    )


def covering_noise(
    drift: Drift, noise: np.ndarray, floor: np.ndarray, reference_var: np.ndarray | None = None
) -> np.ndarray:
    """``noise`` raised, where its propagated 2σ holds fewer than :data:`COVERED` of the segment
    errors (x, y and heading together), by adding to every noisy input's variance one share of
    their mean variance, the smallest that makes it hold them: the odometry's noise is at least
    the drift the segments show (errors that do not grow as a random walk, such as a slow
    encoder's timing, are still covered at the segments' own length), shared by the inputs the
    moments could not tell apart. The errors are held against the odometry's σ and the reference's
    own variances (``reference_var``, where the moments told them apart: a tracker's poses);
    without them (over a window of one increment the reference's noise and the wheels' cannot be
    told apart) against the odometry's alone: a filter must not trust the wheels for what the
    windows show they miss."""
    noise = np.asarray(noise, dtype=float).copy()
    noisy = np.asarray(floor, dtype=float) > 0
    if drift.errors.shape[0] == 0 or not noisy.any():
        return noise
    floor = np.asarray(floor, dtype=float)
    for _ in range(8):
        ref = np.zeros(drift.terms.shape[1]) if reference_var is None else reference_var
        sigma = _sigmas(drift, noise, floor, ref)
        ratio = np.abs(drift.errors) / np.maximum(sigma, 1e-300)
        need = float(np.quantile(ratio, COVERED)) / 2.0
        if need <= 1.0 + 1e-6:
            break
        # One share of the inputs' mean variance (the readings' where the drift showed none).
        share = float(np.mean(noise[noisy] ** 2)) or float(np.mean(floor[noisy] ** 2))
        noise[noisy] = np.sqrt(noise[noisy] ** 2 + (need**2 - 1.0) * share)
    return noise
