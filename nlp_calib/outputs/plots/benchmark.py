"""Benchmark figure: time against problem size (``benchmarks/performance.py``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from matplotlib.figure import Figure

from nlp_calib.outputs.plots.run import figure_png


def scaling_png(cases: Sequence[Mapping[str, Any]]) -> bytes:
    """Benchmark times against the number of residuals, log-log (``benchmarks/performance.py``)."""
    fig = Figure(figsize=(8, 5.5))
    ax = fig.add_subplot(1, 1, 1)
    series = [
        ("eval_ms", "one normal-equation evaluation", "o-"),
        ("gn_ms", "Gauss-Newton solve", "s-"),
        ("ipopt_ms", "IPOPT solve", "^-"),
        ("scipy_ms", "scipy least_squares (same residual, plain LS)", "v--"),
        ("seed_solve_ms", "seed method (numpy, 10 iterations)", "x:"),
    ]
    sims = [c for c in cases if str(c["case"]).startswith("simulated")]
    for key, label, style in series:
        pts = sorted((c["residuals"], c[key]) for c in sims if key in c)
        if pts:
            n, t = zip(*pts)
            ax.plot(n, t, style, label=label)
    for c in cases:
        if not str(c["case"]).startswith("simulated"):
            ax.plot([c["residuals"]], [c["gn_ms"]], "k*", markersize=10)
            ax.annotate(
                str(c["case"]),
                (c["residuals"], c["gn_ms"]),
                fontsize=7,
                xytext=(4, -10),
                textcoords="offset points",
            )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("residuals N (records, single-step)")
    ax.set_ylabel("time [ms] (median)")
    ax.set_title("nlp_calib compiled backend: time against problem size")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return figure_png(fig)
