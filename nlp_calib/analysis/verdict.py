"""The verdict on a run: is the calibration good, usable with caveats, or not determined, and why.

The rules a reader can check:

- **not determined**, and no hand-off file written: the estimate cannot be a real robot of its
  kind although it fits the data: a mirror image (e.g. swapped wheel encoders, one wheel counting
  backwards; the model says), a 3-D sensor's mount upside down that no given mount asked for (what
  reversed or swapped joints give a camera), or a parameter outside what the model can have by
  more than :data:`RANGE_SIGMAS` σ (a wheel's radius of millimetres: joints logged in degrees)
  where the drive leaves no direction free (else a solver stops anywhere along it: the next rule);
- **not determined**: no solver converged, or the drive leaves a parameter undetermined (its σ
  is infinite, or a direction of the information matrix is beyond
  :data:`~nlp_calib.results.checks.NOT_OBSERVABLE` reference units);
- **not usable**: converged and determined, but worse than a given initial guess or than the
  robot's nominal values by what the reference measures well (the data cost of the windows each
  cross-validation fold left out, beyond :data:`~nlp_calib.results.checks.BEATS` standard errors;
  without folds, the data cost on every window), or, fitted to several logs, some log's own fit
  differs from the other logs' beyond their honest σ and beyond what one robot's logs differ by
  (they are not one robot): whatever else holds, such a calibration is not to be used;
- **usable with caveats**: converged and determined, but something needs a look first: a weakly
  observable direction, a parameter whose σ to believe exceeds
  :data:`~nlp_calib.results.checks.WEAK` times the precision a useful calibration needs,
  solvers that disagree, a parameter held at its initial value, forward and reverse driving that
  disagree, parameters that move between logs beyond their σ (a model limit), faults kept in the
  fit or not checked (each a plug-in check's caveat, in the order of its registry), or a fit
  that does worse on held-out data than the start computed from the data itself
  (``initial_guess: auto``: that start is itself a fit, so this is a caveat), or a calibrated
  model that dead-reckons farther from the tracker than the nominal one (segment ATE);
- **good**: none of these.

A run of one log among several fitted together is judged on that log's own comparison with the
others; the joint fit as one run on every log's.
Beside the level, the verdict states the gain over the robot's nominal values (segment ATE), or
that no source knows them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from nlp_calib.analysis.excitation import turns_both_ways
from nlp_calib.models import KinematicModel
from nlp_calib.results import CalibrationRun, Verdict
from nlp_calib.results.checks import (
    CAVEAT,
    NOT_OBSERVABLE,
    UNUSABLE,
    LagEstimate,
)
from nlp_calib.results.layout import CLOCK, HELD, KNOWN, Layout
from nlp_calib.results.run import CAVEATS, GOOD, NOT_USABLE, UNDETERMINED
from nlp_calib.sensors import Sensor, sensor_for
from nlp_calib.sensors.mount import length_params

#: Relative parameter difference beyond which two converged solvers disagree.
AGREE = 1e-4
#: A parameter outside what the model can have by more than this many σ is not the robot's.
RANGE_SIGMAS = 3.0


def concerns(run: CalibrationRun, solver: str, model: KinematicModel) -> dict[str, str]:
    """Each parameter a caveat of ``solver``'s estimate names, with that caveat: each parameter a
    plug-in check puts in doubt (known too loosely, different between forward and reverse driving
    or between logs; the first check's word, in registry order, after those of a check whose word
    on its parameters comes first: one that finds them not determined at all), every parameter
    under a check's caveat on all of them (a wrong model's), or different between the converged
    solvers."""
    out: dict[str, str] = {}
    first = [r for r in run.checks.more if r.about.get("concerns") == "first"]
    for r in [*first, *(r for r in run.checks.more if r not in first)]:
        if r.level in (CAVEAT, UNUSABLE):
            for n, why in r.concerns.items():
                out.setdefault(n, why)
    params = run.reports[solver].result.param_dict()
    for r in run.checks.more:  # a plug-in check's caveat on every parameter (a wrong model's)
        if r.level == CAVEAT and r.about.get("concerns") == "all":
            out.update({n: out.get(n, r.words) for n in params})
    for other in [s for s in run.solver_order() if run.reports[s].result.converged and s != solver]:
        theirs = run.reports[other].result.param_dict()
        for n, v in params.items():
            if abs(v - theirs[n]) > AGREE * max(abs(v), 1e-12):
                out.setdefault(n, f"{solver} and {other} disagree on it")
    return out


def lag_caveats(path: str, lag: LagEstimate | None) -> list[str]:
    """What the time offset of the log at ``path`` leaves open, naming the log: a lag no fit
    converged at (held), pinned on the edge of its search (its value is the bound's, with no σ),
    not determined by the drive (held where the fits settled, with no σ), or two valleys of
    comparable cost."""
    if lag is None:
        return []
    name = Path(path).name or path
    if not lag.converged:
        return [
            f"{name}: the tracker lag could not be fitted (no fit converged from any lag in "
            f"alignment.search): held at {1e3 * lag.lag_s:.0f} ms, not determined (give the lag as "
            "alignment.tracker_lag)"
        ]
    if lag.at_edge:
        return [
            f"{name}: the tracker lag is pinned on the edge of alignment.search at {1e3 * lag.lag_s:.0f} ms "
            "(not determined within it: widen the search, or give the lag)"
        ]
    if lag.loose:
        return [
            f"{name}: the tracker lag is not determined by this drive: held at {1e3 * lag.lag_s:.0f} ms, "
            f"where fits re-sampled off it stay ({100 * (lag.returned or 0.0):.0f} % of the offset taken "
            "back): starts, stops and turns of different lengths determine it, or give the lag as "
            "alignment.tracker_lag"
        ]
    if lag.ambiguous:
        other, cost, own = lag.other
        return [
            f"{name}: the tracker lag is ambiguous: {1e3 * lag.lag_s:.0f} ms or {1e3 * other:.0f} ms (fit "
            f"costs {own:.4g} and {cost:.4g}, {100 * abs(cost / own - 1):.1f} % apart; the lowest kept): a "
            "drive whose wheel speeds change at different rates (starts, stops and turns of different "
            "lengths) tells them apart, or give the lag as alignment.tracker_lag"
        ]
    return []


def steering_caveats(run: CalibrationRun) -> list[str]:
    """A fitted lag beside a steer angle read at one end of each interval: the reading stands
    half an interval off the interval's middle, which the lag takes up in part (biased: the demo's
    simulated log, on time, gives −5.3 ms with ``start``, 0.5 ± 0.5 ms with ``mean``)."""
    sample = run.scenario.residual.get("steering_sample", "mean")
    absolute = any(e.kind == "absolute" for e in run.log.encoders)
    if run.data.lag_estimate is None or sample == "mean" or not absolute or run.log.records < 2:
        return []
    half = 500.0 * run.log.duration_s / (run.log.records - 1)
    side = ("early", "little") if sample == "start" else ("late", "much")
    return [
        f"residual.steering_sample: {sample} reads the steer angle about {half:.0f} ms {side[0]} (half an "
        f"interval), which the fitted tracker lag takes up in part (too {side[1]} by up to that): "
        "steering_sample: mean reads it at the interval's middle"
    ]


def _sensor(run: CalibrationRun) -> Sensor:
    return sensor_for(run.scenario.sensor.kind, run.scenario.sensor.scale)


def _checks(run: CalibrationRun) -> list[str]:
    """What the clock and the held parameters leave open, in words."""
    out = [w for w in run.warnings if " held at its initial value" in w]
    out += lag_caveats(run.log.path, run.data.lag_estimate)
    if run.data.lag_estimate is None:  # a joint fit's: each log's own lag, as that log's run says it
        out += [c for path, est in run.data.lags.values() for c in lag_caveats(path, est)]
    out += steering_caveats(run)
    return out


def caveats(run: CalibrationRun, solver: str, model: KinematicModel) -> list[str]:
    """Why ``solver``'s converged, determined estimate needs a look before it is used: the plug-in
    checks' caveats first (in registry order: what the drive determines first), then the rest."""
    out = [reason for r in run.checks.more if r.level == CAVEAT for reason in r.reasons]
    converged = [s for s in run.solver_order() if run.reports[s].result.converged]
    for other in converged[1:]:
        if (d := run.relative_difference(solver, other)) > AGREE:
            out.append(f"{solver} and {other} disagree by {d:.1e} (relative)")
    out += _checks(run)
    out += _behind_nominal(run, solver)
    start = run.checks.start
    if start is not None and _fitted_start(run) and start.outcome == "worse":
        out.append(f"no better than the data-driven start {start.detail()}")
    return out


