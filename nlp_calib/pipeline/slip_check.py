"""The ``slip`` plug-in check: does the calibration hold at every speed a car drove its bends at?

A car's tyres carry a bend by slip angles: its rear axle slides out of the bend by an angle about
proportional to the lateral acceleration (the linear single-track, "understeer", model: a few
mrad per m/s² on a road car), which the kinematic models lack. At speed ``v`` on curvature ``κ``
that slip moves the rear axle sideways at ``c·v³·κ``, which a sensor ahead of the axle by ``x``
explains as ``x·v·κ`` wherever the speed varies little: the fit moves ``sensor_x`` by ``c·v²``
(0.8 m on a car at 14 m/s with 4 mrad per m/s²), and its σ, the spread of fits along the drive,
says nothing of a shift that every part of the drive shares.

What tells it is the speed: the drive's moving windows are put in :data:`BINS` bins by their own
mean speed, each bin's windows fitted on their own from the run's estimate, and each parameter's
fits regressed on the bins' speed squared (the slip's shift grows with ``v²``; a bin's speed is its
windows' weighed by their squared turn rate, as a lever arm's information is), each bin weighed by its own
information, the slope's σ from the fits' scatter about the line. A slope beyond :data:`T_LIMIT`
of its σ that moves the parameter over the speeds driven by more than the precision the
calibration needs means the model lacks what moves it: the run's value and its σ are not believed
and the parameter is said NOT DETERMINED (a caveat concerning it, so no hand-off file writes it as
calibrated), with its value at zero speed by the line (what a linear tyre model gives) and what to
do. A slope under the limit does not rule the slip out: each parameter's σ to believe takes
in what the line leaves open (:meth:`Lines.shift`; the rule and why in docs/models.md): the
distance from the drive's fit to the value at zero speed, with that value's σ. The check runs on
bases that cannot turn on the spot (cars: a turn on the spot has no lateral
load) whose drive reaches :data:`MIN_LATERAL` in its bends.

A window is binned by its mean speed, not by whether every record of it lies in one bin: a car that
brakes and accelerates within a window's half second would otherwise leave every bin nearly empty.
A bin of speeds is whichever stretches of the drive drove at that speed; a drive that changes its
speed slowly puts few stretches in each, and an error that varies along the drive (a wandering
tracker, one bend) then moves neighbouring bins together, which the scatter does not see: the
limit is set above the scatter's own 1-in-250 point for that. Pieces of the drive in time order
would be independent, but each drives at its own stretch's speed: they span less of the speeds
and hold fewer bends each, and tell the slip less often.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis.noise_rates import base_increments
from nlp_calib.models import KinematicModel
from nlp_calib.pipeline import validation
from nlp_calib.pipeline.fit import Fit
from nlp_calib.problem import ProblemFunctions, ResidualData
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, CheckResult
from nlp_calib.solvers.evaluation import is_singular

NAME = "slip"
#: The lateral acceleration (m/s²) the drive's bends must reach, at the 90th percentile of its moving
#: intervals, for the check to run: below it a road tyre's slip angle stays within a few mrad.
MIN_LATERAL = 1.0
#: The slowest bin's speed must be under this share of the fastest's: the slip's shift grows with
#: the speed squared, so a drive at nearly one speed cannot tell it.
SPEED_RATIO = 0.85
#: Bins of speed fitted on their own, and how many of them must be fitted.
BINS = 16
MIN_BINS = 10
#: A slope beyond this many of its σ is a finding: Student's t with 14 degrees of freedom passes
#: it by chance one time in 800 (3.4: one in 250), with room for neighbouring bins that share an
#: error (see the module's docstring).
T_LIMIT = 4.0
#: The windows a bin needs per free parameter to be fitted on its own.
WINDOWS_PER_FREE = 10
#: The solver whose estimate the bins are fitted from.
SOLVER = "gauss_newton"


def interval_motion(
    fns: ProblemFunctions, data: ResidualData, params: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each interval's base speed (m/s) and turn rate (rad/s) with ``params`` (the full vector;
    NaN across logs and where the records' stamps do not space it)."""
    steps = base_increments(fns, params, data.inputs, np.zeros(data.inputs.shape[0]))[0]
    dt = interval_durations(data)
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where(dt > 0, np.hypot(steps[:, 0], steps[:, 1]) / dt, np.nan)
        rate = np.where(dt > 0, steps[:, 2] / dt, np.nan)
    return speed, rate


