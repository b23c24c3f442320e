"""The calibrated odometry's σ against the drift it truly has on a simulated drive (issue #43 item 4):
over windows of the fit's own length and longer, the dead-reckoned motion against the true base's,
beside the σ the run's noise gives it (the inputs' random walk propagated, or the per-metre and
per-radian rates grown as a filter grows them, each with the readings' rounding at both ends)."""

from __future__ import annotations

from typing import Any

import numpy as np

from nlp_calib.analysis.noise_rates import grown_covariances
from nlp_calib.analysis.odometry import propagate, readings_covariance, segment_covariance
from nlp_calib.core import poses
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.pipeline.analyse import calibrated_drift


def sigma_over_truth(
    calib: Any, run: Any, truth: tuple[np.ndarray, np.ndarray, int], multiples: tuple[int, ...] = (1,)
) -> dict[tuple[str, int], np.ndarray]:
    """For each way (``input``, ``rates``) and each window of ``multiples`` of the fit's own length:
    the factor the σ would need to hold 95 % of the true errors within 2σ, ``q₉₅(|error|/σ)/2``,
    per component (x, y, θ in the base frame at the window's start) and over the three together
    (last): 1 where the σ is the drift the windows truly have (the root-mean-square ratio would be
    ruled by a few windows' heavy tail: a 4 Hz encoder's stale pivots). ``truth``: the true base
    poses' times (s, since ``epoch`` ns), the poses, the epoch."""
    part, fit = calib.parts[0], calib.fitting
    solver = run.handoff_solver() or next(iter(run.reports))
    params = fit.fns.view(run.reports[solver].result.params, 0)
    d = calibrated_drift(fit, part.windows, params, part.prepared.scenario.objective.residual.steering_sample)
    floor = part.windows.input_noise_std
    track, P = propagate(fit.fns, params, d.inputs, d.reference[0], d.noise)
    Pr = propagate(fit.fns, params, d.inputs, d.reference[0], floor)[1]
    t_s, base, epoch = truth
    t = np.asarray(part.windows.selected.time_s) + (run.log.start_ns - epoch) * 1e-9
    true = np.stack([np.interp(t, t_s, c) for c in (base[:, 0], base[:, 1], np.unwrap(base[:, 2]))], axis=1)
    bad = part.windows.masks()[0]  # the intervals a fault spoiled
    spans = part.windows.data.stops - part.windows.data.starts
    own = int(np.bincount(spans).argmax())
    rates = run.odometry.rates if run.odometry is not None else run.reports[solver].controller.noise.rates
    increments = poses.between(track[:-1], track[1:])
    per = np.array([rates.per_metre, rates.per_radian])
    out = {}
    for L in (m * own for m in multiples):
        i = np.arange(0, track.shape[0] - L, max(L // 2, 1))
        i = i[[not bad[a : a + L].any() for a in i]]
        j = i + L
        a, b = poses.between(true[i], true[j]), poses.between(track[i], track[j])
        error = np.c_[a[:, :2] - b[:, :2], wrap_angle(a[:, 2] - b[:, 2])]
        read = readings_covariance(Pr, track, i, j, -track[i, 2])
        ways = {
            "input": segment_covariance(P, track, i, j, -track[i, 2]),
            "rates": grown_covariances(increments, per, np.c_[i, j]),
        }
        for way, C in ways.items():
            sigma = np.sqrt(np.clip(np.diagonal(C + read, axis1=1, axis2=2), 0.0, None))
            ratio = np.abs(error) / np.maximum(sigma, 1e-300)
            need = np.r_[np.quantile(ratio, 0.95, axis=0), np.quantile(ratio, 0.95)] / 2.0
            out[(way, L)] = 1.0 / need
    return out
