"""The uncertainty's per-row sums held a few blocks at a time (nlp_calib.analysis.uncertainty._Rows)."""

from __future__ import annotations

import numpy as np

from nlp_calib.analysis.uncertainty import GROW, STEP, _Rows


class _Kept(_Rows):
    """The rows as released, in order, and the most rows the buffer held at once."""

    def __init__(self, n_rows: int, shape: tuple[int, int]):
        super().__init__(n_rows, shape, True)
        self.released: list[tuple[int, np.ndarray]] = []
        self.most = 0

    def add(self, index: np.ndarray, values: np.ndarray) -> None:
        super().add(index, values)
        self.most = max(self.most, self.buf.shape[0])

    def take(self, first: int, rows: np.ndarray) -> None:
        self.released.append((first, rows.copy()))


def _windows(n_rows: int, horizon: int, block: int, seed: int) -> _Kept:
    """Windows of ``horizon`` intervals, one per start, added a block at a time at both ends and
    released as a run releases them (rows below the next block's first start are final)."""
    rng = np.random.default_rng(seed)
    starts = np.arange(n_rows - horizon)
    rows = _Kept(n_rows, (3, 2))
    for lo in range(0, starts.size, block):
        a = starts[lo : lo + block]
        rows.add(a, rng.standard_normal((a.size, 3, 2)))
        rows.add(a + horizon, rng.standard_normal((a.size, 3, 2)))
        last = lo + block >= starts.size
        rows.release(None if last else int(starts[lo + block]))
    return rows


def test_the_rows_released_are_the_sums_of_every_window_in_order() -> None:
    """Each row released once, in order, every row, holding what the windows added to it in the
    order they were added (the same additions on an array of every row: the same bits)."""
    n, horizon, block = 3 * STEP + 1234, 13, 16_384
    rows = _windows(n, horizon, block, 3)
    rng = np.random.default_rng(3)
    whole = np.zeros((n, 3, 2))
    starts = np.arange(n - horizon)
    for lo in range(0, starts.size, block):
        a = starts[lo : lo + block]
        whole[a] += rng.standard_normal((a.size, 3, 2))
        whole[a + horizon] += rng.standard_normal((a.size, 3, 2))
    firsts = [f for f, _ in rows.released]
    assert firsts == list(range(0, n, STEP))
    assert np.array_equal(np.concatenate([r for _, r in rows.released]), whole)


def test_the_buffer_holds_the_rows_a_window_can_add_to_not_twice_as_many() -> None:
    """Between two releases a block's windows reach at most ``STEP`` + a block + the horizon rows
    past the last release: the buffer grows to that by :data:`GROW` rows, it does not double (a
    doubling held 131,072 rows of 82,000 at 10^5 windows)."""
    n, horizon, block = 4 * STEP + 5000, 13, 16_384
    rows = _windows(n, horizon, block, 5)
    assert rows.most <= STEP + block + horizon + GROW