def window_motion(data: ResidualData, speed: np.ndarray, rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each window's mean base speed (m/s) and turn rate (rad/s) over its intervals (of
    :func:`interval_motion`), their durations weighing them; NaN where an interval is not timed."""
    dt = interval_durations(data)
    timed = np.isfinite(dt) & np.isfinite(speed) & np.isfinite(rate)
    untimed = data.interval_counts(~timed) > 0

    def over(values: np.ndarray) -> np.ndarray:
        c = np.concatenate([[0.0], np.cumsum(np.where(timed, values, 0.0))])
        return c[data.stops] - c[data.starts]

    with np.errstate(divide="ignore", invalid="ignore"):
        duration = over(dt)
        mean_speed, mean_rate = over(speed * dt) / duration, over(rate * dt) / duration
    bad = untimed | ~(duration > 0)
    return np.where(bad, np.nan, mean_speed), np.where(bad, np.nan, mean_rate)


def interval_durations(data: ResidualData) -> np.ndarray:
    """Each interval's duration (s) from its log's stamps; NaN between logs (and everywhere when
    the logs' records are not the windows')."""
    parts = [np.append(np.diff(np.asarray(lg.time_s, dtype=float)), np.nan) for lg in data.logs]
    dt = np.concatenate(parts)[:-1] if parts else np.zeros(0)
    if dt.size != data.n_records - 1:
        return np.full(data.n_records - 1, np.nan)
    return dt


def lateral(speed: np.ndarray, rate: np.ndarray) -> float:
    """The lateral acceleration (m/s²) the drive's bends reach: the 90th percentile of its moving
    windows' (NaN: none moves)."""
    moving = np.isfinite(speed) & np.isfinite(rate) & (speed > 0.0)
    return float(np.percentile(np.abs(speed * rate)[moving], 90)) if moving.any() else float("nan")


def speed_bins(speed: np.ndarray, rate: np.ndarray) -> tuple[np.ndarray, np.ndarray] | str:
    """Per window (its mean ``speed`` and turn ``rate``) its bin of speed (0 to :data:`BINS` − 1,
    slowest first, split at the moving windows' quantiles; −1 standing or not timed) and each bin's
    speed squared, its windows' weighed by their squared turn rate (a straight bin's: their mean);
    or why the drive cannot be binned: too few moving windows, bends under :data:`MIN_LATERAL`, or
    speeds too alike to split or to tell a slip by (the slowest bin over :data:`SPEED_RATIO` of the
    fastest)."""
    moving = np.isfinite(speed) & np.isfinite(rate) & (speed > 0.0)
    if moving.sum() < 4 * BINS:
        return f"it has {int(moving.sum())} timed moving windows ({4 * BINS} needed)"
    if (load := lateral(speed, rate)) < MIN_LATERAL:
        return (
            f"its bends reach {load:.2g} m/s² of lateral acceleration (under {MIN_LATERAL:g} m/s², "
            "tyres barely slide)"
        )
    edges = np.quantile(speed[moving], np.linspace(0.0, 1.0, BINS + 1)[1:-1])
    label = np.where(moving, np.searchsorted(edges, np.where(moving, speed, 0.0)), -1)
    if np.any(np.bincount(label[moving], minlength=BINS) == 0):
        return f"its speeds are too alike to split into {BINS} bins"
    squared = np.empty(BINS)
    for j in range(BINS):
        v2, w = speed[label == j] ** 2, rate[label == j] ** 2
        squared[j] = np.sum(w * v2) / np.sum(w) if np.sum(w) > 0 else np.mean(v2)
    lo, hi = np.sqrt(squared.min()), np.sqrt(squared.max())
    if not lo < SPEED_RATIO * hi:
        return (
            f"its speeds are too alike to tell a slip from a lever arm (its bends at {lo:.3g} to "
            f"{hi:.3g} m/s; the slowest must be under {SPEED_RATIO:.0%} of the fastest)"
        )
    return label, squared


