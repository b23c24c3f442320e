"""Glitches one stream shows on its own: a reading off the path its neighbours agree on.

A tracker pose or an absolute encoder's reading that is off for one record (or a few, when the
log's records interpolate a slower stream) departs from every path its neighbours allow. A
genuine motion does not: the neighbours on one side continue into it (a stop, a reversal or a
start is a kink, explained by the straight line through the two records on one side of it, or by
the two lines meeting between records), or the straight line between the neighbours on both sides
passes through it. A group of ``g`` records is therefore judged by predictions from the two
records on each side: the line through the left pair carried forward (``L``), the line through
the right pair carried back (``R``), the two meeting where they come closest (one kink), and the
chord between the nearest outside records (``B``). Its score is the smallest of the chord's
largest miss, the kinked path's, and, over every split of the group into a left and a right
part, the larger of ``L``'s miss on the left part and ``R``'s on the right: a single kink
anywhere costs nothing, an off reading misses every prediction. Misses are in units of the
stream's scatter about the chord between adjacent neighbours (robust, over the log; growing with
the rate of change where readings are late or early), times each prediction's own noise (a line
carried further from its two records is the less certain). A glitch must also leave the span of
its near neighbours: a corner cut by a slow tracker interpolated onto faster records stays inside
it. Groups are taken strongest first; a sound record a group took in beside or between bad ones,
one that lies on the chord between the records around the group, is given back.

A stuck absolute encoder is another glitch of its own stream: its reading holds for several
records while the thing it measures moves on, then jumps to where it is. A genuine hold ends
with a start no faster than the motion that follows it; a stuck reading ends with a catch-up of
the whole motion it missed (:func:`stuck_runs`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: A group scoring above this many units of its stream's scatter is off its neighbours.
OFF_SIGMAS = 10.0
#: Longest run of consecutive records judged as one group (a slow stream interpolated onto the
#: records of a faster one spreads one bad reading over about twice the rate ratio).
MAX_GROUP = 4
#: Records a stuck reading must hold (the first reading and at least two repeats of it).
MIN_STUCK = 3
#: A catch-up is a jump when it exceeds this many times the motion per record around it.
CATCH_UP_FACTOR = 2.5
#: A stream that makes more than this share of its motion in the steps right after a repeated
#: reading moves by steps (a steering command held between commands, a position updated slower
#: than it is logged): its holds are how it moves, not a stuck sensor's. A sensor that reads
#: smoothly makes a few per cent of it so (the real tricycle's steering: 3 %; a commanded F1/10
#: steering: 48 %).
STEPWISE_SHARE = 0.25
#: Groups scored at once in the first pass over a stream; records bounded at once before it.
FIRST_PASS_BLOCK = 8192
BOUND_BLOCK = 65_536
#: An interval between records longer than this many times their median interval, and than
#: :data:`MIN_GAP_S`, is a gap in a stream (the tracker lost, the joints missing): one arc of the
#: model cannot span it. (A fast log's jitter makes intervals of several times the median, and
#: the model's arc spans a few hundredths of a second of any drive.)
GAP_FACTOR = 5.0
MIN_GAP_S = 0.2


def gap_threshold(time_s: np.ndarray) -> float:
    """The shortest interval between records that is a gap (s)."""
    dt = np.diff(np.asarray(time_s, dtype=float))
    return max(GAP_FACTOR * float(np.median(dt)), MIN_GAP_S) if dt.size else np.inf


def time_gaps(time_s: np.ndarray) -> np.ndarray:
    """The intervals (``k`` joins records ``k`` and ``k + 1``) longer than :func:`gap_threshold`:
    a stream's gap, which no window may cross."""
    return np.diff(np.asarray(time_s, dtype=float)) > gap_threshold(time_s)


