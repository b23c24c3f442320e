"""The plan's sketch: the base's path of each of the best manoeuvres, as driven from a standstill."""

from __future__ import annotations

import math

from matplotlib.figure import Figure

from nlp_calib.outputs.plots.style import figure_png
from nlp_calib.results.preflight import Plan

#: Manoeuvres sketched, best first.
SKETCHED = 4


def plan_png(plan: Plan, title: str) -> bytes:
    """One panel per manoeuvre (the best first): its base path from the start (a dot, heading
    along x: an arrow), the target parameter's σ once it is appended."""
    shown = plan.ranked[:SKETCHED]
    fig = Figure(figsize=(4.2 * max(len(shown), 1), 4.6))
    for i, m in enumerate(shown):
        ax = fig.add_subplot(1, max(len(shown), 1), i + 1)
        P = m.path
        ax.plot(P[:, 0], P[:, 1], color="C0", lw=1.6)
        ax.plot(P[0, 0], P[0, 1], "ko", ms=5)
        span = max(float(max(P[:, 0].max() - P[:, 0].min(), P[:, 1].max() - P[:, 1].min())), 0.5)
        ax.annotate(
            "", xy=(0.15 * span, 0.0), xytext=(0.0, 0.0), arrowprops={"arrowstyle": "->", "color": "k"}
        )
        std = f"{m.target_std_after:.2g}" if math.isfinite(m.target_std_after) else "unbounded"
        unit = f" {plan.target_unit}" if plan.target_unit not in ("", "1") else ""
        ax.set_title(f"{i + 1}. {m.kind.replace('_', ' ')}\nσ {plan.target} → {std}{unit}", fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("forward at the start [m]")
        if i == 0:
            ax.set_ylabel("left at the start [m]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return figure_png(fig)
