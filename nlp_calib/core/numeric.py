"""Small numeric helpers shared across the package (numpy only)."""

from __future__ import annotations

import numpy as np

#: uint32 counters wrap at 2**32 (not 2**32 - 1).
COUNTER_MODULUS = 2**32


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
