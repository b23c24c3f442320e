"""Residual figures: histograms before and after calibration, and the residuals over time."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from nlp_calib.outputs.plots.style import STYLES, envelope, figure_png
from nlp_calib.results.series import ResidualSeries, RunSeries

#: Bins across the calibrated residuals' range: the calibrated peak spans tens of bins.
BINS = 81
_COMPONENTS = (("x", "m"), ("y", "m"), ("θ", "rad"))
_FAULT_COLOURS = {"tracker_jump": "tab:purple"}


def _calibrated_range(after: list[np.ndarray], threshold: float) -> float:
    """The half-width that shows the calibrated residuals (the threshold when nothing else)."""
    spread = [float(np.quantile(np.abs(d), 0.999)) for d in after if d.size]
    top = max(spread, default=0.0)
    return 1.2 * top if top > 0 else 1.25 * threshold


def _threshold_note(threshold: float, R: float) -> str:
    return "" if threshold <= R else ", off the scale"


def _histograms(
    ax: Axes, series: ResidualSeries, i: int, names: Mapping[str, str]
) -> tuple[list[np.ndarray], float]:
    """Component ``i``'s histograms before and after; returns the finite data and the bins' range."""
    solvers = list(series.after)
    shown = solvers[:1] if series.solvers_agree else solvers
    n = series.before.shape[1]
    thr = float(series.thresholds[i])
    # A failed solve may leave NaN residuals; histograms take the finite ones.
    data = [d[np.isfinite(d)] for d in [series.before[i]] + [series.after[s][i] for s in shown]]
    R = _calibrated_range(data[1:], thr)
    bins = np.linspace(-R, R, BINS).tolist()
    clip = R * (1.0 - 1e-9)
    before = f"before: initial guess ({series.inliers_before}/{n} inliers)"
    ax.hist(
        np.clip(data[0], -clip, clip),
        bins=bins,
        histtype="stepfilled",
        color="tab:orange",
        alpha=0.35,
        label=before,
    )
    same = ""
    if series.solvers_agree and len(solvers) > 1:
        same = f"; {', '.join(names.get(o, o) for o in solvers[1:])} identical"
    for s, d, style in zip(shown, data[1:], STYLES[1:]):
        label = f"after: {names.get(s, s)} ({series.inliers_after[s]}/{n} inliers{same})"
        ax.hist(
            np.clip(d, -clip, clip), bins=bins, histtype="step", linewidth=1.8,
            color=style["color"], linestyle=style["linestyle"], label=label,
        )  # fmt: skip
    return data, R


def _panel(ax: Axes, series: ResidualSeries, i: int, names: Mapping[str, str]) -> None:
    """One component: histograms, the kernel's threshold, what the edge bins hold."""
    comp, unit = _COMPONENTS[i]
    what = "kernel threshold" if series.kernel != "none" else "inlier threshold"
    thr = float(series.thresholds[i])
    data, R = _histograms(ax, series, i, names)
    for sign in (-1.0, 1.0) if thr <= R else ():
        label = f"{what} ±δ/√Ω_ii (this component alone gives s = δ²)" if sign > 0 else None
        ax.axvline(sign * thr, color="red", linestyle=":", linewidth=1.6, label=label)
    beyond = [int(np.sum(np.abs(d) > R)) for d in data]
    if any(beyond):
        text = f"edge bins include {beyond[0]} before / {sum(beyond[1:])} after\nbeyond ±{R:.3g} {unit}"
        ax.text(0.02, 0.97, text, transform=ax.transAxes, va="top", fontsize=8)
    after_out = int(np.sum(np.abs(data[1]) > thr)) if len(data) > 1 else 0
    ax.set_yscale("log")
    ax.set_ylim(bottom=0.7)
    ax.xaxis.set_major_locator(MaxNLocator(7))
    ax.set_xlabel(f"{comp} error [{unit}] (bins {2 * R / (BINS - 1):.2g} {unit} wide)")
    ax.set_ylabel("residuals per bin (log scale)")
    note = _threshold_note(thr, R)
    ax.set_title(f"{comp}: {what} ±{thr:.3g} {unit}{note}; {after_out} beyond it", fontsize=10)
    ax.grid(True, which="major", alpha=0.3)


def residuals_png(series: ResidualSeries, names: Mapping[str, str], title: str) -> bytes:
    """Histograms of the x, y, θ residual errors before and after calibration, kernel threshold
    marked; the bins cover the calibrated spread, so the initial guess's wider errors pile up in
    the edge bins (counted on each panel). ``names``: the solvers' display names."""
    fig = Figure(figsize=(15, 5.6), layout="constrained")
    axes = fig.subplots(1, 3)
    for i, ax in enumerate(axes):
        _panel(ax, series, i, names)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=9)
    fig.suptitle(title)
    return figure_png(fig)


def residuals_time_png(series: RunSeries, solver: str, solver_name: str, title: str) -> bytes:
    """``solver``'s residual components over the time of their windows, with the kernel's
    threshold, the residuals beyond it, the faults (left out of the fit) and the hold-out marked."""
    fig = Figure(figsize=(15, 8.5), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    t = series.residuals.time_s
    errors, thresholds = series.residuals.after[solver], series.residuals.thresholds
    # The line breaks where windows were left out, rather than bridging the gap.
    gap = np.flatnonzero(np.diff(t) > 3 * np.median(np.diff(t))) + 1 if t.size > 2 else np.zeros(0, int)
    t_line = np.insert(t.astype(float), gap, np.nan)
    for i, (ax, (comp, unit)) in enumerate(zip(axes, _COMPONENTS)):
        e, thr = errors[i], float(thresholds[i])
        out = np.abs(e) > thr
        ax.plot(
            *envelope(t_line, np.insert(e.astype(float), gap, np.nan)),
            color="tab:blue",
            linewidth=0.8,
            label=f"{solver_name}'s residual",
        )
        ax.plot(t[out], e[out], "o", color="red", markersize=3, label=f"beyond the threshold ({out.sum()})")
        finite = e[np.isfinite(e)]
        lim = _calibrated_range([finite], thr)
        for sign in (-1.0, 1.0):
            if thr <= lim:
                ax.axhline(
                    sign * thr,
                    color="red",
                    linestyle=":",
                    linewidth=1.2,
                    label="±δ/√Ω_ii" if sign > 0 else None,
                )
        kinds_shown: set[str] = set()
        for span in series.fault_spans:
            t0, t1, kind = span.first_s, span.last_s, span.kind
            colour = _FAULT_COLOURS.get(kind, "tab:orange")
            label = f"{kind} (left out)" if kind not in kinds_shown else None
            kinds_shown.add(kind)
            ax.axvspan(t0, max(t1, t0 + 0.05), color=colour, alpha=0.25, linewidth=0, label=label)
        if series.holdout_start_s is not None:
            ax.axvline(series.holdout_start_s, color="0.3", linestyle="--", label="hold-out starts")
        ax.set_ylim(-1.05 * lim, 1.05 * lim)
        ax.set_ylabel(f"{comp} error [{unit}]")
        ax.set_title(f"{comp}: kernel threshold ±{thr:.3g} {unit}{_threshold_note(thr, lim)}", fontsize=10)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time of the window's first record [s]")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=5, fontsize=9)
    fig.suptitle(title)
    return figure_png(fig)
