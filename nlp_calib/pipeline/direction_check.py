"""The direction check as a plug-in: fits on forward-only and on reverse-only driving against each
other (refitted with the cross-validation, :func:`nlp_calib.pipeline.validation.direction_check`),
in its one wording.

A caveat when they disagree beyond their σ and the precision a calibration needs, on each
parameter they disagree on.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, CheckResult
from nlp_calib.results.codec import finite_or_null


def check(run: CalibrationRun) -> CheckResult | None:
    """The forward-reverse comparison of the run (None: it did not run)."""
    d = run.checks.direction
    if d is None:
        return None
    how = "Each part's σ is the jackknife σ of blocks of that part alone." if d.compared else ""
    if not d.significant:
        return CheckResult("direction", FINE, d.sentence(), how=how, record=finite_or_null(d.as_dict()))
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
        d.sentence(),
        caveat=f"forward and reverse driving disagree ({name} by {abs(z):.1f}σ{also})",
        concerns=concerns,
        how=how,
        record=finite_or_null(d.as_dict()),
    )
