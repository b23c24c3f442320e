"""The consistency check of several logs as a plug-in: each log's own fit against the other logs'
(:mod:`nlp_calib.analysis.consistency`, refitted without each log), in its one wording.

Not usable when the logs are not one robot's; a caveat, on each parameter concerned, when
parameters move between the logs beyond their σ (a model limit: their σ take in the spread).
"""

from __future__ import annotations

from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, UNUSABLE, CheckResult


def check(run: CalibrationRun) -> CheckResult | None:
    """The logs' consistency as this run reads it: one log's own rows for a run of one of the
    logs, every row for the joint fit (None: one log)."""
    found = run.checks.consistency
    if found is None:
        return None
    if run.log.path in found.logs:
        found = found.of_log(run.log.path)
    words = found.words()
    if found.significant:
        return CheckResult("consistency", UNUSABLE, words)
    if not found.limits():
        return CheckResult("consistency", FINE, words)
    why = f"it moves between the logs beyond its σ ({words})"
    concerns = {n: why for n, moved in zip(found.names, found.moved) if moved}
    return CheckResult("consistency", CAVEAT, words, concerns=concerns)