def _behind_nominal(run: CalibrationRun, solver: str) -> list[str]:
    """That the calibrated model dead-reckons farther from the tracker than the nominal one (segment
    ATE), in words: a calibration that makes the odometry worse is never good, whatever its σ."""
    nominal, ours = run.checks.nominal, run.reports[solver].metrics
    if nominal is None:
        return []
    base, mine = nominal.metrics.segment_ate.mean, ours.segment_ate.mean
    return [nominal.gain(ours)] if np.isfinite(base) and np.isfinite(mine) and mine > base else []


def _fitted_start(run: CalibrationRun) -> bool:
    """Whether the initial guess was computed from this data (``initial_guess: auto``)."""
    return run.scenario.initial_guess == "auto"


def implausible(run: CalibrationRun, solver: str, model: KinematicModel) -> str:
    """Why ``solver``'s estimate cannot be the robot although it fits the data: a mirror image (the
    model's, or the sensor's: a camera's mount upside down) or a parameter outside what the model can
    have; "" when it can be."""
    params = run.reports[solver].result.param_dict()
    if mirror := model.implausible(params):
        return mirror
    if mirror := _sensor(run).implausible(params, None if _fitted_start(run) else run.initial):
        return mirror
    std = run.std(solver)
    # A held or given value is no estimate of the data's: the encoders are not what put it there.
    layout = run.scenario.layout
    given = {*layout.status(HELD), *layout.status(KNOWN)}
    # A drive that leaves a direction free lets a solver stop anywhere along it, and the values that
    # move with it anywhere too: not determined, as the pre-flight says, not wrong encoders.
    if _unobservable(run):
        return ""
    for name in model.kinematic_params:
        lo, hi = model.physical_ranges.get(name, (-np.inf, np.inf))
        if name not in params or name in given or lo <= params[name] <= hi:
            continue
        # Outside the range but known so loosely that the range is within reach: not determined,
        # which the rules after this one say (with the hand-off they allow).
        reach = RANGE_SIGMAS * std.get(name, 0.0)
        if not np.isfinite(reach) or (params[name] + reach >= lo and params[name] - reach <= hi):
            continue
        unit = run.scenario.units.get(name, "")
        return (
            f"{name} came out {params[name]:.4g} {unit}, outside what a {model.name} can have "
            f"([{lo:g}, {hi:g}]) by more than {RANGE_SIGMAS:g}σ: are the encoders (or joints) the "
            "scenario names the right ones, in the units it says?"
        )
    return ""


