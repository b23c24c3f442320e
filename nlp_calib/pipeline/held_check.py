"""The ``held`` plug-in check: does a value the fit holds move what it estimates?

A value held (a parameter under ``known:``, one the layout holds because the drive cannot determine
it, a tracker lag given as a number) enters the fit as exact: no σ the data give carries its error.
Where the estimates depend on it strongly, a held value a little off moves them by many of those σ,
and a run would hand off a wrong value with a small σ (on a drive whose wheels turn at 2·cos t and 2·sin t, a
lag given as 0 that is 40 ms: a wheel radius 4 % and 10⁵σ off, ``tests/test_held.py``). For each
held value the check measures the fit's linear response of every free parameter,
``∂x̂/∂h = −H⁻¹·∂g/∂h`` (``H``, ``g``: the fit's normal equations at its estimate), by a central
difference of ``g`` over the held value's plausible error either side:

* a time offset: one record interval of the log (a clock offset is rarely known better without a
  synchronisation). A lag given as a number is no parameter of the problem: the encoders are
  re-sampled that interval earlier and later, the same windows evaluated on them; a lag held in the
  problem (``known:``) moves its clock correction;
* any other: the precision a calibration needs of it (its layout's, at its value).

Speeds integrated into positions (``form: speeds``, a bag's joints with only velocities) are
read as samples at their stamps (trapezoids); a speed column does not say whether its value is
that, the mean over the interval before, or a rate held over the interval after (a controller's
command, a simulator's step): each reads the motion half an interval apart, and where the rate
jumps between intervals the trapezoids' positions err by |Δω|·dt/2. That reading is held as a
value too (:data:`SPEEDS`, half an interval either way: the estimate's move between the readings).

A steer angle read at each record (an absolute encoder) is turned into each interval's by the
two readings' mean (``steering_sample: mean``) or the angle its travel saw (``travel``: speed and
angle linear over it); the motion follows the angle weighted by the distance travelled, which
neither reading gives exactly where the drive speeds up or slows down while it steers (off and into
stops). That reading is held as a value too (:data:`STEERING`): the estimate's move between the
two readings, whichever the scenario fits with.

Counts re-sampled between records (at a lag that is no whole number of intervals) are
interpolated linearly, which reads a rate that changes inside the interval (a start from rest:
the speed rises within one interval) off by up to ``f(1 − f)·h·|Δv|`` (``f``: where the reading
falls, ``h``: the interval, ``Δv``: the rate after it less the rate before), by ``f(1 − f)/2·h·Δv``
on average over where the change lies, always on the side of the change. No interpolation of the
readings sees where it lies, and such windows are where the lag's information is. That reading is
held as a value too (:data:`RESAMPLED`): the time offsets' whole move from the counts as
interpolated to each less that expected error (:func:`~nlp_calib.logs.resample.kink_error`),
taken whole, not as independent noise (every start puts its counts off on one side); a change
spread evenly over the intervals around it is read off by half of it, so the move is an upper
bound there. The other parameters' moves are not held against them (:func:`_own`).

A lag the fit pinned on the edge of its search (the data put it there or beyond, with no σ), or
one the drive does not determine (held where its fits settled), is held there too: moved one
record interval (beyond the edge), the others following it as the fit's normal
equations say (``−H_oo⁻¹·H_o,lag``), so what it leaves wrong is said and kept from the hand-off.

Each free parameter's shifts over the held values enter its σ to believe in quadrature
(``std_held``, as the slip's σ does): a value moved within the precision it needs is still off by
that much. A parameter moved by more than its σ (without them) and the precision a calibration needs
of it (a shift within the needed precision changes no use of the value; the slip check's rule) is
a caveat concerning it (so no hand-off file writes it as calibrated), naming the
held value, the shift in its unit and in σ, and what to do: free the value, or give it to within
the error that moves no parameter beyond both. A value the user gives under ``known:`` other than a
time offset is taken as exact (:func:`declared`): what it would move is said, not held against.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.pipeline.fit import Fit
from nlp_calib.problem.blocks import by_definition
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, CheckResult
from nlp_calib.results.layout import CLOCK, KNOWN
from nlp_calib.solvers import ProblemEvaluator

NAME = "held"
#: What the lag given as a number is called in the check's words and its record.
LAG = "alignment.tracker_lag"
#: The plausible errors' rules, as the record states them.
RECORD_INTERVAL = "one record interval"
PINNED = "one record interval beyond the edge of alignment.search it is pinned on"
LOOSE = "one record interval from where the fits settled (the drive does not determine the lag)"
NEEDED = "the precision a calibration needs of it"
#: How speeds integrated into positions are read (held as a value; its error, half an interval).
SPEEDS = "dataset.form: speeds"
HALF_INTERVAL = "each speed the rate held over the interval after its stamp, or the mean over the one before"
#: How each interval's steer angle is read from its two readings (held as a value; its error, the
#: move between the readings' mean and the angle the interval's travel saw).
STEERING = "residual.steering_sample"
READINGS = "each interval's steer angle the one its travel saw, or its two readings' mean"
#: How readings re-sampled between records are read (held as a value; its error, the move from the
#: readings as interpolated to each less its interpolation's expected error).
RESAMPLED = "readings re-sampled between records"
KINKS = "each less its interpolation's expected error where the rate changes inside its interval"


@dataclass(frozen=True)
class Response:
    """One held value's ``error`` (by ``rule``, in ``unit``) and what it moves each free parameter
    by (``shift``, their units), in their σ to believe (``in_sigma``), and the precision a
    calibration needs of each (``needed``, their units)."""

    name: str
    value: float
    error: float
    rule: str
    unit: str
    shift: Mapping[str, float]
    in_sigma: Mapping[str, float]
    needed: Mapping[str, float]

    def beyond_sigma(self) -> tuple[str, ...]:
        """The parameters the error moves by more than their σ to believe."""
        return tuple(n for n, z in self.in_sigma.items() if abs(z) > 1.0)

    def moved(self) -> tuple[str, ...]:
        """The parameters the error moves beyond their σ to believe and the precision a calibration
        needs of them both: a shift within the needed precision changes no use of the value."""
        return tuple(n for n in self.beyond_sigma() if abs(self.shift[n]) > self.needed[n])

    def within(self) -> float:
        """The error of the held value that moves no parameter beyond both its σ and the precision
        it needs (the held value's unit)."""
        ratios = [
            abs(self.shift[n]) / max(abs(self.shift[n] / self.in_sigma[n]), self.needed[n])
            for n in self.moved()
        ]
        return self.error / max(ratios) if ratios else float("inf")

    def as_dict(self) -> dict[str, object]:
        return {
            "value": self.value,
            "error": self.error,
            "rule": self.rule,
            "unit": self.unit,
            "shift": dict(self.shift),
            "shift_in_sigma": {n: (z if np.isfinite(z) else None) for n, z in self.in_sigma.items()},
            "needed": dict(self.needed),
            "beyond_sigma": list(self.beyond_sigma()),
            "moved": list(self.moved()),
        }


def step(H: np.ndarray, plus: np.ndarray, minus: np.ndarray) -> np.ndarray | None:
    """The fit's move for a held value one error up: ``−H⁻¹·(g₊ − g₋)/2`` from the gradients one
    error either side (None: ``H`` singular)."""
    try:
        return np.linalg.solve(H, -0.5 * (plus - minus))
    except np.linalg.LinAlgError:
        return None


def _at_fixed(ev: ProblemEvaluator, x: np.ndarray, x_fixed: np.ndarray) -> np.ndarray:
    """The gradient of the normal equations at ``x`` with the held values ``x_fixed`` (an evaluator
    of its own on the same windows: the fit's stays as it is)."""
    other = ProblemEvaluator(
        ev.fns, ev.data, x_fixed=x_fixed, omega=ev.omega, delta=ev.delta, priors=ev.priors, backend=ev.backend
    )
    g = other.normal_equations(x).g
    other.release()
    return np.asarray(g, dtype=float)


def _at_inputs(ev: ProblemEvaluator, x: np.ndarray, inputs: np.ndarray) -> np.ndarray:
    """The gradient at ``x`` on the same windows with other interval ``inputs`` (the fit's own put
    back after)."""
    kept = ev.data.inputs
    try:
        ev.set_inputs(inputs)
        return np.asarray(ev.normal_equations(x).g, dtype=float)
    finally:
        ev.set_inputs(kept)


def record_interval(fit: Fit) -> float:
    """The median time between the fitted logs' records (s; NaN: not known)."""
    steps = [np.diff(np.asarray(lg.time_s, dtype=float)) for lg in fit.data.logs]
    steps = [s for s in steps if s.size]
    return float(np.median(np.concatenate(steps))) if steps else float("nan")


def _fixed_errors(run: CalibrationRun, fit: Fit) -> list[tuple[float, str]]:
    """Each held parameter's plausible error and its rule, in the fit's order of held values: a
    time offset's, one record interval; any other's, the precision a calibration needs of it."""
    fns, layout = fit.fns, run.scenario.layout
    out: list[tuple[float, str]] = []
    for name, value in zip(fns.fixed, map(float, fit.evaluator.x_fixed)):
        if fns.layout.in_block(name, CLOCK):
            out.append((record_interval(fit), RECORD_INTERVAL))
            continue
        p = layout.param(name) if name in layout else fns.layout.param(name)
        # A block's reference value (what the others are stated against) has no error to move by.
        out.append(
            (float("nan"), NEEDED) if by_definition(p.block, p.key, p.log) else (p.needed(value), NEEDED)
        )
    return out


def responses(run: CalibrationRun, fit: Fit) -> list[Response]:
    """Each held value's response (see the module's docstring), at the chosen solver's estimate."""
    solver = run.chosen_solver()
    if solver is None:
        return []
    report = run.reports[solver]
    x = np.asarray(report.result.x, dtype=float)
    ev, fns = fit.evaluator, fit.fns
    ne = ev.normal_equations(x)
    H, g = ne.H, np.asarray(ne.g, dtype=float)
    params = np.asarray(ev.params(x), dtype=float)
    std, units = run.std(solver), run.scenario.units
    free = [n for n in fns.free if n in report.uncertainty.free]
    estimate = report.result.param_dict()
    needed = run.scenario.layout.needed({n: estimate[n] for n in free})
    found: list[Response] = []

    def response(name: str, value: float, error: tuple[float, str], move: np.ndarray | None) -> None:
        if move is None or not np.all(np.isfinite(move)):
            return
        moved = dict(zip(fns.names, np.asarray(ev.params(ev.boxplus(x, move)), dtype=float) - params))
        shift = {n: float(moved[n]) for n in free}
        z = {n: shift[n] / std[n] if std.get(n, 0.0) > 0 else float("nan") for n in free}
        unit = {SPEEDS: "interval", STEERING: "reading", RESAMPLED: "reading"}.get(name) or units.get(
            name, "s"
        )
        found.append(Response(name, value, error[0], error[1], unit, shift, z, needed))

    base = np.asarray(ev.x_fixed, dtype=float)
    for i, (name, error) in enumerate(zip(fns.fixed, _fixed_errors(run, fit))):
        if not np.isfinite(error[0]) or error[0] <= 0:
            continue
        up, down = base.copy(), base.copy()
        up[i], down[i] = base[i] + error[0], base[i] - error[0]
        response(name, float(base[i]), error, step(H, _at_fixed(ev, x, up), _at_fixed(ev, x, down)))
    if fit.given_lag is not None and np.isfinite(d := record_interval(fit)):
        grads = (_at_inputs(ev, x, fit.given_lag(d)), _at_inputs(ev, x, fit.given_lag(-d)))
        response(LAG, held_lag(run, fit), (d, RECORD_INTERVAL), step(H, *grads))
    # The re-sampled counts' reading is held against the time offsets alone (:func:`_own`): with
    # none determined (given, or pinned with no σ) there is nothing it is held against.
    clocks = any(fns.layout.in_block(n, CLOCK) and n not in run.pinned() for n in free)
    for name, error, move in _readings(fit, x, H, g, clocks):
        response(name, 0.0, error, move)
    d = record_interval(fit)
    for name in (n for n in run.pinned() if n in free and np.isfinite(d)):
        move = pinned_step(H, fns.free.index(name))
        if move is None:
            continue
        # The move's coordinates to the lag's seconds: one record interval of it.
        lag = (np.asarray(ev.params(ev.boxplus(x, move)), dtype=float) - params)[fns.names.index(name)]
        if abs(lag) > 0:
            response(name, estimate[name], (d, _pinned_rule(run, name)), move * d / lag)
    return [
        _own(replace(r, shift=_without(r.shift, r.name), in_sigma=_without(r.in_sigma, r.name)), fit)
        for r in found
    ]


def _own(r: Response, fit: Fit) -> Response:
    """``r`` with only what it is held against: the re-sampled counts' move, the time offsets'
    alone (what the lags' coverage measured it against); the others' moves, not measured against
    what re-sampling does to them, are no error of theirs (on a 0.2 mm skid steer one moved 3× its
    σ where the fit lay 1.2σ off, docs/scenarios.md)."""
    if r.name != RESAMPLED:
        return r
    clocks = [n for n in r.shift if fit.fns.layout.in_block(n, CLOCK)]
    return replace(r, shift={n: r.shift[n] for n in clocks}, in_sigma={n: r.in_sigma[n] for n in clocks})


def _readings(
    fit: Fit, x: np.ndarray, H: np.ndarray, g: np.ndarray, clocks: bool
) -> list[tuple[str, tuple[float, str], np.ndarray | None]]:
    """How the readings are read, each held as a value: its name, its error and rule, and the fit's
    move over that error (``H``, ``g``: the normal equations at ``x``, the readings as fitted;
    ``clocks``: whether a time offset is determined, the one thing re-sampled counts are held
    against)."""
    ev, out = fit.evaluator, []
    if fit.speeds_read is not None:
        # The trapezoids are the two readings' mean: the central difference of the two.
        grads = (_at_inputs(ev, x, fit.speeds_read(1.0)), _at_inputs(ev, x, fit.speeds_read(-1.0)))
        out.append((SPEEDS, (0.5, HALF_INTERVAL), step(H, *grads)))
    if fit.steering_read is not None:
        # The whole move from one reading to the other (step's is half the difference).
        grads = (_at_inputs(ev, x, fit.steering_read("travel")), _at_inputs(ev, x, fit.steering_read("mean")))
        half = step(H, *grads)
        out.append((STEERING, (1.0, READINGS), None if half is None else 2.0 * half))
    if fit.kinked_read is not None and clocks:
        # The whole move from the readings as interpolated (the fit's own gradient) to the other.
        half = step(H, _at_inputs(ev, x, fit.kinked_read()), g)
        out.append((RESAMPLED, (1.0, KINKS), None if half is None else 2.0 * half))
    return out


def _without(values: Mapping[str, float], name: str) -> dict[str, float]:
    """``values`` without the held value's own entry (a lag pinned in the fit moves itself)."""
    return {n: v for n, v in values.items() if n != name}


def _pinned_rule(run: CalibrationRun, name: str) -> str:
    """The rule of pinned lag ``name``'s error: a lag the drive does not determine is held where its
    fits settled, any other on its search's edge (a joint fit's: its own log's estimate)."""
    est = run.lag_estimates().get(name)
    return LOOSE if est is not None and est.loose else PINNED


def pinned_step(H: np.ndarray, i: int) -> np.ndarray | None:
    """The fit's move with its coordinate ``i`` (a lag pinned on its search's edge: held there)
    moved by one unit and the others following it, ``−H_oo⁻¹·H_oi`` (None: singular)."""
    others = [j for j in range(H.shape[0]) if j != i]
    move = np.zeros(H.shape[0])
    move[i] = 1.0
    try:
        move[others] = np.linalg.solve(H[np.ix_(others, others)], -H[others, i])
    except np.linalg.LinAlgError:
        return None
    return move


def held_lag(run: CalibrationRun, fit: Fit) -> float:
    """The lag given as a number that the fit holds: the run's; over several logs, the one every
    log holds (NaN where they hold different ones). A check compares it with what the stored
    calibration held (:func:`~nlp_calib.analysis.drift.common_held`): a joint fit's must be a value."""
    if np.isfinite(run.data.tracker_lag_s):
        return float(run.data.tracker_lag_s)
    lags = {e.alignment.tracker_lag for e in fit.problem.binder.scenario.data.logs}
    return float(lags.pop()) if len(lags) == 1 else float("nan")


def _amount(value: float, unit: str) -> str:
    """``value`` in ``unit`` (a time in ms; a ratio bare; a share of the joints' interval)."""
    if unit == "s":
        return f"{1e3 * value:.3g} ms"
    if unit == "interval":
        return f"{value:.3g} of an interval"
    if unit == "reading":
        return "the other reading" if value else "the scenario's reading"
    return f"{value:.4g}" if unit in ("", "1") else f"{value:.4g} {unit}"


def _what_to_do(r: Response, given: bool) -> str:
    """How to leave the parameters ``r`` moves with a σ that holds (``given``: under known:)."""
    within = f"give it measured to within {_amount(r.within(), r.unit)}"
    if r.rule == PINNED:
        return f"widen alignment.search so that the lag is fitted inside it, or {within}"
    if r.rule == LOOSE:
        return f"drive with starts, stops and turns of different lengths, or {within}"
    if r.name == LAG:
        return f"fit it (alignment.tracker_lag: auto), or {within}"
    if r.name == SPEEDS:
        return "give the joints' angles (form: positions) or their increments per interval (form: increments)"
    if r.name == STEERING:
        return "record faster (the angle and the speed then change less over an interval)"
    if r.name == RESAMPLED:
        return "record the encoders faster (a rate then changes less inside an interval)"
    if not given:
        return within
    return f"free it (leave it out of known:, or give it under priors: with its σ), or {within}"


def concern(r: Response, name: str, run: CalibrationRun) -> str:
    """Why parameter ``name`` is not believed: the held value of ``r`` moves it beyond its σ."""
    unit, layout = run.scenario.units.get(name, ""), run.scenario.layout
    given = r.name in layout and layout.param(r.name).status == KNOWN
    if r.name == SPEEDS:
        return (
            f"{name} rests on how the speeds are read ({SPEEDS}: each a sample at its stamp, integrated "
            f"by trapezoids): read as the rate held over the interval after each stamp, it moves {name} "
            f"by {r.shift[name]:+.3g} {unit}, as the mean over the interval before by {-r.shift[name]:+.3g} "
            f"{unit} ({abs(r.in_sigma[name]):.1f}× the σ the data give; a calibration needs "
            f"{r.needed[name]:.2g} {unit}); {_what_to_do(r, given)}"
        )
    if r.name == STEERING:
        return (
            f"{name} rests on how each interval's steer angle is read ({STEERING}: the motion follows the "
            f"angle weighted by the distance travelled): read as the angle the travel saw instead of the "
            f"two readings' mean, it moves {name} by {r.shift[name]:+.3g} {unit} "
            f"({abs(r.in_sigma[name]):.1f}× the σ the data give; a calibration needs "
            f"{r.needed[name]:.2g} {unit}); {_what_to_do(r, given)}"
        )
    if r.name == RESAMPLED:
        return (
            f"{name} rests on how {RESAMPLED} are read (linearly, where a rate that changes inside an "
            f"interval is read off by up to a quarter of the change over it): {KINKS}, it moves {name} by "
            f"{r.shift[name]:+.3g} {unit} ({abs(r.in_sigma[name]):.1f}× the σ the data give; a calibration "
            f"needs {r.needed[name]:.2g} {unit}); {_what_to_do(r, given)}"
        )
    return (
        f"{name} rests on {r.name} held at {_amount(r.value, r.unit)}: off by {_amount(r.error, r.unit)} "
        f"({r.rule}), it moves {name} by {r.shift[name]:+.3g} {unit} ({r.in_sigma[name]:+.1f}× the σ the "
        f"data give; a calibration needs {r.needed[name]:.2g} {unit}); {_what_to_do(r, given)}"
    )


def fine_words(found: list[Response], units: Mapping[str, str]) -> str:
    """What a check that found no parameter moved says: each held value's error, and the largest
    shift in σ, with the precision that parameter needs where the shift is beyond its σ."""
    said = ", ".join(f"{r.name} by {_amount(r.error, r.unit)}" for r in found)
    shifts = [(abs(z), r, n) for r in found for n, z in r.in_sigma.items() if np.isfinite(z)]
    if not shifts:
        return f"held values off ({said}) move no parameter"
    z, r, n = max(shifts, key=lambda t: t[0])
    most = f"at most {z:.2g}σ ({n}, by {r.name})"
    if z > 1.0:
        unit = units.get(n, "")
        most += f": {abs(r.shift[n]):.2g} {unit}, within the {r.needed[n]:.2g} {unit} a calibration needs"
    return f"held values off ({said}) move no parameter beyond its σ and the precision it needs: {most}"


def declared(r: Response, run: CalibrationRun) -> bool:
    """Whether ``r`` is a value the user gives under ``known:`` other than a time offset: taken as
    exact (its response is said, not held against the parameters it moves). A time offset given
    is rarely known to a record interval without a synchronisation, and a value the layout holds
    because the drive cannot determine it is a start, not a measurement: both are held against."""
    layout = run.scenario.layout
    return r.rule != RECORD_INTERVAL and r.name in layout and layout.param(r.name).status == KNOWN


def rests_on(found: list[Response], units: Mapping[str, str]) -> str:
    """What the declared values (:func:`declared`) that would move a parameter beyond both its σ
    and its needed precision move: said beside the check's words ("" where none)."""
    said = []
    for r in found:
        for n in r.moved():
            unit = units.get(n, "")
            said.append(
                f"{n} rests on {r.name} given as {_amount(r.value, r.unit)} and taken as exact: off by "
                f"{_amount(r.error, r.unit)} ({r.rule}) it would move {n} by {r.shift[n]:+.3g} {unit} "
                f"({r.in_sigma[n]:+.1f}σ)"
            )
    return "; ".join(said) + ("; a value measured to a σ goes under priors: instead" if said else "")


def std_held(found: list[Response], run: CalibrationRun) -> dict[str, dict[str, float]]:
    """``std_held``: each free parameter's σ of the held values (their shifts over their plausible
    errors, in quadrature; values given under ``known:`` other than a time offset count as exact),
    added to its σ to believe as the slip's is (:meth:`~nlp_calib.results.run.Checks.shifts`):
    a value moved by a held one within the precision it needs is still off by that shift."""
    counted = [r for r in found if not declared(r, run)]
    names = dict.fromkeys(n for r in counted for n in r.shift)
    std = {n: float(np.sqrt(sum(r.shift[n] ** 2 for r in counted if n in r.shift))) for n in names}
    std = {n: s for n, s in std.items() if np.isfinite(s) and s > 0}
    # The values held, so that a check knows whether its refit holds the same ones.
    values = {r.name: r.value for r in counted if np.isfinite(r.value)}
    return {"std_held": std, "held_values": values} if std else {}


def check(run: CalibrationRun, fit: Fit | None) -> CheckResult | None:
    """Each held value's error moved into the free parameters, against their σ to believe and the
    precision they need (None: nothing held, no fit at hand or none converged)."""
    found = [] if fit is None else responses(run, fit)
    if not found:
        return None
    record = {"held": {r.name: r.as_dict() for r in found}, **std_held(found, run)}
    exact = rests_on([r for r in found if declared(r, run)], run.scenario.units)
    concerns: dict[str, str] = {}
    for r in found:
        for name in () if declared(r, run) else r.moved():
            said = concern(r, name, run)
            concerns[name] = f"{concerns[name]}; {said}" if name in concerns else said
    if not concerns:
        others = [r for r in found if not (declared(r, run) and r.moved())]
        words = fine_words(others, run.scenario.units) if others else ""
        return CheckResult(NAME, FINE, "; ".join(w for w in (words, exact) if w), record=record)
    held = ", ".join(r.name for r in found if r.moved() and not declared(r, run))
    first, *rest = concerns.values()
    return CheckResult(
        NAME,
        CAVEAT,
        f"{held} held: {', '.join(concerns)} move beyond their σ and the precision they need with its "
        "plausible error" + (f"; {exact}" if exact else ""),
        caveat=first,
        caveats=tuple(rest),
        concerns=concerns,
        how=(
            "Each held value is moved by its plausible error (a time offset: one record interval; any "
            "other: the precision a calibration needs of it) and the fit's linear response taken from "
            "its normal equations."
        ),
        record=record,
    )
