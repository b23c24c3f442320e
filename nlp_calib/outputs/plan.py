"""``plan.md``: what to drive next, when the drive leaves a parameter not determined well enough.

The manoeuvres are ranked by the largest σ over its reference precision once each is appended to
the drive (simulated with the fitted model); ``plan.png`` sketches the best of them.
"""

from __future__ import annotations

import math
from pathlib import Path

from nlp_calib.core.files import atomic_write_text
from nlp_calib.results import CalibrationRun
from nlp_calib.results.preflight import Plan


def _sigma(value: float) -> str:
    return f"{value:.3g}" if math.isfinite(value) else "unbounded"


def plan_text(plan: Plan, name: str) -> str:
    """The plan as Markdown."""
    unit = f" {plan.target_unit}" if plan.target_unit not in ("", "1") else ""
    before = plan.target_std_before
    lines = [
        f"# What to drive next: {name}",
        "",
        f"On this drive, **{plan.target}** is the parameter known least well relative to the precision a "
        f"useful calibration needs: σ {_sigma(before)}{unit if math.isfinite(before) else ''} (the run's "
        f"1σ, as its summary states it), {_sigma(plan.worst_before)} times that precision. Each manoeuvre "
        f"below, about half a minute at the drive's own speed and within what the robot can steer, was "
        f"simulated with {plan.model_from} and appended to the drive; they are ranked by the largest σ "
        "over its needed precision (the tracker lag included) once appended, each σ the plan's white-noise "
        "σ scaled as the run's σ is to it on the drive as it is.",
        "",
        f"| rank | manoeuvre | largest σ / needed | σ of {plan.target}{unit} |",
        "|---|---|---|---|",
    ]
    for i, m in enumerate(plan.ranked):
        lines.append(f"| {i + 1} | {m.words} | {_sigma(m.worst_after)} | {_sigma(m.target_std_after)} |")
    if plan.beyond:
        lines += ["", f"{plan.beyond_words()[0].upper()}{plan.beyond_words()[1:]}."]
    if plan.ranked:
        lines += ["", "![the best manoeuvres, from a standstill heading along x](plan.png)"]
    return "\n".join(lines) + "\n"


def write_plan(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """``plan.md`` when the run has a plan (nothing otherwise)."""
    return write_plan_of(run.checks.plan, run.scenario.name, folder, name)


def write_plan_of(plan: Plan | None, scenario: str, folder: Path, name: str) -> list[Path]:
    """``plan.md`` of ``plan`` (a run's, or the pre-flight's where it stops a run; nothing for None)."""
    if plan is None:
        return []
    path = folder / name
    atomic_write_text(path, plan_text(plan, scenario))
    return [path]
