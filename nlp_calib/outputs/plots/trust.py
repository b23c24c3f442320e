"""Whether to trust each parameter: its σ against the precision a calibration needs, and how the
parameters trade off (their correlations), and the tracker lag's cost profile with its valleys."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from nlp_calib.outputs.plots.style import figure_png
from nlp_calib.results.checks import WEAK, LagEstimate


@dataclass(frozen=True)
class Standing:
    """One parameter as the trust figure shows it: its value and σ to believe (NaN: none), the
    precision a calibration needs of it (both in ``unit``) and its status (free, held, known)."""

    name: str
    unit: str
    value: float
    std: float
    needed: float
    status: str
    #: Why a parameter that is not free is held, in a few words ("": it is not estimated).
    why: str = ""


#: Bar colours: within the precision needed, within the verdict's limit, beyond it (or no σ).
_GOOD, _LOOSE, _BAD, _GIVEN = "tab:green", "tab:orange", "tab:red", "0.6"


def _ratio_axes(ax: Axes, rows: Sequence[Standing]) -> None:
    y = np.arange(len(rows))[::-1]
    finite = [r.std / r.needed for r in rows if r.status == "free" and math.isfinite(r.std) and r.std > 0]
    top = max([WEAK * 4.0, *(2.0 * v for v in finite)])
    low = min([0.05, *(0.5 * v for v in finite)])
    for yi, r in zip(y, rows):
        unit = "" if r.unit in ("", "1") else f" {r.unit}"
        if r.status != "free":
            ax.barh(yi, top, left=low, color=_GIVEN, alpha=0.25)
            ax.text(
                low * 1.1,
                yi,
                f"{r.status}: {r.value:.4g}{unit} ({r.why or 'not estimated'})",
                va="center",
                fontsize=8,
            )
            continue
        if not (math.isfinite(r.std) and r.std > 0):
            ax.barh(yi, top, left=low, color=_BAD, alpha=0.35, hatch="//")
            ax.text(low * 1.1, yi, "no σ: not determined by this drive", va="center", fontsize=8)
            continue
        ratio = r.std / r.needed
        colour = _GOOD if ratio <= 1.0 else (_LOOSE if ratio <= WEAK else _BAD)
        ax.barh(yi, ratio - low, left=low, color=colour, alpha=0.8)
        ax.text(
            min(ratio, top) * 1.08, yi, f"±{r.std:.2g}{unit} (needs {r.needed:.2g})", va="center", fontsize=8
        )
    ax.axvline(1.0, color="k", linewidth=1.0, label="σ = the precision needed")
    ax.axvline(WEAK, color=_BAD, linestyle="--", linewidth=1.0, label=f"{WEAK:g}× it: the verdict's limit")
    handles, _ = ax.get_legend_handles_labels()
    kinds = (
        (_GOOD, "within the precision needed"),
        (_LOOSE, f"within {WEAK:g}× it"),
        (_BAD, "beyond: loose"),
    )
    handles += [Patch(color=c, label=w) for c, w in kinds]
    ax.set_xscale("log")
    ax.set_xlim(low, top * 6.0)  # room for the words right of each bar
    ax.set_yticks(y, [r.name for r in rows])
    ax.set_xlabel("1σ to believe ÷ the precision a useful calibration needs (log scale)")
    ax.set_title("each parameter: left of the black line is determined well enough", fontsize=10)
    # Below the axes: inside them, the box covered the words right of the top bars.
    ax.legend(handles=handles, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3)
    ax.grid(True, axis="x", which="both", alpha=0.3)


def _correlation_axes(fig: Figure, ax: Axes, names: Sequence[str], correlation: np.ndarray) -> None:
    image = ax.imshow(correlation, cmap="RdBu_r", vmin=-1.0, vmax=1.0)
    n = len(names)
    ax.set_xticks(range(n), names, rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(n), names, fontsize=8)
    for i in range(n):
        for j in range(n):
            c = float(correlation[i, j])
            if i != j and math.isfinite(c):
                ax.text(j, i, f"{c:.2f}", ha="center", va="center", fontsize=7,
                        color="white" if abs(c) > 0.6 else "black")  # fmt: skip
    ax.set_title("correlations of the estimates: near ±1, the drive\ncannot tell the two apart", fontsize=10)
    fig.colorbar(image, ax=ax, shrink=0.8, label="correlation")


def trust_png(rows: Sequence[Standing], names: Sequence[str], correlation: np.ndarray, title: str) -> bytes:
    """Left, each parameter's σ over the precision it needs (log scale: green within it, orange
    within the verdict's limit, red beyond); right, the free parameters' correlations."""
    fig = Figure(figsize=(14, max(4.8, 0.45 * len(rows) + 2.2)), layout="constrained")
    ax, ax_c = fig.subplots(1, 2, width_ratios=(1.25, 1))
    _ratio_axes(ax, rows)
    _correlation_axes(fig, ax_c, names, correlation)
    fig.suptitle(title)
    return figure_png(fig)


def lag_png(est: LagEstimate, std: float, title: str) -> bytes:
    """The fit's cost over the tracker lags searched (its valleys), the lags the encoders were
    re-sampled at on the way, the lag kept with its 1σ and a second valley of comparable cost."""
    fig = Figure(figsize=(9, 5), layout="constrained")
    ax = fig.subplots()
    if est.profile_s:
        s, c = 1e3 * np.asarray(est.profile_s), np.asarray(est.profile_costs, dtype=float)
        ax.plot(s, c, "-", color="tab:blue", label="cost at each lag (the other parameters as fitted)")
    path, costs = 1e3 * np.asarray(est.path_s), np.asarray(est.costs, dtype=float)
    ax.plot(path, costs, "o", color="0.3", markersize=5, label="lags the encoders were re-sampled at")
    lag = 1e3 * est.lag_s
    if math.isfinite(std) and std > 0:
        ax.axvspan(lag - 1e3 * std, lag + 1e3 * std, color="tab:green", alpha=0.2, label="kept lag ± 1σ")
    ax.axvline(lag, color="tab:green", linewidth=1.6, label=f"kept: {lag:.1f} ms")
    if est.ambiguous:
        other = 1e3 * est.other[0]
        ax.axvline(
            other, color="tab:red", linestyle="--", label=f"second valley of comparable cost: {other:.1f} ms"
        )
    words = []
    if est.at_edge:
        words.append("the lag ended on the edge of its search: the true lag may lie beyond")
    if not est.converged:
        words.append("the last fit did not converge")
    if est.loose:
        words.append("fits re-sampled off the lag stay there: the drive does not determine it")
    ax.set_xlabel("tracker lag (the scenario's tracker_lag) [ms]")
    ax.set_ylabel("cost of the fit")
    ax.set_title(
        "; ".join(words) if words else "no second valley of comparable cost: the lag is determined",
        fontsize=10,
    )
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.suptitle(title)
    return figure_png(fig)
