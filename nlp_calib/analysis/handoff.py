"""A calibration in the robot stack's terms: the controller's parameters with their 1σ, and the
covariance its odometry publishes.

The model maps its parameters onto its ros2_control controller's; each derived value's 1σ is
propagated to first order from the parameters' covariance (their σ to believe with the
white-noise correlation, as ``result.json`` reports them), with the map's Jacobian taken by
central differences. The odometry's covariance is the one noise model's (the rates per metre and per
radian of :mod:`nlp_calib.analysis.noise_rates`, beside the readings' rounding): the twist's over
one interval, averaged over the moving intervals; the pose's after a metre of driving as the log
drives, over the metres no fault touches (the rates' own: a slipped pivot's drift is stated apart).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis.noise_rates import model_covariances, rates_covariances
from nlp_calib.analysis.odometry import COVERED, covered_margin, restarted
from nlp_calib.core import poses
from nlp_calib.models import KinematicModel
from nlp_calib.models.controllers import EncoderScales
from nlp_calib.problem import ProblemFunctions
from nlp_calib.results.handoff import UNMEASURED, ControllerParams, NoiseRates, OdometryNoise, Placement

#: The distance (m) after which the pose's covariance is stated: a fixed diagonal cannot follow
#: the drift's growth, so it says it at one distance.
POSE_DISTANCE_M = 1.0


def _values(model: KinematicModel, names: Sequence[str], p: np.ndarray, scales: EncoderScales) -> np.ndarray:
    found = model.controller(dict(zip(names, map(float, p))), scales)
    return np.array(list(found.parameters.values()))


#: The span (s) a turn rate is measured over: long against a tracker's noise and its single
#: outliers, short against a manoeuvre.
TURN_SPAN_S = 0.5
#: The base turns (rad/s) above this: slower, it drives straight and any track serves.
TURNING_RATE = 0.05


def driven_turn_rates(time_s: np.ndarray, theta: np.ndarray) -> tuple[float, ...]:
    """The magnitudes of the base's turn rate (rad/s) while turning: the 10th percentile, the
    median and the 90th percentile of the heading's rate over :data:`TURN_SPAN_S` (empty if the
    drive never turns). The heading is the tracker's: the base's up to a fixed angle."""
    t = np.asarray(time_s, dtype=float)
    heading = np.unwrap(np.asarray(theta, dtype=float))
    ahead = np.searchsorted(t, t + TURN_SPAN_S)
    keep = ahead < t.size
    if not keep.any():
        return ()
    i, j = np.flatnonzero(keep), ahead[keep]
    rate = np.abs(heading[j] - heading[i]) / (t[j] - t[i])
    turning = rate[np.isfinite(rate) & (rate > TURNING_RATE)]
    if turning.size == 0:
        return ()
    return tuple(float(v) for v in np.percentile(turning, (10.0, 50.0, 90.0)))


#: A controller value whose 1σ exceeds this share of it is not determined by the drive.
UNDETERMINED_SHARE = 0.25


def _jacobian(
    model: KinematicModel, names: Sequence[str], params: np.ndarray, step: np.ndarray, scales: EncoderScales
) -> np.ndarray:
    """The controller values' Jacobian in the parameters, by central differences."""
    columns = []
    for j in range(len(names)):
        h = 1e-6 * max(abs(float(params[j])), float(step[j]), 1e-9)
        up, down = params.copy(), params.copy()
        up[j] += h
        down[j] -= h
        columns.append((_values(model, names, up, scales) - _values(model, names, down, scales)) / (2.0 * h))
    return np.stack(columns, axis=1)


def _meaningless(
    values: Mapping[str, float],
    sd: np.ndarray,
    rests_on: Mapping[str, tuple[str, ...]],
    held: Mapping[str, str],
) -> dict[str, str]:
    """The controller values no calibration gave: resting on a parameter held at its initial
    value because the drive cannot determine it (the model's guess, or the header's), or too
    loose to mean anything."""
    out = {}
    for i, (name, value) in enumerate(values.items()):
        resting = [n for n in rests_on[name] if n in held]
        if resting:
            out[name] = f"rests on {resting[0]}, held at its initial value ({held[resting[0]]}): keep yours"
        elif sd[i] > UNDETERMINED_SHARE * abs(value):
            out[name] = f"not determined by this drive ({value:.4g} ± {sd[i]:.2g})"
    return out


