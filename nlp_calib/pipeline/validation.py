"""Blocked cross-validation and the direction check: refits of a bound problem without some windows.

Both take a :class:`~nlp_calib.pipeline.steps.Binder` and the whole fit's windows ``data`` (records
``fit`` of the log), select the windows a refit keeps and refit them with the internal solver
from the whole fit's estimate: the windows are never built again. A fold leaves out every window
that touches its block of records, so no window straddles the held-out records.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numpy as np

from nlp_calib.analysis.crossval import blocks, combine, jackknife_std
from nlp_calib.analysis.direction import compare
from nlp_calib.analysis.noise_rates import base_increments
from nlp_calib.analysis.pivots import pivot_intervals, pivot_windows, pivots_std
from nlp_calib.analysis.precision import clock_needed, with_clocks
from nlp_calib.core import memory, threads
from nlp_calib.models import reference_scales
from nlp_calib.pipeline.build import REFIT_SIGMAS, Binder, no_priors
from nlp_calib.problem import ProblemFunctions, ResidualData
from nlp_calib.results.checks import MIN_FOLDS, WEAK, CrossValidation, DirectionCheck, Fold, PivotSpread
from nlp_calib.results.figures import TrajectoryMetrics
from nlp_calib.results.layout import CLOCK, Layout
from nlp_calib.solvers import Priors
from nlp_calib.solvers.evaluation import NormalEquations, ProblemEvaluator, is_singular

#: Refits run at once (each holds its own evaluator's buffers: memory grows with this).
MAX_THREADS = 2

T = TypeVar("T")
R = TypeVar("R")

#: Folds of this many windows or more are one Gauss-Newton step from the whole fit's normal equations
#: less those of the windows left out (:func:`_stepped`); below, they are refitted from the estimate
#: until the next step would move it by less than :data:`REFIT_SIGMAS` (a step's error relative to
#: σ shrinks as σ does, with the square root of the windows).
DOWNDATE_FROM = 50_000

#: A fold needs this many windows of its part in the held-out block to count in a part's jackknife.
MIN_BLOCK_WINDOWS = 20

Canonical = Callable[[np.ndarray], np.ndarray]
#: The figures of each parameter set over records ``[a, b)``, the reference's side computed once.
Score = Callable[[Sequence[np.ndarray], int, int], list[TrajectoryMetrics]]


def _refit(
    binder: Binder,
    data: ResidualData,
    fit: tuple[int, int],
    bad: np.ndarray,
    x: np.ndarray,
    whole: NormalEquations | None = None,
) -> tuple[np.ndarray, bool, int, ProblemEvaluator | None]:
    """The refit of ``data`` without the windows that cross a ``bad`` interval (a mask over the whole
    log's intervals): :func:`refit_without`."""
    return refit_without(binder, data, data.interval_counts(bad[fit[0] : fit[1] - 1]) > 0, x, whole)


def refit_without(
    binder: Binder,
    data: ResidualData,
    crossing: np.ndarray,
    x: np.ndarray,
    whole: NormalEquations | None = None,
) -> tuple[np.ndarray, bool, int, ProblemEvaluator | None]:
    """The refit from ``x`` of ``data`` without the windows ``crossing`` marks (a fold, a jackknife
    block): full parameters, convergence, the windows kept and the evaluator it fitted with (None:
    too few windows). ``whole``: the normal equations of all of ``data`` at ``x``, downdated for the
    first step by the windows left out instead of evaluating the windows kept."""
    kept = data.select(~crossing)
    if kept.n_residuals < binder.fns.n_free:
        return np.full(len(binder.fns.names), np.nan), False, 0, None
    ev = binder.evaluate(kept)
    if whole is not None:
        ne = whole
        if crossing.any():
            ne = whole.less(_left_out(binder, data, crossing).normal_equations(x))
        ev.remember(x, ne)
    # Refits start next to their optimum: Gauss-Newton steps from ``x`` until the next would move
    # the estimate by less than REFIT_SIGMAS of its σ (a step or two), not to rounding; that last
    # step is taken too (the solver's last normal equations: no evaluation).
    _, x_k, converged = binder.fit(ev, x, REFIT_SIGMAS**2 / kept.n_residuals)
    step = ev.normal_equations(x_k).step() if converged else None
    if step is not None:
        x_k = _bounded(binder, ev.boxplus(x_k, step))
    return ev.params(x_k), converged, kept.n_residuals, ev


def _bounded(binder: Binder, x: np.ndarray) -> np.ndarray:
    """``x`` within the bounds the fits keep to (a fit's last step, a fold's step)."""
    return x if binder.bounds is None else np.clip(x, *binder.bounds)


def _left_out(binder: Binder, data: ResidualData, crossing: np.ndarray) -> ProblemEvaluator:
    """An evaluator of the data terms alone (no priors) on the windows ``crossing`` marks, bound to
    the records they span only: it integrates a block's intervals, not the whole log's."""
    data_only = dataclasses.replace(binder, priors=no_priors(binder.fns.n_free))
    return data_only.evaluate(data.select(crossing).spanned())


def _stepped(
    binder: Binder, whole: NormalEquations, left: ProblemEvaluator, x: np.ndarray
) -> tuple[np.ndarray, bool]:
    """A fold of a large fit: one Gauss-Newton step from the whole fit's estimate ``x`` on its
    normal equations ``whole`` less those of the windows ``left`` out, at ``x`` (no evaluation of
    the windows kept). Its optimum is next to ``x`` (σ/√(k−1) away for a block of k): the step
    lands within about 1e-4 of its σ on 10^5 windows, less on more (see docs/speed.md)."""
    ne = whole.less(left.normal_equations(x))
    step = ne.step() if np.isfinite(ne.cost) and not is_singular(ne.H) else None
    if step is None or not np.all(np.isfinite(step)):
        return np.full(len(binder.fns.names), np.nan), False
    return left.params(_bounded(binder, left.boxplus(x, step))), True


def leave_out(
    binder: Binder,
    data: ResidualData,
    crossing: np.ndarray,
    x: np.ndarray,
    whole: NormalEquations | None = None,
) -> tuple[np.ndarray, bool, int, ProblemEvaluator | None]:
    """A fold: the refit from the whole fit's ``x`` of ``data`` without the windows ``crossing``
    marks (a block of records, a log, a jackknife's block of windows). Full parameters,
    convergence, the windows kept and the evaluator of the windows left out (data terms alone;
    None where none was built). ``whole``: the normal equations of all of ``data`` at ``x``, less
    the left-out windows' for the first step, the windows kept not evaluated there. From
    :data:`DOWNDATE_FROM` windows on that step is the fold (:func:`_stepped`); below, or without
    ``whole``, the fold is refitted from ``x`` to :data:`REFIT_SIGMAS` (:func:`refit_without`)."""
    n = data.n_residuals - int(crossing.sum())
    if n < binder.fns.n_free:
        return np.full(len(binder.fns.names), np.nan), False, 0, None
    if not crossing.any():  # nothing left out: the fold is the whole fit
        return np.asarray(binder.fns.assemble(x, binder.x_fixed), dtype=float).ravel(), True, n, None
    if whole is None or data.n_residuals < DOWNDATE_FROM:
        params, converged, n, ev = refit_without(binder, data, crossing, x, whole)
        if ev is not None:
            ev.release()
        return params, converged, n, None
    left = _left_out(binder, data, crossing)
    params, converged = _stepped(binder, whole, left, x)
    return params, converged, n, left


def holding(binder: Binder, x: np.ndarray, names: Sequence[str]) -> Binder:
    """``binder`` with the free parameters ``names`` held at ``x``'s values (stiff priors): a
    refit whose data say nothing of them (a part without their driving, a fold without their log)
    would otherwise meet a singular system."""
    free = binder.fns.free
    idx = [free.index(n) for n in names if n in free]
    if not idx:
        return binder
    mean, sqrt_info = binder.priors.mean.copy(), binder.priors.sqrt_info.copy()
    mean[idx], sqrt_info[idx] = x[idx], 1e6
    return dataclasses.replace(binder, priors=Priors(mean, sqrt_info))


def on_threads(fn: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``fn`` of each item, in order, on up to :data:`MAX_THREADS` threads: the refits are
    independent and CasADi lets go of the interpreter lock while it evaluates, so they overlap."""
    workers = threads.allowed(min(len(items), MAX_THREADS))
    if workers <= 1:
        out = [fn(item) for item in items]
    else:
        pool = ThreadPoolExecutor(workers, thread_name_prefix="refit")
        try:
            out = list(pool.map(fn, items))
        finally:
            # Interrupted: refits not yet started are dropped, the running ones end on their own.
            pool.shutdown(wait=False, cancel_futures=True)
    memory.give_back()  # the refits' evaluators' buffers (hundreds of MB on 10^6 records)
    return out


def _part_fold(
    block: tuple[int, int],
    binder: Binder,
    part: ResidualData,
    fit: tuple[int, int],
    x: np.ndarray,
    whole: NormalEquations | None,
) -> np.ndarray | None:
    """A direction's refit (of its windows ``part``, see :func:`leave_out`) without the records
    ``block`` (None when it does not converge)."""
    bad = _base(fit)
    bad[block[0] : block[1] - 1] = True
    crossing = part.interval_counts(bad[fit[0] : fit[1] - 1]) > 0
    params, converged, _, _ = leave_out(binder, part, crossing, x, whole)
    return params if converged else None


def _base(fit: tuple[int, int]) -> np.ndarray:
    return np.zeros(fit[1] - 1, dtype=bool)


def cross_validate(
    binder: Binder,
    data: ResidualData,
    fit: tuple[int, int],
    x: np.ndarray,
    k: int,
    canonical: Canonical,
    score: Score,
    full: np.ndarray,
    whole: NormalEquations | None = None,
    against: Sequence[np.ndarray] = (),
) -> CrossValidation:
    """``k`` folds over the records ``fit`` (see :func:`folds_over`)."""
    folds = folds_over(binder, data, fit, blocks(*fit, k), (x, full), canonical, score, whole, against)
    return combine(binder.fns.names, folds)


def folds_over(
    binder: Binder,
    data: ResidualData,
    fit: tuple[int, int],
    ranges: Sequence[tuple[int, int]],
    start: tuple[np.ndarray, np.ndarray],
    canonical: Canonical,
    score: Score,
    whole: NormalEquations | None = None,
    against: Sequence[np.ndarray] = (),
    held: Sequence[Sequence[str]] = (),
) -> list[Fold]:
    """One refit of ``data`` (records ``fit``) without each record range of ``ranges`` (blocks, or
    whole logs), from ``start = (x, full)``: the whole fit's free values and full parameters. Each
    fold is scored on its range by ``score([params, full], a, b)``, beside the full fit's parameters on the
    same range, and costed there (the data cost of the windows the fold left out, no priors): its
    own estimate's, then each free-parameter vector of ``against``'s. ``whole``: the normal
    equations of ``data`` at ``x``, when known (each fold's first step downdates them). ``held``:
    per range, the parameters its fold holds at ``x`` (a left-out log's own time offset)."""
    x, full = start
    names, free = binder.fns.names, binder.fns.free
    data_only = dataclasses.replace(binder, priors=no_priors(binder.fns.n_free))

    holds = dict(zip(ranges, held))
    lags = lag_columns(binder)

    def fold(block: tuple[int, int]) -> Fold:
        a, b = block
        bad = _base(fit)
        bad[a : b - 1] = True
        hold = holds.get(block, ())
        crossing = data.interval_counts(bad[fit[0] : fit[1] - 1]) > 0
        # ``whole`` carries the fit's own priors, not a held fold's.
        refit = holding(binder, x, hold)
        params, converged, n, left = leave_out(refit, data, crossing, x, None if hold else whole)
        if not n:
            return Fold(a, b, params, False, None)
        costs: tuple[float, ...] = ()
        if converged and crossing.any():
            ev = left or data_only.evaluate(data.select(crossing))
            mine = params[[names.index(f) for f in free]]
            costs = tuple(float(ev.cost(v)) for v in (mine, *(lag_alike(v, mine, lags) for v in against)))
        params = canonical(params)
        on_block, full_on_block = score([params, full], a, b)
        return Fold(a, b, params, converged, on_block, full_on_block, costs)

    return on_threads(fold, list(ranges))


def lag_columns(binder: Binder) -> list[int]:
    """The places of the time offsets among the free parameters."""
    return [i for i, n in enumerate(binder.fns.free) if binder.fns.layout.in_block(n, CLOCK)]


def lag_alike(v: np.ndarray, fold: np.ndarray, lags: Sequence[int]) -> np.ndarray:
    """The free values ``v`` a fold is compared with on its held-out windows, with the fold's own
    time offsets (``fold``'s): the fold refits the lags of the logs it cuts into, and a compared set
    that kept the whole fit's lags (fitted on the held-out windows too) would be judged on its
    clock, not its parameters: each comparison treats the lag alike on both sides (``lags``: the
    offsets' places among the free values)."""
    if not lags:
        return v
    out = np.array(v, dtype=float)
    out[lags] = fold[lags]
    return out


def direction_check(
    binder: Binder,
    data: ResidualData,
    fit: tuple[int, int],
    x: np.ndarray,
    direction: np.ndarray,
    undetermined: Callable[[np.ndarray], dict[str, str]],
    k: int,
    canonical: Canonical,
    layout: Layout,
) -> DirectionCheck | None:
    """Forward-only and reverse-only fits from ``x``, each with the jackknife σ of its own blocks.

    ``direction`` is the travel direction of every interval of ``log``; ``undetermined(mask)``
    names the parameters a part (intervals ``mask`` of the fit range) cannot determine: they are
    held at ``x``'s values there. ``layout``: the precision each parameter needs on this drive
    (a smaller difference is no finding). None without enough driving either way.
    """
    fns = binder.fns
    first, stop = fit
    estimates, sigmas, windows, held = [], [], [], set()
    for sign in (1, -1):
        other = direction == -sign
        part = np.zeros_like(other)
        part[first : stop - 1] = direction[first : stop - 1] == sign
        hold = [n for n in undetermined(part) if n in fns.free]
        held |= set(hold)
        part_binder = holding(binder, x, hold)
        params, converged, n, ev = _refit(part_binder, data, fit, other, x)
        if not converged or n < 10 * fns.n_free or ev is None:
            return None
        x_part = params[[fns.names.index(f) for f in fns.free]]

        # A block without this direction's driving says nothing about it.
        driven = [(a, b) for a, b in blocks(first, stop, k) if np.sum(part[a : b - 1]) >= MIN_BLOCK_WINDOWS]
        part_data = ev.data  # the windows that cross no ``other`` interval
        whole = None
        if part_data.n_residuals >= DOWNDATE_FROM:
            whole = ev.normal_equations(x_part)
        ev.release()
        fold = functools.partial(
            _part_fold, binder=part_binder, part=part_data, fit=fit, x=x_part, whole=whole
        )
        folds = [canonical(p) for p in on_threads(fold, driven) if p is not None]
        estimates.append(canonical(params))
        sigmas.append(jackknife_std(np.array(folds)) if len(folds) >= 3 else np.full(len(fns.names), np.nan))
        windows.append(n)
    apart = WEAK * with_clocks(
        reference_scales(fns.model, fns.layout.keys(fns.names), estimates[0]), fns.names, clock_needed(layout)
    )
    needed = layout.needed(dict(zip(fns.names, 0.5 * (estimates[0] + estimates[1]))))
    parts = (estimates[0], estimates[1], (windows[0], windows[1]), sigmas[0], sigmas[1])
    return compare(fns.names, *parts, held, apart, np.array([needed[n] for n in fns.names]))


def pivot_spread(
    binder: Binder, data: ResidualData, x: np.ndarray, canonical: Canonical, offset: int = 0
) -> PivotSpread | None:
    """Each pivot of ``data`` fitted on its own, from the estimate ``x`` (free values): the windows
    off every pivot and that pivot's (see :mod:`nlp_calib.analysis.pivots`; ``data`` holds the
    windows of the slipped pivots the estimate left out); the pivots' records numbered from
    ``offset``. Over several logs every log's pivots are one population for what the logs share,
    and a log's own parameters (its mount, its clock) take its own pivots'. None with fewer than
    :data:`MIN_FOLDS` pivots whose own fit converges."""
    fns = binder.fns
    full = np.asarray(fns.assemble(x, binder.x_fixed), dtype=float).ravel()
    label, window_log = _pivot_labels(binder, full, data)
    if label.max(initial=-1) + 1 < MIN_FOLDS:
        return None
    whole = None
    if data.n_residuals >= DOWNDATE_FROM:
        ev = binder.evaluate(data)
        whole = ev.normal_equations(x)
        ev.release()

    def own(g: int) -> np.ndarray | None:
        params, converged, _, _ = leave_out(binder, data, (label >= 0) & (label != g), x, whole)
        return canonical(params) if converged else None

    fits = on_threads(own, list(range(int(label.max()) + 1)))
    done = [g for g, p in enumerate(fits) if p is not None]
    if len(done) < MIN_FOLDS:
        return None
    params = np.array([fits[g] for g in done])
    ranges = tuple(
        (offset + int(data.starts[label == g].min()), offset + int(data.stops[label == g].max()) + 1)
        for g in done
    )
    logs = np.array([window_log[label == g][0] for g in done])
    return PivotSpread(tuple(fns.names), ranges, params, _pooled_std(fns, params, canonical(full), logs))


def _pivot_labels(binder: Binder, full: np.ndarray, data: ResidualData) -> tuple[np.ndarray, np.ndarray]:
    """Each window's pivot (-1: off every pivot) and its log. The base's own motion, as the fault
    screen judges a pivot (a sensor off the turning centre travels on a pivot), each log's from its
    own view of ``full`` (its mount, its clock): a pivot never spans two logs, whose records the
    joint numbering joins by an interval of no motion."""
    fns = binder.fns
    edges = [*data.offsets, data.n_records]
    steps = np.zeros((data.inputs.shape[1], 3))
    for i, (a, b) in enumerate(itertools.pairwise(edges)):
        params = full if len(data.offsets) == 1 else fns.view(full, i)
        inputs = data.inputs[:, a : b - 1]
        steps[a : b - 1] = base_increments(fns, params, inputs, np.zeros(inputs.shape[0]))[0]
    label = pivot_windows(pivot_intervals(steps), data.starts, data.stops)
    return label, np.searchsorted(np.asarray(data.offsets), data.starts, side="right") - 1


def _pooled_std(
    fns: ProblemFunctions, params: np.ndarray, estimate: np.ndarray, logs: np.ndarray
) -> np.ndarray:
    """:func:`pivots_std` of every pivot for the parameters the logs share, and of log ``i``'s
    pivots alone for log ``i``'s own (another log's pivot barely moves them: pooled, their scatter
    would be too small by about the share of that log's pivots)."""
    std = pivots_std(params, estimate)
    owner = {p.name: p.log for p in fns.layout.parameters if p.log is not None}
    for j, name in enumerate(fns.names):
        if name in owner:
            mine = logs == owner[name]
            std[j] = pivots_std(params[mine][:, [j]], estimate[[j]])[0]
    return std
