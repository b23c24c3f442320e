"""The odometry's noise per metre driven and per radian turned, as a filter's process noise takes it.

A rate per metre and per radian for each component (along, across, heading) is what AMCL's
``odom_alpha`` or a hand-written EKF's process noise ask for. Each interval adds
``Q = diag(rates·(|distance|, |turn|))`` in the base frame at its start, grown over a span as a
filter grows it (``P' = F·P·Fᵀ + Q``, the heading's noise carried by the distance still to drive:
:func:`grown_covariances`); the rates are fitted on the drift segments themselves, component by
component (:func:`segment_rates`), beside the reference's own variances (its noise does not grow
with a segment's length, the wheels' does) and the calibration's constant errors (a wheel's scale,
a heading error per metre or per radian, the clocks' offset: they grow faster still, the same on
every segment, so they are regressed on the errors, :func:`systematic_shapes`, and counted over the
shortest segments). A base that pivots turns its heading on the spot by a rate per radian of its
own (:func:`on_spot`: a skid-steer's wheels scrub there), fitted apart from an arc's, and so is its
constant error there: one rate for both gives every arc a pivot's drift. A rate the segments do
not show (a car's wheels under its device's 2 cm) is the joints' own noise's
(:mod:`nlp_calib.analysis.jitter`) where they show one, else the most the segments allow of it
(:data:`BOUND` σ above its fit), said (``bounded``): the inputs' noise propagated (one noise per
interval, which a pivot's drift rules) only where the segments cannot tell it apart. A component
whose 2σ holds fewer than :data:`~nlp_calib.analysis.odometry.COVERED` of the segments' errors gets
the smallest share of the inputs' noise's rates that makes it hold them, each rate on the segments
it is stated for (the pivots' heading rate on those that pivot): at least the drift the windows
show.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from nlp_calib.analysis.odometry import (
    COVERED,
    Drift,
    covered_margin,
    grown_variances,
    moments,
    propagate,
    readings_covariance,
    running_sums,
    weights,
)
from nlp_calib.analysis.pivots import pivot_intervals
from nlp_calib.analysis.uncertainty import nnls_small
from nlp_calib.core import poses
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.problem import ProblemFunctions
from nlp_calib.problem.windows import over_columns
from nlp_calib.results.handoff import NoiseRates


def base_increments(
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


def grown_covariances(
    increments: np.ndarray, rates: np.ndarray, spans: np.ndarray, amounts: np.ndarray | None = None
) -> np.ndarray:
    """The covariance ``(S, 3, 3)`` of each span ``(i, j)``'s motion, in the base frame at ``i``,
    grown from each interval's ``Q = diag(rates·(|distance|, |turn|))`` added at its end and
    carried to ``j`` (a heading error turns the rest of the span; :func:`grown_variances`).
    ``amounts`` ``(n, 2)``: what the rates multiply instead of each interval's |distance| and
    |turn| (a rate per radian turned on the spot: the pivots' turns, 0 elsewhere)."""
    A = np.c_[np.hypot(increments[:, 0], increments[:, 1]), np.abs(increments[:, 2])]
    if amounts is not None:
        A = np.asarray(amounts, dtype=float)
    return grown_variances(increments, A @ rates, spans)


def on_spot(increments: np.ndarray) -> np.ndarray:
    """``(n, 2)``: what a rate per radian turned on the spot multiplies over each interval (0 per
    metre; the radians turned where the base pivots, :func:`~nlp_calib.analysis.pivots.pivot_intervals`)."""
    turned = np.abs(increments[:, 2]) * pivot_intervals(increments)
    return np.c_[np.zeros(turned.size), turned]


def _arcs(increments: np.ndarray) -> np.ndarray:
    """``(n, 2)``: each interval's |distance| and the radians it turns other than on the spot."""
    spun = on_spot(increments)
    return np.c_[np.hypot(increments[:, 0], increments[:, 1]), np.abs(increments[:, 2]) - spun[:, 1]]


def rates_covariances(
    increments: np.ndarray, rates: NoiseRates, spans: np.ndarray, arc: np.ndarray | None = None
) -> np.ndarray:
    """The rates' covariance of each span ``(i, j)``'s motion ``(S, 3, 3)`` (:func:`grown_covariances`),
    the heading's per radian turned on the spot ``rates.on_spot`` in place of ``per_radian``'s;
    with ``arc`` ``(n, 3)``, each interval's one-arc integration error, its square grown beside them
    (:func:`~nlp_calib.analysis.odometry.one_arc_errors`: the odometry integrated one arc per
    interval carries it, a filter integrating the joints' own samples does not)."""
    beside = np.zeros((spans.shape[0], 3, 3)) if arc is None else grown_variances(increments, arc**2, spans)
    return beside + _rates_grown(increments, rates, spans)


def _rates_grown(increments: np.ndarray, rates: NoiseRates, spans: np.ndarray) -> np.ndarray:
    per = np.array([rates.per_metre, rates.per_radian])
    if rates.on_spot is None:
        return grown_covariances(increments, per, spans)
    heading = np.zeros((2, 3))
    heading[1, 2] = 1.0
    per[1, 2] = 0.0
    return (
        grown_covariances(increments, per, spans)
        + grown_covariances(increments, rates.per_radian[2] * heading, spans, _arcs(increments))
        + grown_covariances(increments, rates.on_spot * heading, spans, on_spot(increments))
    )


def model_covariances(
    fns: ProblemFunctions,
    params: np.ndarray,
    inputs: np.ndarray,
    noise: tuple[NoiseRates, np.ndarray],
    spans: np.ndarray,
    arc: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The one noise model's covariance of each span ``(i, j)``'s motion ``(S, 3, 3)`` (``j > i``),
    in the base frame at ``i``, and the track dead-reckoned from the origin ``(n + 1, 3)``: the
    rates per metre and per radian grown as a filter grows them, beside each end's reading's
    rounding (``noise``: the rates, each input's reading 1σ), and ``arc``'s one-arc integration
    errors where the track integrates one arc per interval (:func:`rates_covariances`). Every
    covariance the tool hands off (the controller's diagonals, ``nlp-calib odometry``'s) is one of
    these."""
    rates, floor = noise
    track, P = propagate(fns, params, inputs, np.zeros(3), np.asarray(floor, dtype=float))
    increments = poses.between(track[:-1], track[1:])
    i, j = spans[:, 0], spans[:, 1]
    return rates_covariances(increments, rates, spans, arc) + readings_covariance(
        P, track, i, j, -track[i, 2]
    ), track


def _unit_growth(increments: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """Each rate's covariance of every span at unit rate ``(8, S, 3, 3)`` (per metre along, across,
    heading, then per radian; then the heading's per radian turned on an arc, and on the spot): a
    span's covariance is linear in the rates."""
    units = np.eye(6).reshape(6, 2, 3)
    heading = np.zeros((2, 3))
    heading[1, 2] = 1.0
    grown = [grown_covariances(increments, unit, spans) for unit in units]
    split = [
        grown_covariances(increments, heading, spans, a) for a in (_arcs(increments), on_spot(increments))
    ]
    return np.stack([*grown, *split])


#: The rates :func:`segment_rates` fits among :func:`_unit_growth`'s: the heading's per radian on
#: an arc and on the spot apart (a pivot's scrub would otherwise give every arc its drift).
FITTED = np.array([0, 1, 2, 3, 4, 6, 7])


def _local(drift: Drift, floor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The segments' errors ``(S, 3)``, the readings' rounding's covariance of them ``(S, 3, 3)``
    and the reference's noise terms ``(2, S, 3, 3)`` (per unit variance of its position and of its
    heading), in the reference's axes at each segment's start (along, across, heading, as the rates'
    covariances are)."""
    c, s = np.cos(drift.start_headings), np.sin(drift.start_headings)
    R = np.zeros((c.size, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, s, -s, c, 1.0
    Rt = np.swapaxes(R, 1, 2)
    terms = R[None] @ np.moveaxis(drift.terms, 1, 0) @ Rt[None]
    return np.einsum("sij,sj->si", R, drift.errors), R @ drift.known(floor) @ Rt, terms


def _ratios(units: np.ndarray, rates: np.ndarray, errors: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Each segment error's size in its σ ``(S, 3)``: the rates' grown covariance beside the
    reference's own variances and the readings' rounding (``known`` ``(S, 3, 3)``)."""
    P = np.einsum("k,ksij->sij", np.ravel(rates), units) + known
    sigma = np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2), 0.0, None))
    return np.abs(errors) / np.maximum(sigma, 1e-300)


