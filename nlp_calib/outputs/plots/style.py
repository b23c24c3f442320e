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
    """The figure rendered to PNG bytes (no timestamp, so files are reproducible).

    The layout is computed once and the figure drawn once: ``savefig`` would first draw the whole
    figure without rendering it only to run the layout (a quarter of a figure's CPU), then draw
    it again; the pixels are the same."""
    canvas = FigureCanvasAgg(fig)
    fig.dpi = DPI
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
        fig.set_layout_engine("none")
    buf = io.BytesIO()
    canvas.print_png(buf, metadata={"Software": None})
    return buf.getvalue()