def bin_fits(
    run: CalibrationRun, model: KinematicModel, fit: Fit, label: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each bin's own fit ``(BINS, n_params)`` in canonical form, from the run's estimate, what the
    bin cannot determine held there, and each value's white-noise variance (its bin's information
    alone: what weighs the bins against each other); NaN for a held parameter and for a bin whose
    fit did not converge or had too few windows. A bin's windows are those ``label`` gives its
    number. Every free parameter is fitted at once, as the run fits them: fitted one at a time, each
    takes up what the others would (a gain moves with a slipping sensor's lever arm), and
    a drive whose few stretches of one speed share an error is more often taken for a slip."""
    x = np.asarray(run.reports[SOLVER].result.x, dtype=float)
    binder, data, fns = fit.problem.binder, fit.data, fit.fns
    at = [fns.names.index(f) for f in fns.free]
    fits, variance = np.full((BINS, len(fns.names)), np.nan), np.full((BINS, len(fns.names)), np.nan)

    def own(j: int) -> None:
        part = label == j
        inputs = data.inputs[:, data.intervals_of(np.flatnonzero(part))]
        hold = [n for n in model.undetermined(inputs) if n in fns.free]
        params, converged, n, ev = validation.refit_without(
            validation.holding(binder, x, hold), data, ~part, x
        )
        if ev is None:
            return
        H = ev.normal_equations(params[at]).H
        ev.release()
        if converged and n >= WINDOWS_PER_FREE * fns.n_free and not is_singular(H):
            free = [i for i, f in zip(at, fns.free) if f not in hold]
            fits[j, free] = fit.canonical_params(params)[free]
            variance[j, at] = np.diag(np.linalg.inv(H))

    validation.on_threads(own, list(range(BINS)))
    return fits, variance


@dataclass(frozen=True)
class Lines:
    """Each parameter's weighted line over the speed squared: its value at zero speed and that
    value's σ, its slope (per (m/s)²) and the slope's σ, on ``dof`` degrees of freedom, the
    ``lever``: the bins' speed squared weighed as the line weighs them, and the whole drive's
    fit ``drive`` (NaN: too few bins fitted, or no drive's fit given)."""

    at_zero: np.ndarray
    std_at_zero: np.ndarray
    slope: np.ndarray
    std: np.ndarray
    dof: np.ndarray
    lever: np.ndarray
    drive: np.ndarray

    def shift(self) -> np.ndarray:
        """The σ the slip adds to each parameter's σ to believe: the distance from the drive's fit
        to the value at zero speed, where a slip the line allows puts the truth, with that value's
        σ, ``√(max((drive − at_zero)², (lever·slope)²) + σ_at_zero²)``. The distance is the larger
        of the fit's own and the line's (``lever·slope``): the drive mixes its speeds, and what a
        lever arm fixed over them cannot take of a shift growing with the speed squared another
        parameter takes (a gain of the turn), off every bin's line; a fit near the value at zero
        speed where the line is steep is the noise of one of them."""
        distance = np.fmax(np.abs(self.drive - self.at_zero), np.abs(self.lever * self.slope))
        return np.hypot(distance, self.std_at_zero)


def slopes(fits: np.ndarray, variance: np.ndarray, squared: np.ndarray, drive: np.ndarray) -> Lines:
    """Each parameter's line through its ``fits`` (one row per bin; NaN left out) over the bins'
    speed ``squared``, each bin weighed by its information, the σ from the fits' weighted scatter
    about the line (the information sets only the bins' relative weights: what the bins truly
    differ by sets the scale); ``drive``: the whole drive's fit, in the fits' form."""
    ok = np.isfinite(fits) & np.isfinite(variance) & (variance > 0) & np.isfinite(squared)[:, None]
    w = np.where(ok, 1.0 / np.where(ok, variance, 1.0), 0.0)
    f, u = np.where(ok, fits, 0.0), np.where(ok, squared[:, None], 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        total = np.sum(w, axis=0)
        u_mean, f_mean = np.sum(w * u, axis=0) / total, np.sum(w * f, axis=0) / total
        spread = np.sum(w * (u - u_mean) ** 2, axis=0)
        slope = np.sum(w * (u - u_mean) * (f - f_mean), axis=0) / spread
        at_zero = f_mean - slope * u_mean
        dof = np.sum(ok, axis=0) - 2.0
        scale = np.sum(w * (f - (at_zero + u * slope)) ** 2, axis=0) / dof
        std_at_zero = np.sqrt(scale * (1.0 / total + u_mean**2 / spread))
        std = np.sqrt(scale / spread)
    few = dof < MIN_BINS - 2
    values = (at_zero, std_at_zero, slope, std, dof, u_mean, np.asarray(drive, dtype=float))
    return Lines(*(np.where(few, np.nan, v) for v in values))


@dataclass(frozen=True)
class SpeedLines:
    """Each parameter's fits on the bins of speed (``fits`` ``(BINS, n)``, canonical
    form) at the bins' ``speeds`` (m/s), their :class:`Lines` over the speed squared, each slope
    in its σ (``t``), which parameters move with the speed (indices) and the precision each needs."""

    names: tuple[str, ...]
    speeds: np.ndarray
    fits: np.ndarray
    lines: Lines
    t: np.ndarray
    moved: tuple[int, ...]
    needed: np.ndarray

    def slow_enough(self, i: int) -> float:
        """The speed (m/s) under which the line moves parameter ``i`` from its value at zero speed by
        less than the precision it needs: bends driven slower calibrate it."""
        return float(np.sqrt(self.needed[i] / abs(self.lines.slope[i])))

    def at(self, i: int, speed: float) -> float:
        """Parameter ``i`` at ``speed`` (m/s) by its line."""
        return float(self.lines.at_zero[i] + self.lines.slope[i] * speed**2)

    def as_dict(self) -> dict[str, object]:
        def by_name(values: np.ndarray) -> dict[str, float | None]:
            return {n: (float(v) if np.isfinite(v) else None) for n, v in zip(self.names, values)}

        def listed(values: np.ndarray) -> list[float | None]:
            return [float(v) if np.isfinite(v) else None for v in values]

        return {
            "speeds_mps": listed(self.speeds),
            "fits": {n: listed(self.fits[:, i]) for i, n in enumerate(self.names)},
            "slope_in_sigma": by_name(self.t),
            "slope": by_name(self.lines.slope),
            "at_zero_speed": by_name(self.lines.at_zero),
            "std_at_zero_speed": by_name(self.lines.std_at_zero),
            "lever_speed_squared": by_name(self.lines.lever),
            "std_slip": by_name(self.lines.shift()),
            "moved": [self.names[i] for i in self.moved],
            "made": True,
        }


@dataclass(frozen=True)
class NotMade:
    """Why the check could not be made on a base it is for, and the lateral acceleration (m/s²)
    the drive's bends reach (NaN: not known): at :data:`MIN_LATERAL` or more a slip is left open."""

    why: str
    load: float

    @property
    def open(self) -> bool:
        return not self.load < MIN_LATERAL


def _held(label: np.ndarray) -> str:
    """How many windows the bins of speed hold (a bin is fitted on its own windows)."""
    counts = np.bincount(label[label >= 0], minlength=BINS)
    return f": they hold {counts.min()} to {counts.max()} windows"


def measure(run: CalibrationRun, model: KinematicModel, fit: Fit) -> SpeedLines | NotMade | None:
    """The run's parameters on bins of speed against the speed squared; why they could not be
    made (:class:`NotMade`); None: no solver converged, or the base turns on the spot (no check)."""
    report = run.reports.get(SOLVER)
    chosen = SOLVER if report is not None and report.result.converged else run.chosen_solver()
    if chosen is None:
        return None
    at = np.asarray(run.reports[chosen].result.params, dtype=float)
    if model.reach(run.reports[chosen].result.param_dict()).spot_turns:
        return None
    motion = window_motion(fit.data, *interval_motion(fit.fns, fit.data, at))
    if report is None or chosen != SOLVER:
        said = "is not among the solvers" if report is None else "did not converge"
        return NotMade(
            f"its bins are refitted from {SOLVER}'s estimate, and {SOLVER} {said}", lateral(*motion)
        )
    params = report.result.param_dict()
    cut = speed_bins(*motion)
    if isinstance(cut, str):
        return NotMade(cut, lateral(*motion))
    fits, variance = bin_fits(run, model, fit, cut[0])
    lines = slopes(fits, variance, cut[1], fit.canonical_params(at))
    if not np.any(np.isfinite(lines.slope)):
        fitted, held = int(np.max(np.sum(np.isfinite(fits), axis=0))), _held(cut[0])
        why = (
            f"{fitted} of its {BINS} bins of speed could be fitted on their own ({MIN_BINS} needed; a bin "
            f"needs {WINDOWS_PER_FREE * fit.fns.n_free} windows, {WINDOWS_PER_FREE} a free parameter{held})"
        )
        return NotMade(why, lateral(*motion))
    names = tuple(fit.fns.names)
    needed = run.scenario.layout.needed({n: params[n] for n in names})
    span = np.max(cut[1]) - np.min(cut[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(lines.std > 0, lines.slope / lines.std, np.nan)
    # Beyond its scatter, and by more than a calibration needs over the speeds driven: a shift
    # within the needed precision changes no use of the value, however many σ.
    moved = tuple(
        i
        for i, n in enumerate(names)
        if n in report.uncertainty.free and abs(t[i]) > T_LIMIT and abs(lines.slope[i]) * span > needed[n]
    )
    precision = np.array([needed[n] for n in names], dtype=float)
    return SpeedLines(names, np.sqrt(cut[1]), fits, lines, t, moved, precision)


def check(run: CalibrationRun, model: KinematicModel | None, fit: Fit | None) -> CheckResult | None:
    """Each parameter's fits on bins of speed against the speed squared, or why they could not be
    made (None: the check does not apply, or the run is not at hand)."""
    found = None if model is None or fit is None else measure(run, model, fit)
    if found is None:
        return None
    if isinstance(found, NotMade):
        return not_made(found)
    names = found.names
    v = np.nanmin(found.speeds), np.nanmax(found.speeds)
    said = f"fits on {BINS} bins of speed at {v[0]:.3g} to {v[1]:.3g} m/s"
    if not found.moved:
        worst = int(np.argmax(np.abs(np.where(np.isfinite(found.t), found.t, 0.0))))
        most = f"{abs(found.t[worst]):.1f}σ ({names[worst]})"
        words = f"{said} agree: no parameter moves with the speed beyond {most}"
        return CheckResult(NAME, FINE, words, record=found.as_dict())
    concerns = {names[i]: concern(found, i, run.scenario.units.get(names[i], "")) for i in found.moved}
    first, *rest = concerns.values()
    return CheckResult(
        NAME,
        CAVEAT,
        f"{said} DISAGREE: {', '.join(names[i] for i in found.moved)} moves with the speed",
        caveat=first,
        caveats=tuple(rest),
        # A value the speed moves is not determined, however closely the drive seems to pin it:
        # this word on it comes before another check's σ of it.
        about={"concerns": "first"},
        concerns=concerns,
        how="Each parameter's fits are regressed on the speed squared; the slope's σ is their scatter.",
        record=found.as_dict(),
    )


def not_made(found: NotMade) -> CheckResult:
    """What the run says of a check it could not make: a caveat where the drive's bends load the
    tyres (a slip is left open, and no σ holds it), else a fine word."""
    words = f"not made: {found.why}"
    record = {
        "made": False,
        "why": found.why,
        "lateral_mps2": found.load if np.isfinite(found.load) else None,
    }
    if not found.open:
        return CheckResult(NAME, FINE, words, record=record)
    # Bends not timed (NaN) are not known to stay under the limit: the slip is left open there too.
    bends = f"bends reaching {found.load:.2g} m/s²" if np.isfinite(found.load) else "its bends"
    caveat = (
        f"the slip check was not made ({found.why}): the tyres' slip in {bends}, which moves a lever "
        "arm such as the sensor's x with the speed, is not ruled out and is in no σ; drive bends at "
        "several speeds, slow ones too, for it to be told"
    )
    return CheckResult(NAME, CAVEAT, words, caveat=caveat, record=record)


def concern(found: SpeedLines, i: int, unit: str) -> str:
    """Why parameter ``i`` is not determined, in ``unit``, with its value at zero speed and what to do."""
    unit = "" if unit in ("", "1") else f" {unit}"  # a gain's unit "1" is no unit to print
    lo, hi = float(np.nanmin(found.speeds)), float(np.nanmax(found.speeds))
    zero, std = found.lines.at_zero[i], found.lines.std_at_zero[i]
    return (
        f"{found.names[i]} is NOT DETERMINED: it moves with the speed ({found.at(i, lo):.4g}{unit} at "
        f"{lo:.3g} m/s, {found.at(i, hi):.4g} at {hi:.3g} m/s; {abs(found.t[i]):.1f}σ), as tyres sliding "
        "out of bends at speed move it (a lateral slip the model lacks; a linear tyre model puts it at "
        f"{zero:.4g} ± {std:.2g} at zero speed): give it under known: (measured), or calibrate on bends "
        f"driven under {found.slow_enough(i):.2g} m/s, where the slide moves it by less than the "
        f"{found.needed[i]:.2g}{unit} a calibration needs"
    )


def ahead(fns: ProblemFunctions, data: ResidualData, params: Mapping[str, float]) -> CheckResult | None:
    """The pre-flight's word on the tyres' slip (None: the base turns on the spot, or its bends
    stay under :data:`MIN_LATERAL`): the σ it states hold for tyres that do not slide, and the
    run's check fits the drive's speeds on their own, which can widen them or leave a parameter
    not determined (a pre-flight has no fit of the bins, so it names what the run will judge)."""
    if fns.model.reach(params).spot_turns:
        return None
    full = np.array([params[n] for n in fns.names], dtype=float)
    load = lateral(*window_motion(data, *interval_motion(fns, data, full)))
    if not load >= MIN_LATERAL:
        return None
    caveat = (
        f"the drive's bends reach {load:.2g} m/s² of lateral acceleration, where tyres slide out of "
        "them: the σ below hold for tyres that do not; the run fits the drive's speeds on their own "
        "(its slip check) and widens a parameter's σ by what a slip leaves open, or says it NOT "
        "DETERMINED where the speed moves it"
    )
    return CheckResult(NAME, CAVEAT, caveat, caveat=caveat, record={"lateral_mps2": load})
