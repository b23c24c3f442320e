"""Whether a calibration still holds on a new log: each parameter's change judged in its σ.

For a parameter with the stored estimate θ₀ (σ₀ to believe) and the refit θ₁ on a new,
independent log (σ₁ to believe), the change in units of the combined σ

    z = (θ₁ − θ₀) / √(σ₀² + σ₁²)

is, when nothing changed, approximately Student-t distributed. Each σ to believe is either the
white-noise σ, estimated from thousands of residuals (taken as known: ν = ∞), or the jackknife σ of
K blocks, which has its own sampling error (ν = K − 1). The combined σ's degrees of freedom follow
Welch and Satterthwaite, ``ν = (σ₀² + σ₁²)² / (σ₀⁴/ν₀ + σ₁⁴/ν₁)``. With m parameters tested at once,
each |z| is held against the two-sided Student-t quantile at level α/m (Bonferroni), so a check of
an unchanged robot calls a drift with probability at most α (:data:`FALSE_ALARM`) when the σ are
honest. Nothing here is tuned on data: α is a choice, the rest follows from it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path

import numpy as np

from nlp_calib.analysis.observability import believed_directions
from nlp_calib.models import SENSOR_PARAMS, KinematicModel
from nlp_calib.models.base import reference, reference_scale
from nlp_calib.results import CalibrationRun, ScenarioInfo
from nlp_calib.results.check import CANNOT_TELL, DRIFTED, STILL_GOOD, DriftCheck, ParameterChange
from nlp_calib.results.checks import NOT_OBSERVABLE, WEAK, noise_factor
from nlp_calib.sensors import sensor_for

#: The family-wise probability that a check of an unchanged robot calls a drift.
FALSE_ALARM = 0.01
#: A refit whose σ is this many times smaller than the stored calibration's determines it better.
TIGHTER = 3.0
#: How a parameter held at its initial value is named in a run's notes.
HELD = " held at its initial value: "


def _continued_fraction(a: float, b: float, x: float) -> float:
    """The continued fraction of the regularised incomplete beta function (modified Lentz)."""
    tiny = 1e-300
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 500):
        for num in (m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
                    -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))):  # fmt: skip
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + num / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < 1e-15:
            break
    return h


def incomplete_beta(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    front = math.exp(
        math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    )
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _continued_fraction(a, b, x) / a
    return 1.0 - front * _continued_fraction(b, a, 1.0 - x) / b


def two_sided_tail(t: float, dof: float) -> float:
    """P(|T| > t) for Student's t with ``dof`` degrees of freedom (the normal's for ``inf``)."""
    if math.isinf(dof):
        return math.erfc(abs(t) / math.sqrt(2.0))
    return incomplete_beta(dof / 2.0, 0.5, dof / (dof + t * t))


def t_quantile(p: float, dof: float) -> float:
    """The ``t`` with ``P(|T| > t) = p`` (by bisection: the tail falls monotonically)."""
    lo, hi = 0.0, 1.0
    while two_sided_tail(hi, dof) > p:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if two_sided_tail(mid, dof) > p else (lo, mid)
    return 0.5 * (lo + hi)


def welch_dof(std: Sequence[float], dof: Sequence[float]) -> float:
    """Welch–Satterthwaite degrees of freedom of ``√(Σ σᵢ²)``, each σᵢ with ``dofᵢ`` (inf: known)."""
    total = sum(s * s for s in std) ** 2
    spread = sum(s**4 / d for s, d in zip(std, dof) if math.isfinite(d))
    return total / spread if spread > 0 else math.inf


def believed_dof(white: float, blocks: float | None, folds: int) -> float:
    """Degrees of freedom of a σ to believe: ``folds − 1`` when the jackknife σ of ``folds`` blocks
    is the larger (the one believed), infinite when the white-noise σ is."""
    if blocks is not None and math.isfinite(blocks) and blocks > white and folds >= 2:
        return float(folds - 1)
    return math.inf


def between_logs_std(believed: float, white: float, folds: int) -> float:
    """A σ to believe (``believed``; ``white``: the white-noise σ; ``folds``: the jackknife's) as if
    what errors that vary along the drive add were shared by all of a log's blocks: the part
    beyond what white noise gives a jackknife at its 95 % point then counts at a single block's
    spread, √folds × the jackknife's; the rest averages over the log as before."""
    if folds < 2 or not (math.isfinite(believed) and math.isfinite(white)):
        return believed
    shared = max(0.0, believed * believed - (noise_factor(folds) * white) ** 2)
    return math.sqrt(believed * believed + (folds - 1) * shared)


def run_between_logs(run: CalibrationRun, solver: str, held: bool = True) -> dict[str, float]:
    """Each σ to believe of a run's estimate as :func:`shared_std` widens it."""
    u = run.reports[solver].uncertainty
    cv = run.checks.crossval
    folds = len(cv.converged) if cv is not None else 0
    slip, own = run.checks.shifts(u.names, held), np.fmax(*u.spreads())
    return {
        n: shared_std(sd, (float(u.std[i]), float(own[i]), float(slip[i])), folds)
        for i, (n, sd) in enumerate(run.std(solver, held=held).items())
    }


def shared_std(believed: float, parts: tuple[float, float, float], folds: int) -> float:
    """A σ to believe ``believed`` as :func:`between_logs_std` widens it. ``parts``: its white-noise
    σ, the residuals' own σ and the σ of the shifts the whole drive shares (the slip's and the held
    values'; NaN: none). What averages over a log is the larger of the first two (an error of each
    window's own averages as white noise does); the shifts' σ is shared by the whole drive already,
    so it is taken out before the widening and added back unwidened, in quadrature."""
    white, own, slip = parts
    averaged = float(np.fmax(white, own))
    base = math.sqrt(max(0.0, believed * believed - slip * slip)) if math.isfinite(slip) else believed
    widened = between_logs_std(base, averaged, folds)
    return math.sqrt(widened * widened + max(0.0, believed * believed - base * base))


def run_dof(run: CalibrationRun, solver: str) -> dict[str, float]:
    """The degrees of freedom of each σ to believe of a run's estimate (see :func:`believed_dof`)."""
    white = run.reports[solver].uncertainty.std_dict()
    blocks = run.std_blocks() or {}
    cv = run.checks.crossval
    folds = len(cv.converged) if cv is not None else 0
    return {n: believed_dof(w, blocks.get(n), folds) for n, w in white.items()}


def untested(run: CalibrationRun, solver: str, model: KinematicModel, held: bool = True) -> dict[str, str]:
    """The free parameters this log cannot test, with why: held at the initial value, in a direction
    the log does not observe, or known more loosely than the verdict's
    :data:`~nlp_calib.results.checks.WEAK` × the precision a calibration needs. A parameter in a
    weakly (not un-) observable combination is judged by its own σ, which already carries that
    looseness: the combination alone does not make it untestable. The directions are the white
    noise's and those of the σ to believe
    (:func:`~nlp_calib.analysis.observability.believed_directions`)."""
    out = {w.split(HELD)[0]: w.split(HELD)[1] for w in run.warnings if HELD in w}
    obs = run.checks.observability
    # The run's verdict reads the same directions: the white noise's, then those of the σ to believe.
    for weak in [*(obs.weak if obs is not None else ()), *believed_directions(run, solver, held)]:
        if weak.std_reference > NOT_OBSERVABLE:
            for name in weak.components:
                out.setdefault(name, weak.words())
    params = run.reports[solver].result.param_dict()
    # The sensor's own precisions of its mount (a camera's angles: 0.005 rad, not 1 % of each).
    own = sensor_for(run.scenario.sensor.kind, run.scenario.sensor.scale).reference
    for name, sd in run.std(solver, held=held).items():
        if name not in run.reports[solver].uncertainty.free or name in out:
            continue
        ref = reference_scale(model, run.scenario.layout.key(name), params[name], own)
        if not np.isfinite(sd):
            out[name] = f"{name} is not determined by this drive"
        elif sd > WEAK * ref:
            out[name] = f"{name} is known only to ±{sd:.2g} {run.scenario.units[name]} from this drive"
    return out


def drive_more(
    run: CalibrationRun, model: KinematicModel, names: Sequence[str], std: Mapping[str, float] | None = None
) -> str:
    """What to drive so that a log can test ``names``: where the tyres' slip makes most of their σ
    (``std``: the σ to believe; the slip check's ``std_slip`` over half of it), bends driven slowly
    too; else in the observability analysis' words."""
    slipped = _slip_bound(run, names, std or {})
    if slipped:
        return (
            f"drive bends slowly as well as at speed (the slower, the less tyres slide): the tyres' slip "
            f"in this drive's bends leaves {', '.join(slipped)} open, and bends at several speeds tell it"
        )
    obs = run.checks.observability
    said = [w for w in (obs.warnings if obs is not None else ()) if "drive" in w]
    if said:
        return said[0].split("; ", 1)[-1]
    lever = (*model.turning_params, *SENSOR_PARAMS[:2])
    if any(n in lever for n in names):
        return "drive more turning: S-curves or circles in both directions, over a longer log"
    return f"drive longer, with more of what moves {', '.join(names)}"


def _slip_bound(run: CalibrationRun, names: Sequence[str], std: Mapping[str, float]) -> list[str]:
    """Of ``names``, those the slip check moved with the speed or whose σ to believe (``std``) the
    slip's makes most of (its ``std_slip`` over half of it)."""
    found = next((c for c in run.checks.more if c.name == "slip"), None)
    record = found.record if found is not None and isinstance(found.record, Mapping) else {}
    moved, slip = record.get("moved") or [], record.get("std_slip") or {}
    return [
        n
        for n in names
        if n in moved
        or (slip.get(n) is not None and np.isfinite(std.get(n, np.nan)) and slip[n] > 0.5 * std[n])
    ]


def changes(
    stored: tuple[Mapping[str, float], Mapping[str, float], Mapping[str, float]],
    refit: tuple[Mapping[str, float], Mapping[str, float], Mapping[str, float]],
    info: ScenarioInfo,
    model: KinematicModel,
    skipped: Mapping[str, str],
    shared: tuple[Mapping[str, float], Mapping[str, float]] | None = None,
) -> tuple[ParameterChange, ...]:
    """Each parameter of ``refit`` (values, σ, degrees of freedom) against ``stored`` (the same),
    with the Bonferroni threshold over the parameters tested; ``skipped``: those that cannot be
    tested, with why; ``shared``: the stored and refit σ as :func:`between_logs_std` widens them
    (None: as they are)."""
    values, std, dof = refit
    tested = [n for n in values if n not in skipped and math.isfinite(std[n]) and math.isfinite(stored[1][n])]
    level = FALSE_ALARM / max(len(tested), 1)
    out = []
    for name in values:
        delta = values[name] - stored[0][name]
        if name in model.angle_params:
            delta = math.remainder(delta, 2.0 * math.pi)
        sigma = math.hypot(stored[1][name], std[name])
        nu = welch_dof((stored[1][name], std[name]), (stored[2][name], dof[name]))
        why = skipped.get(name, "" if name in tested else f"{name} has no σ to judge a change by")
        z = delta / sigma if sigma > 0 and math.isfinite(sigma) else math.nan
        wide = math.hypot(shared[0][name], shared[1][name]) if shared is not None else sigma
        z_shared = delta / wide if wide > 0 and math.isfinite(wide) else math.nan
        threshold = math.nan if math.isnan(nu) else t_quantile(level, nu)
        relative = reference(model, info.layout.key(name))[0] == "relative"
        out.append(
            ParameterChange(
                name,
                info.units[name],
                stored[0][name],
                stored[0][name] + delta,
                stored[1][name],
                std[name],
                nu,
                z,
                threshold,
                why,
                relative,
                z_shared,
            )
        )
    return tuple(out)


def decide(found: tuple[ParameterChange, ...], converged: str, hint: str) -> tuple[str, tuple[str, ...], str]:
    """The verdict, its reasons and the hint, from the changes; ``converged`` is "" when the refit
    converged, else why not."""
    loose = [c.untested for c in found if c.untested]
    if converged:
        return (
            CANNOT_TELL,
            (f"the refit on this log did not converge ({converged})", *dict.fromkeys(loose)),
            hint,
        )
    moved = [c for c in found if c.drifted]
    if moved:
        return DRIFTED, tuple(moved_words(c) for c in sorted(moved, key=lambda c: -abs(c.z))), ""
    if loose:
        return CANNOT_TELL, tuple(dict.fromkeys(loose)), hint
    if not found:
        return CANNOT_TELL, ("no parameter could be compared",), hint
    worst = max(found, key=lambda c: abs(c.z) / c.threshold)
    largest = f"largest: {worst.name} {worst.z:+.1f}σ against ±{worst.threshold:.1f}σ"
    better = tighter(found)
    return STILL_GOOD, (f"no parameter moved beyond its threshold ({largest})", *better), ""


def tighter(found: tuple[ParameterChange, ...]) -> tuple[str, ...]:
    """Where the new log determines parameters :data:`TIGHTER` times or more better than the stored
    calibration did and puts the stored value beyond the threshold in its own σ: the words saying
    so (none: ``()``). The stored σ was honest (the change is within it), but a calibration on this
    log would hand the robot values that much closer."""
    better = [
        c
        for c in found
        if not c.untested
        and 0.0 < TIGHTER * c.std_refit < c.std_stored
        and math.isfinite(c.threshold)
        and abs(c.change) > c.threshold * c.std_refit
    ]
    if not better:
        return ()
    said = ", ".join(
        f"{c.name} to ±{c.std_refit:.2g} {c.unit} (the calibration: ±{c.std_stored:.2g}; its value "
        f"{abs(c.change) / c.std_refit:.4g}σ of this log's away)"
        for c in sorted(better, key=lambda c: -abs(c.change) / c.std_refit)
    )
    return (f"this log determines {said}: calibrate on it for a tighter calibration",)


def common_held(
    run: CalibrationRun, solver: str, held: tuple[Mapping[str, float], Mapping[str, float]]
) -> bool:
    """Whether the stored calibration and the refit rest on the same held values (``held``: the
    stored σ's parts from them and the values themselves), each with a part of its σ from them: a
    held value's error then moves both fits alike and drops out of the change, so their σ are
    compared without that part. A refit that holds other values (a scenario giving another lag)
    or none shares nothing: each σ is taken whole."""
    std, values = held
    names = run.reports[solver].uncertainty.names
    if not std or not values or not np.isfinite(run.checks.held(names)).any():
        return False
    mine = run.checks.held_values()
    return mine.keys() == values.keys() and all(
        abs(mine[n] - v) <= 1e-12 * max(1.0, abs(v)) for n, v in values.items()
    )


def _as_stated(
    found: tuple[ParameterChange, ...], stated: tuple[Mapping[str, float], Mapping[str, float]]
) -> tuple[ParameterChange, ...]:
    """``found`` with each σ as the calibration and the refit state it (their held parts in), the
    change judged without them (``z``, the threshold: :func:`common_held`)."""
    stored, refit = stated
    return tuple(
        dataclasses.replace(
            c, std_stored=stored.get(c.name, c.std_stored), std_refit=refit.get(c.name, c.std_refit)
        )
        for c in found
    )


def _without(std: Mapping[str, float], held: Mapping[str, float]) -> dict[str, float]:
    """Each σ of ``std`` with its held part (``held``) taken out in quadrature."""
    return {n: math.sqrt(max(s * s - held.get(n, 0.0) ** 2, 0.0)) for n, s in std.items()}


def moved_words(c: ParameterChange) -> str:
    """``<name> moved by +1.0 % (+0.000105 <unit>, +12.3σ)`` (the percentage for gains and lengths),
    and when the change is not confirmed (:attr:`ParameterChange.confirmed`) how far it is in the
    σ the blocks would have if errors were shared by all of a log's blocks."""
    rel = f"{100.0 * c.change / c.stored:+.2g} % (" if c.relative and c.stored != 0 else "("
    words = f"{c.name} moved by {rel}{c.change:+.3g} {c.unit}, {c.z:+.1f}σ)"
    if c.confirmed:
        return words
    return (
        f"{words}, but only {c.z_shared:+.1f}σ if the errors that vary along the drive are shared by "
        "all of a log's blocks (a tracker's bias wandering over minutes, a model error the drive's "
        "mix sets): not confirmed, check on another log before recalibrating"
    )


def check_drift(
    run: CalibrationRun,
    model: KinematicModel,
    stored: tuple[Mapping[str, float], Mapping[str, float], Mapping[str, float]],
    calibration: str,
    solver: str,
    uncalibrated: Collection[str] = (),
    shared: Mapping[str, float] | None = None,
    held_parts: tuple[Mapping[str, float], Mapping[str, float]] = ({}, {}),
) -> DriftCheck:
    """The check of ``stored`` (values, σ to believe, their degrees of freedom) against ``run``, a
    fit of a new log started from it; ``uncalibrated``: what the stored calibration held or was
    given, which it does not vouch for and a check does not judge; ``shared``: the stored σ as
    :func:`between_logs_std` widens them (None: as they are); ``held_parts``: the stored σ's parts
    from held values and those values (see :func:`common_held`)."""
    result = run.reports[solver].result
    free = run.reports[solver].uncertainty.free
    common = common_held(run, solver, held_parts)
    stated = (dict(stored[1]), run.std(solver))
    if common:
        stored = (stored[0], _without(stored[1], held_parts[0]), stored[2])
        shared = _without(shared, held_parts[0]) if shared is not None else None
    skipped = untested(run, solver, model, held=not common)
    # Fixed by the scenario, or never estimated by the stored calibration: nothing to compare.
    held = [n for n in result.names if (n not in free and n not in skipped) or n in uncalibrated]
    # A recording's own parameters (its clock offset, a gyro's bias: the sensor's own per log) are
    # refitted, not judged: a new log may have another. What the stored calibration does not hold
    # cannot have drifted from it.
    layout, sensor = run.scenario.layout, sensor_for(run.scenario.sensor.kind, run.scenario.sensor.scale)
    robot = {n for n in layout.robot() if layout.key(n) not in sensor.per_log} & set(stored[0])
    values = {n: v for n, v in result.param_dict().items() if n not in held and n in robot}
    refit = (values, run.std(solver, held=not common), run_dof(run, solver))
    widened = (shared if shared is not None else stored[1], run_between_logs(run, solver, held=not common))
    found = changes(stored, refit, run.scenario, model, skipped, widened)
    found = _as_stated(found, stated) if common else found
    hint = drive_more(run, model, [c.name for c in found if c.untested], refit[1])
    verdict, reasons, hint = decide(found, "" if result.converged else result.reason, hint)
    unjudged = [n for n in result.names if n in uncalibrated]
    if unjudged:
        by = Path(calibration).name
        reasons = (*reasons, f"not judged: {', '.join(unjudged)} (not calibrated by {by})")
    return DriftCheck(calibration, solver, found, FALSE_ALARM, verdict, reasons, hint)
