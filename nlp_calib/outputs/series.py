"""The numbers behind the report's figures, gathered from a set-up calibration and its run.

Nothing here draws: :mod:`nlp_calib.outputs.plots` turns these records into images. Tracks are
dead-reckoned with :func:`nlp_calib.analysis.metrics.integrate` and residuals come from the
evaluator, so the figures show exactly what the solvers and metrics saw.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis.metrics import integrate, restarted, segments, steps
from nlp_calib.logs import Log
from nlp_calib.models import SENSOR_PARAMS, header_parameters
from nlp_calib.pipeline import Calibration, CalibrationRun
from nlp_calib.solvers import IterationRecord, solver_label


@dataclass(frozen=True)
class Track:
    """A labelled pose sequence ``(n, 3)`` over the record times ``time_s``; ``ate_mean`` in m."""

    label: str
    T_world_sensor: np.ndarray
    time_s: np.ndarray
    ate_mean: float | None = None
    converged: bool = True


@dataclass(frozen=True)
class TrajectorySeries:
    """The tracker's track and the dead-reckoned ones over the used records.

    ``holdout_start`` is the index (into the tracks) of the first record kept out of the fit.
    """

    tracker: Track
    tracks: tuple[Track, ...]
    holdout_start: int | None
    #: Faults as (index into the tracks, kind), and the first solver's track restarted from the
    #: tracker after each of them (what the segment ATE scores; NaN inside a fault).
    faults: tuple[tuple[int, str], ...] = ()
    restarted: Track | None = None


@dataclass(frozen=True)
class ResidualSeries:
    """Per-residual errors ``(3, n)`` before (initial guess) and after each solver."""

    before: np.ndarray
    after: Mapping[str, np.ndarray]
    inliers_before: int
    inliers_after: Mapping[str, int]
    thresholds: np.ndarray
    kernel: str
    delta: float
    solvers_agree: bool


@dataclass(frozen=True)
class ResidualTimeSeries:
    """One solver's residual errors ``(3, n)`` at their windows' start times, the kernel's
    per-component thresholds, faults as ``(t_first, t_last, kind)`` and the hold-out's start time."""

    solver: str
    time_s: np.ndarray
    errors: np.ndarray
    thresholds: np.ndarray
    faults: tuple[tuple[float, float, str], ...]
    holdout_start_s: float | None


@dataclass(frozen=True)
class ModelCheckSeries:
    """The log's vendor odometry against our base-link model with the header's parameters."""

    time_s: np.ndarray
    vendor: np.ndarray
    ours: np.ndarray
    integration: str
    params: Mapping[str, float]


@dataclass(frozen=True)
class ConvergenceSeries:
    """Iteration histories per solver, and the number of residuals (for the inlier axis)."""

    histories: Mapping[str, tuple[IterationRecord, ...]]
    n_residuals: int
    converged: Mapping[str, bool]


def _inputs(calib: Calibration, log: Log) -> np.ndarray:
    return calib.model.inputs(log, calib.scenario.residual.steering_sample)


def trajectory_series(calib: Calibration, run: CalibrationRun) -> TrajectorySeries:
    """Tracker, uncalibrated and calibrated sensor tracks over the used records."""
    sel = calib.selected
    inputs = _inputs(calib, sel)
    T0 = sel.T_world_sensor[0]
    t = sel.time_s
    p0 = np.array([run.initial[n] for n in calib.fns.names])
    tracks = [
        Track("uncalibrated (initial guess)", integrate(calib.fns, p0, inputs, T0), t, run.baseline.ate_mean)
    ]
    for name, rep in run.reports.items():
        track = integrate(calib.fns, rep.result.params, inputs, T0)
        tracks.append(Track(solver_label(name), track, t, rep.metrics.ate_mean, rep.result.converged))
    holdout = run.fit[1] - run.used[0] if run.fit[1] < run.used[1] - 1 else None
    a, b = run.used
    faults: tuple[tuple[int, str], ...] = ()
    restart = None
    if run.findings is not None and run.findings.report.faults:
        faults = tuple((f.record - a, f.kind) for f in run.findings.report.faults if a <= f.record < b)
        name, rep = next(iter(run.reports.items()))
        parts = segments(b - a, calib.fault_masks[0][a : b - 1])
        track = restarted(steps(calib.fns, rep.result.params, inputs), np.asarray(sel.T_world_sensor), parts)
        restart = Track(
            f"{solver_label(name)}, restarted after each fault", track, t, rep.metrics.segment_ate.mean
        )
    return TrajectorySeries(
        tracker=Track("tracker", np.asarray(sel.T_world_sensor), t),
        tracks=tuple(tracks),
        holdout_start=holdout,
        faults=faults,
        restarted=restart,
    )


