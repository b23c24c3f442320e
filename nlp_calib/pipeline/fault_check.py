"""The fault check as a plug-in: what the screen of the log found (:mod:`nlp_calib.analysis.faults`,
run before the fit, which leaves the faults out) and what was done about it, in its one wording.

A caveat when the counters could not be checked, when faults were kept in the fit, or when the
ground slipped under pivots (slip too small to find stays in the fit).
"""

from __future__ import annotations

from nlp_calib.analysis.faults import MATCH_SCATTER
from nlp_calib.core.text import numbered
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, CheckResult
from nlp_calib.results.codec import finite_or_null
from nlp_calib.results.faults import PIVOT_RADIUS_M, PIVOT_SLIP, Findings, count_kinds

#: Faults listed one per line; the rest are counted.
SHOWN = 6


def check(run: CalibrationRun) -> CheckResult | None:
    """The faults found in the run's log (None: no fault check ran)."""
    findings = run.checks.findings
    if findings is None:
        return None
    caveat = _caveat(findings)
    return CheckResult(
        "faults",
        CAVEAT if caveat else FINE,
        words(findings, run.data.dropped_faulty),
        _details(findings, run.log.numbered),
        caveat=caveat,
        section=_section(findings, run.data.dropped_faulty, run.log.numbered),
        record=finite_or_null(_record(findings, run.data.dropped_faulty)),
    )


def _record(findings: Findings, left_out: int) -> dict[str, object]:
    """What result.json holds of the faults: every one found, with what was done about it."""
    rep = findings.report
    return {
        "handling": findings.handling,
        "checked": not rep.unchecked,
        "unchecked_reason": rep.unchecked or None,
        "found": [f.as_dict(rep.unit) for f in rep.faults],
        "windows_left_out": left_out,
        "repairs": list(findings.repairs),
        "stale_readings": dict(rep.stale),
        f"noise_{rep.unit}": dict(rep.noise),
    }


def words(findings: Findings, left_out: int) -> str:
    """What the fault check found and what was done about it, in its one wording (``left_out``:
    the residual windows crossing them that the fit left out)."""
    rep = findings.report
    if rep.unchecked:
        return f"not checked: {rep.unchecked}"
    stale = sum(rep.stale.values())
    harmless = f"{stale} stale counter readings that catch up at the next record (harmless)"
    if not rep.faults:
        return f"none found; {harmless}"
    done = {
        "exclude": f"{left_out} residual windows crossing them left out",
        "repair": "counter faults repaired, windows at tracker jumps left out",
        "keep": "kept in the fit (faults.handling: keep)",
    }[findings.handling]
    return f"{len(rep.faults)} found ({count_kinds(rep.faults)}); {done}; {harmless}"


def _caveat(findings: Findings) -> str:
    rep = findings.report
    if rep.unchecked:
        return f"encoder faults not checked ({rep.unchecked})"
    if rep.faults and findings.handling == "keep":
        return f"{len(rep.faults)} faults kept in the fit (faults.handling: keep)"
    if slipped := sum(f.kind == PIVOT_SLIP for f in rep.faults):
        return (
            f"{slipped} increments over pivots the ground slipped on were left out (the rule: a pivot, "
            f"under {PIVOT_RADIUS_M:g} m of travel per radian turned, is kept where the wheels agree with "
            f"its increment and left out where they disagree beyond {MATCH_SCATTER:g}× the increments' "
            "robust scatter; the calibration holds for the pivots kept): slip too small to find stays "
            "in the fit, and what the pivots determine (how the base skids as it turns) may be biased "
            "by it beyond its σ; check it on a drive with fewer pivots, or slower ones"
        )
    return ""


def _details(findings: Findings, counted: str) -> tuple[str, ...]:
    """The first faults one per line (encoder faults first: they bias a calibration; tracker jumps
    are many and each one harmless), how many more, and the repairs."""
    rep = findings.report
    if rep.unchecked or not rep.faults:
        return ()
    ordered = sorted(rep.faults, key=lambda f: (f.kind == "tracker_jump", f.record))
    lines = [
        f"record {f.record} ({numbered(counted, f.line)}, t = {f.time_s:.2f} s) {f.kind}: {f.evidence}"
        for f in ordered[:SHOWN]
    ]
    if len(ordered) > SHOWN:
        rest = ordered[SHOWN:]
        lines.append(
            f"... {len(rest)} more ({count_kinds(rest)}): every one is in result.json under faults.found"
        )
    return (*lines, *(f"repaired: {r}" for r in findings.repairs))


def _section(findings: Findings, left_out: int, counted: str) -> tuple[str, ...]:
    """The report's section: the words, then every fault in a table (``counted``: what the log's
    record numbers count, a file's lines or a topic's messages)."""
    said = words(findings, left_out)
    out = ["Encoder and tracker faults", said[0].upper() + said[1:] + ".", ""]
    rep = findings.report
    if rep.unchecked or not rep.faults:
        return tuple(out)
    out += [
        "The fault-robust figures restart dead reckoning from the tracker after each fault and leave "
        "its records out.",
        "",
        f"| record | {counted} | time [s] | kind | evidence |",
        "|---|---|---|---|---|",
    ]
    out += [f"| {f.record} | {f.line} | {f.time_s:.2f} | {f.kind} | {f.evidence} |" for f in rep.faults]
    return (*out, "", *(f"- repaired: {r}" for r in findings.repairs), "")
