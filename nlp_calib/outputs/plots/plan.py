"""The plan's sketch: the base's path of each of the best manoeuvres, as driven from a standstill,
with the direction of travel along it and the robot drawn to scale at the start."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from nlp_calib.outputs.plots.style import figure_png
from nlp_calib.results.preflight import Plan

#: Manoeuvres sketched, best first.
SKETCHED = 4
#: Arrows of the direction of travel drawn along each path.
ARROWS = 8
_ARROW = {"arrowstyle": "-|>", "color": "C0", "lw": 1.2, "mutation_scale": 14}


def _arrows(ax: Axes, P: np.ndarray) -> None:
    """Arrows along the path in the direction the base moves (forwards or backwards)."""
    n = P.shape[0]
    if n < 3:
        return
    for k in np.linspace(1, n - 2, ARROWS).round().astype(int):
        a, b = P[k - 1, :2], P[k + 1, :2]
        if np.hypot(*(b - a)) > 0:
            ax.annotate("", xy=tuple(b), xytext=tuple(a), arrowprops=_ARROW)


def _robot(ax: Axes, size: Mapping[str, float]) -> str:
    """The robot to scale at the start, heading along x (its two largest lengths; a square of
    one); returns the words for the legend."""
    if not size:
        return ""
    (n1, length), *rest = sorted(size.items(), key=lambda kv: -kv[1])
    width = rest[0][1] if rest else length
    ax.add_patch(Rectangle((-0.5 * length, -0.5 * width), length, width, facecolor="0.8", edgecolor="k",
                           alpha=0.6, zorder=0))  # fmt: skip
    return f"grey: the robot to scale, {n1} {length:.2g} m" + (
        f" × {rest[0][0]} {width:.2g} m" if rest else ""
    )


def plan_png(plan: Plan, title: str) -> bytes:
    """One panel per manoeuvre (the best first): its base path from the start (a dot, heading
    along x), arrows in the direction of travel, the robot to scale at the start, the target
    parameter's σ once it is appended."""
    shown = plan.ranked[:SKETCHED]
    fig = Figure(figsize=(4.2 * max(len(shown), 1), 5.0), layout="constrained")
    robot = ""
    for i, m in enumerate(shown):
        ax = fig.add_subplot(1, max(len(shown), 1), i + 1)
        P = m.path
        ax.plot(P[:, 0], P[:, 1], color="C0", lw=1.6)
        _arrows(ax, P)
        ax.plot(P[0, 0], P[0, 1], "ko", ms=5)
        robot = _robot(ax, plan.size_m)
        std = f"{m.target_std_after:.2g}" if math.isfinite(m.target_std_after) else "unbounded"
        unit = f" {plan.target_unit}" if plan.target_unit not in ("", "1") else ""
        words = m.kind.replace("_", " ") + (f", {m.radius_m:.2g} m radius" if m.radius_m else "")
        ax.set_title(f"{i + 1}. {words} at {m.speed_mps:.2g} m/s\nσ {plan.target} → {std}{unit}", fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("forward at the start [m]")
        if i == 0:
            ax.set_ylabel("left at the start [m]")
    note = "; ".join(
        w for w in ("arrows: the direction of travel (backwards where they point back)", robot) if w
    )
    fig.suptitle(f"{title}\n{note}", fontsize=10)
    return figure_png(fig)
