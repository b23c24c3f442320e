"""The determinacy check as a plug-in: what the drive determines of each parameter, from the fit's
information matrix (:mod:`nlp_calib.analysis.observability`, computed by the analyse stage) and
each parameter's σ to believe against the precision a calibration needs, in its one wording.

A caveat for each weakly observable direction and each parameter known more loosely than
:data:`~nlp_calib.results.checks.WEAK` times the precision it needs, on each parameter concerned.
A combination loose in the σ to believe (:func:`~nlp_calib.analysis.observability.believed_directions`:
the white-noise correlations scaled to each parameter's σ to believe) that the white-noise
directions do not name is a caveat too, with what would determine it, on each of its parameters,
unless each of them is under a caveat already. A direction the drive leaves free makes the
estimate not determined: the verdict's own rule (with what to drive), read from the same figures.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from nlp_calib.analysis.excitation import turns_both_ways
from nlp_calib.analysis.observability import believed_directions
from nlp_calib.analysis.verdict import way_out
from nlp_calib.models import MODELS, KinematicModel
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import (
    CAVEAT,
    FINE,
    NOT_OBSERVABLE,
    WEAK,
    CheckResult,
    Observability,
    WeakDirection,
)
from nlp_calib.sensors import sensor_for

#: Its name, the key result.json has always held its figures under.
NAME = "observability"


def check(run: CalibrationRun, model: KinematicModel | None = None) -> CheckResult | None:
    """What the drive determines (None: the observability was not analysed); ``model``: the
    run's (None: the scenario's, by name), whose words say what would determine a loose
    combination."""
    obs = run.checks.observability
    if obs is None:
        return None
    weak = [w for w in obs.weak if w.std_reference <= NOT_OBSERVABLE]
    concerns = {c: w.words() for w in weak for c in w.components}
    solver = run.chosen_solver()
    coarse = loose(run, solver) if solver is not None else {}
    concerns.update(coarse)
    reasons = [*(w.words() for w in weak), *coarse.values()]
    combined = together(run, solver, model, obs, concerns) if solver is not None else []
    # The parameters in doubt only as part of a combination loose in the σ to believe: a value
    # they give that the combination leaves determined is not in doubt (CalibrationRun.waived).
    alone = sorted({n for _, w in combined for n in w.components} - set(concerns))
    for why, w in combined:
        reasons.append(why)
        for n in w.components:
            concerns.setdefault(n, why)
    # Its words say the first warning; the details, the figures and the others.
    details = (
        f"condition number {obs.condition_number:.3g} (Jacobi-scaled information matrix), heading range "
        f"{obs.heading_range_rad:.2f} rad",
        *obs.warnings[1:],
    )
    return CheckResult(
        NAME,
        CAVEAT if reasons else FINE,
        words(obs, [w for _, w in combined]),
        details,
        caveat=reasons[0] if reasons else "",
        caveats=tuple(reasons[1:]),
        concerns=concerns,
        record={
            **obs.as_dict(),
            "loose_in_believed": [_as_dict(w) for _, w in combined],
            "only_together": alone,
        },
    )


def _as_dict(w: WeakDirection) -> dict[str, object]:
    return {"std_in_reference_units": w.std_reference, "components": w.components}


def words(obs: Observability, combined: Sequence[WeakDirection] = ()) -> str:
    """Its one wording: every parameter determined, or the first warning (and how many more);
    ``combined``: the combinations loose only in the σ to believe (:func:`together`)."""
    if not obs.warnings and combined:
        first = combined[0]
        return (
            f"each parameter determined (condition number {obs.condition_number:.3g}), but "
            f"{', '.join(first.components)} move together, one combination of them known only to "
            f"±{first.std_reference:.3g}× the precision it needs in their σ to believe"
        )
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


def together(
    run: CalibrationRun,
    solver: str,
    model: KinematicModel | None,
    obs: Observability,
    said: Mapping[str, str],
) -> list[tuple[str, WeakDirection]]:
    """The combinations loose in the σ to believe that the white-noise directions ``obs`` do not
    name, each caveat with its parameters; one whose parameters are each under a caveat already
    (``said``) says nothing new."""
    named = {frozenset(w.components) for w in obs.weak}
    kind = model if model is not None else MODELS.get(run.scenario.model)
    sensor = sensor_for(run.scenario.sensor.kind, run.scenario.sensor.scale)
    out = []
    for found in believed_directions(run, solver):
        names = tuple(sorted(found.components, key=lambda n: -abs(found.components[n])))
        w = WeakDirection(found.std_reference, {n: found.components[n] for n in names})
        if frozenset(names) in named or set(names) <= set(said):
            continue
        why = (
            f"{', '.join(names)} move together: one combination of them is known only to "
            f"±{w.std_reference:.3g}× the precision it needs (their σ to believe, with the white noise's "
            "correlations: the drive's own errors widen what it ties), looser than each one's σ shows"
        )
        both = turns_both_ways(run.data.excitation)
        advice = way_out(names, kind, run.scenario.layout, sensor, None, both) if kind is not None else ""
        out.append((f"{why}; {advice}" if advice else why, w))
    return out
