"""The run report's figures as PNG bytes (matplotlib lives only in this ``plots`` package).

Figures are drawn on an explicit Agg canvas (``FigureCanvasAgg``) rather than through pyplot:
no display is needed, no global figure state is kept, and the backend of an interactive session
that imports this module is left alone (``matplotlib.use`` would switch it).
"""

from __future__ import annotations

import dataclasses
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, MaxNLocator, NullLocator
from matplotlib.transforms import blended_transform_factory

from nlp_calib.core.numeric import wrap_angle
from nlp_calib.outputs.plots.style import STYLES, envelope, figure_png, path_step, thin_path
from nlp_calib.results import IterationRecord
from nlp_calib.results.series import ModelCheckSeries, Track, TrackSeries

_STYLES = STYLES
_TRACKER: Mapping[str, Any] = {"color": "0.15", "linestyle": "-", "linewidth": 3.0, "alpha": 0.35}
_PLAIN = FuncFormatter(lambda v, _: f"{v:g}")
#: Characters of a title's default font that fit an inch of panel (a conservative count).
_TITLE_CHARS_PER_INCH = 8.5


def _plain_log_ticks(ax: Axes) -> None:
    """Readable ticks on a log axis spanning less than a decade (where log ticks are sparse)."""
    lo, hi = ax.get_ylim()
    if lo > 0 and hi / lo < 10:
        ax.yaxis.set_major_locator(MaxNLocator(6))
        ax.yaxis.set_minor_locator(NullLocator())
        ax.yaxis.set_major_formatter(_PLAIN)


@dataclass(frozen=True)
class ConvergenceSeries:
    """Iteration histories per solver, their display labels, whether each converged, and the
    number of residuals (for the inlier axis)."""

    histories: Mapping[str, tuple[IterationRecord, ...]]
    labels: Mapping[str, str]
    n_residuals: int
    converged: Mapping[str, bool]


# --- trajectory ------------------------------------------------------------------------------


