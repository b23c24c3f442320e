"""The calibrated odometry's σ against the drift it truly has on a simulated drive (issue #43 item 4):
over windows of the fit's own length and longer, the dead-reckoned motion against the true base's,
beside the σ the one noise model gives it (the per-metre and per-radian rates grown as a filter
grows them, with the readings' rounding at both ends and the one-arc integration's own error per
interval where the joints' samples show it, as ``nlp-calib odometry``'s), and ros2_control.yaml's
diagonals (the pose's after a metre, the twist's over one interval) against the true errors over
those spans."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from nlp_calib.analysis.handoff import metre_spans
from nlp_calib.analysis.noise_rates import rates_covariances
from nlp_calib.analysis.odometry import propagate, readings_covariance
from nlp_calib.core import poses
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.pipeline.analyse import calibrated_drift


def sigma_over_truth(
    calib: Any,
    run: Any,
    truth: tuple[np.ndarray, np.ndarray, int],
    multiples: tuple[int, ...] = (1,),
    every_metre: bool = False,
) -> dict[tuple[str, int], np.ndarray]:
    """For each way (``input``, ``rates``) and each window of ``multiples`` of the fit's own length:
    the factor the σ would need to hold 95 % of the true errors within 2σ, ``q₉₅(|error|/σ)/2``,
    per component (x, y, θ in the base frame at the window's start) and over the three together
    (last): 1 where the σ is the drift the windows truly have (the root-mean-square ratio would be
    ruled by a few windows' heavy tail: a 4 Hz encoder's stale pivots). ``truth``: the true base
    poses' times (s, since ``epoch`` ns), the poses, the epoch. ``every_metre``: the pose's diagonal
    also against every metre driven, the faults' included (``("pose_all", 0)``): the diagonal is
    averaged over every metre, and the true base's errors there are the odometry's own (a bad
    match is the reference's fault; a slipped pivot's error is one a filter meets), the odometry
    integrated at the joints' own samples as a controller integrates it; and (``("pivots_all", 0)``)
    the rates with the slipped pivots' heading variance per radian on every pivot, grown over each
    of those metres as a filter grows them, at the joints' samples it integrates (where the
    pivots are: a pivot that starts inside a 2 s record is one there)."""
    part, fit = calib.parts[0], calib.fitting
    solver = run.handoff_solver() or next(iter(run.reports))
    params = fit.fns.view(run.reports[solver].result.params, 0)
    d = calibrated_drift(fit, part.windows, params, part.prepared.scenario.objective.residual.steering_sample)
    floor = part.windows.input_noise_std
    track = propagate(fit.fns, params, d.inputs, d.reference[0], d.noise)[0]
    Pr = propagate(fit.fns, params, d.inputs, d.reference[0], floor)[1]
    t_s, base, epoch = truth
    t = np.asarray(part.windows.selected.time_s) + (run.log.start_ns - epoch) * 1e-9
    true = np.stack([np.interp(t, t_s, c) for c in (base[:, 0], base[:, 1], np.unwrap(base[:, 2]))], axis=1)
    bad = part.windows.masks()[0]  # the intervals a fault spoiled
    spans = part.windows.data.stops - part.windows.data.starts
    own = int(np.bincount(spans).argmax())
    rates = run.odometry.rates if run.odometry is not None else run.reports[solver].controller.noise.rates
    increments = poses.between(track[:-1], track[1:])
    out = _handed_off(run.reports[solver].controller, track, true, bad, np.diff(t))
    if every_metre and out:
        # The odometry a controller publishes integrates the wheels at their own samples, not by
        # the model's one arc per (2 s) interval: over every metre, the slipped pivots' included.
        fine, at = part.windows.selected.at_joint_samples()
        published, at_samples = track, track
        if at is not None:
            u = fit.fns.model.inputs(fine, part.prepared.scenario.objective.residual.steering_sample)
            at_samples = propagate(fit.fns, params, u, d.reference[0], d.noise)[0]
            published = at_samples[at]
        spared = np.zeros_like(bad)
        out[("pose_all", 0)] = _handed_off(
            run.reports[solver].controller, published, true, spared, np.diff(t)
        )[("pose", 0)]
        out[("pivots_all", 0)] = _pivots_grown((published, at_samples, at), true, rates)
    for L in (m * own for m in multiples):
        i = np.arange(0, track.shape[0] - L, max(L // 2, 1))
        i = i[[not bad[a : a + L].any() for a in i]]
        j = i + L
        a, b = poses.between(true[i], true[j]), poses.between(track[i], track[j])
        error = np.c_[a[:, :2] - b[:, :2], wrap_angle(a[:, 2] - b[:, 2])]
        read = readings_covariance(Pr, track, i, j, -track[i, 2])
        C = rates_covariances(increments, rates, np.c_[i, j], d.arc) + read
        out[("rates", L)] = _over(error, np.sqrt(np.clip(np.diagonal(C, axis1=1, axis2=2), 0.0, None)))
    return out


def _pivots_grown(
    published: tuple[np.ndarray, np.ndarray, np.ndarray | None], true: np.ndarray, rates: Any
) -> np.ndarray:
    """Over every metre of the odometry as published (``published``: at the records, at the
    joints' samples it integrates, and where the records fall among those; None: the same), the σ
    a filter grows from ``rates`` (per metre, per radian and per radian on the spot) with the
    slipped pivots' heading variance (``rates.slip_per_radian``) on every radian it turns on the
    spot too (the pivots by the fit's rule at each sample it integrates: it knows when it pivots,
    not when it slips; a pivot's start inside a 2 s record is a pivot there, not an arc) against
    the true errors (:func:`_over`)."""
    track, samples, at = published
    spans = metre_spans(track)
    grown = spans if at is None else at[spans]
    increments = poses.between(samples[:-1], samples[1:])
    C = rates_covariances(increments, replace(rates, on_spot=rates.spot_rate + rates.slip_per_radian), grown)
    i, j = spans[:, 0], spans[:, 1]
    a, b = poses.between(true[i], true[j]), poses.between(track[i], track[j])
    error = np.c_[a[:, :2] - b[:, :2], wrap_angle(a[:, 2] - b[:, 2])]
    return _over(error, np.sqrt(np.clip(np.diagonal(C, axis1=1, axis2=2), 0.0, None)))


def _over(error: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """The σ over the one whose 2σ holds 95 % of ``error``'s rows, per column and together (NaN
    columns left out)."""
    ratio = np.abs(error) / np.maximum(sigma, 1e-300)
    if ratio.shape[0] == 0:
        return np.full(4, np.nan)
    keep = ~np.isnan(ratio[0])
    need = np.r_[np.quantile(ratio, 0.95, axis=0), np.quantile(ratio[:, keep], 0.95)] / 2.0
    return 1.0 / need


def _handed_off(
    controller: Any, track: np.ndarray, true: np.ndarray, bad: np.ndarray, dt: np.ndarray
) -> dict[tuple[str, int], np.ndarray]:
    """ros2_control.yaml's diagonals against the true errors: the pose's over every
    :data:`~nlp_calib.analysis.handoff.POSE_DISTANCE_M` of driving (``("pose", 0)``), the twist's
    (vx, wz; vy NaN) over every moving interval (``("twist", 1)``), the spans a fault spoiled left out."""
    noise = controller.noise if controller is not None else None
    if noise is None:
        return {}
    spans = metre_spans(track)
    spans = spans[[not bad[a:b].any() for a, b in spans]]
    i, j = spans[:, 0], spans[:, 1]
    a, b = poses.between(true[i], true[j]), poses.between(track[i], track[j])
    error = np.c_[a[:, :2] - b[:, :2], wrap_angle(a[:, 2] - b[:, 2])]
    out = {("pose", 0): _over(error, np.sqrt(np.array(noise.pose)[[0, 1, 5]]))}
    a, b = poses.between(true[:-1], true[1:]), poses.between(track[:-1], track[1:])
    moving = ((np.abs(b[:, 0]) + np.abs(b[:, 2])) > 0) & ~bad & (dt > 0)
    v = (
        np.c_[a[:, 0] - b[:, 0], np.full(dt.size, np.nan), wrap_angle(a[:, 2] - b[:, 2])][moving]
        / dt[moving, None]
    )
    sigma = np.sqrt(np.array(noise.twist)[[0, 1, 5]])
    sigma[1] = np.nan
    out[("twist", 1)] = _over(v, np.broadcast_to(sigma, v.shape))
    return out


def reference_base(calib: Any, run: Any) -> tuple[np.ndarray, np.ndarray, int]:
    """The reference's base poses at the fit's records, as :func:`sigma_over_truth` takes a truth
    (times in s since the log's start, the poses, that start): the σ against what the windows show
    of the drift, the reference's own noise in it, as a user's data show it."""
    part, fit = calib.parts[0], calib.fitting
    solver = run.handoff_solver() or next(iter(run.reports))
    params = fit.fns.view(run.reports[solver].result.params, 0)
    steering = part.prepared.scenario.objective.residual.steering_sample
    d = calibrated_drift(fit, part.windows, params, steering)
    t = np.asarray(part.windows.selected.time_s, dtype=float)
    return t, np.asarray(d.reference), int(run.log.start_ns)
