"""A coarse tracker lag from how busy the wheels and the reference are: before any model or fit.

The wheels' speed (each counter's change over :data:`SPAN_S`, in units of its own RMS, summed)
and the reference's (its track's speed and turn rate over the same span, each in units of its
RMS, summed) rise and fall together with the drive's starts, stops and bends, whatever the
wheels' radii, signs or units; the reference's, stamped ``lag`` late, follows the wheels' by that
much. The lag at which they correlate best over ±:data:`REACH_S` is the data's coarse lag when
it is a peak inside that reach, the correlation there positive, and clearly better than the
stamps' as logged (:data:`CLEARER`; :func:`unshown`): what ``init``
drafts ``alignment.search`` to hold (the fit then finds it to its σ). A drive whose speed changes
slowly (circles at one speed) correlates alike over a second of lags and shows none.
"""

from __future__ import annotations

import numpy as np

#: How far either way the lag is looked for (s): a driver's or a network's late stamps; a clock
#: further off is a clock offset (``clock_offset``), not a lag.
REACH_S = 2.0
#: Each speed is a change over this span (s; a tracker's noise differentiated over one record
#: would swamp it), on a grid of this step (s).
SPAN_S, STEP_S = 0.2, 0.01
#: At most this many grid points (the middle of the log's): the cost does not grow with the log.
MAX_POINTS = 30_000
#: A coarse lag is shown where its correlation exceeds the stamps' as logged (lag 0) by this much.
CLEARER = 0.05
#: Each speed is clipped at this quantile (an outlying tracker pose is one spike, not the drive).
CLIP_QUANTILE = 0.98


def _speed(time_s: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """``values``' (n, d) change over :data:`SPAN_S` about each time of ``grid`` (its length), per
    second."""
    half = 0.5 * SPAN_S
    change = [np.interp(grid + half, time_s, v) - np.interp(grid - half, time_s, v) for v in values.T]
    return np.sqrt(np.sum(np.square(change), axis=0)) / SPAN_S


def busy(time_s: np.ndarray, streams: list[np.ndarray], grid: np.ndarray) -> np.ndarray | None:
    """How busy the ``streams`` (each (n, d): a counter, a position, a heading) are at ``grid``:
    each one's speed (clipped, over its RMS) summed over those that move (None: none moves)."""
    total = np.zeros(grid.size)
    moved = False
    for values in streams:
        v = np.asarray(values, dtype=float).reshape(time_s.size, -1)
        ok = np.all(np.isfinite(v), axis=1)
        if ok.sum() < 2:
            continue
        s = _speed(time_s[ok], v[ok], grid)
        s = np.minimum(s, np.quantile(s, CLIP_QUANTILE))
        rms = float(np.sqrt(np.mean(s**2)))
        if rms > 0:
            total += s / rms
            moved = True
    return total if moved else None


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    scale = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
    return float(np.sum(a * b) / scale) if scale > 0 else float("nan")


def coarse_lag(
    time_s: np.ndarray, wheels: np.ndarray, track: np.ndarray, reach_s: float = REACH_S
) -> tuple[float, float, float] | None:
    """The lag (s; the reference's stamps late of the wheels') within ±``reach_s`` at which the
    wheels' positions ``wheels`` (n, k) and the reference's track ``track`` (n, 3: x, y, unwrapped
    heading) at the records' ``time_s`` are busy together the most, with its correlation and the
    stamps' as logged (None: either never moves, or the log spans too little)."""
    t = np.asarray(time_s, dtype=float)
    lo, hi = t[0] + SPAN_S + reach_s, t[-1] - SPAN_S - reach_s
    if not hi - lo > 2 * reach_s:
        return None
    grid = np.arange(lo, hi, STEP_S)
    if grid.size > MAX_POINTS:
        middle = grid.size // 2
        grid = grid[middle - MAX_POINTS // 2 : middle + MAX_POINTS // 2]
    T = np.asarray(track, dtype=float)
    reference = busy(t, [T[:, :2], T[:, 2]], grid)
    if reference is None:
        return None
    steps = round(reach_s / STEP_S)
    lags = STEP_S * np.arange(-steps, steps + 1)
    # The reference at t against the wheels at t - lag: the reference stamped lag late.
    W = np.asarray(wheels, dtype=float)
    found = [busy(t, list(W.T), grid - lag) for lag in lags]
    scores = np.array([_correlation(reference, w) if w is not None else np.nan for w in found])
    if not np.any(np.isfinite(scores)):
        return None
    best = int(np.nanargmax(scores))
    return float(lags[best]), float(scores[best]), float(scores[steps])


def shown_lag(found: tuple[float, float, float] | None, reach_s: float = REACH_S) -> float | None:
    """The coarse lag of :func:`coarse_lag`'s ``found`` (over ±``reach_s``) where the data show it,
    else None (:func:`unshown` says why)."""
    return None if found is None or unshown(found, reach_s) else found[0]


def unshown(found: tuple[float, float, float], reach_s: float = REACH_S) -> str:
    """Why :func:`coarse_lag`'s ``found`` shows no lag, in words ("": it shows one). The best lag
    must be a peak inside the reach (at its edge the correlation still rises beyond: a slow drift,
    not a lag), the speeds must rise and fall together there (a car that slows into its bends
    makes the wheels' speed fall as the reference's turning rises: a negative correlation, best
    at whichever edge it drifts to), and it must correlate :data:`CLEARER` better than the stamps
    as logged."""
    lag, best, logged = found
    if not best > 0:
        return f"they never rise and fall together (correlation {best:.2f} at best)"
    if abs(lag) > reach_s - 0.5 * STEP_S:
        return f"their correlation still rises at the edge of ±{reach_s:g} s: no peak, no lag"
    if not best - logged >= CLEARER:
        return "hardly better than as stamped (a drive whose speed changes slowly tells lags apart poorly)"
    return ""