def _far_outside(P: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether a track strays beyond the box [lo, hi] by more than half its size."""
    reach = 0.5 * float(np.max(hi - lo))
    return bool(np.any(P[:, :2] < lo - reach) or np.any(P[:, :2] > hi + reach))


def _label(track: Track, outside: bool) -> str:
    # No full-run ATE over records that do not connect (its track would chain them).
    ate = f"(ATE {track.ate_mean:.3f} m)" if np.isfinite(track.ate_mean) else "(no full-run ATE: parts apart)"
    parts = [track.label, ate]
    if not track.converged:
        parts.append("NOT CONVERGED")
    if outside:
        parts.append("[leaves the frame]")
    return " ".join(parts)


def _tracks(ax: Axes, ax_err: Axes, series: TrackSeries) -> tuple[np.ndarray, np.ndarray]:
    """Draw every track and its distance to the tracker; returns the box that frames the tracker
    and the converged tracks."""
    tr, t, good = series.tracker, series.time_s - series.time_s[0], _good(series)
    # The poses left out (tracker jumps) are not drawn: a line through each would be a spike.
    # Frame the tracker and the calibrated tracks; a run-away track (the uncalibrated one on a
    # real log drifts by tens of metres) is drawn but not allowed to shrink the others to a dot.
    kept = [tr[good]] + [tk.T_world_sensor for tk in series.tracks[1:] if tk.converged]
    xy = np.concatenate([P[:, :2] for P in kept])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    step = path_step(xy)
    ax.plot(*thin_path(tr[good, 0], tr[good, 1], step), label="tracker (measured sensor pose)", **_TRACKER)
    for track, style in zip(series.tracks, _STYLES):
        P = track.T_world_sensor
        outside = _far_outside(P, lo, hi)
        ax.plot(
            *thin_path(P[:, 0], P[:, 1], step), label=_label(track, outside), scalex=not outside,
            scaley=not outside, **style,
        )  # fmt: skip
        if not outside:
            ax.plot(P[-1, 0], P[-1, 1], marker="s", markersize=7, color=style["color"], linestyle="none")
        err = np.linalg.norm(P[1:, :2] - tr[1:, :2], axis=1)  # record 0 is the shared start: 0
        shown = np.where((err > 0) & good[1:], err, np.nan)
        ax_err.plot(*envelope(t[1:], shown), label=track.label, **style)
    ax.plot(tr[-1, 0], tr[-1, 1], marker="s", markersize=7, color="0.15", linestyle="none")
    ax.plot(tr[0, 0], tr[0, 1], marker="o", markersize=9, color="black", linestyle="none", label="start")
    ax.plot([], [], marker="s", color="0.4", linestyle="none", label="end (colour of each track)")
    return lo, hi


def _marks(ax: Axes, ax_err: Axes, series: TrackSeries, restarted: Track | None) -> None:
    """The track restarted after each fault, the faults and the first hold-out record."""
    tr, t, good = series.tracker, series.time_s - series.time_s[0], _good(series)
    if restarted is not None:
        P = restarted.T_world_sensor
        err = np.linalg.norm(P[1:, :2] - tr[1:, :2], axis=1)
        fair = f"{restarted.label} (segment ATE {restarted.ate_mean:.3f} m)"
        shown = np.where((err > 0) & good[1:], err, np.nan)
        ax_err.plot(*envelope(t[1:], shown), color="tab:cyan", linewidth=1.0, label=fair)
    _jumps(ax, ax_err, series, good)
    labelled = False
    for k, kind in series.faults:
        if kind == "tracker_jump":
            continue
        label = None if labelled else "encoder fault (the fair track restarts)"
        labelled = True
        ax.plot(tr[k, 0], tr[k, 1], marker="X", color="red", markersize=10, linestyle="none", label=label)
        ax_err.axvline(t[k], color="red", linewidth=0.8, alpha=0.6, label=label)
    if series.holdout_start is not None:
        k = series.holdout_start
        ax.plot(
            tr[k, 0], tr[k, 1], marker="^", markersize=10, color="red", linestyle="none",
            label="first hold-out record (not fitted)",
        )  # fmt: skip
        ax_err.axvline(t[k], color="red", linestyle=":", label="fitted | hold-out records")


def _good(series: TrackSeries) -> np.ndarray:
    """The tracker poses kept (not flagged bad), as a boolean mask over the records."""
    good = np.asarray(series.good, dtype=bool)
    return good if good.shape == (series.tracker.shape[0],) else np.ones(series.tracker.shape[0], bool)


def _jumps(ax: Axes, ax_err: Axes, series: TrackSeries, good: np.ndarray) -> None:
    """The tracker poses left out, de-emphasised: a small tick on the track where each happened
    (at the last kept pose before it; the bad pose itself may lie a metre away) and a tick on the
    error panel's time axis, one legend entry for them all."""
    jumps = [k for k, kind in series.faults if kind == "tracker_jump"]
    if not jumps:
        return
    kept = np.flatnonzero(good)
    at = [int(kept[max(np.searchsorted(kept, k) - 1, 0)]) for k in jumps] if kept.size else jumps
    tr, t = series.tracker, series.time_s - series.time_s[0]
    label = f"{len(jumps)} tracker poses left out (jumps), where they happened"
    ax.plot(tr[at, 0], tr[at, 1], marker="|", markersize=6, color="magenta", alpha=0.7, linestyle="none",
            label=label)  # fmt: skip
    rug = blended_transform_factory(ax_err.transData, ax_err.transAxes)
    ax_err.plot(t[jumps], np.full(len(jumps), 0.015), marker="|", markersize=8, color="magenta",
                alpha=0.7, linestyle="none", transform=rug, label=label)  # fmt: skip


def _levelled(series: TrackSeries, restarted: Track | None) -> tuple[TrackSeries, Track | None]:
    """A 3-D sensor's tracks with their positions turned by ``series.level`` (the floor plane as
    x-y, from the first record); planar tracks as they are."""
    if series.level is None:
        return series, restarted
    level, origin = series.level, series.tracker[0, :3]

    def turned(P: np.ndarray) -> np.ndarray:
        return (P[:, :3] - origin) @ level.T

    tracks = tuple(dataclasses.replace(t, T_world_sensor=turned(t.T_world_sensor)) for t in series.tracks)
    again = (
        None
        if restarted is None
        else dataclasses.replace(restarted, T_world_sensor=turned(restarted.T_world_sensor))
    )
    return dataclasses.replace(series, tracker=turned(series.tracker), tracks=tracks), again


def trajectory_png(series: TrackSeries, restarted: Track | None, title: str) -> bytes:
    """Tracker track and dead-reckoned sensor tracks (equal axes), and their distance over time;
    ``restarted``: a track restarted after each fault, its distance drawn too."""
    frame = "the base's frame at the start" if series.level is not None else "the tracker's world frame"
    series, restarted = _levelled(series, restarted)
    fig = Figure(figsize=(14, 6.2), layout="constrained")
    ax, ax_err = fig.subplots(1, 2, width_ratios=(1.35, 1))
    lo, hi = _tracks(ax, ax_err, series)
    _marks(ax, ax_err, series, restarted)
    # Plotting grows the data limits with every line; reset them to the framed tracks so the
    # equal-aspect autoscale ignores a run-away track (fixed limits would fight the aspect).
    pad = 0.03 * max(float(np.max(hi - lo)), 1e-3)
    ax.dataLim.set_points(np.array([lo - pad, hi + pad]))
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel(f"x in {frame} [m]")
    ax.set_ylabel(f"y in {frame} [m]")
    ax.set_title("sensor track: tracker vs dead reckoning from the tracker's first pose")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, framealpha=0.85)
    ax_err.set_yscale("log")
    ax_err.set_xlabel("time since the first used record [s]")
    ax_err.set_ylabel("distance to the tracker's position [m] (log scale)")
    ax_err.set_title("position error of each dead-reckoned track")
    ax_err.grid(True, which="both", alpha=0.3)
    ax_err.legend(loc="lower right", fontsize=8)
    fig.suptitle(title)
    return figure_png(fig)


