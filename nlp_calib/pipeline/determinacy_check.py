"""The determinacy check as a plug-in: what the drive determines of each parameter, from the fit's
information matrix (:mod:`nlp_calib.analysis.observability`, computed by the analyse stage) and
each parameter's σ to believe against the precision a calibration needs, in its one wording.

A caveat for each weakly observable direction and each parameter known more loosely than
:data:`~nlp_calib.results.checks.WEAK` times the precision it needs, on each parameter concerned.
A direction the drive leaves free makes the estimate not determined: the verdict's own rule (with
what to drive), read from the same figures.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, NOT_OBSERVABLE, WEAK, CheckResult, Observability

#: Its name, the key result.json has always held its figures under.
NAME = "observability"


def check(run: CalibrationRun) -> CheckResult | None:
    """What the drive determines (None: the observability was not analysed)."""
    obs = run.checks.observability
    if obs is None:
        return None
    weak = [w for w in obs.weak if w.std_reference <= NOT_OBSERVABLE]
    concerns = {c: w.words() for w in weak for c in w.components}
    solver = run.chosen_solver()
    coarse = loose(run, solver) if solver is not None else {}
    concerns.update(coarse)
    reasons = [*(w.words() for w in weak), *coarse.values()]
    # Its words say the first warning; the details, the figures and the others.
    details = (
        f"condition number {obs.condition_number:.3g} (Jacobi-scaled information matrix), heading range "
        f"{obs.heading_range_rad:.2f} rad",
        *obs.warnings[1:],
    )
    return CheckResult(
        NAME,
        CAVEAT if reasons else FINE,
        words(obs),
        details,
        caveat=reasons[0] if reasons else "",
        caveats=tuple(reasons[1:]),
        concerns=concerns,
        record=obs.as_dict(),
    )


def words(obs: Observability) -> str:
    """Its one wording: every parameter determined, or the first warning (and how many more)."""
    if not obs.warnings:
        return f"every parameter determined (condition number {obs.condition_number:.3g})"
    more = len(obs.warnings) - 1
    return obs.warnings[0] + (f" (and {more} more)" if more else "")


def loose(run: CalibrationRun, solver: str) -> dict[str, str]:
    """Each parameter whose σ to believe exceeds WEAK times the precision its layout needs (the
    vehicle's, :mod:`nlp_calib.analysis.precision`), with why."""
    std = run.std(solver)
    params = run.reports[solver].result.param_dict()
    needed = run.scenario.layout.needed({n: params[n] for n in std})
    out: dict[str, str] = {}
    for name, s in std.items():
        if np.isfinite(s) and not s <= WEAK * needed[name]:
            unit, ref = run.scenario.units[name], needed[name]
            out[name] = f"{name} is known only to ±{s:.2g} {unit} (over {WEAK:g}× the {ref:.2g} needed)"
    return out
