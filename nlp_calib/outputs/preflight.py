"""The pre-flight's report as text: what the recording holds, the drive, units and signs, each
parameter's standing, the verdict and what to drive next (``nlp-calib preflight``)."""

from __future__ import annotations

import math

from nlp_calib.results.preflight import (
    CHECK_DATA,
    ENOUGH,
    HELD_AT_START,
    NOT_DETERMINED,
    NOT_ENOUGH,
    WEAK_DRIVE,
    WEAKLY,
    Excitation,
    Preflight,
    Recording,
)


def _recording(rec: Recording) -> list[str]:
    lines = [f"recording {rec.path} ({rec.source}): {rec.records} records over {rec.duration_s:.1f} s"]
    for s in rec.streams:
        if s.rate_hz > 0:
            gaps = f"{s.gaps} gap(s), longest {s.longest_gap_s:.3g} s" if s.gaps else "no gap"
            lines.append(
                f"  {s.name}: {s.count} at {s.rate_hz:.1f} Hz ({s.kind}), {gaps}; {s.note}".rstrip("; ")
            )
        else:
            used = f" (read as the {s.note})" if s.note else ""
            lines.append(f"  topic {s.name}: {s.kind}, {s.count} messages{used}")
    if rec.overlap_s is not None:
        lines.append(f"  clocks: the joints' stream covers {rec.overlap_s:.1f} s of the tracker's records")
    lines += [f"  {note}" for note in rec.notes]
    return lines


def _drive(ex: Excitation) -> list[str]:
    radii = []
    for side, r in (("left", ex.radii_left_m), ("right", ex.radii_right_m)):
        if r:
            radii.append(f"{side} {r[1]:.2g} m ({r[0]:.2g}-{r[2]:.2g})")
    moving = f"{ex.duration_s:.1f} s (travelling {100 * ex.moving_fraction:.0f} % of it, by the wheels)"
    if not math.isfinite(ex.distance_m):  # a reference that measures no position (a gyro)
        return [
            f"  {moving}; no distance, speed or turn radius: the reference measures no position",
            f"  heading spans {ex.heading_span_rad:.2f} rad; turned {ex.turned_left_rad:.1f} rad left and "
            f"{ex.turned_right_rad:.1f} rad right",
            f"  {ex.reversals} reversal(s); {100 * ex.reverse_fraction:.0f} % of the driving backwards",
        ]
    return [
        f"  {ex.distance_m:.1f} m in {moving}; speed "
        f"{ex.speed_median_mps:.2g} m/s median while travelling, {ex.speed_max_mps:.2g} m/s at most",
        f"  heading spans {ex.heading_span_rad:.2f} rad; turned {ex.turned_left_rad:.1f} rad left and "
        f"{ex.turned_right_rad:.1f} rad right; turn radii: {', '.join(radii) or 'none'}",
        f"  {ex.reversals} reversal(s); {100 * ex.reverse_fraction:.0f} % of the driving backwards",
    ]


VERDICT_WORDS = {
    ENOUGH: "ENOUGH: the drive determines every parameter",
    WEAK_DRIVE: "WEAK: {names} (see above)",
    NOT_ENOUGH: "NOT ENOUGH: the drive cannot determine {names}",
    CHECK_DATA: "CHECK THE DATA: {units}",
}


def _weak_words(report: Preflight) -> str:
    """What leaves the drive weak: parameters determined only weakly, and those the run holds (at
    their start, or a time offset where its fit settled)."""
    weak = report.named(WEAKLY)
    held = [p for p in report.parameters if p.status == NOT_DETERMINED]
    start = [p.name for p in held if p.because.startswith(HELD_AT_START)]
    settled = [p.name for p in held if not p.because.startswith(HELD_AT_START)]
    return "; ".join(
        [*([f"{', '.join(weak)} determined only weakly"] if weak else []),
         *([f"{', '.join(start)} held at its start, as the run will hold it"] if start else []),
         *([f"{', '.join(settled)} held with no σ, as the run will hold it"] if settled else [])]
    )  # fmt: skip


def preflight_lines(report: Preflight) -> list[str]:
    """The report, line by line."""
    lines = [f"pre-flight of {report.scenario} (model {report.model}), {report.time_s:.2f} s, no fit"]
    for rec in report.recordings:
        lines += _recording(rec)
    for i, ex in enumerate(report.excitation):
        lines.append(
            "drive" + (f" ({report.recordings[i].path})" if len(report.excitation) > 1 else "") + ":"
        )
        lines += _drive(ex)
    lines += [line for r in report.checks for line in r.lines()]
    lines.append(f"parameters (the Jacobian at {report.start}; noise: {report.noise}):")
    lines += [f"  {p.words()}" for p in report.parameters]
    missing = ", ".join(p.name for p in report.missing()) or _weak_words(report)
    units = "; ".join(report.blocking())
    lines.append("verdict: " + VERDICT_WORDS[report.verdict].format(names=missing, units=units))
    if report.way_out:
        lines.append(f"  {report.way_out}")
    plan = report.plan
    if plan is not None:
        lines.append(f"plan: {plan.line()}")
        unit = f" {plan.target_unit}" if plan.target_unit not in ("", "1") else ""
        for m in [m for m in plan.ranked if m is not plan.best][:3] if plan.best is not None else []:
            std = f"{m.target_std_after:.2g}" if math.isfinite(m.target_std_after) else "unbounded"
            lines.append(f"  then: {m.words}: σ of {plan.target} {std}{unit}")
    return lines
