"""The direction check as a plug-in: fits on forward-only and on reverse-only driving against each
other (refitted with the cross-validation, :func:`nlp_calib.pipeline.validation.direction_check`),
in its one wording.

A caveat when they disagree beyond their σ and the precision a calibration needs, on each
parameter they disagree on.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, SIGNIFICANT, CheckResult, DirectionCheck
from nlp_calib.results.codec import finite_or_null


def check(run: CalibrationRun) -> CheckResult | None:
    """The forward-reverse comparison of the run (None: it did not run)."""
    d = run.checks.direction
    if d is None:
        return None
    how = "Each part's σ is the jackknife σ of blocks of that part alone." if d.compared else ""
    record = finite_or_null(d.as_dict())
    if not d.significant:
        return CheckResult("direction", FINE, sentence(d), how=how, record=record)
    name, z = d.worst
    widened = np.isfinite(d.spread()[d.names.index(name)])
    also = "; its σ covers both" if widened else ""
    concerns = {
        n: f"forward and reverse driving disagree on it by {abs(v):.1f}σ"
        for n, v, flagged in zip(d.names, d.z, d.flagged)
        if flagged
    }
    return CheckResult(
        "direction",
        CAVEAT,
        sentence(d),
        caveat=f"forward and reverse driving disagree ({name} by {abs(z):.1f}σ{also})",
        concerns=concerns,
        how=how,
        record=record,
    )


def sentence(d: DirectionCheck) -> str:
    """Its one wording: the parts' windows and :func:`words`."""
    return (
        f"fits on forward-only ({d.windows[0]} windows) and reverse-only ({d.windows[1]}) driving {words(d)}"
    )


def words(d: DirectionCheck) -> str:
    """The finding in words: agree within, disagree by, or could not compare (and why)."""
    if not d.compared:
        return (
            "could not be compared: no parameter has a σ in both parts (each part's σ needs at "
            "least 3 blocks with 20 or more windows of its driving)"
        )
    name, z = d.worst
    if d.significant:
        return f"DISAGREE: {name} by {abs(z):.1f}σ"
    if abs(z) > SIGNIFICANT and d.needed is not None:
        i = d.names.index(name)
        share = abs(d.forward[i] - d.reverse[i]) / d.needed[i]
        return (
            f"agree within the precision needed ({name} differs by {abs(z):.1f}σ, only "
            f"{share:.2g}× the precision it needs)"
        )
    return f"agree within {abs(z):.1f}σ ({name})"
