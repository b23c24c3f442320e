"""A batch's summary table, one row per log, as CSV (for scripts) and markdown (for people)."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path

from nlp_calib.core.files import atomic_write_text
from nlp_calib.results.batch import BatchRow
from nlp_calib.results.figures import FAIR_FIGURES

SUMMARY_FILES = ("summary.csv", "summary.md")


def _parameters(rows: Sequence[BatchRow]) -> list[str]:
    """Every headline parameter of the rows, in the order they first appear."""
    return list(dict.fromkeys(n for r in rows for n in r.parameters))


def _g(v: float) -> str:
    return f"{v:.6g}" if math.isfinite(v) else ""


def summary_csv(rows: Sequence[BatchRow]) -> str:
    """One line per log: its name, source, folder, model, verdict, each headline parameter and its
    σ, the fair figures, the time and the error (empty when it ran)."""
    names = _parameters(rows)
    head = ["log", "source", "folder", "model", "verdict", "detail"]
    head += (
        [c for n in names for c in (n, f"{n}_std")] + list(FAIR_FIGURES) + ["seconds", "error", "warnings"]
    )
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(head)
    for r in rows:
        values = [c for n in names for c in (map(_g, r.parameters[n]) if n in r.parameters else ("", ""))]
        figures = [_g(r.figures[f]) if f in r.figures else "" for f in FAIR_FIGURES]
        writer.writerow(
            [
                r.name,
                r.source,
                r.folder,
                r.model,
                r.verdict,
                r.detail,
                *values,
                *figures,
                f"{r.seconds:.2f}",
                r.error,
                " | ".join(r.notes),
            ]
        )
    return out.getvalue()


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def summary_markdown(rows: Sequence[BatchRow]) -> str:
    """The table a person reads: per log the verdict, then the error of a log that failed, or why
    (the verdict's reasons; a check's what to drive when it cannot tell), headline parameters ± σ,
    fair figures and time."""
    names = _parameters(rows)
    units = {n: u for r in rows for n, u in r.units.items()}
    head = [
        "log",
        "verdict",
        "why",
        *(f"{n} [{units.get(n, '')}]" for n in names),
        *FAIR_FIGURES,
        "time [s]",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        params = [
            f"{_g(r.parameters[n][0])} ± {r.parameters[n][1]:.2g}" if n in r.parameters else "" for n in names
        ]
        figures = [_g(r.figures[f]) if f in r.figures else "" for f in FAIR_FIGURES]
        cells = [r.name, r.verdict, r.error or r.detail, *params, *figures, f"{r.seconds:.1f}"]
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    ok = sum(r.ok for r in rows)
    return "\n".join(lines) + f"\n\n{ok} of {len(rows)} logs ran to the end.\n"


def write_summary(rows: Sequence[BatchRow], folder: Path) -> list[Path]:
    """``summary.csv`` and ``summary.md`` of ``rows`` into ``folder`` (each atomically)."""
    paths = [folder / name for name in SUMMARY_FILES]
    atomic_write_text(paths[0], summary_csv(rows))
    atomic_write_text(paths[1], summary_markdown(rows))
    return paths
