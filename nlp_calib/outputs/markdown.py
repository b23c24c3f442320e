"""``report.md``: one page that glues the figures to the solver comparison table."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.version import __version__
from nlp_calib.outputs.summary import summary_lines
from nlp_calib.results import CalibrationRun
from nlp_calib.results.figures import TrajectoryMetrics

#: Figures in page order, with what to look for in each.
FIGURES: tuple[tuple[str, str, str], ...] = (
    (
        "trajectory.png",
        "Trajectory",
        "The sensor track dead-reckoned from the tracker's first pose with the initial guess and with "
        "each solver's estimate, against the tracker; right, each track's distance to the tracker over "
        "time. A good calibration stays on the tracker's track; its remaining drift is what the "
        "encoders cannot explain.",
    ),
    (
        "convergence.png",
        "Convergence",
        "Gauss-Newton's cost and χ² per iteration (rejected Levenberg-Marquardt steps in red) and its "
        "inlier count; IPOPT's objective, constraint violation and dual infeasibility per iteration. "
        "The cost should fall and settle.",
    ),
    (
        "residuals.png",
        "Residuals",
        "Histograms of the x, y and θ residual errors at the initial guess and at the estimate, binned "
        "for the estimate's spread (the initial guess's larger errors fall in the edge bins); the red "
        "lines mark the robust kernel's threshold on each component. Samples beyond them are treated as "
        "outliers.",
    ),
    (
        "residuals_time.png",
        "Residuals over time",
        "Each residual component of the written calibration at the time of its window, with the "
        "kernel's threshold; red points lie beyond it. Shaded spans are the faults found (left out of "
        "the fit). A fault, a stall or a timing problem shows here as a burst or a drift at one time; "
        "a good calibration leaves noise centred on zero.",
    ),
    (
        "model_check.png",
        "Kinematic model check",
        "The log's `model_pose` (the vendor's base-link odometry) against our model integrated with the "
        "log header's parameters, integrated as the fit integrates and first-order (Euler: along the "
        "heading, then turned), as a robot's own odometry usually is: the curve that agrees shows how the "
        "vendor integrates, and what is left is the integration's error, not the model's. Close tracks "
        "validate the kinematic model; this uses no tracker data.",
    ),
    (
        "trust.png",
        "Can I trust each parameter?",
        "Left, each parameter's 1σ to believe (the same as the table above) divided by the precision a "
        "useful calibration needs of it: left of the black line it is determined well enough, beyond "
        "the dashed line the verdict calls it loose. Right, the estimates' correlations: a pair near ±1 "
        "is one the drive cannot tell apart (an error in one is made up by the other).",
    ),
    (
        "lag.png",
        "Tracker lag",
        "The fit's cost at each tracker lag searched, the other parameters as fitted: the lag kept sits "
        "in the lowest valley; a second valley of comparable cost leaves the lag ambiguous.",
    ),
)


def fmt_value(v: float) -> str:
    """A parameter value as the report prints it."""
    return f"{v:.7g}"


def fmt_std(v: float) -> str:
    """A 1σ value as the report prints it."""
    return f"{v:.2g}"


def _cell(v: float | None, fmt: str = ".4g") -> str:
    if v is None or not np.isfinite(v):
        return "–"
    return format(v, fmt)


def _parameter_table(run: CalibrationRun, solvers: Sequence[str]) -> list[str]:
    units, label = run.scenario.units, run.scenario.label
    names = list(run.reports[solvers[0]].result.names)
    head = ["parameter", "unit", "initial"]
    for s in solvers:
        head += [label(s), "± 1σ"]
    pair = len(solvers) == 2
    if pair:
        head.append(f"{label(solvers[0])} − {label(solvers[1])}")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for n in names:
        row = [f"`{n}`", units.get(n, ""), fmt_value(run.initial[n])]
        for s in solvers:
            rep = run.reports[s]
            row += [fmt_value(rep.result.param_dict()[n]), fmt_std(run.std(s)[n])]
        if pair:
            a, b = (run.reports[s].result.param_dict()[n] for s in solvers)
            row.append(f"{a - b:+.2e}")
        lines.append("| " + " | ".join(row) + " |")
    return lines


def _metric_rows(prefix: str, base: TrajectoryMetrics, per: list[TrajectoryMetrics | None]) -> list[str]:
    rows = []
    for i, (label, value) in enumerate(base.figures()):
        cells = [_cell(value, ".4f")] + [
            _cell(m.figures()[i][1] if m is not None else None, ".4f") for m in per
        ]
        rows.append(f"| {prefix}{label} | " + " | ".join(cells) + " |")
    return rows


def _uncertainty_section(run: CalibrationRun) -> list[str]:
    cv, first = run.checks.crossval, next(iter(run.reports), None)
    if first is None:
        return []
    white = run.reports[first].uncertainty.std_dict()
    blocked = run.std_blocks()
    out = ["## Uncertainty and cross-validation", ""]
    if blocked is None or cv is None:
        return [
            *out,
            "The ± 1σ above is the white-noise σ only: a lower bound where timing or model errors are.",
            "",
        ]
    out += [
        "The ± 1σ above is the larger of two estimates: the **white-noise σ** (white tracker and encoder "
        "noise propagated through the fit: a floor) and the **block σ**, the jackknife spread of "
        f"{len(cv.converged)} fits that each leave one contiguous block of the records out (every error "
        "that varies along the drive). Believe the larger one.",
        "",
        "| parameter | white-noise σ | block σ | ratio | spread of the block fits |",
        "|---|---|---|---|---|",
    ]
    for n, spread in zip(cv.names, cv.spread()):
        ratio = blocked[n] / white[n] if white[n] > 0 else float("nan")
        cells = [fmt_std(white[n]), fmt_std(blocked[n]), _cell(ratio, ".1f"), fmt_std(spread)]
        out.append(f"| `{n}` | " + " | ".join(cells) + " |")
    labels = ("segment ATE mean [m]", "RPE over 1 m [m]")
    held = "; ".join(
        f"{label} {_cell(cv.heldout_mean(label), '.4f')} "
        f"(the full fit: {_cell(cv.insample_mean(label), '.4f')})"
        for label in labels
    )
    out += [
        "",
        f"Each block scored by the fit without it, beside the full fit on the same block (mean over "
        f"the blocks): {held}.",
    ]
    out += [line for r in run.checks.more if not r.section for line in ("", r.sentence())]
    return [*out, ""]


def _check_sections(run: CalibrationRun) -> list[str]:
    """The plug-in checks with a section of their own (its title, then its lines)."""
    return [line for r in run.checks.more if r.section for line in (f"## {r.section[0]}", "", *r.section[1:])]


def _solver_table(run: CalibrationRun, solvers: Sequence[str]) -> list[str]:
    reps = [run.reports[s] for s in solvers]
    head = ["", "initial guess", *(run.scenario.label(s) for s in solvers)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def row(label: str, cells: list[str], initial: str = "–") -> None:
        lines.append(f"| {label} | {initial} | " + " | ".join(cells) + " |")

    row("cost Σρ(s)", [_cell(r.result.cost, ".6g") for r in reps])
    row("χ² = Σ eᵀΩe", [_cell(r.result.chi2, ".6g") for r in reps])
    row("inliers", [f"{r.result.inliers} / {r.result.n_residuals}" for r in reps])
    row("iterations", [str(r.result.iterations) for r in reps])
    row("time [ms]", [f"{1e3 * r.result.time_s:.1f}" for r in reps])
    row("converged", ["yes" if r.result.converged else f"**NO**: {r.result.reason}" for r in reps])
    lines += _metric_rows("", run.baseline, [r.metrics for r in reps])
    if run.baseline_holdout is not None:
        lines += _metric_rows("hold-out ", run.baseline_holdout, [r.holdout for r in reps])
    return lines


def _summary(run: CalibrationRun, next_steps: Sequence[str]) -> list[str]:
    head, *rest = summary_lines(run, next_steps)
    return [head, "", *(f"- {line.strip()}" for line in rest if not line.startswith("        "))]


def _header(run: CalibrationRun) -> list[str]:
    sc, data = run.scenario, run.data
    r, robust = sc.residual, sc.robust
    lag = f"{1e3 * data.tracker_lag_s:.1f} ms" + (" (estimated)" if data.lag_estimate is not None else "")
    return [
        f"# Calibration report: {sc.name}",
        "",
        f"- scenario: `{sc.path if sc.path is not None else sc.name}`, model `{sc.model}`, "
        f"nlp_calib {__version__}",
        f"- dataset: `{sc.dataset}`, records [{data.used[0]}, {data.used[1]}) of {run.log.records}, "
        f"fitted on [{data.fit[0]}, {data.fit[1]})",
        f"- residuals: {data.n_residuals} windows of horizon {r['horizon']} (stride {r['stride']}, "
        f"{r['integration']} integration); kernel {robust['kernel']}, δ = {robust['delta']:g}; "
        f"tracker lag {lag}",
    ]


def _handoff_section(run: CalibrationRun, handoff: Sequence[str]) -> list[str]:
    chosen = run.chosen_solver()
    out = ["## Hand-off files", ""]
    if chosen is None or not handoff:
        out.append("No solver converged, so no hand-off files were written.")
    else:
        files = ", ".join(f"[`{f}`]({f})" for f in handoff[:-1]) + f" and [`{handoff[-1]}`]({handoff[-1]})"
        out.append(
            f"{files} carry {run.scenario.label(chosen)}'s estimate (the first converged solver in the "
            f"order {', '.join(run.solver_order())})."
        )
    return [*out, ""]


_FIGURES_TEXT = (
    "Segment ATE: the sensor track dead-reckoned from the tracker, restarted after each fault, "
    "against the tracker (aligned: after the best {group} alignment). RPE over 1 m and 5 m: the "
    "relative pose error between records that far apart along the tracker's path, within one "
    "fault-free segment. Full-run ATE: one track from the first record (a fault's lost counts "
    "stay in it). RPE over {window} records: the same over a fixed count of records."
)


def report_markdown(
    run: CalibrationRun, images: Sequence[str], handoff: Sequence[str] = (), next_steps: Sequence[str] = ()
) -> str:
    """The Markdown page of a run; ``images`` are the figure files written beside it, ``handoff``
    the hand-off files of the calibration and ``next_steps`` what the summary says of them."""
    solvers = run.solver_order()
    out = _header(run)
    out += ["", "## Summary", "", *_summary(run, next_steps), ""]
    out += ["## Parameters", "", *_parameter_table(run, solvers), ""]
    group = run.scenario.sensor.group
    out += ["## Solvers", "", _FIGURES_TEXT.format(window=run.baseline.rpe_window, group=group), ""]
    out += [*_solver_table(run, solvers), "", *_check_sections(run), *_uncertainty_section(run)]
    for s in solvers:
        res = run.reports[s].result
        if not res.converged:
            out += [
                f"> **{run.scenario.label(s)} did not converge** ({res.reason}); do not use its parameters.",
                "",
            ]
    out += [f"> warning: {w}" for w in run.every_warning()]
    out += _handoff_section(run, handoff)
    for file, heading, caption in FIGURES:
        if file in images:
            out += [f"## {heading}", "", caption, "", f"![{heading}]({file})", ""]
    return "\n".join(out)


def write_report(
    run: CalibrationRun, folder: Path, name: str, handoff: Sequence[str], next_steps: Sequence[str]
) -> list[Path]:
    """Write ``report.md`` beside the figures already in ``folder``."""
    images = [file for file, _, _ in FIGURES if (folder / file).exists()]
    atomic_write_text(folder / name, report_markdown(run, images, handoff, next_steps) + "\n")
    return [folder / name]
