"""Small numeric helpers shared across the package (numpy only)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: uint32 counters wrap at 2**32 (not 2**32 - 1).
COUNTER_MODULUS = 2**32


def robust_spread(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The columns' median and robust σ (1.4826 × the median absolute deviation: a Gaussian's σ
    that a few outliers do not move)."""
    centre = np.median(x, axis=0)
    return centre, 1.4826 * np.median(np.abs(x - centre), axis=0)


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angles onto (-π, π] (encoder convention: ticks above s_max/2 are negative angles)."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2.0 * np.pi)


def wrapped_difference(ticks: np.ndarray, modulus: int = COUNTER_MODULUS) -> np.ndarray:
    """``d = ((t[k+1] - t[k] + m/2) mod m) - m/2``: the signed step of a wrapping counter; in
    whole ticks (int64) for logged readings, fractional for counts re-sampled between them."""
    t = np.asarray(ticks)
    t = t.astype(np.int64) if np.issubdtype(t.dtype, np.integer) else t.astype(float)
    half = modulus // 2
    return ((t[1:] - t[:-1] + half) % modulus) - half


#: Sizes of the pieces an interpreted map or fold over columns is built in, one after the other (a
#: size repeated): a map's build grows with its size (about 4 µs a column) and every number of
#: columns would build its own; pieces of fixed sizes are built once per Function.
PIECE_SIZES = (256, 16, 1)


def pieces(n: int, sizes: Sequence[int] = PIECE_SIZES) -> list[int]:
    """``n`` as a sum of ``sizes`` (ending in 1), largest first."""
    out = []
    for size in sizes:
        out += [size] * (n // size)
        n %= size
    return out
