"""Encoder counter faults injected into a simulated log, so that their detection has a truth.

The kinds are those seen on real robots: ``stall_then_jump`` (the counter reads stale for a few
samples, then its catch-up increment loses 2¹⁶ ticks, as a 16-bit counter that wraps in the
logger does; the count is off from then on) and ``reversal`` (one increment against the motion,
not made up afterwards). Faults are placed in steady motion at the log's typical speed or more.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from nlp_calib.core.numeric import COUNTER_MODULUS, wrapped_difference

COUNTER_FAULT_KINDS = ("stall_then_jump", "reversal")
WRAP_16 = 2**16
#: Records kept clear between faults and at the log's ends.
_GAP = 50


@dataclass(frozen=True)
class InjectedFault:
    """A fault put into the log: intervals ``first..record-1`` carry it, ``record`` shows it.

    ``true_ticks`` and ``logged_ticks`` are the counter's increment over those intervals before
    and after the fault.
    """

    kind: str
    encoder: str
    first: int
    record: int
    true_ticks: int
    logged_ticks: int

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def inject(
    ticks: np.ndarray,
    encoder_names: Sequence[str],
    counters: Sequence[str],
    n: int,
    kinds: Sequence[str],
    rng: np.random.Generator,
) -> tuple[np.ndarray, tuple[InjectedFault, ...]]:
    """``ticks`` (records × encoders) with ``n`` faults in the ``counters``, kinds taken in turn."""
    out = np.array(ticks, dtype=np.int64)
    faults: list[InjectedFault] = []
    taken = np.zeros(out.shape[0], dtype=bool)
    taken[:_GAP] = taken[-_GAP:] = True
    for i in range(n):
        kind = kinds[i % len(kinds)]
        encoder = counters[i % len(counters)]
        col = list(encoder_names).index(encoder)
        step = wrapped_difference(out[:, col])
        stall = int(rng.integers(3, 7)) if kind == "stall_then_jump" else 0
        # A stretch of steady motion in one direction (every interval of it moves the counter), at
        # least at the log's typical speed: a fault in a creep is no fault a tracker can see.
        typical = float(np.median(np.abs(step[step != 0]))) if np.any(step) else 0.0
        steady = np.array(
            [
                r >= stall + 2
                and not taken[r - stall - 2 : r + 2].any()
                and abs(np.sign(step[r - stall - 2 : r]).sum()) == stall + 2
                and abs(step[r]) >= typical
                for r in range(out.shape[0] - 1)
            ]
        )
        places = np.flatnonzero(steady)
        if places.size == 0:
            break
        r = int(rng.choice(places))  # the interval whose increment shows the fault
        first = r - stall
        true = int(step[first : r + 1].sum())
        if kind == "stall_then_jump":
            out[first + 1 : r + 1, col] = out[first, col]  # stale: intervals first..r-1 read nothing
            logged = true - int(np.sign(true)) * WRAP_16
        else:
            logged = -int(step[r])
        offset = logged - true
        out[r + 1 :, col] = np.mod(out[r + 1 :, col] + offset, COUNTER_MODULUS)
        taken[max(first - _GAP, 0) : r + _GAP] = True
        faults.append(InjectedFault(kind, encoder, first, r + 1, true, logged))
    return out, tuple(sorted(faults, key=lambda f: f.record))
