"""Each stream's own glitches, told from genuine motion: the tracker's and an absolute encoder's
readings off their neighbours, stuck readings, and the counter screen's lag."""

from __future__ import annotations

import numpy as np
import pytest

from nlp_calib.analysis import streams
from nlp_calib.analysis.counters import at_lag, screen_counter, screen_lag
from nlp_calib.analysis.streams import Scatter, off_neighbours, scatter, stuck_runs


def _times(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.concatenate([[0.0], np.cumsum(0.04 + rng.normal(0.0, 0.004, n - 1))])


def _path(t: np.ndarray, kinks: list[tuple[float, float]]) -> np.ndarray:
    """A 1-D position moving at piecewise constant speed: ``(time, new speed)`` changes."""
    speed = np.full(t.size, 0.5)
    for when, v in kinks:
        speed[t >= when] = v
    # Exact integral of the piecewise constant speed (the kink falls between records).
    grid = np.linspace(0.0, t[-1], 200001)
    v = np.full(grid.size, 0.5)
    for when, s in kinks:
        v[grid >= when] = s
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(grid))])
    return np.interp(t, grid, x)


def test_abrupt_reversals_and_stops_between_records_are_not_off_their_neighbours() -> None:
    t = _times(400)
    x = _path(t, [(3.017, -0.6), (5.551, 0.0), (7.009, 0.6), (9.983, -0.6), (12.0, 0.6)])
    y = x + np.random.default_rng(1).normal(0.0, 0.002, t.size)
    assert off_neighbours(t, y, scatter(t, y)) == []


@pytest.mark.parametrize("group", [1, 2, 3])
def test_a_reading_off_its_neighbours_is_found_with_its_size(group: int) -> None:
    t = _times(400)
    y = _path(t, [(3.017, -0.6), (9.983, 0.6)]) + np.random.default_rng(2).normal(0.0, 0.002, t.size)
    # One bad reading, or a slow stream's bad reading interpolated onto a faster one's records.
    offsets = {1: [0.2], 2: [0.12, 0.18], 3: [0.1, 0.2, 0.1]}[group]
    y[200 : 200 + group] += offsets
    found = off_neighbours(t, y, scatter(t, y))
    assert [(g.first, g.last) for g in found] == [(200, 200 + group - 1)]
    assert found[0].offset[0] == pytest.approx(max(offsets), abs=0.02)


def _strongest_one_by_one(t, y, sc, span, usable, limits):  # type: ignore[no-untyped-def]
    """The strongest group scored a group at a time, as a reading of the rule (the reference)."""
    threshold, excursion, max_group = limits
    best = None
    for g in range(1, max_group + 1):
        for p in range(span[0], span[1] - g + 2):
            around = streams._outside(usable, p, p + g - 1)
            if not usable[p : p + g].all() or around is None:
                continue
            m = np.arange(p, p + g)[None, :]
            s, off = streams._scores(t, y, sc, tuple(around[:, None]), m, excursion)
            if s[0] > threshold and (best is None or s[0] > best.score):
                best = streams.OffGroup(p, p + g - 1, float(s[0]), off[0])
    return best


@pytest.mark.parametrize("seed", [4, 5])
def test_the_strongest_group_is_the_one_scored_a_group_at_a_time(seed: int) -> None:
    """Groups of each size scored together pick the group a one-by-one search picks, with its
    score and offset, around records already left out and near the log's ends."""
    rng = np.random.default_rng(seed)
    t = _times(160, seed)
    y = np.column_stack([_path(t, [(2.0, -0.6), (4.5, 0.6)]), _path(t, [(3.0, 0.2)])])
    y += rng.normal(0.0, 0.002, y.shape)
    for first in rng.choice(np.arange(1, 150), 8, replace=False):
        y[first : first + rng.integers(1, 4)] += rng.normal(0.0, 0.2, 2)
    sc, usable = scatter(t, y), rng.random(t.size) > 0.1
    limits = (streams.OFF_SIGMAS, 0.0, streams.MAX_GROUP)
    picked = 0
    while (ref := _strongest_one_by_one(t, y, sc, (0, t.size - 1), usable, limits)) is not None:
        got = streams._strongest(t, y, sc, (0, t.size - 1), usable, limits)
        assert got is not None and (got.first, got.last) == (ref.first, ref.last)
        assert got.score == pytest.approx(ref.score, rel=1e-12)
        np.testing.assert_allclose(got.offset, ref.offset, rtol=1e-12)
        usable[got.first : got.last + 1] = False
        picked += 1
    assert picked >= 3 and streams._strongest(t, y, sc, (0, t.size - 1), usable, limits) is None


