"""Counter faults: counts lost or gained, shown by the counter's own history and confirmed by the
tracker over several intervals.

Each interval's residual, linearised in its inputs, gives per counter the correction ``c`` (in
ticks) that would make the reading agree with the tracker's motion over the interval. Summed,
the corrections give the count the tracker implies at each record. The tracker reports its poses
some time after the encoders read (the tracker lag), so the implied count is compared with the
logged one at the lag: the implied count is read ``lag`` later on the tracker's clock, between
records (the tracker's own glitches are taken out before, so nothing bad is spread). The lag is
the scenario's, or, when it is to be estimated, the one in its search range that makes the two
counts agree best: the screen runs before the lag is estimated, on the records as logged.

The difference between the counts is flat with noise, ramps while the counter reads stale and
returns when it catches up, and steps where counts were lost or gained. Its level is read only
right after a non-zero reading (no stall pending), as a median over :data:`PERSIST_INTERVALS`
such points before and after a stretch, which a short burst does not move. A **fault** is a step
beyond :data:`FAULT_SIGMAS` standard deviations of such steps along the log (or
:data:`AGAINST_SIGMAS` when the reading contradicts the tracker's direction) that the counter's
own history shows too: its count over the stretch is short of what its own speed just before and
after implies, in the same direction, by at least half as much. A genuine stop, reversal or wrap
agrees with the tracker once the lag is allowed for; a tracker that freezes or jumps leaves the
counter's history smooth: neither is a counter fault.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis.streams import robust_sigma, running_medians

#: A correction beyond this many robust standard deviations starts a candidate fault...
CANDIDATE_SIGMAS = 6.0
#: ...which is a fault when the level steps by more than this many standard deviations of such
#: steps across its stretch (:data:`PERSIST_INTERVALS` either side), or by more than
#: :data:`AGAINST_SIGMAS` when the reading contradicts the tracker's direction (itself evidence:
#: a sound counter never does).
FAULT_SIGMAS = 6.0
AGAINST_SIGMAS = 4.0
PERSIST_INTERVALS = 10
#: Longest stall a fault's stretch extends back over.
MAX_STALL = 25
#: The counter's own history must show at least this share of the deficit the tracker shows,
#: judged by its speed over this many moving intervals on either side.
OWN_SHARE = 0.5
OWN_INTERVALS = 3
#: Step of the grid of lags the screen tries when the lag is to be estimated (s), and where its
#: loss turns from quadratic to linear (units of scatter: a fault weighs no more than its size).
LAG_STEP = 0.002
HUBER = 3.0
#: The screen's terms are taken for every lag of its grid at once over a block of records, about
#: this many terms a block.
LAG_TERMS = 1 << 17


@dataclass(frozen=True)
class CounterFinding:
    """A counter fault over intervals ``first..last`` (``last + 1`` the record showing it): the
    counter's total over them as logged and as the tracker implies, and the latter's 1σ (ticks)."""

    kind: str
    first: int
    last: int
    logged: float
    implied: float
    noise: float


@dataclass(frozen=True)
class CounterScreen:
    """A counter's faults, its stale readings that caught up, and its per-interval noise (ticks)."""

    findings: tuple[CounterFinding, ...]
    stale: int
    noise: float


def counter_corrections(e: np.ndarray, de_du: np.ndarray, rows: list[int], scale: np.ndarray) -> np.ndarray:
    """Per interval, the counter increments (ticks) that best explain each residual ``e`` (rows, N:
    3 for a planar tracker, 6 for a 3-D one).

    ``de_du`` is (rows, N, n_in); the corrections of the counter ``rows`` solve the weighted least
    squares ``min |e + de_du·c|²`` with each residual component weighted by its robust scatter.
    """
    w = 1.0 / np.maximum([robust_sigma(e[i]) for i in range(e.shape[0])], 1e-12) ** 2
    G = de_du[:, :, rows]  # (rows, N, m)
    A = np.einsum("inj,i,ink->njk", G, w, G)
    b = -np.einsum("inj,i,in->nj", G, w, e)
    A = A + 1e-12 * np.trace(A, axis1=1, axis2=2)[:, None, None] * np.eye(len(rows))
    c = np.linalg.solve(A, b[:, :, None])[:, :, 0]  # (N, m) in input units
    return c * scale[None, :]


