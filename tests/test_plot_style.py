"""figure_png: one measured layout, one draw, no text clipped or overlapping; plain log labels say the
same as matplotlib's; long series thinned to what the pixels show."""

from __future__ import annotations

import io

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogFormatterSciNotation
from matplotlib.transforms import Bbox
from PIL import Image

from nlp_calib.outputs.plots.style import (
    DPI,
    PlainLogFormatter,
    envelope,
    figure_png,
    path_step,
    thin_path,
)


def _figure() -> Figure:
    fig = Figure(figsize=(7, 3.5), layout="constrained")
    ax, ax_named = fig.subplots(1, 2)
    t = np.linspace(0.0, 10.0, 200)
    ax.plot(t, 1e3 * np.sin(t), label="a sine")
    ax.set_title("a linear axis with a long title")
    ax.set_xlabel("time [s]")
    ax.legend(loc="upper right")
    ax_named.barh([0, 1, 2], [3.0, 1.0, 2.0])
    ax_named.set_yticks([0, 1, 2], ["first", "second", "a third name"])
    ax_named.set_title("named rows (a fixed title)", fontsize=9)
    fig.suptitle("suptitle")
    return fig


def _texts(fig: Figure) -> list[tuple[object, Bbox]]:
    """Every visible, non-empty text of the figure with its owner (axes or figure) and extent."""
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    out: list[tuple[object, Bbox]] = []
    for ax in fig.axes:
        texts = [ax.title, ax.xaxis.label, ax.yaxis.label]
        for axis in (ax.xaxis, ax.yaxis):  # the ticks drawn: those within the axis's limits
            lo, hi = sorted(axis.get_view_interval())
            texts += [t.label1 for t in axis.get_major_ticks() if lo <= t.get_loc() <= hi]
        out += [(ax, t.get_window_extent(renderer)) for t in texts if t.get_visible() and t.get_text()]
    out += [(fig, fig._suptitle.get_window_extent(renderer))] if fig._suptitle is not None else []
    return out


def _positions_px(fig: Figure) -> np.ndarray:
    return np.array([ax.get_position().transformed(fig.transFigure).extents for ax in fig.axes])


def test_figure_png_lays_out_within_pixels_of_two_passes_with_no_text_clipped_or_overlapping() -> None:
    ours = _figure()
    png = np.asarray(Image.open(io.BytesIO(figure_png(ours))))
    assert png.shape == (round(3.5 * DPI), round(7 * DPI), 3)
    twice = _figure()
    FigureCanvasAgg(twice)
    twice.dpi = DPI
    twice.get_layout_engine().execute(twice)  # type: ignore[union-attr]
    assert np.max(np.abs(_positions_px(ours) - _positions_px(twice))) <= 3.0
    texts = _texts(ours)
    inside = ours.bbox
    for _, box in texts:
        assert inside.x0 <= box.x0 and box.x1 <= inside.x1 and inside.y0 <= box.y0 and box.y1 <= inside.y1
    for i, (a, box_a) in enumerate(texts):
        for b, box_b in texts[i + 1 :]:
            assert a is b or not box_a.overlaps(box_b), (box_a, box_b)