def _given(rests_on: Mapping[str, tuple[str, ...]], given: Mapping[str, str]) -> dict[str, str]:
    """The controller values resting on given parameters alone (``known:``, ``fixed:``), with where
    each comes from: the user's values, not the calibration's."""
    return {
        name: "; ".join(given[n] for n in names)
        for name, names in rests_on.items()
        if names and all(n in given for n in names)
    }


def controller_params(
    model: KinematicModel,
    names: Sequence[str],
    estimate: tuple[np.ndarray, np.ndarray, np.ndarray],
    scales: EncoderScales,
    extra: tuple[OdometryNoise | None, Mapping[str, str], Mapping[str, str]] = (None, {}, {}),
) -> ControllerParams:
    """``model``'s controller parameters at ``estimate`` (the parameters in ``names`` order, their
    1σ and correlation) with their 1σ; ``extra``: the odometry's noise, the parameters held at
    their initial values because the drive cannot determine them (with why), whose controller
    values are left out, as is a value too loose to mean anything, and the parameters the user
    gave (``known:``, ``fixed:``, with where from), whose values are said to be given."""
    params, std, correlation = estimate
    noise, held, given = extra
    values = dict(zip(names, map(float, params)))
    found = model.controller(values, scales)
    finite = np.where(np.isfinite(std), std, 0.0)
    cov = np.nan_to_num(correlation) * np.outer(finite, finite)
    jac = _jacobian(model, names, params, finite, scales)
    sd = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", jac, cov, jac), 0.0, None))
    rests_on = {
        v: tuple(n for j, n in enumerate(names) if jac[i, j] != 0.0) for i, v in enumerate(found.parameters)
    }
    from_user = {v: why for v, why in _given(rests_on, given).items() if v not in found.settings}
    left_out = _meaningless(found.parameters, sd, rests_on, held)
    units = dict(model.units)
    elsewhere = tuple(
        Placement(
            n,
            values[n],
            math.nan if n in given else float(std[list(names).index(n)]),
            units.get(n, ""),
            f"{given[n]}; {where}" if n in given else where,
        )
        for n, where in found.places.items()
    )
    kept = [i for i, n in enumerate(found.parameters) if n not in left_out]
    parameters = list(found.parameters.items())
    return ControllerParams(
        found.controller,
        {parameters[i][0]: parameters[i][1] for i in kept},
        {parameters[i][0]: float(sd[i]) for i in kept},
        elsewhere,
        found.assumes,
        {**found.omitted, **left_out},
        noise,
        rests_on={v: tuple(n for n in deps if n not in given) for v, deps in rests_on.items()},
        given={v: why for v, why in from_user.items() if v not in left_out},
        settings=dict(found.settings),
        gradient={
            v: {n: float(jac[i, j]) for j, n in enumerate(names) if n in rests_on[v] and n not in given}
            for i, v in enumerate(found.parameters)
        },
    )


#: How many of a mixture's variances :func:`covering_variance` judges it by at most: its quantiles
#: beyond that (10^6 intervals need not each be summed 60 times).
MIXTURE_LEVELS = 4096


def covering_variance(variances: np.ndarray) -> np.ndarray:
    """Per column of ``variances`` ``(n, k)`` (each row a zero-mean Gaussian's, all equally
    likely): the variance whose 2σ holds :data:`~nlp_calib.analysis.odometry.COVERED` of the
    mixture's draws, ``mean_i erf(√2·s/σ_i) = COVERED``. One diagonal stated for every span of a
    drive that mixes a few large variances (a skid-steer's pivots) among many small ones: their
    mean would be ruled by the few and over-state the rest's drift many times."""
    v = np.clip(np.asarray(variances, dtype=float), 0.0, None)
    if v.shape[0] > MIXTURE_LEVELS and np.all(np.isfinite(v)):
        v = np.quantile(v, (np.arange(MIXTURE_LEVELS) + 0.5) / MIXTURE_LEVELS, axis=0)
    sigma = np.sqrt(v)
    out = np.full(v.shape[1], np.nan)
    for c in range(v.shape[1]):
        s = sigma[:, c]
        if not np.all(np.isfinite(s)):  # as their mean would be
            continue
        out[c] = _covering_sigma(s[s > 0], s.size) ** 2 if np.any(s > 0) else 0.0
    return out


_ERF = np.frompyfunc(math.erf, 1, 1)