def robust_sigma(x: np.ndarray) -> float:
    """1.4826 × the median absolute deviation (a standard deviation that ignores outliers)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan")
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def printed_step(y: np.ndarray) -> np.ndarray:
    """Each column's printed precision: the step of the decimals its values were written with (0
    when they carry more than nine, or none could be told): rounding to it is noise the screen
    must allow for however clean the data are."""
    y = np.asarray(y, dtype=float).reshape(len(y), -1)
    out = np.zeros(y.shape[1])
    for c in range(y.shape[1]):
        v = y[np.isfinite(y[:, c]), c]
        # |v|·10^k rounds up with |v|: its largest is the largest |v|'s.
        largest = float(np.max(np.abs(v))) if v.size else 0.0
        for k in range(10):
            if not v.size or largest * 10.0**k > 1e9:
                break  # beyond what a double tells apart from its decimals
            # The first readings tell most columns' decimals apart (and cost a fraction of all).
            if _rounded(v[:PRINTED_HEAD], k) and _rounded(v, k):
                out[c] = 10.0**-k
                break
    return out


#: The readings :func:`printed_step` tries each number of decimals on before all of them.
PRINTED_HEAD = 4096


def _rounded(v: np.ndarray, k: int) -> bool:
    """Whether the values ``v`` are written with ``k`` decimals (to 1e-6 of a step)."""
    scaled = v * 10.0**k
    return bool(np.max(np.abs(scaled - np.round(scaled))) < 1e-6)


@dataclass(frozen=True)
class Scatter:
    """A stream's scatter about the chord between a reading's neighbours, per component: ``floor``
    at rest, growing with the rate of change by ``timing`` (s: the readings' timing noise).
    ``bend`` ``(2, n, d)``, where given: the path's own acceleration around each record, looking
    back (``bend[0]``) and ahead (``bend[1]``), where it exceeds what the noise explains: a smooth
    path misses a chord by that much whatever its noise (:func:`path_bend`). ``vector``: how many
    leading columns are one vector's components (a position), whose rate changes as a whole."""

    floor: np.ndarray
    timing: np.ndarray
    bend: np.ndarray | None = None
    vector: int = 0

    def at(self, rate: np.ndarray) -> np.ndarray:
        return np.sqrt(self.floor**2 + (self.timing * rate) ** 2)

    def bent(self, rate: np.ndarray, outer: tuple[np.ndarray, np.ndarray], span: np.ndarray) -> np.ndarray:
        """:meth:`at`, with the miss of a path bending as it does beyond the records ``outer``
        ``(l2, r2)`` from a chord over ``span`` (s): the discretisation of a smooth drive."""
        sigma = self.at(rate)
        if self.bend is None:
            return sigma
        accel = np.maximum(self.bend[0][outer[0]], self.bend[1][outer[1]])
        return np.sqrt(sigma**2 + (accel * (span**2 / 8.0)[:, None]) ** 2)


def scatter(t: np.ndarray, y: np.ndarray, resolution: np.ndarray | float = 0.0) -> Scatter:
    """The scatter of ``y`` ``(n, d)`` about its chords (:func:`chord_scatter`) and where its path
    bends beyond it (:func:`path_bend`)."""
    y = np.asarray(y, dtype=float).reshape(len(t), -1)
    sc = chord_scatter(t, y, resolution)
    return sc if len(t) < 5 else Scatter(sc.floor, sc.timing, path_bend(t, y, sc))


def chord_scatter(t: np.ndarray, y: np.ndarray, resolution: np.ndarray | float = 0.0) -> Scatter:
    """The scatter of ``y`` ``(n, d)`` about its chords: robust over the slowest quarter of the
    records at rest (at least ``resolution``, a reading's step), and relative to the rate over the
    fastest half."""
    y = np.asarray(y, dtype=float).reshape(len(t), -1)
    d = y.shape[1]
    res = np.broadcast_to(np.asarray(resolution, dtype=float), (d,))
    if len(t) < 5:
        return Scatter(res.copy(), np.zeros(d))
    span = np.maximum(t[2:] - t[:-2], 1e-12)[:, None]
    s = (t[1:-1] - t[:-2])[:, None] / span
    miss = y[1:-1] - (y[:-2] + s * (y[2:] - y[:-2]))
    rate = np.abs(y[2:] - y[:-2]) / span
    floor, timing = np.empty(d), np.zeros(d)
    for c in range(d):
        slow = rate[:, c] <= np.percentile(rate[:, c], 25)
        floor[c] = max(robust_sigma(miss[slow, c]), res[c])
        fast = rate[:, c] >= max(np.median(rate[:, c]), 1e-12)
        if np.sum(fast) >= 10:
            timing[c] = robust_sigma(miss[fast, c] / rate[fast, c])
    return Scatter(floor, timing)


#: Second differences around a record a path's bend is taken over (the median: a glitch's own
#: do not count).
BEND_WINDOW = 7
#: The path bends where its second differences exceed this many times what its noise gives.
BEND_OVER_NOISE = 3.0


def path_bend(t: np.ndarray, y: np.ndarray, sc: Scatter) -> np.ndarray | None:
    """Each record's acceleration of the path ``(2, n, d)`` over :data:`BEND_WINDOW` second
    differences behind it and ahead of it, where it exceeds :data:`BEND_OVER_NOISE` times what the
    stream's scatter explains (0 elsewhere: a noisy stream's chords already allow for it); None
    when nothing bends beyond its noise. Taken :data:`MEDIAN_BLOCK` records at a time (each
    record's value from its own neighbours: the temporaries of a block, not of the log)."""
    n, d = y.shape
    if n < BEND_WINDOW + 2:
        return None
    bend = np.zeros((2, n, d))
    for lo in range(BEND_WINDOW - 1, n, MEDIAN_BLOCK):
        hi = min(lo + MEDIAN_BLOCK, n)
        bend[0, lo:hi] = _bend_behind(t, y, sc, (lo, hi))
    # Looking ahead from a record is looking back from the record a window later.
    bend[1, : n - BEND_WINDOW + 1] = bend[0, BEND_WINDOW - 1 :]
    return bend if bend[0].any() else None


def _bend_behind(t: np.ndarray, y: np.ndarray, sc: Scatter, rows: tuple[int, int]) -> np.ndarray:
    """:func:`path_bend` looking back, at the records ``rows`` (``lo >= BEND_WINDOW - 1``): the
    median of the second differences at the :data:`BEND_WINDOW` records ending at each (nan at a
    log's ends), where it exceeds that of their noise floors (inf at the ends)."""
    lo, hi = rows
    n, d = y.shape
    a = lo - (BEND_WINDOW - 1)  # the first record whose second difference a row's median takes
    i0, i1 = max(a, 1), min(hi, n - 1)  # those of them with a neighbour on each side
    ts, ys = t[i0 - 1 : i1 + 1], y[i0 - 1 : i1 + 1]
    h_left, h_right = np.maximum(ts[1:-1] - ts[:-2], 1e-12), np.maximum(ts[2:] - ts[1:-1], 1e-12)
    slope_left, slope_right = (ys[1:-1] - ys[:-2]) / h_left[:, None], (ys[2:] - ys[1:-1]) / h_right[:, None]
    accel = np.abs(slope_right - slope_left) / (0.5 * (h_left + h_right))[:, None]
    h2 = (0.5 * (h_left + h_right))[:, None] ** 2
    rate = np.maximum(np.abs(slope_left), np.abs(slope_right))
    # White noise of scatter σ gives second differences of median 0.6745·√6·σ.
    noise = 0.6745 * np.sqrt(6.0) * sc.at(rate) / h2
    level = np.full((hi - a, d), np.nan)
    level[i0 - a : i1 - a] = accel
    floor = np.full((hi - a, d), np.inf)
    floor[i0 - a : i1 - a] = BEND_OVER_NOISE * noise
    medians = np.nan_to_num(running_medians(level), nan=0.0)
    return np.where(medians > running_medians(floor), medians, 0.0)


#: Records whose trailing medians are taken at once: bounds the window's copies (a log's worth at
#: once held 2·7 copies of the signal, hundreds of MB on 10^6 records).
MEDIAN_BLOCK = 65_536


def running_medians(a: np.ndarray, w: int = BEND_WINDOW) -> np.ndarray:
    """The nan-median of every run of ``w`` rows of ``a`` ``(n, ...)``, ``(n - w + 1, ...)``
    (:func:`_window_medians`), a block of rows at a time; ``np.median``'s values where no run
    holds a nan (a zero's sign may differ)."""
    n = a.shape[0]
    out = np.empty((max(n - w + 1, 0), *a.shape[1:]))
    for lo in range(0, out.shape[0], MEDIAN_BLOCK):
        hi = min(lo + MEDIAN_BLOCK, out.shape[0])
        out[lo:hi] = _window_medians(a[lo : hi + w - 1], w)
    return out


def _window_medians(a: np.ndarray, w: int) -> np.ndarray:
    """``np.nanmedian`` of every run of ``w`` rows of ``a``, to the bit: runs without a nan sorted
    by an odd-even transposition network of elementwise min/max over whole columns (nanmedian on
    short runs goes through masked arrays, most of the screen's time on long logs); runs with one
    by ``nanmedian`` itself."""
    m = a.shape[0] - w + 1
    rows = [a[i : i + m] for i in range(w)]
    for phase in range(w):
        for i in range(phase % 2, w - 1, 2):
            rows[i], rows[i + 1] = np.minimum(rows[i], rows[i + 1]), np.maximum(rows[i], rows[i + 1])
    # Even runs: the mean of the middle two, as np.median takes it.
    med = np.array(rows[w // 2]) if w % 2 else (rows[w // 2 - 1] + rows[w // 2]) / 2
    isnan = np.isnan(a)
    if not isnan.any():
        return med
    # The runs with a nan: those over which the count of nans grows.
    count = np.concatenate([np.zeros((1, *a.shape[1:]), dtype=np.int64), np.cumsum(isnan, axis=0)])
    nan = count[w:] > count[:-w]
    med[nan] = np.nanmedian(np.lib.stride_tricks.sliding_window_view(a, w, axis=0)[nan], axis=-1)
    return med


@dataclass(frozen=True)
class OffGroup:
    """Records ``first..last`` off their neighbours by ``score`` units of scatter; ``offset`` is
    the reading's departure from the chord between the neighbours where it is largest."""

    first: int
    last: int
    score: float
    offset: np.ndarray


def _spread(t: np.ndarray, a: np.ndarray, b: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The noise of a reading's miss from the line through records ``a`` and ``b`` (P,) at times
    ``at`` (P, g), in units of a reading's miss from the chord midway between its neighbours."""
    s = (at - t[a][:, None]) / np.maximum(t[b] - t[a], 1e-12)[:, None]
    return np.sqrt(((1.0 - s) ** 2 + s**2 + 1.0) / 1.5)


def _scores(
    t: np.ndarray,
    y: np.ndarray,
    sc: Scatter,
    outside: tuple[np.ndarray, ...],
    m: np.ndarray,
    excursion: np.ndarray | float,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_scored`, where a stream without scatter (a noise-free simulation) has no scale to
    judge a miss by: its scores are nan, and nan is never off the path."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return _scored(t, y, sc, outside, m, excursion)


def _scored(
    t: np.ndarray,
    y: np.ndarray,
    sc: Scatter,
    outside: tuple[np.ndarray, ...],
    m: np.ndarray,
    excursion: np.ndarray | float,
) -> tuple[np.ndarray, np.ndarray]:
    """Scores of groups of records ``m`` ``(P, g)``, each between the outside records ``(l2, l1,
    r1, r2)`` ``(P,)`` (see the module docstring), and each group's largest chord miss ``(P, d)``."""
    l2, l1, r1, r2 = outside
    tm = t[m]
    vL = (y[l1] - y[l2]) / np.maximum(t[l1] - t[l2], 1e-12)[:, None]
    vR = (y[r2] - y[r1]) / np.maximum(t[r2] - t[r1], 1e-12)[:, None]
    L = y[l1][:, None] + vL[:, None] * (tm - t[l1][:, None])[..., None]
    R = y[r1][:, None] + vR[:, None] * (tm - t[r1][:, None])[..., None]
    chord = (y[r1] - y[l1]) / np.maximum(t[r1] - t[l1], 1e-12)[:, None]
    C = y[l1][:, None] + chord[:, None] * (tm - t[l1][:, None])[..., None]
    sigma = sc.bent(np.maximum(np.abs(vL), np.abs(vR)), (l2, r2), t[r1] - t[l1])
    # A kink where the two lines come closest (in units of scatter), between the near neighbours.
    A = (y[l1] - vL * t[l1][:, None] - y[r1] + vR * t[r1][:, None]) / sigma
    B = (vL - vR) / sigma
    bb = np.sum(B * B, axis=1)
    kink = np.where(bb > 0, -np.sum(A * B, axis=1) / np.where(bb > 0, bb, 1.0), t[l1])
    kink = np.clip(kink, t[l1], t[r1])
    before = tm <= kink[:, None]
    K = np.where(before[..., None], L, R)
    ym = y[m]
    # Each prediction's noise, in units of the chord's between adjacent neighbours: lines carried
    # further from the two records that define them are the less certain.
    fL, fR, fC = _spread(t, l2, l1, tm), _spread(t, r1, r2, tm), _spread(t, l1, r1, tm)

    # A change of rate from vL to vR made smoothly anywhere between the near neighbours (a start
    # over a few records, not a corner) misses every one of these paths by up to a quarter of the
    # change times the span: no noise, so taken off the miss rather than scaled by the threshold.
    # A vector's rate may turn as it changes (a start while the wheel swings): each component is
    # allowed the size of the whole change.
    change = np.abs(vR - vL)
    if sc.vector > 1:
        change[:, : sc.vector] = np.linalg.norm(change[:, : sc.vector], axis=1)[:, None]
    slack = (change * (t[r1] - t[l1])[:, None] / 4.0)[:, None]

    def size(D: np.ndarray, k: np.ndarray) -> np.ndarray:
        D = np.maximum(np.abs(D) - slack, 0.0)
        return np.sqrt(np.sum((D / (k[..., None] * sigma[:, None])) ** 2, axis=-1))

    left = np.maximum.accumulate(size(ym - L, fL), axis=1)  # left[:, j]: worst of 0..j
    right = np.maximum.accumulate(size(ym - R, fR)[:, ::-1], axis=1)[:, ::-1]
    zero = np.zeros((m.shape[0], 1))
    split = np.maximum(np.hstack([zero, left]), np.hstack([right, zero])).min(axis=1)
    kinked = size(ym - K, np.where(before, fL, fR)).max(axis=1)
    score = np.minimum.reduce([size(ym - C, fC).max(axis=1), kinked, split])
    departs = _departs(y, (l1, r1), m, excursion)
    worst = np.argmax(size(ym - C, fC), axis=1)
    return np.where(departs, score, 0.0), (ym - C)[np.arange(m.shape[0]), worst]


def _departs(
    y: np.ndarray, near: tuple[np.ndarray, np.ndarray], m: np.ndarray, excursion: np.ndarray | float
) -> np.ndarray:
    """Whether each group ``m`` ``(P, g)`` leaves the span of its near neighbours ``(l1, r1)`` by
    more than ``excursion`` (a reading that departs and returns); all True without one."""
    l1, r1 = near
    least = np.broadcast_to(np.asarray(excursion, dtype=float), (y.shape[1],))
    if not np.any(least > 0):
        return np.ones(m.shape[0], dtype=bool)
    ym = y[m]
    hi, lo = np.maximum(y[l1], y[r1])[:, None], np.minimum(y[l1], y[r1])[:, None]
    beyond = (np.maximum(ym - hi, 0.0) + np.maximum(lo - ym, 0.0)) / np.where(least > 0, least, np.inf)
    return np.asarray(np.sqrt(np.sum(beyond**2, axis=-1)).max(axis=1) > 1.0)


def _outside(usable: np.ndarray, first: int, last: int) -> np.ndarray | None:
    """The two nearest usable records before ``first`` and after ``last`` (None at a log end)."""
    before = np.flatnonzero(usable[:first])[-2:]
    after = np.flatnonzero(usable[last + 1 :])[:2] + last + 1
    if before.size < 2 or after.size < 2:
        return None
    return np.array([before[0], before[1], after[0], after[1]])


def _strongest(
    t: np.ndarray,
    y: np.ndarray,
    sc: Scatter,
    span: tuple[int, int],
    usable: np.ndarray,
    limits: tuple[float, np.ndarray | float, int],
) -> OffGroup | None:
    """The group of up to ``max_group`` usable records in ``span`` that scores highest above
    ``threshold`` against the two nearest usable records on each side (the first such, by size
    then position, on a tie); every group of a size scored at once."""
    threshold, excursion, max_group = limits
    idx = np.flatnonzero(usable)
    gaps = np.concatenate([[0], np.cumsum(~usable)])
    best: OffGroup | None = None
    for g in range(1, int(max_group) + 1):
        p = np.arange(span[0], span[1] - g + 2)
        p = p[gaps[p + g] == gaps[p]]  # every record of the group usable
        k, j = np.searchsorted(idx, p), np.searchsorted(idx, p + g - 1, side="right")
        inside = (k >= 2) & (j + 1 < idx.size)  # two usable records on each side
        p, k, j = p[inside], k[inside], j[inside]
        if not p.size:
            continue
        outside = (idx[k - 2], idx[k - 1], idx[j], idx[j + 1])
        s, off = _scores(t, y, sc, outside, p[:, None] + np.arange(g)[None, :], excursion)
        top = int(np.argmax(np.where(s > threshold, s, -np.inf)))
        if s[top] > threshold and (best is None or s[top] > best.score):
            best = OffGroup(int(p[top]), int(p[top]) + g - 1, float(s[top]), off[top])
    return best


def _resolve(
    t: np.ndarray,
    y: np.ndarray,
    sc: Scatter,
    span: tuple[int, int],
    usable: np.ndarray,
    limits: tuple[float, np.ndarray | float, int],
) -> list[OffGroup]:
    """The groups off their neighbours among the records ``span``: the strongest first, each judged
    against the nearest usable records not already found; then each group's ends that are not off
    on their own are given back."""
    threshold = limits[0]
    usable = usable.copy()
    found: list[OffGroup] = []

    while (best := _strongest(t, y, sc, span, usable, limits)) is not None:
        usable[best.first : best.last + 1] = False
        found.append(best)

    def chord(e: int, f: OffGroup) -> float:
        """How far record ``e`` is off the chord between the nearest usable records around its group."""
        around = _outside(usable, f.first, f.last)
        if around is None:
            return np.inf
        a, b = around[1], around[2]
        slope = (y[b] - y[a]) / max(t[b] - t[a], 1e-12)
        miss = y[e] - (y[a] + slope * (t[e] - t[a]))
        return float(np.sqrt(np.sum((miss / sc.at(np.abs(slope))) ** 2)))

    # A group may have taken in a sound record beside or between bad ones: give back every record
    # that lies on the chord between the records around its group.
    kept = []
    for f in found:
        off = [e for e in range(f.first, f.last + 1) if chord(e, f) > threshold]
        usable[f.first : f.last + 1] = True
        usable[off] = False
        for run in np.split(np.array(off, dtype=int), np.flatnonzero(np.diff(off) > 1) + 1):
            if run.size:
                kept.append(OffGroup(int(run[0]), int(run[-1]), f.score, f.offset))
    return sorted(kept, key=lambda f: f.first)


def _may_depart(y: np.ndarray, idx: np.ndarray, excursion: np.ndarray | float, reach: int) -> np.ndarray:
    """Per usable record ``idx``, whether it may leave the span of some pair of near neighbours
    (usable, within ``reach`` of it on either side) by more than ``excursion`` (:func:`_departs`);
    a record that may not is in no group that departs. Each component's departure from any pair is
    at most its departure from the largest of the least neighbours on each side and the least of
    the largest (a bound with the same roundings in the same direction, taken with a margin); a
    reading that is not a number may always. A block of records at a time."""
    least = np.broadcast_to(np.asarray(excursion, dtype=float), (y.shape[1],))
    may = np.ones(idx.size, dtype=bool)
    if not np.any(least > 0):
        return may
    scale = np.where(least > 0, least, np.inf)
    for lo in range(0, idx.size, BOUND_BLOCK):
        hi = min(lo + BOUND_BLOCK, idx.size)
        a, b = max(lo - reach, 0), min(hi + reach, idx.size)
        # The block with its neighbours, and beyond the log's ends readings that bound nothing.
        low, high = np.full((2, b - a + 2 * reach, y.shape[1]), np.inf)
        high[:] = -np.inf
        low[reach : reach + b - a] = high[reach : reach + b - a] = y[idx[a:b]]
        at, m = reach + lo - a, hi - lo
        # The largest of the least readings on each side, and the least of the largest.
        least_of, most_of = low[at - 1 : at - 1 + m].copy(), high[at - 1 : at - 1 + m].copy()
        right_least, right_most = low[at + 1 : at + 1 + m].copy(), high[at + 1 : at + 1 + m].copy()
        for k in range(2, reach + 1):
            np.minimum(least_of, low[at - k : at - k + m], out=least_of)
            np.maximum(most_of, high[at - k : at - k + m], out=most_of)
            np.minimum(right_least, low[at + k : at + k + m], out=right_least)
            np.maximum(right_most, high[at + k : at + k + m], out=right_most)
        np.maximum(least_of, right_least, out=least_of)
        np.minimum(most_of, right_most, out=most_of)
        yq = low[at : at + m]
        out = np.maximum(yq - least_of, most_of - yq)
        out = np.maximum(out, 0.0) / scale
        may[lo:hi] = ~(np.sum(out * out, axis=1) <= 1.0 - 1e-9)
    return may


def _candidates(
    t: np.ndarray,
    y: np.ndarray,
    sc: Scatter,
    usable: np.ndarray,
    limits: tuple[float, np.ndarray | float, int],
) -> np.ndarray:
    """The first pass: the records of every group of up to ``max_group`` usable records that
    scores above ``threshold`` against its adjacent usable neighbours (a mask over the records)."""
    threshold, excursion, max_group = limits
    idx = np.flatnonzero(usable)
    candidate = np.zeros(len(t), dtype=bool)
    # How many of the usable records before each may leave the span of a pair of near neighbours:
    # a group with none among its records does not (its score is 0), and is not looked at.
    may = np.concatenate([[0], np.cumsum(_may_depart(y, idx, excursion, max_group))])
    for g in range(1, max_group + 1):
        # A block of groups at a time (each group's score is its own: blocks keep the temporaries
        # in cache), and of those only the groups that leave the span of their near neighbours
        # (the others score 0).
        P = idx.size - g - 3
        for lo in range(0, max(P, 0), FIRST_PASS_BLOCK):
            p = np.arange(lo, min(lo + FIRST_PASS_BLOCK, P))
            p = p[may[p + 2 + g] > may[p + 2]]
            m = idx[(p + 2)[:, None] + np.arange(g)[None, :]]
            keep = _departs(y, (idx[p + 1], idx[p + 2 + g]), m, excursion)
            m, p = m[keep], p[keep]
            outside = (idx[p], idx[p + 1], idx[p + 2 + g], idx[p + 3 + g])
            # Every group kept departs: its score is not judged against the excursion again.
            s, _ = _scores(t, y, sc, outside, m, 0.0)
            candidate[m[s > threshold].ravel()] = True
    return candidate


def off_neighbours(
    t: np.ndarray,
    y: np.ndarray,
    sc: Scatter,
    usable: np.ndarray | None = None,
    threshold: float = OFF_SIGMAS,
    excursion: np.ndarray | float = 0.0,
    max_group: int = MAX_GROUP,
) -> list[OffGroup]:
    """The groups of records of the signal ``y`` ``(n, d)`` at times ``t`` that are off their
    neighbours (see the module docstring); records not ``usable`` are neither judged nor used."""
    y = np.asarray(y, dtype=float).reshape(len(t), -1)
    n = len(t)
    usable = np.ones(n, dtype=bool) if usable is None else np.asarray(usable, dtype=bool)
    candidate = _candidates(t, y, sc, usable, (threshold, excursion, max_group))
    if not candidate.any():
        return []
    # Clusters of candidates, with the records whose neighbours they are, resolved one by one.
    where = np.flatnonzero(candidate)
    found: list[OffGroup] = []
    for run in np.split(where, np.flatnonzero(np.diff(where) > 2 * max_group) + 1):
        span = (max(int(run[0]) - max_group, 0), min(int(run[-1]) + max_group, n - 1))
        found += _resolve(t, y, sc, span, usable, (threshold, excursion, max_group))
    return found


def moves_by_steps(readings: np.ndarray) -> bool:
    """Whether a stream makes more than :data:`STEPWISE_SHARE` of its motion in the steps right
    after a repeated reading (a stream that does not move: no)."""
    step = np.abs(np.diff(np.asarray(readings, dtype=float)))
    total = float(np.sum(step[1:]))
    return total > 0 and float(np.sum(step[1:][step[:-1] == 0])) > STEPWISE_SHARE * total


def stuck_runs(
    t: np.ndarray, readings: np.ndarray, floor: float, moving: np.ndarray | None = None
) -> list[tuple[int, int, float]]:
    """Runs of records ``first..last`` whose reading held (``first`` is the last one read, the
    repeats follow) and then caught up by ``jump`` (reading units) at ``last + 1``, more than
    :data:`CATCH_UP_FACTOR` times the motion per record around it and more than ``floor``; with
    ``moving`` (per interval), only runs over which the robot moved (a reading held while it
    stands still misleads nothing). None in a stream that moves by steps (:func:`moves_by_steps`):
    there a hold and the jump after it are how the stream moves."""
    y = np.asarray(readings, dtype=float)
    if moves_by_steps(y):
        return []
    n = y.size
    step = np.diff(y)
    held = np.concatenate([[False], step == 0])  # held[k]: record k repeats record k - 1
    found = []
    k = 1
    while k < n:
        if not held[k]:
            k += 1
            continue
        first = k - 1
        while k < n and held[k]:
            k += 1
        last = k - 1  # records first..last read the same
        if last - first + 1 < MIN_STUCK or last + 2 >= n or first < 1:
            continue
        if moving is not None and np.mean(moving[first:last]) < 0.5:
            continue
        dt = t[last + 1] - t[last]
        around = [abs(step[first - 1]) / max(t[first] - t[first - 1], 1e-12)]
        around += [abs(step[j]) / max(t[j + 1] - t[j], 1e-12) for j in range(last + 1, min(last + 3, n - 1))]
        jump = float(step[last])
        if abs(jump) > max(CATCH_UP_FACTOR * max(around) * dt, floor):
            found.append((first, last, jump))
    return found