def test_the_scatter_grows_with_the_rate_when_readings_are_late() -> None:
    """Readings taken a random few ms off their stamps: the scatter's timing term finds it."""
    t = _times(2000)
    rng = np.random.default_rng(3)
    speed = np.where((t // 2.0) % 2 == 0, 1.0, 0.05)
    truth = lambda tq: np.interp(tq, t, np.concatenate([[0.0], np.cumsum(speed[:-1] * np.diff(t))]))  # noqa: E731
    y = truth(t + rng.normal(0.0, 0.005, t.size))
    sc = scatter(t, y)
    assert 0.002 < sc.timing[0] < 0.01  # of the order of the readings' 5 ms timing noise
    assert sc.floor[0] < 0.2 * sc.timing[0] * 1.0


def test_a_spike_must_leave_the_span_of_its_neighbours() -> None:
    t = _times(50)
    y = np.concatenate([np.zeros(20), np.arange(30) * 10.0])  # a hold, then a fast steady turn
    ahead = y.copy()
    ahead[30] += 8.0  # ahead of the motion but inside the span of its neighbours: not a spike
    sc = Scatter(np.array([1.0]), np.array([0.0]))
    assert off_neighbours(t, ahead, sc, excursion=4.0, max_group=1) == []
    ahead[30] += 40.0
    assert [g.first for g in off_neighbours(t, ahead, sc, excursion=4.0, max_group=1)] == [30]


def test_stuck_readings_while_moving_are_found_a_hold_at_rest_or_a_start_is_not() -> None:
    t = np.arange(60) * 0.04
    y = np.concatenate([np.zeros(20), np.arange(40) * 5.0])  # held still, then turns at 5 a record
    stuck = y.copy()
    stuck[41:46] = stuck[40]  # stuck for 5 records while turning, reads right again at 46
    moving = np.ones(59, dtype=bool)
    assert stuck_runs(t, y, 3.0, moving) == []  # the genuine hold ends with a start, not a jump
    assert stuck_runs(t, stuck, 3.0, moving) == [(40, 45, 30.0)]
    at_rest = moving.copy()
    at_rest[38:47] = False
    assert stuck_runs(t, stuck, 3.0, at_rest) == []


def test_a_stream_that_moves_by_steps_has_no_stuck_readings(monkeypatch: pytest.MonkeyPatch) -> None:
    """A steering command held between commands (4 Hz, logged at 20 Hz) moves by a hold and a jump
    every time it moves: no stuck reading. The share that decides it, independently: the steps
    right after a repeat over all steps."""
    t = np.arange(400) * 0.05
    angle = 0.3 * np.sin(t / 1.3) * np.sin(t / 0.7)
    command = angle[(np.arange(t.size) // 5) * 5]  # each command held over five records
    moving = np.ones(t.size - 1, dtype=bool)
    step = np.abs(np.diff(command))
    assert np.sum(step[1:][step[:-1] == 0]) / np.sum(step[1:]) > streams.STEPWISE_SHARE
    assert streams.moves_by_steps(command) and stuck_runs(t, command, 0.01, moving) == []
    monkeypatch.setattr(streams, "STEPWISE_SHARE", 1.0)  # judged as a smooth sensor: many "stuck"
    assert len(stuck_runs(t, command, 0.01, moving)) > 10
    monkeypatch.undo()
    stuck = angle.copy()
    stuck[101:106] = stuck[100]  # a smooth sensor's stuck reading is still found
    assert not streams.moves_by_steps(stuck) and [r[:2] for r in stuck_runs(t, stuck, 0.01, moving)] == [
        (100, 105)
    ]


def _counter(lag: float, n: int = 3000, seed: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A counter's increments and the tracker's implied ones ``lag`` late, with tracker noise."""
    t = _times(n, seed)
    rng = np.random.default_rng(seed)
    knots = np.arange(0.0, t[-1] + 3.0, 1.5)
    v = np.interp(t, knots, rng.uniform(-8000.0, 8000.0, knots.size) / 0.04)  # ticks per second
    grid = np.linspace(-1.0, t[-1] + 1.0, 400001)
    count = np.cumsum(np.interp(grid, t, v)) * (grid[1] - grid[0])
    logged = np.round(np.interp(t, grid, count))
    implied = np.interp(t - lag, grid, count) + rng.normal(0.0, 500.0, t.size)
    ticks = np.diff(logged)
    return t, ticks, np.diff(implied) - ticks


def test_the_screen_finds_the_lag_at_which_the_counts_agree() -> None:
    """Roughly: the screen needs the lag only to keep a reversal's count from stepping (the fit
    estimates it to the millisecond afterwards); a fault it does not mistake for the lag."""
    t, ticks, c = _counter(0.05)
    assert screen_lag(t, [ticks], c[:, None], (-0.2, 0.2)) == pytest.approx(0.05, abs=0.01)
    lost = ticks.copy()
    lost[1500] -= 2**16
    assert screen_lag(t, [lost], (c + ticks - lost)[:, None], (-0.2, 0.2)) == pytest.approx(0.05, abs=0.01)


def test_a_reversal_is_no_fault_at_the_lag_but_a_lost_count_is() -> None:
    t, ticks, c = _counter(0.05)
    assert screen_counter(ticks, at_lag(t, ticks, c, 0.05), t).findings == ()
    lost = ticks.copy()
    lost[1500] -= 2**16  # 2^16 counts lost at one record
    found = screen_counter(lost, at_lag(t, lost, c + ticks - lost, 0.05), t).findings
    assert [(f.kind, f.last) for f in found] in ([("counter_jump", 1500)], [("reversal", 1500)])
    assert found[0].implied - found[0].logged == pytest.approx(2**16, abs=5 * found[0].noise)


def test_a_tracker_that_jumps_for_good_is_not_blamed_on_the_counter() -> None:
    """The tracker's count steps while the counter runs smoothly on: the counter's own history
    clears it."""
    t, ticks, c = _counter(0.0)
    shifted = c.copy()
    shifted[1500] += 2**16
    assert screen_counter(ticks, shifted, t).findings == ()


def test_each_candidate_step_is_taken_once_per_fault_found(monkeypatch: pytest.MonkeyPatch) -> None:
    """Candidates passed over (a tracker that jumps, cleared by the counter's own history) change no
    level: a candidate's step is taken again only after a fault is found."""
    from nlp_calib.analysis import counters

    t, ticks, c = _counter(0.0)
    lost = ticks.copy()
    lost[1500] -= 2**16
    shifted = c + ticks - lost
    for k in (400, 900, 2200):  # the tracker's count steps there; the counter runs on
        shifted[k] += 2**16
    levels: list[tuple[int, ...]] = []
    level = counters._level

    def counted(C: np.ndarray, idx: np.ndarray) -> float:
        levels.append(tuple(idx.tolist()))
        return level(C, idx)

    monkeypatch.setattr(counters, "_level", counted)
    found = screen_counter(lost, shifted, t).findings
    assert [f.last for f in found] == [1500]
    after = levels[0::2]  # a step is its level after the candidate less the one before it
    assert len(after) <= len(set(after)) * (len(found) + 1)


@pytest.mark.parametrize("excursion", [0.0, 0.01])
def test_the_blocked_screened_first_pass_finds_what_scoring_every_group_at_once_finds(
    excursion: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The first pass scores blocks of groups, and only groups that leave their neighbours' span:
    the same groups as scoring every group in one call (an independent, unblocked computation)."""
    from nlp_calib.analysis import streams

    t = _times(3000, seed=4)
    rng = np.random.default_rng(5)
    y = np.column_stack([_path(t, [(20.0, -0.6), (70.0, 0.3)]), np.sin(0.05 * t)])
    y += rng.normal(0.0, 0.002, y.shape)
    # Glitches of every size about the threshold, some next to each other.
    bad = rng.choice(np.arange(10, t.size - 10), 300, replace=False)
    y[bad] += rng.normal(0.0, 0.05, (bad.size, 2))
    sc = scatter(t, y)
    usable = rng.random(t.size) > 0.02
    idx = np.flatnonzero(usable)
    expected = np.zeros(t.size, dtype=bool)
    for g in range(1, 4):
        P = idx.size - g - 3
        m = idx[np.arange(2, 2 + P)[:, None] + np.arange(g)[None, :]]
        outside = (idx[:P], idx[1 : P + 1], idx[2 + g : 2 + g + P], idx[3 + g : 3 + g + P])
        s, _ = streams._scores(t, y, sc, outside, m, excursion)
        expected[m[s > streams.OFF_SIGMAS].ravel()] = True
    assert expected.any()
    monkeypatch.setattr(streams, "FIRST_PASS_BLOCK", 97)
    got = streams._candidates(t, y, sc, usable, (streams.OFF_SIGMAS, excursion, 3))
    assert np.array_equal(got, expected)


@pytest.mark.parametrize("w", [6, 7])
def test_the_trailing_medians_are_nanmedians_to_the_bit(w: int) -> None:
    """The min/max network's medians (and nanmedian's where a run has a nan) are numpy's own:
    every 0/1 run (the network sorts all inputs if it sorts these) and runs with nans, infinities
    and ties."""
    import itertools

    from nlp_calib.analysis.streams import _window_medians

    runs = np.array(list(itertools.product([0.0, 1.0], repeat=w)))
    got = np.concatenate([_window_medians(run[:, None], w) for run in runs])
    assert np.array_equal(got[:, 0], np.median(runs, axis=1))
    rng = np.random.default_rng(3)
    a = rng.normal(size=(2000, 3))
    for value, share in ((np.nan, 0.02), (np.inf, 0.03), (-np.inf, 0.03), (0.5, 0.2)):
        a[rng.random(a.shape) < share] = value
    a[:12, 0] = np.nan
    with pytest.warns(RuntimeWarning, match="All-NaN"):  # both: the first runs are all nan
        want = np.nanmedian(np.lib.stride_tricks.sliding_window_view(a, w, axis=0), axis=-1)
        got = _window_medians(a, w)
    assert np.array_equal(got, want, equal_nan=True)


def test_the_screens_lag_is_the_written_out_huber_profiles_least() -> None:
    """Issue 41: the screen's lag profile, taken over blocks of records, has its least where Huber's
    loss written out has it."""
    from nlp_calib.analysis.counters import HUBER, LAG_STEP, robust_sigma

    rng = np.random.default_rng(7)
    n = 3000
    t = np.cumsum(0.02 + 0.002 * rng.random(n + 1))
    ticks = [rng.integers(-3, 40, n).astype(float), rng.integers(0, 9, n).astype(float)]
    c = rng.normal(0.0, 1.5, (n, 2))
    grid = -0.1 + LAG_STEP * np.arange(101)
    cost = np.zeros(grid.size)
    for j, x in enumerate(ticks):
        count = np.concatenate([[0.0], np.cumsum(x)])
        for i, g in enumerate(grid):
            r = np.abs(np.diff(np.interp(t - g, t, count)) - x - c[:, j]) / robust_sigma(c[:, j])
            cost[i] += np.sum(np.where(r < HUBER, 0.5 * r * r, HUBER * r - 0.5 * HUBER**2))
    assert screen_lag(t, ticks, c, (-0.1, 0.1)) == grid[int(np.argmin(cost))]
    # One record, no interval: every lag costs nothing, the range's first is kept.
    assert screen_lag(t[:1], [x[:0] for x in ticks], c[:0], (0.0, 0.0)) == 0.0


def test_the_screens_lag_costs_are_one_pass_per_lag_to_the_last_bit() -> None:
    """Issue 41: the lag profile taken over blocks of records, every lag at once, is each lag's
    pass over every record (np.interp on all of them, np.sum of all terms) bit for bit: over
    several blocks, irregular records, a record stamped twice and lags that read before the first
    record and after the last."""
    from nlp_calib.analysis.counters import HUBER, LAG_STEP, LAG_TERMS, lag_costs, robust_sigma

    rng = np.random.default_rng(31)
    n = 5000
    t = np.cumsum(0.001 + 0.04 * rng.random(n + 1))
    t[700] = t[699]
    x = rng.integers(-5, 60, n).astype(float)
    c = rng.standard_t(3, n) * 2.0
    grid = -0.4 + LAG_STEP * np.arange(401)
    assert n > 3 * (LAG_TERMS // grid.size)  # several blocks, their sums joined
    count = np.concatenate([[0.0], np.cumsum(x)])
    want = np.empty(grid.size)
    for i, g in enumerate(grid):
        r = np.abs(np.diff(np.interp(t - g, t, count)) - x - c) / max(robust_sigma(c), 1e-12)
        want[i] = np.sum(np.where(r < HUBER, 0.5 * r * r, HUBER * r - 0.5 * HUBER**2))
    assert np.array_equal(lag_costs(t, x, c, grid), want)


def test_pairwise_sums_of_blocks_are_numpys_sum_of_all() -> None:
    """Issue 41: block sums joined as numpy's pairwise summation joins halves give np.sum of the
    whole array to the last bit, whatever the blocks' size (a plain running sum of the blocks does
    not: the check can fail)."""
    from nlp_calib.analysis.counters import _pairwise

    rng = np.random.default_rng(5)
    a = rng.standard_normal((3, 100_003)) * 10.0 ** rng.uniform(-6, 6, (3, 100_003))

    def sums(lo: int, hi: int) -> np.ndarray:
        return a[:, lo:hi].sum(axis=1)

    want = np.array([np.sum(row) for row in a])
    for n in (0, 7, 129, 4096, 100_003):
        for leaf in (128, 1000, 8192, 1 << 17):
            expected = np.array([np.sum(row[:n]) for row in a])
            assert np.array_equal(_pairwise(sums, 0, n, leaf), expected), (n, leaf)
    running = sum(sums(lo, min(lo + 1000, a.shape[1])) for lo in range(0, a.shape[1], 1000))
    assert not np.array_equal(running, want)


def test_the_screens_least_lag_skips_lags_and_is_the_whole_profiles_argmin() -> None:
    """Issue 41: the screen's lag, with the lags that already cost more than one lag's whole cost
    skipped block by block, is ``np.argmin`` of every counter's whole profile summed (each profile
    one pass per lag to the last bit: the test above), over many blocks, two counters and
    irregular records; and lags were skipped (a check that skips none would pass alone)."""
    from nlp_calib.analysis import counters
    from nlp_calib.analysis.counters import LAG_STEP, lag_costs

    taken: list[int] = []
    add = counters._LagProfile.add

    def counted(self: counters._LagProfile, leaf: int, lags: np.ndarray) -> np.ndarray:
        taken.append(lags.size * (self.leaves[leaf][1] - self.leaves[leaf][0]))
        return add(self, leaf, lags)

    for seed, lag in ((3, 0.06), (4, -0.13), (5, 0.0)):
        t, tick, c = _counter(lag, n=40_000, seed=seed)
        rng = np.random.default_rng(seed)
        other = rng.integers(0, 9, tick.size).astype(float)
        cs = np.stack([c, rng.standard_t(3, tick.size) * 1.5], axis=1)
        grid = -0.3 + LAG_STEP * np.arange(301)
        want = lag_costs(t, tick, cs[:, 0].copy(), grid) + lag_costs(t, other, cs[:, 1].copy(), grid)
        mp = pytest.MonkeyPatch()
        mp.setattr(counters._LagProfile, "add", counted)
        taken.clear()
        try:
            got = screen_lag(t, [tick, other], cs, (-0.3, 0.3))
        finally:
            mp.undo()
        assert got == grid[int(np.argmin(0.0 + want))], seed
        assert sum(taken) < 0.9 * 2 * grid.size * tick.size, seed  # lags were skipped
        # The lags taken over every block, some a few at a time, cost what every lag at once does.
        profile = counters._LagProfile(t, tick, cs[:, 0].copy(), grid)
        counters._least([profile], grid.size)
        whole = np.flatnonzero(~np.isnan(profile.sums).any(axis=0))
        assert 0 < whole.size < grid.size, seed
        assert np.array_equal(profile.joined(whole), lag_costs(t, tick, cs[:, 0].copy(), grid)[whole]), seed


def test_the_screens_least_lag_is_argmins_on_any_profile() -> None:
    """Issue 41: whatever the blocks' sums (ties, a least among the sampled blocks' worst, NaN,
    which ``np.argmin`` picks, from a reading that is not a number, infinities), the lag kept is
    ``np.argmin`` of the whole profiles' sum at every lag."""
    from nlp_calib.analysis import counters

    class Table(counters._LagProfile):
        """A profile whose blocks' sums are given (one block per item)."""

        def __init__(self, table: np.ndarray) -> None:
            self.table, self.finite = table, not np.any(np.isnan(table))
            self.leaves = [(i, i + 1) for i in range(table.shape[0])]
            self.first = {i: i for i in range(table.shape[0])}
            self.sums = np.full(table.shape, np.nan)

        def add(self, leaf: int, lags: np.ndarray) -> np.ndarray:
            self.sums[leaf, lags] = self.table[leaf, lags]
            return self.sums[leaf, lags]

        def joined(self, lags: np.ndarray) -> np.ndarray:
            # Every block of these lags must have been taken: one left out is NaN here.
            return np.array([np.sum(self.sums[:, j]) for j in lags])

    rng = np.random.default_rng(11)
    for case in range(40):
        n_leaves, n_lags = int(rng.integers(1, 300)), int(rng.integers(1, 60))
        tables = [rng.exponential(1.0, (n_leaves, n_lags)) * rng.uniform(0.5, 3.0, n_lags) for _ in range(2)]
        if case % 4 == 1:  # ties: two lags alike
            for t in tables:
                t[:, -1] = t[:, 0]
        if case % 4 == 2:  # the least lag, by 1e-9, costs most on the blocks sampled first
            n_leaves, n_lags = int(rng.integers(500, 3000)), int(rng.integers(2, 60))
            tables = [rng.exponential(1.0, (n_leaves, n_lags)) for _ in range(2)]
            m, rest = n_lags // 2, np.ones(n_leaves, dtype=bool)
            rest[:: counters.SAMPLE_EVERY] = False
            for t in tables:
                t[~rest, m] *= 10.0
                least = min(np.sum(t[:, j]) for j in range(n_lags) if j != m) * (1.0 - 1e-9)
                t[rest, m] *= (least - np.sum(t[~rest, m])) / np.sum(t[rest, m])
        if case % 4 == 3:
            tables[1][rng.integers(n_leaves), rng.integers(n_lags)] = (np.nan, np.inf)[case % 8 == 3]
        want = np.zeros(n_lags)
        for t in tables:
            want += np.array([np.sum(t[:, j]) for j in range(n_lags)])
        assert counters._least([Table(t) for t in tables], n_lags) == int(np.argmin(want)), case


def test_the_screens_least_lag_when_every_other_lag_costs_more_after_the_sample() -> None:
    """A counter the tracker implies nearly exactly (noise of a tick, not hundreds): after the
    sampled blocks every lag but the best already costs more than the best's whole cost, and the
    search ends with the best's cost alone taken (it had raised an IndexError on no lags left)."""
    from nlp_calib.analysis import counters
    from nlp_calib.analysis.counters import LAG_STEP, lag_costs

    t = _times(20_000, 7)
    rng = np.random.default_rng(7)
    knots = np.arange(0.0, t[-1] + 3.0, 1.5)
    v = np.interp(t, knots, rng.uniform(-8000.0, 8000.0, knots.size) / 0.04)
    fine = np.linspace(-1.0, t[-1] + 1.0, 400001)
    count = np.cumsum(np.interp(fine, t, v)) * (fine[1] - fine[0])
    ticks = np.diff(np.round(np.interp(t, fine, count)))
    c = np.diff(np.interp(t - 0.04, fine, count) + rng.normal(0.0, 1.0, t.size)) - ticks
    grid = -0.2 + LAG_STEP * np.arange(401)
    want = grid[int(np.argmin(lag_costs(t, ticks, c.copy(), grid)))]
    profile = counters._LagProfile(t, ticks, c.copy(), grid)
    assert grid[counters._least([profile], grid.size)] == want
    # Every other lag was dropped before the last blocks: only the best was taken over them all.
    assert np.flatnonzero(~np.isnan(profile.sums).any(axis=0)).size == 1
    assert screen_lag(t, [ticks], c[:, None], (-0.2, 0.2)) == pytest.approx(0.04, abs=LAG_STEP)


def test_a_group_that_departs_has_a_record_that_may() -> None:
    """The first pass's bound per record (:func:`streams._may_depart`) is never below a group's
    departure: every group of up to ``reach`` usable records that leaves its near neighbours'
    span (``_departs``) holds a record the bound says may, on readings at the threshold, equal
    readings, infinities and nans, and with components of no excursion."""
    rng = np.random.default_rng(11)
    for trial in range(40):
        n, d = int(rng.integers(8, 400)), int(rng.choice([1, 2, 3, 6]))
        y = np.round(rng.normal(0.0, 1.0, (n, d)), int(rng.integers(0, 3)))
        y[rng.integers(0, n, 3)] = rng.choice([np.nan, np.inf, -np.inf, 0.0], (3, d))
        least = rng.choice([0.0, 0.5, 1.0], d) if trial % 2 else np.full(d, 1.0)
        # A record exactly the excursion beyond a neighbour: the threshold itself.
        y[n // 2] = y[n // 2 - 1] + least
        idx = np.flatnonzero(rng.random(n) > 0.1)
        for reach in range(1, 5):
            may = streams._may_depart(y, idx, least, reach)
            for g in range(1, reach + 1):
                P = idx.size - g - 3
                if P <= 0:
                    continue
                p = np.arange(P)
                m = idx[(p + 2)[:, None] + np.arange(g)[None, :]]
                departs = streams._departs(y, (idx[p + 1], idx[p + 2 + g]), m, least)
                members = may[(p + 2)[:, None] + np.arange(g)[None, :]].any(axis=1)
                assert not np.any(departs & ~members), (trial, reach, g)


def test_the_first_pass_judges_only_groups_with_a_record_that_may_depart(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """On a moving path with noise and a few glitches, the first pass asks whether a group departs
    of a small share of the groups (it asked of every one), and finds what judging every group
    finds (an independent, unblocked computation)."""
    t = _times(6000, seed=2)
    rng = np.random.default_rng(3)
    y = np.column_stack([_path(t, [(60.0, -0.6), (150.0, 0.3)]), 3.0 * np.sin(0.05 * t)])
    y += rng.normal(0.0, 0.002, y.shape)
    bad = rng.choice(np.arange(10, t.size - 10), 30, replace=False)
    y[bad] += rng.normal(0.0, 0.05, (bad.size, 2))
    sc = scatter(t, y)
    excursion = 3.0 * sc.floor
    usable = np.ones(t.size, dtype=bool)
    expected = np.zeros(t.size, dtype=bool)
    for g in range(1, 5):
        P = t.size - g - 3
        m = np.arange(2, 2 + P)[:, None] + np.arange(g)[None, :]
        outside = (
            np.arange(P),
            np.arange(1, P + 1),
            np.arange(2 + g, 2 + g + P),
            np.arange(3 + g, 3 + g + P),
        )
        s, _ = streams._scores(t, y, sc, outside, m, excursion)
        expected[m[s > streams.OFF_SIGMAS].ravel()] = True
    assert expected[bad].sum() >= 5
    asked = []
    departs = streams._departs

    def counted(
        y: np.ndarray, near: tuple[np.ndarray, np.ndarray], m: np.ndarray, least: object
    ) -> np.ndarray:
        if np.any(np.asarray(least) > 0):
            asked.append(m.shape[0])
        return departs(y, near, m, least)

    monkeypatch.setattr(streams, "_departs", counted)
    got = streams._candidates(t, y, sc, usable, (streams.OFF_SIGMAS, excursion, 4))
    assert np.array_equal(got, expected)
    assert sum(asked) < 0.1 * 4 * t.size


def test_the_path_bend_holds_a_block_not_the_log(monkeypatch: pytest.MonkeyPatch) -> None:
    """``path_bend`` takes its medians a block of records at a time: its values are those of every
    record's window over the whole log at once (np.nanmedian, computed here), and the memory it
    holds beyond its output is a block's (it held a dozen copies of the signal)."""
    import tracemalloc

    monkeypatch.setattr(streams, "MEDIAN_BLOCK", 4096)
    n, w = 60_000, streams.BEND_WINDOW
    t = _times(n, seed=6)
    rng = np.random.default_rng(6)
    y = np.column_stack([np.sin(0.3 * t), np.cos(0.05 * t), 0.01 * t]) + rng.normal(0.0, 1e-4, (n, 3))
    sc = streams.chord_scatter(t, y)
    tracemalloc.start()
    got = streams.path_bend(t, y, sc)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert got is not None and got.any()
    h_left, h_right = np.maximum(t[1:-1] - t[:-2], 1e-12), np.maximum(t[2:] - t[1:-1], 1e-12)
    left, right = (y[1:-1] - y[:-2]) / h_left[:, None], (y[2:] - y[1:-1]) / h_right[:, None]
    mid = (0.5 * (h_left + h_right))[:, None]
    level = np.vstack([np.full((1, 3), np.nan), np.abs(right - left) / mid, np.full((1, 3), np.nan)])
    noise = 0.6745 * np.sqrt(6.0) * sc.at(np.maximum(np.abs(left), np.abs(right))) / mid**2
    floor = np.vstack([np.full((1, 3), np.inf), streams.BEND_OVER_NOISE * noise, np.full((1, 3), np.inf)])
    window = np.lib.stride_tricks.sliding_window_view
    with np.errstate(invalid="ignore"):
        med = np.nan_to_num(np.nanmedian(window(level, w, axis=0), axis=-1), nan=0.0)
    back = np.zeros((n, 3))
    back[w - 1 :] = np.where(med > np.nanmedian(window(floor, w, axis=0), axis=-1), med, 0.0)
    assert got.tobytes() == np.stack([back, np.vstack([back[w - 1 :], np.zeros((w - 1, 3))])]).tobytes()
    assert peak < got.nbytes + 40 * 4096 * 3 * 8


def test_a_counters_step_noise_takes_running_medians_as_np_median_does() -> None:
    """``running_medians`` gives np.median's values over every run (readings rounded to whole
    ticks: many equal, zeros of either sign), and a counter's step noise from them is the one from
    np.median's to the bit, with a nan among the levels (its runs' medians nan) or without."""
    from nlp_calib.analysis.counters import PERSIST_INTERVALS, _step_noise
    from nlp_calib.analysis.streams import robust_sigma, running_medians

    rng = np.random.default_rng(9)
    W = PERSIST_INTERVALS
    window = np.lib.stride_tricks.sliding_window_view
    for trial in range(6):
        C = np.round(rng.normal(0.0, 2.0, 5000)) * rng.choice([1.0, -1.0], 5000)
        if trial % 2:
            C[rng.integers(0, C.size, 3)] = np.nan
        valid = rng.random(C.size) > 0.3
        levels = C[valid]
        expected = np.median(window(levels, W), axis=1)
        if trial % 2 == 0:
            assert np.array_equal(running_medians(levels, W), expected)
        want = max(robust_sigma(expected[W:] - expected[:-W]), 0.1)
        assert np.float64(_step_noise(C, valid, C[:30], 0.1)).tobytes() == np.float64(want).tobytes()