def _covering_sigma(s: np.ndarray, n: int) -> float:
    """The root ``t`` of ``Σ_i erf(√2·t/s_i) / n = COVERED`` over the nonzero σ ``s`` of ``n``
    (each zero one holds everything): Newton's steps from the largest σ, kept inside the bracket
    (a single Gaussian's 2σ holds 95.4 %: the root lies between the smallest σ, or 0, and the largest), a
    bisection where a step leaves it; a few passes over ``s`` where bisection alone took 60."""
    ratio = np.sqrt(2.0) / s
    lo, hi = (0.97 * float(np.min(s)) if s.size == n else 0.0), float(np.max(s))
    t = hi
    for _ in range(100):
        z = ratio * t
        miss = (float(np.sum(_ERF(z).astype(float))) + (n - s.size)) / n - COVERED
        if miss == 0.0:
            return t
        lo, hi = (t, hi) if miss < 0 else (lo, t)
        slope = float(np.sum(ratio * np.exp(-(z**2)))) * 2.0 / math.sqrt(math.pi) / n
        step = t - miss / slope if slope > 0 else lo
        ahead = step if lo < step < hi else 0.5 * (lo + hi)
        if abs(ahead - t) <= 4.0 * np.finfo(float).eps * t or hi - lo <= 4.0 * np.finfo(float).eps * hi:
            return ahead
        t = ahead
    return t


def _twist(
    fns: ProblemFunctions, inputs: np.ndarray, dt: np.ndarray, C: np.ndarray, faults: np.ndarray | None
) -> np.ndarray:
    """The variance of ``(vx, vy, wz)`` over one interval over the moving intervals no fault
    ``faults`` marks (:func:`covering_variance`): each interval's covariance ``C`` ``(n, 3, 3)``
    over its duration squared."""
    moving = fns.model.moving(inputs)
    if faults is not None and np.any(moving & ~faults):
        moving = moving & ~faults
    if not np.any(moving):
        return np.full(3, np.nan)
    return covering_variance(np.diagonal(C[moving], axis1=1, axis2=2) / dt[moving, None] ** 2)


def _rounding(found: np.ndarray, track: np.ndarray, rates: NoiseRates, spans: np.ndarray) -> np.ndarray:
    """The readings' rounding's share of each span's covariance ``found`` ``(S, 3)`` (diagonal):
    what is not the rates' (:func:`~nlp_calib.analysis.noise_rates.model_covariances`' sum)."""
    grown = rates_covariances(poses.between(track[:-1], track[1:]), rates, spans)
    return np.clip(np.diagonal(found - grown, axis1=1, axis2=2), 0.0, None)


#: The most intervals :func:`_covering_twist` judges the twist by, spread over the drive: an order
#: statistic at 95 % is as sure from these, and 10^6 intervals' errors and terms are 0.3 GB.
TWIST_INTERVALS = 20_000