def _unobservable(run: CalibrationRun) -> set[str]:
    """The parameters in a direction the drive leaves free (beyond
    :data:`~nlp_calib.results.checks.NOT_OBSERVABLE` reference units, or unbounded)."""
    obs = run.checks.observability
    weak = obs.weak if obs is not None else ()
    return {n for w in weak if not w.std_reference <= NOT_OBSERVABLE for n in w.components}


def _unusable(run: CalibrationRun) -> list[str]:
    """Why a converged, determined estimate is not to be used: the logs are not one robot's, or the
    fit does worse than a given initial guess or the robot's nominal values."""
    out = [reason for r in run.checks.more if r.level == UNUSABLE for reason in r.reasons]
    start, nominal = run.checks.start, run.checks.nominal
    if start is not None and not _fitted_start(run) and start.outcome == "worse":
        out.append(start.words())
    if nominal is not None and nominal.cost is not None and nominal.cost.outcome == "worse":
        out.append(nominal.cost.words())
    return out


def gain(run: CalibrationRun, solver: str) -> str:
    """The gain over the robot's nominal values in words, or that no source knows them."""
    nominal = run.checks.nominal
    if nominal is None:
        return (
            "no nominal robot known (no log header, ROBOT.yaml, /tf_static or initial_guess values "
            "give one): the gain over it cannot be stated"
        )
    return nominal.gain(run.reports[solver].metrics)


