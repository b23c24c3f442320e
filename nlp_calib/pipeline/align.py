"""Time alignment as a pipeline step: the tracker lag, given or estimated, applied to the encoders.

An estimated lag is a parameter of the problem (``tracker_lag``, :mod:`nlp_calib.problem.clock`):
the internal solver fits it with every other parameter, the encoders re-sampled at its value, and
again at the new value until it moves by less than :data:`LAG_TOLERANCE_S` (the problem's clock
correction is exact to first order in the distance from the re-sampled lag, so that distance
ends near zero). The settled lag is a root of g(τ) = (the lag fitted on the encoders re-sampled at
τ) − τ: where those re-samplings stop bringing g towards zero (a loose lag, where the fits
overshoot each other and alternate between two lags), the next τ is a secant or bisection step
between the last lags where g had either sign, so the re-samplings close in on the root; then
the re-sampling of least cost of all tried is kept (the costs compare fits of the same tracker
poses: a root can lie where re-sampling between rows fits worse than the readings as logged).
``alignment.search`` bounds it; its σ, correlations and observability come from the same
Functions as every other parameter's.

That σ holds where the fit on data re-sampled off the lag takes the offset back: the problem's
correction moves each window's ends along the rates at them, read from the same rounded
readings, and where the drive's speeds barely change (circles at constant speed) those rates'
differences are the readings' rounding alone. Their noise then makes up the lag's information
(a σ too small) and shrinks what the fit takes back of an offset (errors in the variables): the
fitted lag follows the lag the data were re-sampled at, g has roots wherever its noise crosses
zero, and the one kept is wrong by many of its σ (constant circles each way: −90 ms ± 13 ms, the
truth 0). So the settled lag is re-sampled ``RETURN_SIGMAS`` (8) white σ either side and fitted
there (:meth:`_LagFits.returned`). A lag whose fits take back less than ``RETURNS`` (a quarter:
2σ, their own noise) is named not determined (held where it settled, with no σ, as a lag pinned
on its search's edge); one whose fits take back only part beyond their noise has its white σ over
that share as its σ (:meth:`~nlp_calib.results.checks.LagEstimate.returned_std`; the shipped
real log: half, 2.8 ms, within its blocks' 4.4 ms).
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.core.errors import NlpCalibError, NlpCalibWarning
from nlp_calib.logs import Log, resample_encoders
from nlp_calib.logs.resample import Resampler
from nlp_calib.pipeline.build import Binder
from nlp_calib.pipeline.keys import scenario_key
from nlp_calib.pipeline.prepare import fit_records
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.results.checks import RETURN_SIGMAS, LagEstimate
from nlp_calib.results.layout import CLOCK
from nlp_calib.solvers import ProblemEvaluator

#: The re-sampling is done again until the fitted lag moves by less than this (s).
LAG_TOLERANCE_S = 1e-4
#: ...or this many times.
MAX_RESAMPLINGS = 8
#: Re-samplings stop bringing the lag towards where it stays when one moves it by more than this
#: share of the last move: the next lag is then a secant or bisection step (:func:`next_lag`).
SHRINK = 0.8
#: Steps of that kind beyond :data:`MAX_RESAMPLINGS` (each at least quarters the lags' bracket).
BRACKET_STEPS = 8
#: Lags over the search a fit starts from when the fit from the lag's initial value does not converge.
COARSE_STARTS = 9
#: The profile of the cost over the search: at most this many lags, at least this far apart (s).
#: It only finds the valleys the fits then settle in (to :data:`LAG_TOLERANCE_S`): over the
#: default ±0.5 s that is one lag every 25 ms, finer than a valley of a drive's motion is wide,
#: and the profile was the largest cost of a default run at one lag every 10 ms.
PROFILE_LAGS = 41
PROFILE_STEP_S = 0.002
#: ...on at most this many records (the middle of the fitted ones): its cost does not grow with the log.
PROFILE_RECORDS = 20_000
#: Valleys of the profile other than the one the fit settled in that are fitted from too.
OTHER_VALLEYS = 2
#: Two lags lie in two valleys where the profile between them rises this share above both.
RIDGE = 0.02
#: Two valleys whose fitted costs differ by less than this share of the lower are comparable: the
#: lag is named ambiguous, with both values.
COMPARABLE = 0.1


@dataclass(frozen=True)
class Alignment:
    """The tracker lag used, how it was found, and the log with encoders on the tracker's clock.

    ``valid`` is the record range whose shifted times lie inside the log.
    """

    lag_s: float
    estimate: LagEstimate | None
    log: Log
    valid: tuple[int, int]
    #: The log as it was before its encoders were re-sampled (None: not kept).
    source: Log | None = None


def stays(moved_s: float, std_s: float) -> bool:
    """Whether a lag fitted on the encoders re-sampled at another moved from it (``moved_s``) by
    less than the larger of :data:`LAG_TOLERANCE_S` and a quarter of its white-noise σ ``std_s``:
    the re-sampling is then done (the run's alignment and the pre-flight's fit alike)."""
    return abs(moved_s) < max(LAG_TOLERANCE_S, 0.25 * std_s)


def white_std(H: np.ndarray, sigma2: float, column: int) -> float:
    """The white-noise σ of free parameter ``column`` from normal equations ``H`` and residuals of
    variance ``sigma2`` (0 when singular)."""
    try:
        var = float(np.linalg.inv(H)[column, column]) * sigma2
    except np.linalg.LinAlgError:
        return 0.0
    return float(np.sqrt(var)) if np.isfinite(var) and var > 0 else 0.0


def lag_column(binder: Binder) -> int | None:
    """The place of the (single log's) lag among the free parameters; None when it is not free."""
    return next((i for i, n in enumerate(binder.fns.free) if binder.fns.layout.in_block(n, CLOCK)), None)


def beside_column(binder: Binder) -> int | None:
    """The place of a second sensor's clock offset (a gyro's beside the reference) among the free
    parameters, where the reference's is free too (None: one clock, or either held)."""
    clocks, layout, free = binder.fns.sensor.clocks, binder.fns.layout, binder.fns.free
    keys = [layout.param(n).key if layout.in_block(n, CLOCK) else None for n in free]
    if len(clocks) < 2 or clocks[0] not in keys or clocks[1] not in keys:
        return None
    return keys.index(clocks[1])


@dataclass
class _LagFits:
    """The lag's fits on one log: the records, the evaluator they share and the path so far."""

    binder: Binder
    log: Log
    records: tuple[int, int]
    column: int
    evaluator: ProblemEvaluator | None = None
    #: The log's re-sampling at any lag (what does not depend on the lag computed once).
    resampler: Resampler | None = None
    #: The second clock's column (a gyro's offset; None: one clock): its records are re-sampled at
    #: its own offset, not moved there by the problem's first-order correction.
    beside: int | None = None

    def beside_s(self, x: np.ndarray) -> float | None:
        """The second clock's offset over the reference's at ``x`` (None: one clock)."""
        return None if self.beside is None else float(x[self.beside] - x[self.column])

    def resampled(
        self, lag: float, records: tuple[int, int] | None = None, beside_s: float | None = None
    ) -> Log:
        """The log's encoders re-sampled at ``lag`` (``records``: those alone; ``beside_s``: the
        second clock's offset over the reference's)."""
        if self.resampler is None:
            self.resampler = Resampler(self.log, self.binder.fns.model.encoder_kinds)
        return self.resampler.at(lag, records, beside_s)[0]

    def bound(
        self, shifted: Log, records: tuple[int, int], evaluator: ProblemEvaluator | None
    ) -> ProblemEvaluator:
        """``evaluator`` (None: a new one), bound to ``records`` of the log or of another of its
        re-samplings, bound to those of ``shifted``: only its inputs computed again."""
        if evaluator is None:
            return self.binder.bind(shifted, *records)[1]
        return self.binder.rebind(evaluator, shifted, *records)

    def fit(self, x: np.ndarray) -> tuple[float, np.ndarray, bool]:
        """The internal fit from ``x`` on the encoders re-sampled at ``x``'s lags."""
        shifted = self.resampled(float(x[self.column]), beside_s=self.beside_s(x))
        self.evaluator = self.bound(shifted, self.records, self.evaluator)
        cost, x_new, converged = self.binder.fit(self.evaluator, x)
        return cost, x_new, bool(converged and np.all(np.isfinite(x_new)))

    def settle(self, x: np.ndarray) -> tuple[np.ndarray, list[float], list[float], bool]:
        """Fits from ``x``, re-sampled at each new lag until it stays within the larger of
        :data:`LAG_TOLERANCE_S` and a quarter of its white-noise σ (see the module docstring). Where
        the re-samplings took secant or bisection steps (:func:`next_lag`), the fit of least cost of
        all kept: its lag, re-sampled there once more (the cost compares fits of one tracker)."""
        path: list[float] = []
        costs: list[float] = []
        tried: list[tuple[float, float]] = []  # (the lag re-sampled at, the lag fitted there)
        fits: list[np.ndarray] = []
        converged = False
        for _ in range(MAX_RESAMPLINGS + BRACKET_STEPS):
            resampled, beside = float(x[self.column]), self.beside_s(x)
            cost, x_new, converged = self.fit(x)
            path.append(resampled)
            costs.append(cost)
            if not converged:
                return x, path, costs, converged
            tried.append((resampled, float(x_new[self.column])))
            fits.append(x_new)
            now = self.beside_s(x_new)
            tolerance = max(LAG_TOLERANCE_S, 0.25 * self.lag_std(x_new))
            still = now is None or beside is None or stays(now - beside, self.lag_std(x_new, self.beside))
            ends = bracket(tried)
            if still and abs(tried[-1][1] - resampled) < tolerance:
                break
            if ends is not None and abs(tried[ends[0]][0] - tried[ends[1]][0]) < tolerance:
                break
            lag = next_lag(tried)
            if len(tried) >= MAX_RESAMPLINGS and lag == tried[-1][1]:
                break  # plain re-samplings (each closer than the last) and their budget spent
            x = _moved_to(x_new, lag, self.column, self.beside)
        best = int(np.argmin(costs))
        if plain(tried) or (best == len(fits) - 1 and abs(tried[-1][1] - tried[-1][0]) < tolerance):
            return fits[-1], path, costs, converged
        # Back to the cheapest fit's re-sampling, so that the fit from it is that fit again.
        x = _moved_to(fits[best], tried[best][0], self.column, self.beside)
        cost, x_new, converged = self.fit(x)
        path.append(tried[best][0])
        costs.append(cost)
        return _moved_to(x_new, tried[best][0], self.column, self.beside), path, costs, converged

    def lag_std(self, x: np.ndarray, column: int | None = None) -> float:
        """The lag's (``column``'s) white-noise σ at ``x`` from the last fit's normal equations (0
        when singular)."""
        assert self.evaluator is not None
        ne = self.evaluator.normal_equations(x)
        dof = max(self.binder.fns.error_rows * self.evaluator.n_residuals - self.binder.fns.n_free, 1)
        return white_std(ne.H, ne.cost / dof, self.column if column is None else column)

    def profile(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The cost over the search at ``x``'s other parameters: lags at most :data:`PROFILE_LAGS`
        and at least :data:`PROFILE_STEP_S` apart, the encoders re-sampled at each, on the middle
        :data:`PROFILE_RECORDS` of the fitted records."""
        lo, hi = self.binder.scenario.log.alignment.search
        n = int(min(PROFILE_LAGS, max(3, round((hi - lo) / PROFILE_STEP_S) + 1)))
        grid = np.linspace(lo, hi, n)
        a, b = self.records
        mid, half = (a + b) // 2, PROFILE_RECORDS // 2
        records = (max(a, mid - half), min(b, mid + half))
        # The fits' evaluator where the profile reads the same records (a log of up to
        # PROFILE_RECORDS): the profile's windows are the fits', already bound.
        evaluator = self.evaluator if records == self.records else None
        costs = np.full(n, np.nan)
        for i, lag in enumerate(grid):
            # Only the profile's records re-sampled (a long log's others are never read here); the
            # second clock's records stay where ``x`` reads them: its offset is ``x``'s.
            beside = None if self.beside is None else float(x[self.beside] - lag)
            shifted = self.resampled(float(lag), records, beside)
            try:
                evaluator = self.bound(shifted, records, evaluator)
            except NlpCalibError:
                continue
            at = np.array(x, dtype=float)
            at[self.column] = lag
            costs[i] = float(evaluator.cost(at))
        return grid, costs

    def returned(self, x: np.ndarray) -> float | None:
        """The share of a displacement of ``RETURN_SIGMAS`` white-noise σ of the settled lag
        (``x``'s) that fits on the encoders re-sampled there take back, averaged over the sides
        inside the search whose fits converge (1: each returns to the lag; 0: each stays where it
        was re-sampled). None: no σ, or no such side."""
        lag = float(x[self.column])
        # The normal equations at the settled lag, on the data re-sampled there.
        shifted = self.resampled(lag, beside_s=self.beside_s(x))
        self.evaluator = self.bound(shifted, self.records, self.evaluator)
        step = RETURN_SIGMAS * self.lag_std(x)
        lo, hi = self.binder.scenario.log.alignment.search
        sides = [s for s in (-step, step) if step > 0 and lo <= lag + s <= hi]
        shares = []
        for side in sides:
            _, x_new, converged = self.fit(_moved_to(x, lag + side, self.column, self.beside))
            if converged:  # one that stops short says nothing (a short car's log: 0.7-0.85 back)
                shares.append((lag + side - float(x_new[self.column])) / side)
        return float(np.mean(shares)) if shares else None

    def coarse_start(self, x0: np.ndarray) -> np.ndarray | None:
        """The start of the converged fit of least cost from lags spread over the search (None: none
        converged): a start only, the lag is then fitted from it."""
        lo, hi = self.binder.scenario.log.alignment.search
        best: tuple[float, np.ndarray] | None = None
        for lag in np.linspace(lo, hi, COARSE_STARTS):
            x = x0.copy()
            x[self.column] = lag
            cost, x_new, converged = self.fit(x)
            if converged and (best is None or cost < best[0]):
                best = (cost, x_new)
        return None if best is None else best[1]


def _moved_to(x: np.ndarray, lag: float, column: int, beside: int | None) -> np.ndarray:
    """``x`` with its lag at ``lag`` (a second clock, at ``beside``, keeps its offset over it)."""
    if lag == float(x[column]):
        return x
    moved = x.copy()
    moved[column] = lag
    if beside is not None:
        moved[beside] = x[beside] + (lag - float(x[column]))
    return moved


def plain(tried: list[tuple[float, float]]) -> bool:
    """Whether each of the re-sampled lags ``tried`` (the lag, the lag fitted there) was the lag
    fitted at the one before (no secant or bisection step)."""
    return all(b[0] == a[1] for a, b in itertools.pairwise(tried))


def bracket(tried: list[tuple[float, float]]) -> tuple[int, int] | None:
    """The last of the re-sampled lags ``tried`` (the lag, the lag fitted there) and the last before
    it where the fit moved the other way (their indices; None: no such pair): g's root lies between."""
    sign = np.sign(tried[-1][1] - tried[-1][0]) if tried else 0.0
    if sign == 0.0:
        return None
    other = next(
        (i for i in range(len(tried) - 2, -1, -1) if np.sign(tried[i][1] - tried[i][0]) == -sign), None
    )
    return None if other is None else (len(tried) - 1, other)


def next_lag(tried: list[tuple[float, float]]) -> float:
    """The lag to re-sample at next after ``tried`` (the lag, the lag fitted there): the fitted lag
    while each fit moves it by under :data:`SHRINK` of the move before; else the secant of g
    between the ends of the :func:`bracket` (bisection where it falls outside the bracket's middle
    half, which then at least quarters), or through the last two lags where g has kept its sign;
    once a step was not the fitted lag, none is."""
    g = [fitted - lag for lag, fitted in tried]
    if plain(tried) and (len(tried) < 2 or abs(g[-1]) < SHRINK * abs(g[-2])):
        return tried[-1][1]
    ends = bracket(tried)
    if ends is None:
        (a, ga), (b, gb) = (tried[-2][0], g[-2]), (tried[-1][0], g[-1])
        secant = b - gb * (b - a) / (gb - ga) if gb != ga else b + gb
        # Only onwards in g's direction, and no further than plain steps shrinking by SHRINK
        # each would sum to (1 / (1 - SHRINK) of the last): a secant of two close values of a
        # noisy g reaches far beyond where it holds.
        reach = (secant - b) / gb if gb != 0.0 else 0.0
        return float(secant) if 1.0 < reach <= 1.0 / (1.0 - SHRINK) else tried[-1][1]
    (a, ga), (b, gb) = ((tried[i][0], g[i]) for i in ends)
    secant = a - ga * (b - a) / (gb - ga)
    lo, hi = min(a, b), max(a, b)
    quarter = 0.25 * (hi - lo)
    return float(secant) if lo + quarter <= secant <= hi - quarter else 0.5 * (a + b)


def valleys(grid: np.ndarray, costs: np.ndarray) -> list[float]:
    """The lags of the profile's local minima (the ends included), lowest cost first."""
    c = np.where(np.isfinite(costs), costs, np.inf)
    if not np.isfinite(c).any():
        return []
    left = np.concatenate([[np.inf], c[:-1]])
    right = np.concatenate([c[1:], [np.inf]])
    found = np.flatnonzero((c <= left) & (c <= right) & np.isfinite(c))
    return [float(grid[i]) for i in found[np.argsort(c[found])]]


@dataclass(frozen=True)
class _Settled:
    """One fit of the lag settled: its free values, cost, convergence and the path there."""

    x: np.ndarray
    cost: float
    converged: bool
    path: tuple[float, ...]
    costs: tuple[float, ...]


def _settled(fits: _LagFits, x: np.ndarray) -> _Settled:
    x, path, costs, converged = fits.settle(x)
    return _Settled(x, costs[-1] if costs else np.inf, converged, tuple(path), tuple(costs))


def _global(
    fits: _LagFits, first: _Settled
) -> tuple[_Settled, _Settled | None, tuple[np.ndarray, np.ndarray]]:
    """The lowest of the fits from the valley ``first`` settled in and from the profile's other
    lowest valleys (:data:`OTHER_VALLEYS`), the runner-up where its cost is comparable
    (:data:`COMPARABLE`) and a ridge of the profile parts the two, and the profile (lags, costs)."""
    column = fits.column
    grid, costs = fits.profile(first.x)
    # A valley more than one of the profile's steps from the settled lag is another place to fit
    # from: on a flat cost the settled fit (stopped once the lag stays within its tolerance) and
    # the profile's lowest point can lie steps apart, and the fit from there may settle lower
    # (a real tricycle's square: 293 ms settled, the profile lowest at 325 ms, the fit from there
    # 365 ms at 1.4 % less cost).
    width = 1.01 * float(np.ptp(grid)) / max(grid.size - 1, 1)
    tried = [first]
    for lag in [v for v in valleys(grid, costs) if abs(v - first.x[column]) > width][:OTHER_VALLEYS]:
        x = first.x.copy()
        x[column] = lag
        other = _settled(fits, x)
        if other.converged:
            tried.append(other)
    tried.sort(key=lambda t: (not t.converged, t.cost))
    best = tried[0]
    runner = next(
        (
            t
            for t in tried[1:]
            if t.converged
            and t.cost <= (1 + COMPARABLE) * best.cost
            and apart(grid, costs, t.x[column], best.x[column])
        ),
        None,
    )
    return best, runner, (grid, costs)


def apart(grid: np.ndarray, costs: np.ndarray, a: float, b: float) -> bool:
    """Whether lags ``a`` and ``b`` lie in two valleys of the profile: a ridge between them rises
    above the higher of the two by :data:`RIDGE` of it."""
    lo, hi = min(a, b), max(a, b)
    between = costs[(grid > lo) & (grid < hi) & np.isfinite(costs)]
    if between.size == 0:
        return False
    ends = np.interp([a, b], grid[np.isfinite(costs)], costs[np.isfinite(costs)])
    return bool(between.max() > (1 + RIDGE) * ends.max())


def estimate_tracker_lag(binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray) -> LagEstimate:
    """The tracker lag fitted with every other parameter, re-sampling the encoders at each new value
    (see the module docstring); from the lag's initial value in ``x0``, or, when that fit does not
    converge, from the best of :data:`COARSE_STARTS` lags over the search; then from the other
    valleys of the cost's profile over the search, the lowest kept (a fit stops in the valley
    it starts in: a lag off by a period of the drive's motion is a valley too)."""
    column = lag_column(binder)
    assert column is not None
    records = fit_records(binder.scenario, log, start, stop)
    fits = _LagFits(binder, log, records, column, beside=beside_column(binder))
    lower, upper = binder.bounds if binder.bounds is not None else (None, None)
    x = np.clip(np.asarray(x0, dtype=float), lower, upper) if lower is not None else np.asarray(x0, float)
    first = _settled(fits, x)
    if not first.converged and (better := fits.coarse_start(np.asarray(x0, dtype=float))) is not None:
        again = _settled(fits, better)
        first = replace(again, path=first.path + again.path, costs=first.costs + again.costs)
    if not first.converged:
        return LagEstimate(float(first.x[column]), first.path, first.costs, False, False)
    best, runner, (grid, profile) = _global(fits, first)
    back = fits.returned(best.x)
    lag = float(best.x[column])
    lo, hi = binder.scenario.log.alignment.search
    at_edge = bool(abs(lag - lo) < 1e-6 or abs(lag - hi) < 1e-6)
    path = first.path + (best.path if best is not first else ())
    costs = first.costs + (best.costs if best is not first else ())
    other = () if runner is None else (float(runner.x[column]), float(runner.cost), float(best.cost))
    return LagEstimate(
        lag,
        path,
        costs,
        at_edge,
        True,
        tuple(map(float, grid)),
        tuple(map(float, profile)),
        other,
        fits.beside_s(best.x),
        back,
    )


def align(binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray) -> Alignment:
    """The scenario's tracker lag (given, or estimated when ``auto``) applied to the encoders."""
    sc = binder.scenario
    lag = sc.log.alignment.tracker_lag
    estimate = None
    if lag == "auto" and lag_column(binder) is not None:
        with scenario_key(sc, "alignment.search"):
            estimate = estimate_tracker_lag(binder, log, start, stop, x0)
        if not estimate.converged:
            # No fit converged at any lag: the lag is held where it starts (the stamps as logged,
            # unless the search lies all on one side), and the rest is fitted there.
            column = lag_column(binder)
            assert column is not None
            estimate = replace(estimate, lag_s=float(np.asarray(x0, dtype=float)[column]))
            warnings.warn(lag_not_fitted(sc, estimate.lag_s), NlpCalibWarning, stacklevel=2)
        elif estimate.at_edge:
            warnings.warn(lag_at_edge(sc, estimate.lag_s), NlpCalibWarning, stacklevel=2)
        elif estimate.loose:
            warnings.warn(lag_loose(sc, estimate), NlpCalibWarning, stacklevel=2)
        lag = estimate.lag_s
    elif lag == "auto":
        # Held (known, or fixed at its initial value): the data are re-sampled there.
        held = [i for i, n in enumerate(binder.fns.fixed) if binder.fns.layout.in_block(n, CLOCK)]
        lag = float(binder.x_fixed[held[0]]) if held else 0.0
    with scenario_key(sc, "alignment.tracker_lag"):
        beside = None if estimate is None or not estimate.converged else estimate.beside_s
        aligned, valid = resample_encoders(
            log, float(lag), binder.fns.model.encoder_kinds, beside_lag_s=beside
        )
    return Alignment(lag_s=float(lag), estimate=estimate, log=aligned, valid=valid, source=log)


def lag_at_edge(sc: Scenario, lag_s: float) -> str:
    """The warning for a tracker lag estimated at an end of the searched range."""
    lo, hi = sc.log.alignment.search
    return (
        f"{sc.path or sc.name}: alignment.tracker_lag: the fitted lag {1e3 * lag_s:.1f} ms lies at the "
        f"edge of alignment.search [{lo:g}, {hi:g}] s, which bounds it: either the lag lies beyond it "
        "(widen alignment.search, or check the log's timestamps: a gap or a jump in time misleads the "
        "fit), or this drive does not determine the lag (the observability lines say with what it "
        "trades off; give the lag as alignment.tracker_lag, or drive so that the wheels' speeds change "
        "independently)"
    )


def lag_not_fitted(sc: Scenario, lag_s: float) -> str:
    """The warning for a tracker lag that no fit converged at, from any start in the search."""
    lo, hi = sc.log.alignment.search
    return (
        f"{sc.path or sc.name}: alignment.search: no fit converged from any lag in [{lo:g}, {hi:g}] s, so "
        f"the lag is not fitted (the encoders are read at {1e3 * lag_s:.1f} ms): the observability lines "
        "say what this drive cannot determine; where they name nothing, search around the lag the "
        "log's clocks allow, or give it as alignment.tracker_lag"
    )


def lag_loose(sc: Scenario, estimate: LagEstimate) -> str:
    """The warning for a tracker lag the drive does not determine (:attr:`LagEstimate.loose`)."""
    share = 100.0 * (estimate.returned or 0.0)
    return (
        f"{sc.path or sc.name}: alignment.tracker_lag: the drive does not determine the lag: fits on the "
        f"encoders re-sampled {RETURN_SIGMAS:g} of its white-noise σ either side of "
        f"{1e3 * estimate.lag_s:.1f} ms take back {share:.0f} % of that (a determined lag, all of it), "
        "so it is held there with no σ; "
        "the wheels' speeds barely change on this drive (starts, stops and turns of different lengths "
        "determine it), or give the lag as alignment.tracker_lag"
    )


def lag_held(estimate: LagEstimate) -> str:
    """Why the run holds a pinned tracker lag (:attr:`LagEstimate.pinned`) with no σ, in words (the
    pre-flight's, beside the run's warning)."""
    at = f"{1e3 * estimate.lag_s:.1f} ms"
    if not estimate.converged:
        return f"no fit converged at any lag in alignment.search: the run holds it at {at} with no σ"
    if estimate.at_edge:
        return (
            f"the run's fit puts it on the edge of alignment.search ({at}), held there with no σ (widen "
            "the search, or give the lag as alignment.tracker_lag)"
        )
    share = 100.0 * (estimate.returned or 0.0)
    return (
        f"the run holds it at {at} with no σ: fits on the encoders re-sampled {RETURN_SIGMAS:g} of its "
        f"white-noise σ either side take back {share:.0f} % of that (a determined lag, all of it); "
        "starts, stops and turns of different lengths determine it, or give the lag as "
        "alignment.tracker_lag"
    )