def _covering_twist(
    twist: np.ndarray,
    track: np.ndarray,
    intervals: tuple[np.ndarray, np.ndarray, tuple[np.ndarray, NoiseRates]],
    shown: Shown,
) -> np.ndarray:
    """``twist`` (vx, vy, wz) never over the drift each moving interval ``intervals`` marks (with
    the durations, and each interval's covariance ``(n, 3, 3)`` from the rates beside it, of which
    the readings' rounding is the floor) shows against the reference (at most
    :data:`TWIST_INTERVALS` of them, evenly spread), as
    :func:`covering_pose` caps the pose's, over the intervals no fault marks (their positions'
    errors, the base's across velocity, are not stated); not raised to it: over one interval the
    reference's own noise rules the errors (a tracker's millimetres against the wheels' microns
    per 10 ms), and their difference from its fitted variance is that fit's error, not drift (the
    diff-drive's known wz 1.26 -> 1.85x its truth)."""
    moving, dt, (C, rates) = intervals
    keep = moving & ~shown.faults & (dt > 0)
    if not np.any(keep):
        return twist
    at = np.flatnonzero(keep)
    at = at[:: max(1, at.size // TWIST_INTERVALS)]
    steps = np.c_[at, at + 1]
    least = covering_variance(_rounding(C[at], track, rates, steps) / dt[at, None] ** 2)
    found = np.minimum(covering_pose(twist, track, steps, shown, (dt[at], least)), twist)
    return np.r_[found[0], twist[1], found[2]]


def metre_spans(track: np.ndarray) -> np.ndarray:
    """Spans ``(i, j)`` of :data:`POSE_DISTANCE_M` of driving along ``track`` (at most about 200,
    spread over it; none when it drives less)."""
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(track[:, :2], axis=0).T))])
    starts = np.flatnonzero(travelled <= travelled[-1] - POSE_DISTANCE_M)
    i = starts[:: max(1, starts.size // 200)]
    j = np.maximum(np.searchsorted(travelled, travelled[i] + POSE_DISTANCE_M), i + 1)
    return np.c_[i, j].astype(int)


@dataclass(frozen=True)
class Shown:
    """What the drive shows of the odometry: the intervals a fault marks ``(n,)``, the reference's
    base poses ``(n + 1, 3)``, the base's position less the sensor's at each record ``(n + 1, 2)``
    and the reference's own variances of its position and heading (``(2,)``), fitted on
    ``segments`` drift segments; ``chained``: the reference is its own increments chained, one an
    interval (a scan matcher's), its noise over a span each increment's; ``bad_records``
    ``(n + 1,)``: the reference's poses a fault spoiled (a tracker's outlier: no end of a span
    judged); ``arc`` ``(n, 3)``: each interval's one-arc integration error
    (:func:`~nlp_calib.analysis.odometry.one_arc_errors`; None: not known)."""

    faults: np.ndarray
    reference: np.ndarray
    lever: np.ndarray
    reference_var: np.ndarray
    segments: int
    chained: bool = False
    bad_records: np.ndarray | None = None
    arc: np.ndarray | None = None


def most_reference(variances: np.ndarray, segments: int) -> np.ndarray:
    """The reference's own variances at two σ of their fit over theirs: a variance fitted on ``m``
    squared errors (a χ² with one degree of freedom each) has a relative σ of ``√(2/m)``, and
    ``segments`` half-overlapping segments give about half as many. The errors are held against
    the most of the reference's noise its fit allows: what it cannot take is the odometry's."""
    m = max(0.5 * segments, 1.0)
    return np.asarray(variances, dtype=float) * (1.0 + 2.0 * np.sqrt(2.0 / m))


def _needed(track: np.ndarray, spans: np.ndarray, shown: Shown) -> tuple[np.ndarray, np.ndarray]:
    """Each span's squared error over 4, and the most of the reference's own variance of it its fit
    allows, ``(S, 3)`` each (x, y, θ in the base frame at its start; the odometry ``track``
    restarted from the reference at each start): a span's error lies within 2σ of a variance at
    least their difference."""
    errors, terms = restarted(shown.reference, track, spans, shown.lever)
    turn = shown.reference[spans[:, 0], 2]
    c, s = np.cos(turn), np.sin(turn)
    local = np.c_[c * errors[:, 0] + s * errors[:, 1], -s * errors[:, 0] + c * errors[:, 1], errors[:, 2]]
    R = np.zeros((turn.size, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, s, -s, c, 1.0
    own = np.einsum("k,skij->sij", most_reference(shown.reference_var, shown.segments), terms)
    if shown.chained:  # each increment chained adds its own noise: one's over each
        own = own * (spans[:, 1] - spans[:, 0])[:, None, None]
    own = R @ own @ np.swapaxes(R, 1, 2)
    return local**2 / 4.0, np.diagonal(own, axis1=1, axis2=2)


def _independent(spans: np.ndarray) -> float:
    """About how many of ``spans`` ``(S, 2)`` (in order of their starts) do not overlap: all where
    each ends before the next starts, fewer as they overlap."""
    if spans.shape[0] < 2:
        return float(spans.shape[0])
    apart = float(np.median(np.diff(spans[:, 0])))
    length = float(np.median(spans[:, 1] - spans[:, 0]))
    return spans.shape[0] * min(1.0, apart / length) if length > 0 else float(spans.shape[0])


def covering_pose(
    pose: np.ndarray,
    track: np.ndarray,
    spans: np.ndarray,
    shown: Shown,
    per: tuple[np.ndarray | None, np.ndarray] | None = None,
) -> np.ndarray:
    """The diagonal ``pose`` (x, y, θ in the base frame at a span's start) held, component by
    component, within the drift ``spans`` show against the reference (the odometry ``track``
    restarted from it at each start): never under the smallest variance whose 2σ, beside the most
    of the reference's own noise its fit allows, holds :data:`~nlp_calib.analysis.odometry.COVERED`
    of the spans' errors (a pivot that slipped unflagged among them), nor over the one that holds
    them with the reference's noise counted as the odometry's (a rate the segments only bound,
    stated at the most they allow: on a skid-steer's arcs 3-4x the drift). Not beside the least of
    the reference's noise: the fit minimised these very errors (its windows' own, one interval
    long), so they are under the true drift by what the fit absorbed (on a skid-steer's intervals,
    vx to 0.3x). ``per`` ``(S,)``: each span's errors divided by it (an interval's duration: a
    twist's diagonal)."""
    divided, rounding = (None, np.zeros(3)) if per is None else per
    if shown.bad_records is not None:  # a tracker's outlier is the reference's error, not the drift
        keep = ~(shown.bad_records[spans[:, 0]] | shown.bad_records[spans[:, 1]])
        spans, divided = spans[keep], None if divided is None else divided[keep]
        if not spans.size:
            return pose
    scale = np.ones(spans.shape[0]) if divided is None else 1.0 / np.asarray(divided, dtype=float) ** 2
    # |e| ≤ 2·√(σ² + r) holds for the spans whose e²/4 − r is at most σ²: the smallest σ² that
    # holds COVERED of them is that order statistic.
    half_squared, reference = _needed(track, spans, shown)
    beside = (half_squared - reference) * scale[:, None]
    least, most = (
        np.quantile(v, COVERED, axis=0, method="inverted_cdf")
        for v in (beside, half_squared * scale[:, None])
    )
    # Raised only where the share ``pose`` holds falls short of COVERED by more than sampling
    # explains: where the odometry drifts far less than the reference's own noise the spans'
    # errors are that noise, whose order statistic over a few hundred spans strays by a tenth (it
    # had raised a car's lateral drift of 35 µm per metre to 12 mm).
    held = np.mean(beside <= np.asarray(pose, dtype=float), axis=0)
    least = np.where(held < COVERED - covered_margin(_independent(spans)), least, -np.inf)
    most = np.maximum(most, rounding)
    return np.where(most > 0.0, np.clip(pose, least, np.maximum(most, least)), np.maximum(pose, least))


def odometry_noise(
    fns: ProblemFunctions,
    params: np.ndarray,
    inputs: np.ndarray,
    time_s: np.ndarray,
    noise: tuple[NoiseRates, np.ndarray, Mapping[str, float]],
    shown: Shown | None = None,
) -> OdometryNoise:
    """The covariance diagonals a controller publishes with its odometry, over the intervals of
    ``inputs`` (at ``time_s``), from the one noise model (``noise``: the rates per metre and per
    radian, each input's reading 1σ, and each input's random walk per interval they were shaped
    by, stated beside them): the twist's over one interval, the pose's after
    :data:`POSE_DISTANCE_M` of driving as the log drives (over the metres no interval
    ``shown.faults`` marks touches, where there are any: the rates hold those; a slipped pivot's
    drift is stated apart), both :func:`~nlp_calib.analysis.noise_rates.model_covariances`, the
    pose's never under the drift those metres show (:func:`covering_pose`)."""
    rates, reading, walk = noise
    dt = np.diff(np.asarray(time_s, dtype=float))
    n = inputs.shape[1]
    steps = np.c_[np.arange(n), np.arange(1, n + 1)]
    # The track integrates one arc per interval, as the spans' drift it is held to does: both
    # carry that integration's error where the joints' own samples show it.
    arc = shown.arc if shown is not None else None
    C, track = model_covariances(fns, params, inputs, (rates, reading), steps, arc)
    faults = shown.faults if shown is not None else None
    twist = _twist(fns, inputs, dt, C, faults) if n else np.full(3, np.nan)
    if shown is not None and n:
        twist = _covering_twist(twist, track, (fns.model.moving(inputs), dt, (C, rates)), shown)
    vx, _, wz = twist
    spans = metre_spans(track)
    if shown is not None and spans.size:
        # Faults counted up to each interval: a span holds none where the count does not change.
        counted = np.concatenate([[0], np.cumsum(shown.faults, dtype=np.int64)])
        clean = counted[spans[:, 1]] == counted[spans[:, 0]]
        spans = spans[clean] if clean.any() else spans
    pose = np.full(3, np.nan)
    if spans.size:
        found = model_covariances(fns, params, inputs, (rates, reading), spans, arc)[0]
        pose = covering_variance(np.diagonal(found, axis1=1, axis2=2))
        if shown is not None:
            rounding = covering_variance(_rounding(found, track, rates, spans))
            pose = covering_pose(pose, track, spans, shown, (None, rounding))
    x, y, yaw = pose
    u = UNMEASURED
    return OdometryNoise(
        pose=(float(x), float(y), u, u, u, float(yaw)),
        twist=(float(vx), u, u, u, u, float(wz)),
        interval_s=float(np.median(dt)) if dt.size else float("nan"),
        distance_m=POSE_DISTANCE_M,
        input_noise=dict(walk),
        rates=rates,
    )