# --- convergence -----------------------------------------------------------------------------


def _int_iterations(ax: Axes) -> None:
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("iteration")
    ax.grid(True, which="both", alpha=0.3)


def _positive(values: np.ndarray) -> np.ndarray:
    """Values for a log axis: non-positive ones become NaN (not drawn)."""
    v = np.asarray(values, dtype=float)
    return np.where(v > 0, v, np.nan)


def _status(series: ConvergenceSeries, name: str) -> str:
    return "" if series.converged[name] else " — NOT CONVERGED"


def _is_interior_point(history: Sequence[IterationRecord]) -> bool:
    """Whether a history tracks constraint violation and dual infeasibility (IPOPT-like)."""
    return any(np.isfinite(h.dual_infeasibility) for h in history)


def _least_squares_axes(ax_cost: Axes, ax_in: Axes, series: ConvergenceSeries, name: str) -> None:
    hist = series.histories[name]
    it = np.array([h.iteration for h in hist])
    acc = np.array([h.accepted for h in hist], dtype=bool)
    cost = np.array([h.cost for h in hist])
    chi2 = np.array([h.chi2 for h in hist])
    ax_cost.plot(it[acc], _positive(cost[acc]), "o-", color="tab:blue", label="cost Σρ(s) (accepted steps)")
    ax_cost.plot(
        it[acc],
        _positive(chi2[acc]),
        "s--",
        color="tab:purple",
        markersize=4,
        label="χ² = Σ eᵀΩe (accepted steps)",
    )
    if np.any(~acc):
        ax_cost.plot(
            it[~acc],
            _positive(cost[~acc]),
            "x",
            color="red",
            markersize=9,
            mew=2,
            label="rejected LM step: its cost (damping raised, x kept)",
        )
    ax_cost.set_yscale("log")
    _plain_log_ticks(ax_cost)
    ax_cost.set_ylabel("cost, χ² (log scale)")
    ax_cost.set_title(f"{series.labels.get(name, name)}: cost and χ² per iteration{_status(series, name)}")
    ax_cost.legend(fontsize=8)
    _int_iterations(ax_cost)
    inl = np.array([h.inliers for h in hist])[acc]
    n = series.n_residuals
    ax_in.plot(it[acc], inl, "o-", color="tab:blue", label="inliers (s = eᵀΩe ≤ δ²)")
    ax_in.axhline(n, color="0.4", linestyle=":", label=f"all {n} residuals")
    low = float(inl.min()) if inl.size else 0.0
    pad = max(0.08 * (n - low), 2.0)
    ax_in.set_ylim(max(low - pad, 0.0), n + pad)
    ax_in.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax_in.set_ylabel("number of residuals")
    ax_in.set_title(f"{series.labels.get(name, name)}: inliers per accepted iteration")
    ax_in.legend(fontsize=8, loc="best")
    _int_iterations(ax_in)