def _undetermined(run: CalibrationRun, model: KinematicModel, hint: str) -> Verdict | None:
    """The verdict when the estimate is not determined (see the module's rules), else None."""
    solver = run.chosen_solver()
    if solver is not None and (mirror := implausible(run, solver, model)):
        return Verdict(UNDETERMINED, (mirror + hint,), handoff=False)
    obs = run.checks.observability
    loose = [w.words() for w in obs.weak if w.std_reference > NOT_OBSERVABLE] if obs is not None else []
    group = [n for w in (obs.weak if obs is not None else ()) for n in w.components]
    lag = run.data.lag_estimate
    unfitted = ["the tracker lag could not be fitted"] if lag is not None and not lag.converged else []
    if unfitted and solver is not None and lag is not None and lag.lag_s != 0.0:
        # Held where its search starts, away from the stamps as logged: a lag nothing chose.
        words = f"{unfitted[0]}: the encoders were read {1e3 * lag.lag_s:.0f} ms off, where its search starts"
        return Verdict(UNDETERMINED, (words + hint,), handoff=False)
    if solver is None:
        failures = dict.fromkeys(run.reports[s].result.reason for s in run.solver_order())
        out = (*unfitted, *loose, *(f"no solver converged: {r}" for r in failures))
        return Verdict(UNDETERMINED, (*out, _way_out(run, group, model)) if loose else out)
    if bounded := _trade_off(run, solver):
        return Verdict(
            UNDETERMINED,
            (bounded, _way_out(run, run.reports[solver].uncertainty.bounded, model)),
        )
    # A lag pinned on its search's edge has no σ; it is a caveat naming its log (lag_caveats).
    missing = [n for n, sd in run.std(solver).items() if not np.isfinite(sd) and n not in run.pinned()]
    if missing or loose:
        why = loose or [f"{', '.join(missing)} not determined by this drive"]
        values = dict(
            zip(run.reports[solver].uncertainty.names, map(float, run.reports[solver].result.params))
        )
        return Verdict(
            UNDETERMINED,
            (*why, _way_out(run, [*missing, *group], model, values)),
        )
    return None


def _way_out(
    run: CalibrationRun, names: Sequence[str], model: KinematicModel, values: dict[str, float] | None = None
) -> str:
    """:func:`way_out` for ``names`` on ``run``'s drive (its reference, and whether it turns both ways)."""
    both = turns_both_ways(run.data.excitation)
    return way_out(names, model, run.scenario.layout, _sensor(run), values, both)


def _trade_off(run: CalibrationRun, solver: str) -> str:
    """The parameters this drive determines only together, each known only within the bounds of
    one of them (a lag within its search), in words; "" when there are none."""
    std, units = run.std(solver), run.scenario.units
    # Known within the bounds is a finite σ; a direction the bounds did not hold is not determined.
    group = tuple(n for n in run.reports[solver].uncertainty.bounded if np.isfinite(std[n]))
    if not group:
        return ""
    spread = ", ".join(f"{n} ±{std[n]:.2g} {units.get(n, '')}".rstrip() for n in group)
    return (
        f"{', '.join(group)} trade off on this drive (changing one is undone by the others), so each is "
        f"known only within the range the search allows ({spread})"
    )


def unseen_lengths(names: Sequence[str], model: KinematicModel, sensor: Sensor | None) -> tuple[str, ...]:
    """The model's lengths among ``names`` when ``sensor`` measures none (a gyro): their common
    scale is what no drive determines; the last is the one the others' ratios are stated over."""
    lengths = length_params(model)
    if sensor is None or not sensor.lengths_unseen or not any(n in lengths for n in names):
        return ()
    return lengths