def at_lag(time_s: np.ndarray, ticks: np.ndarray, c: np.ndarray, lag_s: float) -> np.ndarray:
    """Corrections with the tracker-implied count read ``lag_s`` later than the logged one."""
    logged = np.concatenate([[0.0], np.cumsum(ticks)])
    implied = logged + np.concatenate([[0.0], np.cumsum(c)])
    shifted = np.interp(time_s + lag_s, time_s, implied)
    return np.diff(shifted) - ticks


def screen_lag(
    time_s: np.ndarray, ticks: list[np.ndarray], c: np.ndarray, lag: float | tuple[float, float]
) -> float:
    """``lag`` when given; else the lag in the range ``lag`` at which the counters' increments
    ``ticks``, read that much earlier, best match those the tracker implies (``ticks + c``, c
    ``(N, m)``): Huber's loss, each counter in units of its corrections' scatter at no lag.

    The counters are the ones interpolated here, not the tracker-implied counts: those carry the
    tracker's noise, which interpolation between records would smooth the more the further the
    lag falls between two records, and the smoothing, not the lag, would decide.
    """
    if not isinstance(lag, tuple):
        return float(lag)
    lo, hi = lag
    grid = lo + LAG_STEP * np.arange(int(np.floor((hi - lo) / LAG_STEP + 1e-9)) + 1)
    profiles = [_LagProfile(time_s, x, np.ascontiguousarray(c[:, j]), grid) for j, x in enumerate(ticks)]
    return float(grid[_least(profiles, grid.size)])