def _interior_point_axes(ax_obj: Axes, ax_inf: Axes, series: ConvergenceSeries, name: str) -> None:
    hist = series.histories[name]
    it = np.array([h.iteration for h in hist])
    obj = np.array([h.cost for h in hist])
    ax_obj.plot(it, _positive(obj), "o-", color="tab:green", label="objective Σρ(s)")
    ax_obj.set_yscale("log")
    _plain_log_ticks(ax_obj)
    ax_obj.set_ylabel("objective (log scale)")
    ax_obj.set_title(f"{series.labels.get(name, name)}: objective per iteration{_status(series, name)}")
    ax_obj.legend(fontsize=8)
    _int_iterations(ax_obj)
    pr = np.array([h.constraint_violation for h in hist])
    du = np.array([h.dual_infeasibility for h in hist])
    ax_inf.plot(
        it, _positive(du), "s--", color="tab:olive", markersize=4, label="dual infeasibility (gradient)"
    )
    if np.any(pr > 0):
        ax_inf.plot(it, _positive(pr), "o-", color="tab:red", label="constraint violation (0 not drawn)")
    else:
        # No constraints (or bounds kept strictly inside): a log axis cannot show the zeros.
        ax_inf.plot([], [], "o-", color="tab:red", label="constraint violation: 0 at every iteration")
    ax_inf.set_yscale("log")
    ax_inf.set_ylabel("infeasibility (log scale)")
    ax_inf.set_title(f"{series.labels.get(name, name)}: constraint violation and dual infeasibility")
    ax_inf.legend(fontsize=8)
    _int_iterations(ax_inf)


def _excess_axes(ax: Axes, series: ConvergenceSeries, names: Sequence[str]) -> None:
    """Each solver's cost above the lowest cost any solver reached: the rate and the agreement."""
    costs = {}
    for name in names:
        hist = series.histories[name]
        keep = [h for h in hist if h.accepted]
        costs[name] = (np.array([h.iteration for h in keep]), np.array([h.cost for h in keep]))
    best = min(float(np.nanmin(c)) for _, c in costs.values())
    scale = max(abs(best), 1e-300)
    for (name, (it, c)), style in zip(costs.items(), _STYLES[1:]):
        ax.plot(
            it,
            _positive((c - best) / scale),
            "o-",
            color=style["color"],
            label=series.labels.get(name, name),
        )
    ax.set_yscale("log")
    ax.set_ylabel("(cost − lowest cost) / lowest cost")
    ax.set_title(f"cost above the lowest cost any solver reached ({best:.6g}), log scale; zero is not drawn")
    ax.legend(fontsize=8)
    _int_iterations(ax)


def convergence_png(series: ConvergenceSeries, title: str) -> bytes:
    """Per solver, a column: Gauss-Newton cost/χ² and inliers; IPOPT objective and infeasibilities."""
    names = [n for n in series.histories if series.histories[n]]
    cols = max(len(names), 1)
    fig = Figure(figsize=(6.5 * cols + 1, 11), layout="constrained")
    grid = fig.add_gridspec(3, cols, height_ratios=(1, 1, 0.8))
    for col, name in enumerate(names):
        top, mid = fig.add_subplot(grid[0, col]), fig.add_subplot(grid[1, col])
        if _is_interior_point(series.histories[name]):
            _interior_point_axes(top, mid, series, name)
        else:
            _least_squares_axes(top, mid, series, name)
    bottom = fig.add_subplot(grid[2, :])
    if names:
        _excess_axes(bottom, series, names)
    else:
        bottom.text(0.5, 0.5, "no iteration history recorded", ha="center", transform=bottom.transAxes)
    for ax in fig.axes:  # a title wider than its panel is wrapped, never clipped
        wide = 6.5 * cols if ax is bottom else 6.5
        ax.set_title(textwrap.fill(ax.get_title(), int(_TITLE_CHARS_PER_INCH * wide)))
    fig.suptitle(title)
    return figure_png(fig)