#: Which of :func:`systematic_shapes` the odometry's own error makes (a wheel's scale, a heading
#: error per metre or per radian, the clocks' offset, a pivot's mean slip); one across the motion
#: is a mount's yaw, the reference's.
ODOMETRY_SHAPES = np.array([1.0, 0.0, 1.0, 1.0, 1.0, 1.0])

#: Which of :func:`systematic_shapes` grows on the pivots alone (a heading error per radian turned
#: on the spot): its variance is the pivots' rate, not an arc's.
SPOT_SHAPE = 5


def systematic_shapes(increments: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """What a constant error of the calibration makes of each span ``(i, j)``'s motion, in the base
    frame at ``i`` ``(6, S, 3)``: a scale of the distance along the motion, one across it, a heading
    error per metre driven and one per radian turned (each signed as the motion: a wheel's radius,
    a mount's yaw, a steer offset, a track), an offset of the reference's clock by one
    interval, and a heading error per radian turned on the spot (a skid-steer's pivots slipping
    one way more than the other), at unit size. It is the same
    on every segment, so the segments' errors regress on it; a random walk's do not."""
    track = poses.accumulate(np.zeros(3), increments)
    xy = track[:, :2]
    distance = np.sign(increments[:, 0]) * np.hypot(increments[:, 0], increments[:, 1])
    i, j = spans[:, 0], spans[:, 1]
    moved = xy[j] - xy[i]
    out = np.zeros((6, spans.shape[0], 3))
    out[0, :, :2] = moved
    out[1, :, :2] = np.c_[-moved[:, 1], moved[:, 0]]
    spun = increments[:, 2] * pivot_intervals(increments)
    for k, w in ((2, distance), (3, increments[:, 2]), (SPOT_SHAPE, spun)):
        W = running_sums(w)
        Wp = running_sums(w[:, None] * xy[1:])
        turned = W[j] - W[i]
        arm = xy[j] * turned[:, None] - (Wp[j] - Wp[i])  # Σ w·(p_j − p_{k+1})
        out[k, :, :2] = np.c_[-arm[:, 1], arm[:, 0]]
        out[k, :, 2] = turned
    # The motion per interval at each record: the mean of the intervals either side of it.
    step = np.diff(track, axis=0)
    at = 0.5 * (step[np.r_[0, np.arange(step.shape[0])]] + step[np.r_[np.arange(step.shape[0]), -1]])
    # Read late by one interval: the motion at the end less that at the start, the start's heading
    # turned by its own turn per interval (the segment restarts from the reference's heading).
    out[4] = at[j] - at[i]
    out[4, :, :2] -= at[i, 2, None] * np.c_[-moved[:, 1], moved[:, 0]]
    c, s = np.cos(track[i, 2]), np.sin(track[i, 2])
    x, y = out[:, :, 0].copy(), out[:, :, 1].copy()
    out[:, :, 0], out[:, :, 1] = c * x + s * y, -s * x + c * y
    return out


def segment_rates(
    units: np.ndarray, shapes: np.ndarray, errors: np.ndarray, known: tuple[np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rates (one per unit covariance ``units`` holds) and the reference's own variances
    (those ``known[0]`` holds terms of, ``(k, S, 3, 3)``, returned third) whose covariances, beside
    the readings' rounding (``known[1]``), best give the segments' squared ``errors`` less the
    calibration's constant error (its ``shapes``' sizes, returned last, regressed on the errors
    themselves), each component its own (the method of moments: the wheels' noise model ties
    along, across and heading together, a slipping or slow-read base's drift does not); a rate the
    segments do not show is NaN, and second, the most the segments allow of each rate
    (:func:`_shown`)."""
    terms, reads = known
    diag = np.diagonal(np.concatenate([units, terms]), axis1=-2, axis2=-1)  # (6 + k, S, 3)
    A = np.concatenate([diag[:, :, c].T for c in range(3)])
    k = np.concatenate([reads[:, c, c] for c in range(3)])
    B = np.concatenate([shapes[:, :, c].T for c in range(3)])
    e = np.concatenate([errors[:, c] for c in range(3)])
    scale = np.maximum(np.max(np.abs(A), axis=0), 1e-300)
    predicted = np.repeat([max(float(np.mean(errors[:, c] ** 2)), 1e-300) for c in range(3)], len(errors))
    var, bias = np.zeros(A.shape[1]), np.zeros(B.shape[1])
    for _ in range(3):
        w = 1.0 / np.sqrt(np.maximum(predicted, 1e-12 * float(np.max(predicted))))
        # An error far out of the last fit (a reference's glitch) is left out of the regression
        # as the moments leave it out: its square would rule both.
        w = np.where(weights((e - B @ bias) ** 2, predicted) > 0, w, 0.0)
        bias = np.linalg.lstsq(B * w[:, None], e * w, rcond=None)[0]
        var = moments(A / scale, (e - B @ bias) ** 2, k, predicted) / scale
        predicted = A @ var + k
    k = units.shape[0]
    shown, allowed = _shown(A, var, predicted)
    return np.where(shown[:k], var[:k], np.nan), allowed[:k], var[k:], bias


#: The rates' components.
AXES = ("along", "across", "heading")

#: How many σ of its own a rate the segments fit must stand above zero to count as shown by them.
SHOWN = 2.0

#: How many σ of its own above its fit the most the segments allow of a rate lies: a bound the
#: rate is under with :data:`~nlp_calib.analysis.odometry.COVERED` confidence however skewed the
#: fit's distribution (variances fitted on a few dozen squared errors: a Gaussian's one-sided σ
#: does not hold), as long as it has one mode: the one-sided Vysochanskij–Petunin inequality,
#: ``P(X − μ ≥ kσ) ≤ 4 / (9·(1 + k²))``, gives ``k = √(4 / (9·(1 − COVERED)) − 1)``: 2.81σ.
BOUND = float(np.sqrt(4.0 / (9.0 * (1.0 - COVERED)) - 1.0))


def _spread(A: np.ndarray, w: np.ndarray, on: np.ndarray, k: int) -> float:
    """The fit's σ of variance ``k`` fitted beside those ``on`` (NaN: the segments cannot tell it
    from them)."""
    cols = on.copy()
    cols[k] = True
    try:
        cov = 2.0 * np.linalg.inv(A[:, cols].T @ (A[:, cols] * w[:, None]))
    except np.linalg.LinAlgError:
        return float("nan")
    d = float(cov[np.count_nonzero(cols[:k]), np.count_nonzero(cols[:k])])
    return float(np.sqrt(d)) if d > 0 else float("nan")


def _shown(A: np.ndarray, var: np.ndarray, predicted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which fitted variances ``var`` the squared errors show (:data:`SHOWN` σ above 0), and the
    most they allow of each (:data:`BOUND` σ above its fit, NaN where the segments cannot tell it
    from the others): each squared error's variance is twice its prediction's square (a χ² with
    one degree of freedom) and half-overlapping segments count about half, so the fit's covariance
    is twice ``(AᵀWA)⁻¹`` over the variances it fitted (one not fitted, held at 0, beside them).
    One fitted under the reference's noise (a car's wheels under its device's 2 cm) is noise of
    that fit, not the odometry's."""
    on = var > 0
    # In units of the largest prediction, floored as the fit's weights are: squared errors of a few
    # micrometres square to under 1e-300, and an infinite weight leaves every rate untold.
    top = max(float(np.max(predicted, initial=0.0)), 1e-300)
    w = 1.0 / (2.0 * np.maximum(predicted / top, 1e-12) ** 2)
    sigma = top * np.array([_spread(A, w, on, k) for k in range(var.size)])
    shown = on & (var > SHOWN * np.nan_to_num(sigma, nan=np.inf))
    return shown, np.maximum(var, 0.0) + BOUND * sigma


def systematic_rates(
    increments: np.ndarray, spans: np.ndarray, systematic: np.ndarray
) -> tuple[np.ndarray, float]:
    """``(2, 3)``: the rates that give the shortest segments that do not pivot the variance of the
    calibration's constant error over them (``systematic`` ``(S, 3)``, each segment's), and the
    heading's per radian turned on the spot that gives those that pivot the rest of theirs: over
    the windows the fit judged, that error is the odometry's drift as much as its noise is. It
    grows as the turn's square, a rate as the turn: a pivot's turns (a few radians) fitted beside
    an arc's would give every arc a pivot's share."""
    lengths = spans[:, 1] - spans[:, 0]
    travel, turn = (
        running_sums(np.hypot(increments[:, 0], increments[:, 1])),
        running_sums(np.abs(increments[:, 2])),
    )
    spun = running_sums(on_spot(increments)[:, 1])
    i, j = spans[:, 0], spans[:, 1]
    along = np.c_[travel[j] - travel[i], np.zeros(i.size), turn[j] - turn[i] - spun[j] + spun[i]]
    pivots = spun[j] > spun[i]
    arcs = (lengths == lengths[~pivots].min()) & ~pivots if np.any(~pivots) else lengths == lengths.min()
    rates = fit_rates(along[arcs], systematic[arcs] ** 2)
    if not np.any(pivots):
        return rates, 0.0
    at = pivots & (lengths == lengths[pivots].min())
    grown = along[at][:, [0, 2]] @ rates[:, 2]
    spot = nnls_small((spun[j] - spun[i])[at, None], systematic[at, 2] ** 2 - grown)
    return rates, float(spot[0])


def covering_target(segments: int, shared: bool) -> float:
    """The share of ``segments`` errors a component's 2σ must hold: :data:`COVERED`, less two
    binomial σ of it over half of them (they overlap by half) where the reference's own noise in
    that component was fitted on the same errors (``shared``): within that, the share is its
    sampling and the reference's noise may take the rest. Where no fitted noise of the reference's
    is beside it (a reference's own increments' heading), nothing else may: never under the drift
    the segments show."""
    if not shared:
        return COVERED
    return COVERED - 2.0 * float(np.sqrt(COVERED * (1.0 - COVERED) / max(0.5 * segments, 1.0)))


def _covering_share(
    units: np.ndarray,
    added: tuple[np.ndarray, np.ndarray, int],
    errors: np.ndarray,
    known: np.ndarray,
    target: float,
) -> float:
    """The smallest share of ``shape`` added to the rates (``added``: the rates as ``units`` holds
    them, the shape, the component ``c`` it raises) whose 2σ holds ``target`` of the segments'
    errors in that component (:func:`covering_target`; 0: they do already; the shape: the inputs'
    noise's rates, what the wheels' noise makes of each component)."""
    rates, shape, c = added

    def need(share: float) -> float:
        ratios = _ratios(units, rates + share * shape, errors, known)[:, c]
        return float(np.quantile(ratios, target, method="inverted_cdf")) / 2.0

    if need(0.0) <= 1.0 or not np.any(shape > 0):
        return 0.0
    hi = 1e-9
    while need(hi) > 1.0 and hi < 1e12:
        hi *= 4.0
    lo = 0.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if need(mid) <= 1.0 else (mid, hi)
    return hi


def narrowing_target(segments: int) -> float:
    """The share of ``segments`` errors a component's 2σ may hold before its rates are narrowed:
    :data:`COVERED` and two binomial σ of it over half of them (they overlap by half), so that a
    share the sampling alone gives is left as it is."""
    return min(1.0, COVERED + covered_margin(0.5 * segments))


def _narrowing_share(
    units: np.ndarray,
    rates: np.ndarray,
    which: tuple[np.ndarray, int],
    against: tuple[np.ndarray, np.ndarray],
) -> float:
    """The smallest factor in (0, 1] on the rates ``which`` selects (of component ``c``) whose 2σ
    still holds :func:`narrowing_target`'s share of the segments' errors in that component (1:
    it holds fewer already)."""
    (mask, c), (errors, known) = which, against
    target = narrowing_target(errors.shape[0])

    def need(share: float) -> float:
        scaled = np.where(mask, share * rates, rates)
        ratios = _ratios(units, scaled, errors, known)[:, c]
        return float(np.quantile(ratios, target, method="inverted_cdf")) / 2.0

    if need(1.0) > 1.0:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if need(mid) <= 1.0 else (mid, hi)
    return hi


def _narrowed(
    units: np.ndarray, rates: np.ndarray, bounded: tuple[str, ...], against: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """``rates`` (as ``units`` holds them) narrowed, rate by rate as :func:`_populations` groups
    them and the heading's first (it carries into the positions), to the smallest share whose 2σ
    holds :func:`narrowing_target`'s share of their segments' errors: the method of moments fits
    the squared errors' mean, which a few segments far out rule (a skid-steer's turns against a
    tracker read late, a slip), and a σ over the rest's many times wider is none a filter can
    use. A component the segments only bound (:func:`_unshown`) stays the most they allow."""
    errors, known = against
    rates = np.array(rates, dtype=float)
    for c, which, on in sorted(_populations(units), key=lambda p: -p[0]):
        if AXES[c] in bounded or not np.any(on) or not np.any(rates[which] > 0):
            continue
        share = _narrowing_share(units[:, on], rates, (which, c), (errors[on], known[on]))
        rates = np.where(which, share * rates, rates)
    return rates


def hold_rates(
    units: np.ndarray,
    rates: tuple[np.ndarray, np.ndarray],
    bounded: tuple[str, ...],
    against: tuple[np.ndarray, np.ndarray, np.ndarray],
    reads: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The fitted rates (``rates``: those as ``units`` holds them, and the inputs' noise's) held
    to the drift their segments show (``against``: as :func:`_covered` takes it), both ways:
    narrowed where their 2σ holds more than sampling allows (:func:`_narrowed`), then raised where
    it holds too few (:func:`_covered`); and the shares so raised per component. Narrowed beside
    the readings' rounding alone (``reads``), the reference's noise counted as the odometry's:
    never under what holds the errors, so a drift under the reference's noise is not narrowed to
    nothing (a filter then trusting the wheels completely)."""
    held, given = rates
    errors = against[0]
    return _covered(units, _narrowed(units, held, bounded, (errors, reads)), given, against)


def _three(v: np.ndarray) -> tuple[float, float, float]:
    return float(v[0]), float(v[1]), float(v[2])


def _unshown(
    rates: np.ndarray, allowed: np.ndarray, given: np.ndarray, least: np.ndarray
) -> tuple[np.ndarray, tuple[str, ...]]:
    """The rates ``(2, 3)`` with those the segments do not show (NaN) filled, and the components
    so bounded. Such a rate is the joints' own noise's (``least``) where they show some in that
    component (a car's wheel speeds under its device's noise), else the most the segments allow
    (bounded, said): the inputs' noise's rates ``given`` (the most along the wheels' noise), but
    never over the most they allow of that rate alone (``allowed``; NaN: they cannot tell it
    apart): the wheels' noise is one per interval, an arc's and a pivot's alike, so a pivot's
    drift would rule an arc's rate)."""
    jittered = np.broadcast_to(np.any(least > 0, axis=0), rates.shape)
    unshown = np.isnan(rates)
    bounded = tuple(a for a, c in zip(AXES, np.any(unshown & ~jittered, axis=0)) if c)
    most = np.fmin(allowed, given)
    return np.where(unshown, np.where(jittered, least, most), np.maximum(rates, least)), bounded


#: The component (along, across, heading) each rate :func:`_covered` raises is of: per metre, per
#: radian (an arc's, where a pivot's is apart), then the heading's per radian on the spot.
COMPONENTS = np.array([0, 1, 2, 0, 1, 2, 2])


def _populations(units: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """What :func:`_covered` raises, each with the segments it is judged on: a component's rates
    (those :data:`COMPONENTS` gives it) on every segment; where the pivots' heading rate is apart
    (``units``' seventh), the arcs' heading rates on the segments that do not pivot and the
    pivots' on those that do: each rate never under the drift of the segments it is stated for."""
    n = units.shape[0]
    of, every = COMPONENTS[:n], np.ones(units.shape[1], dtype=bool)
    if n < 7:
        return [(c, of == c, every) for c in range(3)]
    pivots = units[6][:, 2, 2] > 0
    arcs = (of == 2) & (np.arange(n) < 6)
    return [(0, of == 0, every), (1, of == 1, every), (2, arcs, ~pivots), (2, np.arange(n) == 6, pivots)]


def _covered(
    units: np.ndarray,
    rates: np.ndarray,
    given: np.ndarray,
    against: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """``rates`` (as ``units`` holds them: per metre, per radian, and the pivots' heading rate
    where they have one) raised, rate by rate as :func:`_populations` groups them, by the smallest
    share of the inputs' noise's rates (``given``, the pivots' as an arc's: one noise per
    interval) whose 2σ holds :func:`covering_target`'s share of their segments' errors
    (``against``: those, their known covariance, and in which components the reference's own
    noise was fitted beside them), and the shares added per component: a pivot that slipped
    unflagged raises the pivots' rate, not the arcs'."""
    errors, known, shared = against
    rates, raised = np.array(rates, dtype=float), np.zeros(3)
    given = np.r_[np.ravel(given), given[1, 2]][: rates.size]
    for _ in range(4):  # a heading raised carries into the positions: again
        for c, which, on in _populations(units):
            if not np.any(on):
                continue
            shape = np.where(which, given if np.any(given[which] > 0) else rates, 0.0)
            target = covering_target(int(np.count_nonzero(on)), bool(shared[c]))
            share = _covering_share(units[:, on], (rates, shape, c), errors[on], known[on], target)
            rates += share * shape
            raised[c] = max(raised[c], share)
    return rates, raised


def noise_rates(
    fns: ProblemFunctions,
    params: np.ndarray,
    inputs: np.ndarray,
    noise: np.ndarray,
    checked: tuple[Drift, np.ndarray, np.ndarray],
    jitter: np.ndarray | None = None,
) -> NoiseRates:
    """The rates of the module docstring over ``inputs`` at ``params``: ``checked`` holds the drift
    segments over the same records, the reference's own position and heading variances (those
    credited, > 0, are refitted) and the readings' 1σ per input (their rounding, which does not add
    up per metre); ``noise`` each input's 1σ per interval (its random walk: the rates where there is
    no segment, and the shape of what a short component gets), ``jitter`` what the joints' own
    noise gives each input per interval (never under it)."""
    drift, reference_var, floor = checked
    increments, variances = base_increments(fns, params, inputs, noise)
    given = fit_rates(increments, variances)
    least = np.zeros((2, 3))
    if jitter is not None and np.any(jitter > 0):
        least = fit_rates(*base_increments(fns, params, inputs, jitter))
    if drift.spans.shape[0] == 0:
        return NoiseRates(_three(given[0]), _three(given[1]), None, 0, 0.0)
    units = _unit_growth(increments, drift.spans)
    errors, reads, terms = _local(drift, floor)
    shapes = systematic_shapes(increments, drift.spans)
    # The reference's variances refitted beside the rates (those the wheels' fit credited it with).
    credited = np.asarray(reference_var) > 0
    fitted, allowed, reference, bias = segment_rates(units[FITTED], shapes, errors, (terms[credited], reads))
    # A constant error across the motion is the mount's yaw (the reference's, not the odometry's).
    errors = errors - np.einsum("m,msc->sc", bias * (1.0 - ODOMETRY_SHAPES), shapes)
    systematic = np.einsum("m,msc->sc", bias * ODOMETRY_SHAPES, shapes)
    more, more_spot = systematic_rates(increments, drift.spans, systematic)
    rates, bounded = _unshown(fitted[:6].reshape(2, 3), allowed[:6].reshape(2, 3), given, least)
    rates = rates + more
    # A pivot's heading drifts by its own rate per radian (the wheels scrub), an arc's by the
    # rates': one rate for both would give every arc a pivot's drift (none: no pivot to tell it).
    spot = fitted[6] if np.isfinite(fitted[6]) else np.fmin(allowed[6], given[1, 2])
    spot = float(spot) + more_spot if np.any(on_spot(increments)[:, 1] > 0) else None
    known = np.einsum("k,ksij->sij", reference, terms[credited]) + reads
    units, held = (
        (units[FITTED], np.r_[np.ravel(rates), spot]) if spot is not None else (units[:6], np.ravel(rates))
    )
    fitted = np.einsum("k,ksii->i", reference, terms[credited]) > 0
    held, raised = hold_rates(units, (held, given), bounded, (errors, known, fitted), reads)
    coverage = float(np.mean(_ratios(units, held, errors, known) <= 2.0))
    return NoiseRates(
        _three(held[:3]),
        _three(held[3:6]),
        coverage,
        int(drift.spans.shape[0]),
        float(np.max(raised)),
        bounded,
        on_spot=float(held[6]) if spot is not None else None,
    )


def ground_rate(
    fns: ProblemFunctions,
    params: np.ndarray,
    track: tuple[np.ndarray, np.ndarray],
    ground: np.ndarray,
    rates: NoiseRates,
) -> NoiseRates:
    """``rates`` with the heading's variance per radian turned over the stretches of intervals
    ``ground`` marks (pivots the ground slipped on: the odometry meets them, the fit leaves them
    out) beyond what the rates grow there: the stretches' heading errors against the reference
    (``track``: the inputs per interval and the reference's base poses at the records), squared
    and summed, less the rates' variance over them, per radian the wheels turned there."""
    inputs, reference = track
    if not np.any(ground):
        return rates
    increments = base_increments(fns, params, inputs, np.zeros(inputs.shape[0]))[0]
    edges = np.diff(np.r_[0, ground.astype(int), 0])
    first, stop = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    turned = np.array([np.abs(increments[a:b, 2]).sum() for a, b in zip(first, stop)])
    moved = np.array([np.abs(increments[a:b, 0]).sum() for a, b in zip(first, stop)])
    spun = on_spot(increments)[:, 1]
    spun = np.array([spun[a:b].sum() for a, b in zip(first, stop)])
    seen = wrap_angle(reference[stop, 2] - reference[first, 2])
    error = wrap_angle(seen - np.array([increments[a:b, 2].sum() for a, b in zip(first, stop)]))
    grown = rates.per_metre[2] * moved + rates.per_radian[2] * (turned - spun) + rates.spot_rate * spun
    extra = max(float(np.sum(error**2 - grown)), 0.0) / max(float(turned.sum()), 1e-12)
    return replace(rates, slip_per_radian=extra, slipped=int(first.size))