def lag_costs(time_s: np.ndarray, x: np.ndarray, c: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """One counter's term of :func:`screen_lag`'s cost at each lag of ``grid`` (increasing):
    Huber's loss of ``|Δcount(t − g) − x − c| / unit`` summed over the intervals.

    Taken over blocks of records, every lag at once (temporaries that stay in the processor's
    cache, where one pass over every record per lag went through memory a dozen times), and
    summed as that pass's ``np.sum`` did: the same cost to the last bit (:func:`_pairwise`)."""
    profile = _LagProfile(time_s, x, c, grid)
    every = np.arange(grid.size)
    for leaf in range(len(profile.leaves)):
        profile.add(leaf, every)
    return profile.joined(every)


class _LagProfile:
    """One counter's lag profile (:func:`lag_costs`) by blocks of records (the leaves of
    :func:`_pairwise`'s halving), each block's sums kept per lag so that any lags' costs are joined
    from them as the pass over every record sums them: the lags need not be taken together."""

    def __init__(self, time_s: np.ndarray, x: np.ndarray, c: np.ndarray, grid: np.ndarray) -> None:
        self.time_s, self.x, self.c, self.grid = time_s, x, c, grid
        self.unit = max(robust_sigma(c), 1e-12)
        self.count = np.concatenate([[0.0], np.cumsum(x)])
        #: Whether every term is a number (no NaN a lag's skipped blocks could hold).
        self.finite = bool(
            np.all(np.isfinite(time_s)) and np.all(np.isfinite(self.count)) and np.all(np.isfinite(c))
        )
        self.leaf = max(LAG_TERMS // max(grid.size, 1), 128)
        self.leaves = _leaves(0, x.size, self.leaf)
        self.first = {a: i for i, (a, _) in enumerate(self.leaves)}
        #: Each block's sum per lag (NaN: not taken yet).
        self.sums = np.full((len(self.leaves), grid.size), np.nan)

    def add(self, leaf: int, lags: np.ndarray) -> np.ndarray:
        """The sums of block ``leaf`` at the lags ``lags`` (indices into the grid, increasing),
        kept and returned."""
        a, b = self.leaves[leaf]
        terms = _lag_terms(
            self.time_s, self.count, (a, b), self.x[a:b], self.c[a:b], self.unit, self.grid[lags]
        )
        self.sums[leaf, lags] = terms.sum(axis=1)
        return self.sums[leaf, lags]

    def joined(self, lags: np.ndarray) -> np.ndarray:
        """The cost at ``lags``, every block of theirs taken: np.sum's over every record."""
        return _pairwise(lambda a, _: self.sums[self.first[a], lags], 0, self.x.size, self.leaf)


#: Blocks of the lag profile taken at every lag before the rest are taken lag by lag as needed:
#: every this many-th block (a sample spread over the log, which picks the lag to beat).
SAMPLE_EVERY = 16
#: The lags that cost more than the lag to beat already are dropped every this many blocks.
PRUNE_EVERY = 8


def _least(profiles: list[_LagProfile], n_lags: int) -> int:
    """The index of the least of the counters' summed lag profiles (``n_lags`` ≥ 1 lags), as
    ``np.argmin`` of their sum at every lag gives it, without taking every lag over every record:
    the terms are never negative, so a lag whose blocks taken so far already cost more than one
    lag's whole cost is not the least, and its other blocks are skipped. The lags left are summed
    as the whole profile sums them. With a reading that is not a number none is skipped: a NaN,
    which ``np.argmin`` picks, could be in a block skipped."""
    every = np.arange(n_lags)
    n_leaves = len(profiles[0].leaves) if profiles else 0
    order = [i for r in range(SAMPLE_EVERY) for i in range(r, n_leaves, SAMPLE_EVERY)]
    sample, rest = order[: -(-n_leaves // SAMPLE_EVERY)], order[-(-n_leaves // SAMPLE_EVERY) :]
    taken = np.zeros(n_lags)
    for leaf in sample:
        for p in profiles:
            taken += p.add(leaf, every)
    best = np.array([int(np.argmin(taken))])
    for leaf in rest:
        for p in profiles:
            p.add(leaf, best)
    # The partial sums' rounding is far below this margin: a lag skipped costs more than ``best``.
    bound = _total(profiles, best)[0] * (1.0 + 1e-9)
    alive = every[every != best[0]]
    skip = all(p.finite for p in profiles)
    for k, leaf in enumerate(rest):
        if skip and k % PRUNE_EVERY == 0:
            alive = alive[~(taken[alive] > bound)]
        if not alive.size:  # every other lag costs more already: the best's blocks are all taken
            break
        for p in profiles:
            taken[alive] += p.add(leaf, alive)
    left = np.union1d(alive, best)
    return int(left[int(np.argmin(_total(profiles, left)))])


def _total(profiles: list[_LagProfile], lags: np.ndarray) -> np.ndarray:
    """The counters' costs at ``lags`` added as :func:`screen_lag` adds their profiles."""
    cost = np.zeros(lags.size)
    for p in profiles:
        cost += p.joined(lags)
    return cost


def _lag_terms(
    time_s: np.ndarray,
    count: np.ndarray,
    span: tuple[int, int],
    x: np.ndarray,
    c: np.ndarray,
    unit: float,
    grid: np.ndarray,
) -> np.ndarray:
    """The loss of the intervals ``span`` ``(lags, intervals)``, each term as one lag's pass over
    every record computes it (the operations in the same order)."""
    ends = time_s[span[0] : span[1] + 1]
    # The records bracketing every time read: np.interp on them alone gives what it does on all.
    a = max(int(np.searchsorted(time_s, ends[0] - grid[-1], "right")) - 1, 0)
    b = int(np.searchsorted(time_s, ends[-1] - grid[0], "right")) + 1
    # A lag's records along a row (no transposed copy): np.interp's guess of the bracket holds
    # from one to the next.
    shifted = np.interp(ends[None, :] - grid[:, None], time_s[a:b], count[a:b])
    r = shifted[:, 1:] - shifted[:, :-1]
    r -= x
    r -= c
    np.abs(r, out=r)
    r /= unit
    inside = r < HUBER
    square = r * 0.5
    square *= r
    r *= HUBER
    r -= 0.5 * HUBER**2
    np.copyto(r, square, where=inside)
    return r


def _leaves(lo: int, n: int, leaf: int) -> list[tuple[int, int]]:
    """The blocks ``(a, b)`` at which :func:`_pairwise` over ``lo … lo + n`` calls ``sums``, in order."""
    if n <= leaf:
        return [(lo, lo + n)]
    half = n // 2 - (n // 2) % 8
    return _leaves(lo, half, leaf) + _leaves(lo + half, n - half, leaf)


def _pairwise(sums: Callable[[int, int], np.ndarray], lo: int, n: int, leaf: int) -> np.ndarray:
    """The sum over the items ``lo … lo + n`` from ``sums`` of blocks of at most ``leaf`` items
    (``sums(a, b)``, the sum over items ``a … b``, one per column), added as numpy's pairwise
    summation adds one array's items (halves, the first a multiple of eight): ``np.sum`` of all,
    to the last bit, without holding all."""
    if n <= leaf:
        return sums(lo, lo + n)
    half = n // 2 - (n // 2) % 8
    return _pairwise(sums, lo, half, leaf) + _pairwise(sums, lo + half, n - half, leaf)


def _level(C: np.ndarray, idx: np.ndarray) -> float:
    """The level over indices ``idx``: their median (NaN for fewer than two)."""
    return float(np.median(C[idx])) if idx.size >= 2 else float("nan")


def _stretches(ticks: np.ndarray, c: np.ndarray, candidates: list[int], sigma: float) -> dict[int, int]:
    """Per candidate interval, the first interval of its stretch: back over the stall before it
    (readings that stayed put, or caught up only partly, short in the fault's direction by 2σ)."""
    firsts = {}
    for k in candidates:
        first = k
        while first > 0 and k - first < MAX_STALL:
            prev = first - 1
            if not (ticks[prev] == 0 or (np.sign(c[prev]) == np.sign(c[k]) and abs(c[prev]) > 2.0 * sigma)):
                break
            first = prev
        firsts[int(k)] = int(first)
    return firsts


def own_deficits(ticks: np.ndarray, time_s: np.ndarray, first: int, last: int) -> list[float]:
    """The counts the counter's own speed implies over intervals ``first..last``, less those it
    logged: at its speed just before, just after (medians over :data:`OWN_INTERVALS` moving
    intervals) and their mean (the robot may change speed or direction on either side)."""
    speed = ticks / np.maximum(np.diff(time_s), 1e-9)
    span = float(time_s[last + 1] - time_s[first])
    before, after = speed[:first][ticks[:first] != 0], speed[last + 1 :][ticks[last + 1 :] != 0]
    sides = [float(np.median(s)) for s in (before[-OWN_INTERVALS:], after[:OWN_INTERVALS]) if s.size]
    rates = sides + ([float(np.mean(sides))] if len(sides) == 2 else [])
    return [r * span - float(np.sum(ticks[first : last + 1])) for r in rates]


def _step_noise(C: np.ndarray, valid: np.ndarray, fallback: np.ndarray, sigma: float) -> float:
    """The noise of a level step, from steps taken everywhere along the log (faults are few)."""
    W = PERSIST_INTERVALS
    levels = C[valid]
    if levels.size >= 2 * W:
        # A sorting network's medians where no level is a nan: np.median's values (a zero's sign
        # aside, which the robust σ of their steps drops: the same σ to the bit); a nan makes its
        # runs' medians nan, as np.median does.
        if np.isnan(levels).any():
            medians = np.median(np.lib.stride_tricks.sliding_window_view(levels, W), axis=1)
        else:
            medians = running_medians(levels, W)
        return max(robust_sigma(medians[W:] - medians[:-W]), sigma)
    return max(robust_sigma(fallback), sigma)


def screen_counter(ticks: np.ndarray, c: np.ndarray, time_s: np.ndarray) -> CounterScreen:
    """The faults of one counter, its increments ``ticks`` (N,) against the corrections ``c`` (N,)
    the tracker implies at the lag (see the module docstring); ``time_s`` the N + 1 record times."""
    N = c.size
    implied = ticks + c
    sigma = robust_sigma(c)
    if not np.isfinite(sigma) or sigma <= 0:
        return CounterScreen((), 0, sigma)
    C = np.concatenate([[0.0], np.cumsum(c)])  # C[k] = sum of c over intervals < k
    valid = np.concatenate([[0], np.flatnonzero(ticks != 0) + 1])
    W = PERSIST_INTERVALS
    against = (np.sign(ticks) == -np.sign(implied)) & (ticks != 0) & (np.abs(c) > 3.0 * sigma)
    catch_up = np.zeros(N, dtype=bool)
    catch_up[1:] = (ticks[1:] != 0) & (ticks[:-1] == 0)  # zero readings are judged with their catch-up
    large = (np.abs(c) > CANDIDATE_SIGMAS * sigma) & (ticks != 0)
    open_: list[int] = np.flatnonzero(against | catch_up | large).tolist()
    firsts = _stretches(ticks, c, open_, sigma)
    accepted: list[tuple[int, int]] = []  # stretches (first, last) of the faults found so far
    # Each candidate's step, until the next fault found: a candidate passed over changes no level.
    known: dict[int, float] = {}

    def step(k: int) -> float:
        if k in known:
            return known[k]
        # Levels never reach across a fault already found: it would lend its step to k.
        lo = max((last + 1 for first, last in accepted if last < firsts[k]), default=0)
        hi = min((first for first, last in accepted if first > k), default=N)
        b0, b1 = np.searchsorted(valid, lo, "left"), np.searchsorted(valid, firsts[k], "right")
        a0, a1 = np.searchsorted(valid, k + 1, "left"), np.searchsorted(valid, hi, "right")
        known[k] = _level(C, valid[a0:a1][:W]) - _level(C, valid[b0:b1][-W:])
        return known[k]

    step_sigma = _step_noise(C, valid, np.array([step(k) for k in open_]), sigma)
    found: list[CounterFinding] = []
    # The most significant step first, so that the strongest faults bound their neighbours' levels.
    while open_:
        steps = np.array([step(k) for k in open_])
        # Across a stall the level wanders by the corrections of the stalled intervals too.
        noise = np.hypot(step_sigma, sigma * np.sqrt([k - firsts[k] for k in open_]))
        limit = np.array([AGAINST_SIGMAS if against[k] else FAULT_SIGMAS for k in open_]) * noise
        score = np.abs(steps) / limit
        if not np.any(score > 1.0):
            break
        i = int(np.nanargmax(score))
        k = open_.pop(i)
        first = firsts[k]
        if not any(d * steps[i] >= OWN_SHARE * steps[i] ** 2 for d in own_deficits(ticks, time_s, first, k)):
            continue  # the counter's own history runs smoothly through: the tracker is off, not it
        accepted.append((first, k))
        known.clear()
        open_ = [j for j in open_ if not first <= j <= k and not firsts[j] <= k < j]
        kind = "stall_then_jump" if first < k else ("reversal" if against[k] else "counter_jump")
        total = (float(np.sum(ticks[first : k + 1])), float(np.sum(implied[first : k + 1])))
        found.append(CounterFinding(kind, first, k, *total, float(sigma * np.sqrt(k + 1 - first))))
    faulty = np.zeros(N, dtype=bool)
    for f in found:
        faulty[f.first : f.last + 1] = True
    n_stale = int(np.sum((ticks == 0) & (np.abs(implied) > 3.0 * sigma) & ~faulty))
    return CounterScreen(tuple(sorted(found, key=lambda f: f.first)), n_stale, sigma)


def screen_counters(
    e: np.ndarray,
    de_du: np.ndarray,
    logged: np.ndarray,
    counters: Mapping[str, tuple[int, float]],
    time_s: np.ndarray,
    lag: float | tuple[float, float],
) -> tuple[dict[str, CounterScreen], float]:
    """Each counter's screen from the N intervals' residuals ``e`` (rows, N) and ``de_du`` (rows, N,
    n_in) and inputs ``logged`` (n_in, N); ``counters`` maps names to input row and ticks per unit.
    Also the lag used (given, or estimated when ``lag`` is a range)."""
    names = list(counters)
    if not names or e.shape[1] == 0:
        return {}, float(lag) if not isinstance(lag, tuple) else 0.0
    rows = [counters[n][0] for n in names]
    scale = np.array([counters[n][1] for n in names])
    corrections = counter_corrections(e, de_du, rows, scale)
    ticks = [logged[r] * s for r, s in zip(rows, scale)]
    lag_s = screen_lag(time_s, ticks, corrections, lag)
    out = {}
    for j, name in enumerate(names):
        out[name] = screen_counter(ticks[j], at_lag(time_s, ticks[j], corrections[:, j], lag_s), time_s)
    return out, lag_s
