"""The consistency check of several logs as a plug-in: each log's own fit against the other logs'
(:mod:`nlp_calib.analysis.consistency`, refitted without each log), in its one wording.

Not usable when the logs are not one robot's; a caveat, on each parameter concerned, when
parameters move between the logs beyond their σ (a model limit: their σ take in the spread).
"""

from __future__ import annotations

import numpy as np

from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import (
    CAVEAT,
    CONSISTENCY_SIGMAS,
    FINE,
    UNUSABLE,
    WEAK,
    CheckResult,
    ConsistencyCheck,
)


def check(run: CalibrationRun) -> CheckResult | None:
    """The logs' consistency as this run reads it: one log's own rows for a run of one of the
    logs, every row for the joint fit (None: one log)."""
    found = run.checks.consistency
    if found is None:
        return None
    if run.log.path in found.logs:
        found = found.of_log(run.log.path)
    said = words(found)
    if found.significant:
        return CheckResult("consistency", UNUSABLE, said)
    if not limits(found):
        return CheckResult("consistency", FINE, said)
    why = f"it moves between the logs beyond its σ ({said})"
    concerns = {n: why for n, moved in zip(found.names, found.moved) if moved}
    return CheckResult("consistency", CAVEAT, said, concerns=concerns)


def limits(c: ConsistencyCheck) -> list[str]:
    """One phrase per parameter that moves between the logs beyond their σ without setting them
    apart: by how much at most and in how many σ."""
    out = []
    for j in np.flatnonzero(c.moved):
        d = np.abs(c.own[:, j] - c.others[:, j])
        z = np.where(np.isfinite(c.z[:, j]), np.abs(c.z[:, j]), 0.0)
        i = int(np.argmax(z))
        rel = d[i] / max(abs(float(c.joint[j])), 1e-12)
        unit = f" {c.units[j]}" if c.units else ""
        size = f"{100 * rel:.2g} %" if rel < 1 else f"{d[i]:.3g}{unit}"
        out.append(f"{c.names[j]} by {size} ({z[i]:.0f}σ, {_name(c.logs[i])})")
    return out


def words(c: ConsistencyCheck) -> str:
    """One line: which logs are not one robot's and on which parameters, which parameters move
    between the logs (a model limit), that the logs agree, or that nothing could be compared."""
    if not c.compared:
        return (
            "each log's own fit could not be compared with the other logs' (no parameter that a log "
            "determines on its own has a σ on both sides)"
        )
    if c.significant:
        return _apart(c)
    if moving := limits(c):
        return (
            f"parameters move between the logs beyond their σ: {'; '.join(moving)}; the model misses "
            "something that changes with the driving (a model limit), so their σ include the spread "
            "over the logs"
        )
    w = c.worst
    assert w is not None
    return (
        f"each log's own fit agrees with the other logs' within {abs(w.z):.1f}σ "
        f"(largest: {w.parameter} in {_name(w.log)})"
    )


def _apart(c: ConsistencyCheck) -> str:
    worst = c.different
    logs = [_name(log) for log in sorted({d.log for d in worst}, key=c.logs.index)]
    params = list(dict.fromkeys(d.parameter for d in (*worst, *c.disagreements)))
    detail = "; ".join(
        f"{d.parameter} in {_name(d.log)}: {d.own:.6g} against {d.others:.6g} from the other logs "
        f"({d.z:+.1f}σ)"
        for d in worst[:3]
    )
    return (
        f"the logs do not agree on one robot: {', '.join(params)} differ in {', '.join(logs)} beyond "
        f"{CONSISTENCY_SIGMAS:g}σ and beyond {WEAK:g}× the precision a calibration needs ({detail})"
    )


def _name(log: str) -> str:
    """A log's file name: what names it in one line (its result holds the path)."""
    return log.replace("\\", "/").rsplit("/", 1)[-1]
