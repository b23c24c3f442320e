"""Odometry figure: the dead-reckoned base track with its covariance ellipses."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from nlp_calib.outputs.plots.style import envelope, figure_png, path_step, thin_path
from nlp_calib.results.series import OdometryTrack


def odometry_png(
    track: OdometryTrack, reference: np.ndarray | None, title: str, sigma: float = 3.0, ellipses: int = 25
) -> bytes:
    """Track, ``sigma``-σ position ellipses at ``ellipses`` evenly spaced records, and the
    tracker-derived base track as reference; right: the 1σ of x, y, θ over time."""
    fig = Figure(figsize=(14, 6))
    ax, ax_s = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    P = track.T_world_base
    step = path_step(P)
    if reference is not None:
        # Dots, not a line: a tracker outlier would otherwise draw a long spike.
        dots = thin_path(reference[:, 0], reference[:, 1], step)
        ax.plot(*dots, ".", color="0.6", ms=2, label="base pose from the tracker")
    ax.plot(*thin_path(P[:, 0], P[:, 1], step), color="C0", lw=1.2, label="calibrated odometry (base link)")
    picks = np.linspace(0, P.shape[0] - 1, ellipses).astype(int)[1:]
    largest = max(float(np.sqrt(np.max(np.linalg.eigvalsh(track.covariance[k, :2, :2])))) for k in picks)
    extent = float(np.max(np.ptp(P[:, :2], axis=0)))
    # Millimetre ellipses on a metre-sized track are invisible: magnify them by a round factor.
    magnify = 1.0
    if sigma * largest < 0.02 * extent and largest > 0:
        target = 0.03 * extent / (sigma * largest)
        decade = 10 ** np.floor(np.log10(target))
        magnify = float(max(m * decade for m in (1, 2, 5) if m * decade <= target))
    for k in picks:
        cov = track.covariance[k, :2, :2]
        vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
        vals = np.clip(vals, 0.0, None)
        angle = np.degrees(np.arctan2(vecs[1, 1], vecs[0, 1]))
        ax.add_patch(
            Ellipse(
                (P[k, 0], P[k, 1]),
                2 * magnify * sigma * np.sqrt(vals[1]),
                2 * magnify * sigma * np.sqrt(vals[0]),
                angle=angle,
                fill=False,
                color="C3",
                lw=0.8,
            )
        )
    scale = f", magnified ×{magnify:g}" if magnify > 1 else ""
    ax.plot([], [], color="C3", lw=0.8, label=f"{sigma:g}σ position ellipse{scale}")
    ax.plot(P[0, 0], P[0, 1], "ko", label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x in the tracker's world frame [m]")
    ax.set_ylabel("y in the tracker's world frame [m]")
    ax.set_title("base-link odometry and its propagated uncertainty")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    std = np.sqrt(np.clip(np.diagonal(track.covariance, axis1=1, axis2=2), 0.0, None))
    ax_s.plot(*envelope(track.time_s, 1e3 * std[:, 0]), label="σ x [mm]")
    ax_s.plot(*envelope(track.time_s, 1e3 * std[:, 1]), label="σ y [mm]")
    ax_s.plot(*envelope(track.time_s, 1e3 * std[:, 2]), label="σ θ [mrad]")
    ax_s.set_xlabel("time since the first record [s]")
    ax_s.set_ylabel("1σ (mm, mrad)")
    ax_s.set_title("growth of the odometry's uncertainty (input noise calibrated on its drift)")
    ax_s.grid(True, alpha=0.3)
    ax_s.legend(fontsize=8)
    fig.suptitle(title)
    return figure_png(fig)
