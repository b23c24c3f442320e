"""Encoder faults that no calibration can absorb: counter steps against the direction of motion."""

from __future__ import annotations

import numpy as np


def counter_reversals(increments: np.ndarray, window: int = 6, ratio: float = 1.0) -> np.ndarray:
    """Indices of increments that jump against the surrounding motion.

    An increment is flagged when at least two thirds of the non-zero increments within ``window``
    intervals on either side move the other way and it is larger than ``ratio`` times their
    median size: a wheel cannot reverse at full speed for one sample and resume. A genuine
    reversal passes through small steps, so its neighbourhood is mixed or slow.
    """
    inc = np.asarray(increments, dtype=float)
    flagged = []
    for k in np.flatnonzero(inc):
        lo, hi = max(0, k - window), min(inc.size, k + window + 1)
        nb = np.concatenate([inc[lo:k], inc[k + 1 : hi]])
        nb = nb[nb != 0]
        if nb.size < 3:
            continue
        opposite = np.sign(nb) == -np.sign(inc[k])
        if opposite.mean() >= 2.0 / 3.0 and abs(inc[k]) > ratio * np.median(np.abs(nb)):
            flagged.append(int(k))
    return np.array(flagged, dtype=np.int64)
