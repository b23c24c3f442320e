"""Several calibrations side by side (``nlp-calib compare``): every parameter with its 1σ, the
tracker lag, the sensor's mount, the fair figures and the verdict, one column per scenario and
solver; ``compare.md`` holds the same table, ``compare.csv`` one row per scenario and solver.

A parameter a model does not have is shown as ``-``; the rows follow the runs' own order of
parameters (the first run's, then any the others add).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.version import __version__
from nlp_calib.results import CalibrationRun

MARKDOWN_FILE = "compare.md"
CSV_FILE = "compare.csv"
FILES = (MARKDOWN_FILE, CSV_FILE)

Column = tuple[CalibrationRun, str]


def columns(runs: Sequence[CalibrationRun]) -> list[Column]:
    """One column per scenario and solver, in the runs' order and each run's solver order."""
    return [(run, solver) for run in runs for solver in run.solver_order()]


def parameters(runs: Sequence[CalibrationRun]) -> list[str]:
    """Every parameter of any run, in the order the runs give them."""
    names: list[str] = []
    for run in runs:
        for rep in run.reports.values():
            names += [n for n in rep.result.names if n not in names]
    return names


def _unit(runs: Sequence[CalibrationRun], name: str) -> str:
    return next((run.scenario.units[name] for run in runs if name in run.scenario.units), "")


def _sensor(run: CalibrationRun, solver: str) -> str:
    mount = run.reports[solver].mount
    if mount is None:
        return run.log.sensor_frame
    return mount.child + ("" if mount.parent == "base_link" else f" on {mount.parent}") + f" ({mount.kind})"


def _lag(run: CalibrationRun, solver: str) -> str:
    """The solver's fitted lag where the lag is a parameter of the fit (the encoders were re-sampled
    near it, not at it), else the one the encoders were read at."""
    params = run.reports[solver].result.param_dict()
    fitted = [params[e.lag] for e in run.checks.lag_effects or () if e.lag in params]
    if len(fitted) == 1:
        return f"{1e3 * fitted[0]:.1f} (estimated)"
    how = "estimated" if run.data.lag_estimate is not None else "given"
    return f"{1e3 * run.data.tracker_lag_s:.1f} ({how})"


def _value(run: CalibrationRun, solver: str, name: str) -> tuple[float, float] | None:
    params = run.reports[solver].result.param_dict()
    return (params[name], run.std(solver)[name]) if name in params else None


def rows(runs: Sequence[CalibrationRun]) -> list[tuple[str, list[str]]]:
    """The table's rows: a label and one cell per column."""
    cols = columns(runs)
    out = [
        ("scenario", [run.scenario.name for run, _ in cols]),
        ("model", [run.scenario.model for run, _ in cols]),
        ("solver", [s for _, s in cols]),
        ("converged", ["yes" if run.reports[s].result.converged else "NO" for run, s in cols]),
    ]
    for name in parameters(runs):
        unit = _unit(runs, name)
        label = name if unit in ("", "1") else f"{name} [{unit}]"
        cells = []
        for run, solver in cols:
            found = _value(run, solver, name)
            cells.append("-" if found is None else f"{found[0]:.7g} ± {found[1]:.2g}")
        out.append((label, cells))
    out += [
        ("tracker lag [ms]", [_lag(run, solver) for run, solver in cols]),
        ("sensor", [_sensor(run, s) for run, s in cols]),
        ("segment ATE [m]", [f"{run.reports[s].metrics.segment_ate.mean:.4g}" for run, s in cols]),
        ("RPE over 5 m [m]", [f"{run.reports[s].metrics.rpe_distance[5.0].mean:.4g}" for run, s in cols]),
        *_holdout_rows(runs, cols),
        ("verdict", [run.verdict.level for run, _ in cols]),
    ]
    return out