def residual_series(calib: Calibration, run: CalibrationRun) -> ResidualSeries:
    """Residual errors at the initial guess and at each solver's estimate (fitted records)."""
    ev = calib.evaluator
    e0, s0, _ = ev.robust_terms(calib.x0)
    after: dict[str, np.ndarray] = {}
    inliers: dict[str, int] = {}
    for name, rep in run.reports.items():
        e, s, _ = ev.robust_terms(rep.result.x)
        after[name] = np.array(e)
        inliers[name] = int(np.sum(s <= ev.delta**2))
    errs = list(after.values())
    scale = max((float(np.max(np.abs(e))) for e in errs), default=0.0)
    # Solvers that met the same optimum give residual sets indistinguishable in a histogram.
    agree = len(errs) > 1 and all(
        np.allclose(e, errs[0], rtol=0.0, atol=1e-6 * max(scale, 1e-12)) for e in errs
    )
    return ResidualSeries(
        before=np.array(e0),
        after=after,
        inliers_before=int(np.sum(s0 <= ev.delta**2)),
        inliers_after=inliers,
        thresholds=ev.delta / np.sqrt(np.asarray(ev.omega, dtype=float)),
        kernel=calib.scenario.robust.kernel,
        delta=ev.delta,
        solvers_agree=agree,
    )


def residual_time_series(calib: Calibration, run: CalibrationRun, solver: str) -> ResidualTimeSeries:
    """``solver``'s residuals over the time of the fitted windows, with the faults' time spans."""
    ev, data = calib.evaluator, calib.data
    e, _, _ = ev.robust_terms(run.reports[solver].result.x)
    log = calib.aligned
    faults: tuple[tuple[float, float, str], ...] = ()
    if run.findings is not None:
        last = log.n_records - 1
        faults = tuple(
            (float(log.time_s[f.first]), float(log.time_s[min(f.last + 1, last)]), f.kind)
            for f in run.findings.report.faults
        )
    holdout = float(log.time_s[run.fit[1]]) if run.fit[1] < run.used[1] - 1 else None
    return ResidualTimeSeries(
        solver=solver,
        time_s=np.asarray(data.log.time_s)[data.starts],
        errors=np.array(e),
        thresholds=ev.delta / np.sqrt(np.asarray(ev.omega, dtype=float)),
        faults=faults,
        holdout_start_s=holdout,
    )


def model_check_series(calib: Calibration) -> ModelCheckSeries:
    """Our model's base-link track with the log header's parameters next to ``model_pose``."""
    # The vendor integrated the encoders as logged, so the un-shifted log is the fair comparison
    # (``calib.aligned`` re-samples the encoders to the tracker's clock when a lag is used).
    log = calib.log
    header = header_parameters(calib.model, log.header)
    params = {n: float(header.get(n, calib.initial[n])) for n in calib.model.kinematic_params}
    params.update(dict.fromkeys(SENSOR_PARAMS, 0.0))
    p = np.array([params[n] for n in calib.fns.names])
    ours = integrate(calib.fns, p, _inputs(calib, log), np.asarray(log.model_pose[0], dtype=float))
    return ModelCheckSeries(
        time_s=np.asarray(log.time_s),
        vendor=np.asarray(log.model_pose),
        ours=ours,
        integration=calib.scenario.residual.integration,
        params={n: params[n] for n in calib.model.kinematic_params},
    )


def convergence_series(run: CalibrationRun) -> ConvergenceSeries:
    """Each solver's iteration history."""
    return ConvergenceSeries(
        histories={n: rep.result.history for n, rep in run.reports.items()},
        n_residuals=run.n_residuals,
        converged={n: rep.result.converged for n, rep in run.reports.items()},
    )