# --- residuals -------------------------------------------------------------------------------


# --- model check -----------------------------------------------------------------------------


def _model_check_tracks(series: ModelCheckSeries) -> list[tuple[np.ndarray, str, dict[str, Any]]]:
    """Our tracks the model check compares with the vendor's: as the fit integrates, and (where
    computed) first-order, as a robot's own odometry usually integrates."""
    out: list[tuple[np.ndarray, str, dict[str, Any]]] = [
        (series.ours, f"ours ({series.integration} integration)", {"color": "tab:blue"})
    ]
    if series.first_order is not None and series.integration != "euler":
        out.append((series.first_order, "ours, first-order like the vendor", {"color": "tab:green"}))
    return out


def model_check_png(series: ModelCheckSeries, title: str) -> bytes:
    """The log's vendor odometry against our model's base-link track, and their difference."""
    fig = Figure(figsize=(14, 6.2), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=(1.2, 1))
    ax = fig.add_subplot(grid[:, 0])
    ax_pos = fig.add_subplot(grid[0, 1])
    ax_rot = fig.add_subplot(grid[1, 1], sharex=ax_pos)
    v, o = series.vendor, series.ours
    step = path_step(v, o)
    ax.plot(*thin_path(v[:, 0], v[:, 1], step), label="vendor odometry (log's model_pose)", **_TRACKER)
    ax.plot(
        *thin_path(o[:, 0], o[:, 1], step),
        label=f"our model ({series.integration} integration)",
        **{**_STYLES[2], "color": "tab:blue"},
    )
    ax.plot(v[0, 0], v[0, 1], marker="o", markersize=9, color="black", linestyle="none", label="start")
    ax.plot(
        v[-1, 0], v[-1, 1], marker="s", markersize=9, color="0.15", linestyle="none", label="end (vendor)"
    )
    ax.plot(
        o[-1, 0], o[-1, 1], marker="s", markersize=5, color="tab:blue", linestyle="none", label="end (ours)"
    )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x in the odometry frame [m]")
    ax.set_ylabel("y in the odometry frame [m]")
    params = ", ".join(f"{k} = {val:g}" for k, val in series.params.items())
    ax.set_title(f"base-link odometry with the log header's parameters\n{params}", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    t = series.time_s - series.time_s[0]
    driven = float(np.sum(np.linalg.norm(np.diff(v[:, :2], axis=0), axis=1)))
    said = []
    for P, words, style in _model_check_tracks(series):
        dpos = np.linalg.norm(P[:, :2] - v[:, :2], axis=1)
        drot = wrap_angle(P[:, 2] - v[:, 2])
        said_pos = f"{words}: max {dpos.max():.3g} m, final {dpos[-1]:.3g} m"
        ax_pos.plot(*envelope(t, dpos), label=said_pos, **style)
        ax_rot.plot(*envelope(t, drot), label=f"{words}: max |Δθ| {np.abs(drot).max():.3g} rad", **style)
        said.append(float(dpos.max()))
    ax_pos.set_ylabel("position difference [m]")
    why = ""
    if len(said) == 2 and said[1] < 0.5 * said[0]:
        why = "\nintegrated first-order as the vendor does, ours agrees: the rest is integration error"
    ax_pos.set_title(f"ours − vendor over {driven:.1f} m driven{why}", fontsize=10)
    ax_pos.legend(fontsize=8, loc="upper left")
    ax_rot.set_ylabel("heading difference [rad]")
    ax_rot.set_title("heading", fontsize=10)
    ax_rot.legend(fontsize=8, loc="upper left")
    ax_rot.set_xlabel("time since the log's first record [s]")
    for a in (ax_pos, ax_rot):
        a.yaxis.set_major_formatter(_PLAIN)  # no offset/multiplier text that is easy to miss
        a.grid(True, alpha=0.3)
    fig.suptitle(title)
    return figure_png(fig)