def _holdout_rows(
    runs: Sequence[CalibrationRun], cols: Sequence[tuple[CalibrationRun, str]]
) -> list[tuple[str, list[str]]]:
    """The figures on records no fit saw: the trailing hold-out (``validation.holdout_fraction``)
    where a run has one, and the blocked cross-validation's (each block scored by the fit without
    it; the run's, whichever solver)."""
    out = []
    if any(run.reports[s].holdout is not None for run, s in cols):
        out.append(("hold-out segment ATE [m]", [_holdout(run, s) for run, s in cols]))
    if any(_crossval(run) != "-" for run in runs):
        out.append(("cross-validated segment ATE [m]", [_crossval(run) for run, _ in cols]))
    return out


def _crossval(run: CalibrationRun) -> str:
    """The cross-validation's held-out segment ATE (mean over its blocks), or "-"."""
    cv = run.checks.crossval
    if cv is None or not cv.converged:
        return "-"
    value = cv.heldout_mean("segment ATE mean [m]")
    return f"{value:.4g}" if value == value else "-"


def _holdout(run: CalibrationRun, solver: str) -> str:
    held = run.reports[solver].holdout
    return "-" if held is None else f"{held.segment_ate.mean:.4g}"


def compare_table(runs: Sequence[CalibrationRun]) -> str:
    """The table as plain text for the terminal."""
    table = rows(runs)
    label_width = max(len(label) for label, _ in table) + 2
    widths = [max(len(cells[i]) for _, cells in table) + 2 for i in range(len(table[0][1]))]
    lines = ["side by side"]
    for label, cells in table:
        lines.append(f"{label:<{label_width}}" + "".join(f"{c:>{w}}" for c, w in zip(cells, widths)))
    return "\n".join(lines)


def compare_markdown(runs: Sequence[CalibrationRun]) -> str:
    """``compare.md``: the table, and each run's verdict in words."""
    table = rows(runs)
    head = ["", *table[0][1]]
    lines = [
        f"# Side by side (nlp_calib {__version__})",
        "",
        "Each value ± its 1σ to believe (the larger of the white-noise σ and the block jackknife σ).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    lines += ["| " + " | ".join([label, *cells]) + " |" for label, cells in table[1:]]
    lines += ["", "## Verdicts", ""]
    lines += [f"- **{run.scenario.name}**: {run.verdict.line()}" for run in runs]
    return "\n".join(lines) + "\n"


def compare_csv(runs: Sequence[CalibrationRun]) -> str:
    """``compare.csv``: one row per scenario and solver; each parameter's value and 1σ (empty where
    the model has none), the lag (s), the sensor, the figures and the verdict."""
    names = parameters(runs)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    head = ["scenario", "model", "solver", "converged"]
    head += [c for n in names for c in (n, f"{n}_std")]
    head += ["tracker_lag_s", "sensor_frame", "sensor_mount", "segment_ate_m", "rpe_5m_m", "verdict"]
    writer.writerow(head)
    for run, solver in columns(runs):
        rep = run.reports[solver]
        cells: list[object] = [run.scenario.name, run.scenario.model, solver, rep.result.converged]
        for name in names:
            found = _value(run, solver, name)
            cells += ["", ""] if found is None else [repr(found[0]), repr(found[1])]
        mount = rep.mount
        cells += [repr(run.data.tracker_lag_s), mount.child if mount else run.log.sensor_frame]
        cells += [mount.kind if mount else "", repr(rep.metrics.segment_ate.mean)]
        cells += [repr(rep.metrics.rpe_distance[5.0].mean), run.verdict.level]
        writer.writerow(["" if isinstance(c, float) and not np.isfinite(c) else c for c in cells])
    return buf.getvalue()


def write_compare(runs: Sequence[CalibrationRun], folder: Path) -> list[Path]:
    """``compare.md`` and ``compare.csv`` of ``runs`` into ``folder``."""
    atomic_write_text(folder / MARKDOWN_FILE, compare_markdown(runs))
    atomic_write_text(folder / CSV_FILE, compare_csv(runs))
    return [folder / MARKDOWN_FILE, folder / CSV_FILE]