def _as_mathtext_reads(label: str) -> str:
    """What matplotlib's mathtext label reads as, written out independently."""
    body = label.removeprefix("$\\mathdefault{").removesuffix("}$").replace("\\times", "×")
    if "^{" not in body:
        return body
    head, exponent = body.split("^{")
    digits = dict(zip("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return head + "".join(digits[c] for c in exponent.rstrip("}"))


def test_plain_log_labels_read_as_matplotlibs() -> None:
    values = [1e-14, 1e-3, 2e-3, 5e-1, 1.0, 10.0, 3e4, 1e6]
    plain, mathtext = PlainLogFormatter(base=10.0), LogFormatterSciNotation(base=10.0)
    got = [plain(v) for v in values]
    assert got == [_as_mathtext_reads(mathtext(v)) for v in values]
    assert got[:4] == ["10⁻¹⁴", "10⁻³", "2×10⁻³", "5×10⁻¹"]


def test_log_axes_of_a_figure_get_plain_labels_and_other_formatters_stay() -> None:
    fig = Figure(figsize=(6, 3), layout="constrained")
    ax, ax_kept = fig.subplots(1, 2)
    for a in (ax, ax_kept):
        a.plot([1, 2, 3], [1e-4, 1e-2, 1.0])
        a.set_yscale("log")
    kept = FuncFormatter(lambda v, _: f"{v:g}")
    ax_kept.yaxis.set_major_formatter(kept)
    figure_png(fig)
    labels = [t.get_text() for t in ax.get_yticklabels() if t.get_text()]
    assert {"10⁻⁴", "10⁻³", "10⁻²", "10⁻¹", "10⁰"} <= set(labels)
    assert not any("$" in s for s in labels)
    assert ax_kept.yaxis.get_major_formatter() is kept


def test_envelope_keeps_each_runs_extremes_ends_and_breaks() -> None:
    rng = np.random.default_rng(3)
    n, columns = 100_003, 1000
    x, y = np.arange(n) * 0.01, rng.standard_normal(n)
    y[5_000:5_004] = np.nan
    tx, ty = envelope(x, y, columns)
    assert columns < tx.size <= 5 * columns and np.all(np.diff(tx) > 0)
    assert (tx[0], tx[-1]) == (x[0], x[-1])
    kept = np.round(tx / 0.01).astype(int)
    assert np.array_equal(ty, y[kept], equal_nan=True)  # points of the series, not new ones
    assert np.isnan(ty).sum() == 1 and 5_000 <= kept[np.isnan(ty)][0] < 5_004
    size = -(-n // columns)
    for start in range(0, n, size):  # every run's lowest and highest point is drawn
        run = y[start : start + size]
        inside = (kept >= start) & (kept < start + size)
        assert np.nanmax(ty[inside]) == np.nanmax(run) and np.nanmin(ty[inside]) == np.nanmin(run)
    short = np.arange(10.0)
    assert np.array_equal(envelope(short, short)[1], short)


def test_thin_path_stays_within_its_step_of_every_point() -> None:
    rng = np.random.default_rng(5)
    n = 50_000
    s = np.linspace(0.0, 30.0, n)
    x = 5.0 * np.cos(s / 4) + 1e-3 * rng.standard_normal(n)
    y = 3.0 * np.sin(s / 3) + 1e-3 * rng.standard_normal(n)
    step = path_step(np.column_stack([x, y]))
    assert step == max(np.ptp(x), np.ptp(y)) / 1600.0
    tx, ty = thin_path(x, y, step)
    assert tx.size < n // 4 and (tx[0], ty[0], tx[-1], ty[-1]) == (x[0], y[0], x[-1], y[-1])
    keep = np.flatnonzero(np.isin(x, tx))
    j = np.clip(np.searchsorted(keep, np.arange(n), side="right") - 1, 0, keep.size - 2)
    a = np.column_stack([x[keep[j]], y[keep[j]]])
    b = np.column_stack([x[keep[j + 1]], y[keep[j + 1]]])
    p = np.column_stack([x, y])
    u = np.clip(np.sum((p - a) * (b - a), axis=1) / np.maximum(np.sum((b - a) ** 2, axis=1), 1e-300), 0, 1)
    off = np.linalg.norm(p - (a + u[:, None] * (b - a)), axis=1)
    assert off.max() <= step  # the drawn line is everywhere within a step of the path
    assert thin_path(x, y, 1e-6)[0] is x  # no stride keeps the line this close
    gap = x.copy()
    gap[100] = np.nan
    assert thin_path(gap, y, step)[0] is gap  # a path with a gap is drawn as it is
