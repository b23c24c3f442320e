"""Blocked cross-validation and the direction check: refits of a bound problem without some windows.

Both take a :class:`~nlp_calib.pipeline.steps.Binder` and the whole fit's windows ``data`` (records
``fit`` of the log), select the windows a refit keeps and refit them with the internal solver
from the whole fit's estimate: the windows are never built again. A fold leaves out every window
that touches its block of records, so no window straddles the held-out records.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from nlp_calib.analysis.crossval import CrossValidation, Fold, blocks, combine, jackknife_std
from nlp_calib.analysis.direction import DirectionCheck, compare
from nlp_calib.analysis.metrics import TrajectoryMetrics
from nlp_calib.pipeline.steps import Binder
from nlp_calib.problem import ResidualData
from nlp_calib.solvers import Priors

#: A fold needs this many windows of its part in the held-out block to count in a part's jackknife.
MIN_BLOCK_WINDOWS = 20

Canonical = Callable[[np.ndarray], np.ndarray]
#: Trajectory metrics of parameters on the records ``a:b``.
Score = Callable[[np.ndarray, int, int], TrajectoryMetrics]


def _fit(
    binder: Binder, data: ResidualData, fit: tuple[int, int], bad: np.ndarray, x: np.ndarray
) -> tuple[np.ndarray, bool, int]:
    """Full parameters, convergence and window count of a refit of ``data`` without the windows
    that cross a ``bad`` interval (a mask over the whole log's intervals)."""
    kept = data.select(data.interval_counts(bad[fit[0] : fit[1] - 1]) == 0)
    if kept.n_residuals < binder.fns.n_free:
        return np.full(len(binder.fns.names), np.nan), False, 0
    ev = binder.evaluate(kept)
    _, x_k, converged = binder.fit(ev, x)
    return ev.params(x_k), converged, kept.n_residuals


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
) -> CrossValidation:
    """``k`` folds over the records ``fit``, each scored on its block by ``score(params, a, b)``."""
    folds = []
    for a, b in blocks(*fit, k):
        bad = _base(fit)
        bad[a : b - 1] = True
        params, converged, n = _fit(binder, data, fit, bad, x)
        if not n:
            folds.append(Fold(a, b, params, False, None))
            continue
        params = canonical(params)
        folds.append(Fold(a, b, params, converged, score(params, a, b)))
    return combine(binder.fns.names, folds)


def direction_check(
    binder: Binder,
    data: ResidualData,
    fit: tuple[int, int],
    x: np.ndarray,
    direction: np.ndarray,
    undetermined: Callable[[np.ndarray], dict[str, str]],
    k: int,
    canonical: Canonical,
) -> DirectionCheck | None:
    """Forward-only and reverse-only fits from ``x``, each with the jackknife σ of its own blocks.

    ``direction`` is the travel direction of every interval of ``log``; ``undetermined(mask)``
    names the parameters a part (intervals ``mask`` of the fit range) cannot determine: they are
    held at ``x``'s values there. None without enough driving either way.
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
        part_binder = binder
        if hold:
            idx = [fns.free.index(n) for n in hold]
            mean, sqrt_info = binder.priors.mean.copy(), binder.priors.sqrt_info.copy()
            mean[idx], sqrt_info[idx] = x[idx], 1e6  # stiff: held where the whole fit put it
            part_binder = dataclasses.replace(binder, priors=Priors(mean, sqrt_info))
        params, converged, n = _fit(part_binder, data, fit, other, x)
        if not converged or n < 10 * fns.n_free:
            return None
        x_part = params[[fns.names.index(f) for f in fns.free]]
        folds = []
        for a, b in blocks(first, stop, k):
            if np.sum(part[a : b - 1]) < MIN_BLOCK_WINDOWS:
                continue  # a block without this direction's driving says nothing about it
            bad = other.copy()
            bad[a : b - 1] = True
            p_k, ok, _ = _fit(part_binder, data, fit, bad, x_part)
            if ok:
                folds.append(canonical(p_k))
        estimates.append(canonical(params))
        sigmas.append(jackknife_std(np.array(folds)) if len(folds) >= 3 else np.full(len(fns.names), np.nan))
        windows.append(n)
    return compare(
        fns.names, estimates[0], estimates[1], (windows[0], windows[1]), sigmas[0], sigmas[1], held
    )
