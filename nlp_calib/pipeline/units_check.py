"""The units-and-signs check as a plug-in of the pre-flight: what the data imply of units and signs
(:mod:`nlp_calib.analysis.units`: joints in degrees, wheel angles that wrap, a mirrored wheel axis),
each finding judged by the fit where one converged, in its one wording.

Unusable (the run stops before any fit) on a blocking finding; fine otherwise. A sign finding
(:data:`JUDGED_BY_FIT`) stops a run only where the converged fit confirms it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

from nlp_calib.analysis.units import findings
from nlp_calib.models import KinematicModel
from nlp_calib.pipeline.prepare import PreparedLog
from nlp_calib.problem import ProblemFunctions
from nlp_calib.results import codec
from nlp_calib.results.checks import FINE, UNUSABLE, CheckResult
from nlp_calib.results.preflight import UnitFinding

#: Its name: the pre-flight's record and ``preflight.json`` hold its findings under it.
NAME = "units"
#: Unit and sign findings that stop a run only where the converged fit confirms them.
JUDGED_BY_FIT = ("mirrored",)


def check(
    parts: Sequence[PreparedLog],
    fns: ProblemFunctions,
    start: Mapping[str, float],
    fitted: Mapping[str, float] | None,
) -> CheckResult:
    """The units and signs of the logs ``parts`` fitted with ``fns`` from ``start`` (``fitted``: the
    converged fit's parameters; None: no fit converged)."""
    found = unit_findings(parts, fns, start, fitted)
    blocking = [f.words for f in found if f.blocking]
    return CheckResult(
        NAME,
        UNUSABLE if blocking else FINE,
        f"{len(found)} finding(s) in units and signs" if found else "nothing suspicious in units and signs",
        tuple(f.words for f in found),
        caveat=blocking[0] if blocking else "",
        caveats=tuple(blocking[1:]),
        record=codec.to_data(found),
    )


def unit_findings(
    parts: Sequence[PreparedLog],
    fns: ProblemFunctions,
    start: Mapping[str, float],
    fitted: Mapping[str, float] | None,
) -> tuple[UnitFinding, ...]:
    """What the data of each log imply of units and signs, each finding once, judged by the fit."""
    out: list[UnitFinding] = []
    for i, part in enumerate(parts):
        log = part.log.select(part.start, part.split)
        T = fns.sensor.floor_track(log)
        mount = fns.sensor.planar_mount(fns.view_dict(start, i))
        found = findings(log, part.model, (T[:, :2], T[:, 2]), mount, not fns.sensor.lengths_unseen)
        out += [f for f in found if f not in out]
    return tuple(_judged_by_fit(f, fns.model, fitted) for f in out)


def _judged_by_fit(
    finding: UnitFinding, model: KinematicModel, fitted: Mapping[str, float] | None
) -> UnitFinding:
    """``finding`` as the converged fit (``fitted``: its parameters; None: no fit converged) judges
    it: a mirrored wheel makes a fitted wheel radius negative, so a fit whose every parameter is
    plausible says the wheels' signs are as the model reads them (a sensor turned 90°, a scan
    matcher's slips on gentle curves): the finding is said and the run goes on."""
    if finding.kind not in JUDGED_BY_FIT or fitted is None or implausible(model, fitted):
        return finding
    return replace(
        finding,
        blocking=False,
        words=finding.words + "; but the fit on these data finds every parameter plausible (the wheels' "
        "signs as read agree with the reference), so the run goes on",
    )


def implausible(model: KinematicModel, values: Mapping[str, float]) -> str:
    """The parameters of ``values`` outside the model's plausible ranges, in words ("" when none is)."""
    out = [
        f"{n} {v:.3g}"
        for n, v in values.items()
        if n in model.physical_ranges and not model.physical_ranges[n][0] <= v <= model.physical_ranges[n][1]
    ]
    return ", ".join(out)