def ratios(lengths: Sequence[str], values: Mapping[str, float]) -> str:
    """Each length over the last of ``lengths`` at ``values``, in words."""
    last = lengths[-1]
    return ", ".join(f"{n}/{last} = {values[n] / values[last]:.6g}" for n in lengths[:-1] if values[last])


def way_out(
    names: Sequence[str],
    model: KinematicModel,
    layout: Layout,
    sensor: Sensor | None = None,
    values: Mapping[str, float] | None = None,
    turned_both_ways: bool = False,
) -> str:
    """What lets a drive determine the parameters ``names`` (of ``layout``) that trade off on this
    one, in words (``sensor``: the reference, when it may be what leaves them free; ``values``: an
    estimate whose ratios it then states; ``turned_both_ways``: the drive already turns both ways,
    so turning more the same way is no advice)."""
    names = list(dict.fromkeys(names))
    if lengths := unseen_lengths(names, model, sensor):
        # With another parameter loose beside the lengths (a tricycle's steering gain on a drive of
        # small steering angles), the ratios trade with it too: values at this point would be a guess.
        others = [n for n in names if n in model.kinematic_params and n not in lengths]
        stated = values and not others and all(n in values for n in lengths)
        said = f" ({ratios(lengths, values)})" if stated and values else ""
        what = (
            f"no drive determines the scale of {', '.join(lengths)}, and on this one {', '.join(others)} "
            "trade(s) with their ratios too (no ratio is stated)"
            if others
            else f"only the ratios of {', '.join(lengths)} are determined{said}, not their scale"
        )
        return (
            f"{sensor.lengths_unseen if sensor else ''}: {what}; next: give one as measured (known: "
            f"{{{lengths[-1]}: <metres>}}), or {sensor.lengths_from if sensor else 'measure a distance'}"
        )
    if any(layout.in_block(n, CLOCK) for n in names):
        return (
            "next: give the lag (alignment.tracker_lag: <seconds>, from how the clocks are synchronised), "
            "or record a drive whose wheel speeds change independently of each other (starts and stops, "
            "turns of several radii both ways), which a time offset cannot imitate"
        )
    turning = [n for n in names if n in model.turning_params or n in ("sensor_x", "sensor_y")]
    if turning and turned_both_ways:
        return (
            f"next: the drive turns both ways, yet it leaves {', '.join(names)} loose: hold one at a "
            f"measured value (known: {{{turning[0]}: <value>}}), or add turns that tell them apart (tighter "
            "ones, at other speeds)"
        )
    if turning:
        return "next: drive turns in both directions (S-curves, circles each way) and fit again"
    held = next((n for n in names), "")
    return (
        f"next: hold one of them at a measured value (known: {{{held}: <value>}}), or drive so that they act "
        f"differently ({model.turning_note or 'other speeds and turns'})"
    )


def verdict(run: CalibrationRun, model: KinematicModel, hint: str = "") -> Verdict:
    """The run's verdict and why (see the module's rules); ``hint``: what the data source says of
    a mirror image's likely cause (e.g. the joints' order it was given)."""
    undetermined = _undetermined(run, model, hint)
    solver = run.chosen_solver()
    if undetermined is not None:
        return undetermined
    assert solver is not None  # no converged solver is not determined
    said = gain(run, solver)
    unusable = _unusable(run)
    if unusable:
        return Verdict(NOT_USABLE, tuple(unusable), gain=said)
    found = caveats(run, solver, model)
    if found:
        return Verdict(CAVEATS, tuple(found), gain=said, concerns=concerns(run, solver, model))
    reasons = [f"{solver} converged", "every parameter determined to the precision a calibration needs"]
    if len([s for s in run.reports if run.reports[s].result.converged]) > 1:
        reasons.append("the solvers agree")
    if run.checks.start is not None:
        reasons.append(run.checks.start.words())
    return Verdict(GOOD, tuple(reasons), gain=said)
