"""The report's figures, each drawn from a run's result into its output folder.

Importing this module imports matplotlib (through :mod:`nlp_calib.outputs.plots`); the registry
of outputs imports it only when a figure is written.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from nlp_calib.core.files import atomic_write_bytes
from nlp_calib.outputs import plots
from nlp_calib.outputs.plots.run import ConvergenceSeries
from nlp_calib.outputs.plots.trust import Standing
from nlp_calib.results import CalibrationRun
from nlp_calib.results.layout import CLOCK
from nlp_calib.results.preflight import Plan
from nlp_calib.results.series import Track


def _write(folder: Path, name: str, png: bytes) -> list[Path]:
    path = folder / name
    atomic_write_bytes(path, png)
    return [path]


def _fit_span(run: CalibrationRun) -> str:
    return f"fitted records [{run.data.fit[0]}, {run.data.fit[1]})"


def trajectory(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """The sensor tracks against the tracker, and their distance to it over time."""
    tracks = run.require_series().tracks
    restarted = None
    solver = next(iter(run.reports))
    if tracks.faults:
        label = f"{run.scenario.label(solver)}, restarted after each fault"
        ate = run.reports[solver].metrics.segment_ate.mean
        restarted = Track(label, solver, tracks.restarted[solver], ate)
    used = run.data.used
    title = f"{run.scenario.name}: sensor trajectory, records [{used[0]}, {used[1]}) of {run.log.records}"
    return _write(folder, name, plots.trajectory_png(tracks, restarted, title))


def plan(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """The plan's sketch: the best manoeuvres' paths (nothing when the run needs none)."""
    return plan_sketch(run.checks.plan, run.scenario.name, folder, name)


def plan_sketch(ahead: Plan | None, scenario: str, folder: Path, name: str) -> list[Path]:
    """The sketch of ``ahead`` (a run's plan, or the pre-flight's where it stops a run)."""
    if ahead is None or not ahead.ranked:
        return []
    title = f"{scenario}: what to drive next to determine {ahead.target} (best first)"
    return _write(folder, name, plots.plan_png(ahead, title))


def convergence(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """Each solver's iterations."""
    series = ConvergenceSeries(
        histories={n: rep.result.trace.history for n, rep in run.reports.items()},
        labels=run.scenario.labels,
        n_residuals=run.data.n_residuals,
        converged={n: rep.result.converged for n, rep in run.reports.items()},
    )
    robust = run.scenario.robust
    title = (
        f"{run.scenario.name}: solver convergence ({run.data.n_residuals} residuals, kernel "
        f"{robust['kernel']} δ = {robust['delta']:g})"
    )
    return _write(folder, name, plots.convergence_png(series, title))


def residuals(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """Histograms of the residuals before and after."""
    H = run.scenario.residual["horizon"]
    title = (
        f"{run.scenario.name}: residual errors e = t2v(Z⁻¹·h) of the {run.data.n_residuals} windows "
        f"(horizon {H}), {_fit_span(run)}"
    )
    return _write(
        folder, name, plots.residuals_png(run.require_series().residuals, run.scenario.labels, title)
    )


def residuals_time(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """The chosen solver's residuals over time."""
    solver = run.chosen_solver() or next(iter(run.reports))
    H = run.scenario.residual["horizon"]
    title = f"{run.scenario.name}: residual errors over time, horizon {H}, {_fit_span(run)}"
    png = plots.residuals_time_png(run.require_series(), solver, run.scenario.label(solver), title)
    return _write(folder, name, png)


def model_check(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """Our model against the vendor's odometry (only where the log carries it)."""
    check = run.require_series().model_check
    if check is None:
        return []
    title = (
        f"{run.scenario.name}: kinematic model check on all {run.log.records} records "
        f"of {Path(run.log.path).name}"
    )
    return _write(folder, name, plots.model_check_png(check, title))


def odometry(run: CalibrationRun, folder: Path, name: str, sigma: float = 3.0) -> list[Path]:
    """The calibrated odometry with its σ ellipses beside the base poses the tracker implies."""
    if run.odometry is None or run.odometry.reference is None:
        return []
    solver = run.chosen_solver() or next(iter(run.reports))
    title = f"{run.scenario.name}: calibrated odometry ({solver}), {sigma:g}σ ellipses"
    return _write(folder, name, plots.odometry_png(run.odometry, run.odometry.reference, title, sigma=sigma))


def trust(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """Each parameter's σ to believe against the precision its layout says a calibration needs,
    and the estimates' correlations (the estimate the hand-off carries, else the first converged)."""
    solver = run.handoff_solver() or run.chosen_solver()
    if solver is None:
        return []
    values, std = run.reports[solver].result.param_dict(), run.std(solver)
    # A time offset the run holds with no σ is held here as in every file (its reason's first words).
    layout, held = run.stated_layout(), run.held_lags()
    rows = [
        Standing(p.name, p.unit, values.get(p.name, p.start), std.get(p.name, math.nan),
                 p.needed(values.get(p.name, p.start)), p.status, held.get(p.name, "").split(":")[0])
        for p in layout.parameters
    ]  # fmt: skip
    u = run.reports[solver].uncertainty
    free = [i for i, n in enumerate(u.names) if n in u.free]
    names = [u.names[i] for i in free]
    correlation = np.asarray(u.correlation)[np.ix_(free, free)]
    title = f"{run.scenario.name}: can I trust each parameter? ({run.scenario.label(solver)}'s estimate)"
    return _write(folder, name, plots.trust_png(rows, names, correlation, title))


def lag(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """The tracker lag's cost profile over its search, where the run estimated the lag."""
    est = run.data.lag_estimate
    if est is None:
        return []
    solver = run.chosen_solver()
    # The lag this estimate is of (a joint fit's view: its own log's, among every log's).
    clock = [n for n, e in run.lag_estimates().items() if e is est] or run.scenario.layout.block(CLOCK)
    std = run.std(solver).get(clock[0], math.nan) if solver is not None and len(clock) == 1 else math.nan
    title = f"{run.scenario.name}: the tracker lag's cost profile ({Path(run.log.path).name})"
    return _write(folder, name, plots.lag_png(est, std, title))
