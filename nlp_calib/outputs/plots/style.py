"""What every figure shares: line styles and rendering to PNG bytes."""

from __future__ import annotations

import io
from collections.abc import Mapping
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

DPI = 110
#: Line styles per track, in drawing order: uncalibrated, first solver, second solver, ...
STYLES: tuple[Mapping[str, Any], ...] = (
    {"color": "tab:orange", "linestyle": "-.", "linewidth": 1.2},
    {"color": "tab:blue", "linestyle": "-", "linewidth": 1.6},
    {"color": "tab:green", "linestyle": "--", "linewidth": 1.4},
    {"color": "tab:purple", "linestyle": ":", "linewidth": 1.4},
)


def figure_png(fig: Figure) -> bytes:
    """The figure rendered to PNG bytes (no timestamp, so files are reproducible)."""
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None})
    return buf.getvalue()
