"""``write_report``: the figures and ``report.md`` of a run, written into its output folder.

Importing this module imports matplotlib (through :mod:`nlp_calib.outputs.plots`); the command
line imports it only when ``--report`` is given.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from nlp_calib.core.files import atomic_write_bytes, atomic_write_text
from nlp_calib.outputs import plots, series
from nlp_calib.outputs.handoff import chosen_solver
from nlp_calib.outputs.markdown import report_markdown
from nlp_calib.outputs.trajectories import write_trajectories
from nlp_calib.pipeline import Calibration, CalibrationRun

TRAJECTORY_FILE = "trajectory.png"
CONVERGENCE_FILE = "convergence.png"
RESIDUALS_FILE = "residuals.png"
RESIDUALS_TIME_FILE = "residuals_time.png"
MODEL_CHECK_FILE = "model_check.png"
REPORT_FILE = "report.md"


def _titles(calib: Calibration, run: CalibrationRun) -> dict[str, str]:
    sc = run.scenario
    span = f"records [{run.used[0]}, {run.used[1]}) of {run.log.n_records}"
    fit = f"fitted records [{run.fit[0]}, {run.fit[1]})"
    r = sc.residual
    return {
        TRAJECTORY_FILE: f"{sc.name}: sensor trajectory, {span}",
        CONVERGENCE_FILE: f"{sc.name}: solver convergence ({run.n_residuals} residuals, kernel "
        f"{sc.robust.kernel} δ = {sc.robust.delta:g})",
        RESIDUALS_FILE: f"{sc.name}: residual errors e = t2v(Z⁻¹·h) of the {run.n_residuals} windows "
        f"(horizon {r.horizon}), {fit}",
        RESIDUALS_TIME_FILE: f"{sc.name}: residual errors over time, horizon {r.horizon}, {fit}",
        MODEL_CHECK_FILE: f"{sc.name}: kinematic model check on all {calib.log.n_records} records "
        f"of {Path(calib.log.path).name}",
    }


def write_report(calib: Calibration, run: CalibrationRun, out_dir: Path) -> list[Path]:
    """Draw the four figures and ``report.md`` into ``out_dir``; returns the paths written."""
    titles = _titles(calib, run)
    solver = chosen_solver(run) or next(iter(run.reports))
    figures: dict[str, Callable[[], bytes]] = {
        TRAJECTORY_FILE: lambda: plots.trajectory_png(
            series.trajectory_series(calib, run), titles[TRAJECTORY_FILE]
        ),
        CONVERGENCE_FILE: lambda: plots.convergence_png(
            series.convergence_series(run), titles[CONVERGENCE_FILE]
        ),
        RESIDUALS_FILE: lambda: plots.residuals_png(
            series.residual_series(calib, run), titles[RESIDUALS_FILE]
        ),
        RESIDUALS_TIME_FILE: lambda: plots.residuals_time_png(
            series.residual_time_series(calib, run, solver), titles[RESIDUALS_TIME_FILE]
        ),
        MODEL_CHECK_FILE: lambda: plots.model_check_png(
            series.model_check_series(calib), titles[MODEL_CHECK_FILE]
        ),
    }
    written = []
    for name, draw in figures.items():
        path = out_dir / name
        atomic_write_bytes(path, draw())
        written.append(path)
    report = out_dir / REPORT_FILE
    atomic_write_text(report, report_markdown(run, list(figures)) + "\n")
    written.append(report)
    return written + write_trajectories(calib, run, out_dir)
