"""What every figure shares: line styles and rendering to PNG bytes."""

from __future__ import annotations

import io
import re
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import LogFormatterSciNotation, ScalarFormatter
from matplotlib.transforms import Bbox
from PIL import Image  # matplotlib's own PNG writer (a dependency of matplotlib)

DPI = 110
#: zlib's level 3 instead of 6: a third less CPU to encode for ~5 % more bytes (the dropped alpha
#: channel, opaque everywhere, saves more than that).
_PNG_COMPRESSION = 3
#: Line styles per track, in drawing order: uncalibrated, first solver, second solver, ...
STYLES: tuple[Mapping[str, Any], ...] = (
    {"color": "tab:orange", "linestyle": "-.", "linewidth": 1.2},
    {"color": "tab:blue", "linestyle": "-", "linewidth": 1.6},
    {"color": "tab:green", "linestyle": "--", "linewidth": 1.4},
    {"color": "tab:purple", "linestyle": ":", "linewidth": 1.4},
)


#: Columns a time series is thinned to (:func:`envelope`): more than a panel's pixels across.
COLUMNS = 2500


def envelope(x: np.ndarray, y: np.ndarray, columns: int = COLUMNS) -> tuple[np.ndarray, np.ndarray]:
    """A long series thinned to what a line of ``columns`` pixel columns can show: in each of
    ``columns`` runs of consecutive points its first, lowest, highest and last point, and its
    first NaN (where the line breaks), in their order. Drawing a million noisy points costs
    seconds for the same pixels. Short series are returned as they are."""
    x, y = np.asarray(x), np.asarray(y, dtype=float)
    n = y.size
    if n <= 4 * columns:
        return x, y
    size = -(-n // columns)
    flat = np.full(size * columns, np.nan)
    flat[:n] = y
    rows = flat.reshape(columns, size)
    gaps = np.isnan(rows)
    start = np.arange(columns) * size
    picks = [
        start,
        start + np.argmin(np.where(gaps, np.inf, rows), axis=1),
        start + np.argmax(np.where(gaps, -np.inf, rows), axis=1),
        np.minimum(start + size - 1, n - 1),
        (start + np.argmax(gaps, axis=1))[gaps.any(axis=1)],
    ]
    keep = np.unique(np.concatenate(picks))
    keep = keep[keep < n]
    return x[keep], y[keep]


def _off_chords(x: np.ndarray, y: np.ndarray, keep: np.ndarray) -> float:
    """How far the farthest point of a path lies from the polyline through its points ``keep``."""
    j = np.minimum(np.searchsorted(keep, np.arange(x.size), side="right") - 1, keep.size - 2)
    ax, ay, bx, by = x[keep[j]], y[keep[j]], x[keep[j + 1]], y[keep[j + 1]]
    dx, dy = bx - ax, by - ay
    u = np.clip(((x - ax) * dx + (y - ay) * dy) / np.maximum(dx * dx + dy * dy, 1e-300), 0.0, 1.0)
    return float(np.max(np.hypot(x - ax - u * dx, y - ay - u * dy)))


def thin_path(x: np.ndarray, y: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """A long x-y path drawn through every m-th point (and the last), m the largest of 64, 32, ...,
    2 that leaves every point of the path within ``step`` (a fraction of a pixel) of the line:
    the same pixels, and a legend placed "best" no longer tests a million points a place. Short
    paths, paths with gaps (NaN), ``step`` ≤ 0 and paths no stride keeps that close: as they are."""
    x, y = np.asarray(x), np.asarray(y)
    if x.size <= 4 * COLUMNS or not step > 0 or not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        return x, y
    for m in (64, 32, 16, 8, 4, 2):
        keep = np.union1d(np.arange(0, x.size, m), [x.size - 1])
        if _off_chords(x, y, keep) <= step:
            return x[keep], y[keep]
    return x, y


def path_step(*paths: np.ndarray) -> float:
    """How near :func:`thin_path` keeps the line to paths framed together: a 1600th of their
    extent (half a pixel on a panel 800 pixels wide)."""
    xy = np.concatenate([np.asarray(P)[:, :2] for P in paths])
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    return float(np.max(np.ptp(xy, axis=0))) / 1600.0 if xy.size else 0.0


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")
_EXPONENT = re.compile(r"\^\{(-?\d+)\}")


class PlainLogFormatter(LogFormatterSciNotation):
    """A log axis's labels (10⁻², 2×10⁻³) as plain text in Unicode superscripts: the same labels
    as matplotlib's, without parsing and typesetting each through mathtext (a tenth of a figure's
    CPU in a fresh process)."""

    def __call__(self, x: float, pos: int | None = None) -> str:
        label = str(super().__call__(x, pos))
        if not (label.startswith("$\\mathdefault{") and label.endswith("}$")):
            return label
        body = label[len("$\\mathdefault{") : -2].replace("\\times", "×")
        body = _EXPONENT.sub(lambda m: m.group(1).translate(_SUPERSCRIPT), body)
        return body.replace("-", "\N{MINUS SIGN}") if body.startswith("-") else body


def _plain_log_labels(fig: Figure) -> None:
    """Every log axis still labelled by matplotlib's default formatter gets :class:`PlainLogFormatter`."""
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            if axis.get_scale() != "log":
                continue
            if type(axis.get_major_formatter()) is LogFormatterSciNotation:
                axis.set_major_formatter(PlainLogFormatter(base=10.0))
            if type(axis.get_minor_formatter()) is LogFormatterSciNotation:
                axis.set_minor_formatter(PlainLogFormatter(base=10.0))


def _fixed_titles(fig: Figure, offsets_known: bool) -> None:
    """Titles placed at the top of their axes once, where nothing can rise into them: matplotlib
    otherwise re-measures the whole y axis of every titled axes (for a multiplier text such as
    "1e-5" that could overlap the title) in each layout pass and in the draw, a tenth of a figure.
    Fixed: axes whose x ticks are below and whose y labels carry no multiplier: before the layout,
    those not labelled by a ``ScalarFormatter`` (log, fixed and plain labels); once the layout has
    set the multipliers (``offsets_known``), the rest without one. The pixels are the same."""
    for ax in fig.axes:
        title = ax.title
        if not title.get_text() or ax.xaxis.get_ticks_position() != "bottom":
            continue
        scalar = isinstance(ax.yaxis.get_major_formatter(), ScalarFormatter)
        if scalar and not (offsets_known and not ax.yaxis.offsetText.get_text()):
            continue
        ax.set_title(title.get_text(), y=1.0, fontsize=title.get_fontsize())


@contextmanager
def _decorations_measured_once(fig: Figure) -> Iterator[None]:
    """Inside, each axes of auto aspect reports its decorations (tick labels, labels, title) as
    measured the first time, around wherever it then is: the constrained layout, which measures
    every axes twice (the second time only in case the first move changed its tick labels), then
    measures once, 40 % of a figure's CPU. Equal-aspect axes and colour bars, whose decorations
    do change as they move, are measured each time. On the report's figures of the four runs of
    ``benchmarks/figure_cpu.py`` the axes land within a pixel of where two measurements put them,
    6 px on the model check's side panels (tests/test_plot_style.py: no text clipped or
    overlapping)."""
    first: dict[Axes, tuple[float, float, float, float]] = {}

    def once(ax: Axes, measure: Callable[..., Any]) -> Callable[..., Any]:
        def tightbbox(renderer: Any = None, *args: Any, **kwargs: Any) -> Any:
            if not kwargs.get("for_layout_only"):
                return measure(renderer, *args, **kwargs)
            pos = ax.get_position(original=True).transformed(fig.transFigure)
            if ax not in first:
                box = measure(renderer, *args, **kwargs)
                first[ax] = (pos.x0 - box.x0, pos.y0 - box.y0, box.x1 - pos.x1, box.y1 - pos.y1)
            left, bottom, right, top = first[ax]
            return Bbox.from_extents(pos.x0 - left, pos.y0 - bottom, pos.x1 + right, pos.y1 + top)

        return tightbbox

    patched = [ax for ax in fig.axes if ax.get_aspect() == "auto" and not hasattr(ax, "_colorbar")]
    for ax in patched:
        ax.get_tightbbox = once(ax, ax.get_tightbbox)  # type: ignore[method-assign]
    try:
        yield
    finally:
        for ax in patched:
            del ax.get_tightbbox


def figure_png(fig: Figure) -> bytes:
    """The figure rendered to PNG bytes (no timestamp, so files are reproducible).

    The layout is computed once and the figure drawn once: ``savefig`` would first draw the whole
    figure without rendering it only to run the layout (a quarter of a figure's CPU), then draw
    it again; the pixels are the same. Log labels in plain text and fixed titles: see
    :func:`_plain_log_labels`, :func:`_fixed_titles`. Written as RGB (the figures are opaque)
    without metadata."""
    canvas = FigureCanvasAgg(fig)
    fig.dpi = DPI
    _plain_log_labels(fig)
    _fixed_titles(fig, offsets_known=False)
    engine = fig.get_layout_engine()
    if engine is not None:
        with _decorations_measured_once(fig):
            engine.execute(fig)
        fig.set_layout_engine("none")
        _fixed_titles(fig, offsets_known=True)
    canvas.draw()
    rgb = np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[..., :3])
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="png", compress_level=_PNG_COMPRESSION, dpi=(DPI, DPI))
    return buf.getvalue()
