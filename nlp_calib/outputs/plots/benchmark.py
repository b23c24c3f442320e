"""Benchmark figure: time against problem size (``benchmarks/performance.py``)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from matplotlib.figure import Figure

from nlp_calib.outputs.plots.run import figure_png


def scaling_png(sizes: Mapping[str, Mapping[str, Any]]) -> bytes:
    """End-to-end wall time and the Gauss-Newton solve against the number of records, log-log."""
    fig = Figure(figsize=(8, 5.5))
    ax = fig.add_subplot(1, 1, 1)
    n = sorted(int(k) for k in sizes)
    for key, scale, label, style in (
        ("wall_s", 1e3, "run --solver gauss_newton, end to end (fresh process)", "o-"),
        ("gn_ms", 1.0, "Gauss-Newton solve", "s-"),
    ):
        ax.plot(n, [scale * float(sizes[str(k)][key]) for k in n], style, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("records N (single-step residuals)")
    ax.set_ylabel("time [ms] (median)")
    ax.set_title("nlp_calib: time against problem size")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return figure_png(fig)
