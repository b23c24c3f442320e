"""Encoder faults injected into a simulated log, so that their detection has a truth.

Counter faults are those seen on real robots: ``stall_then_jump`` (the counter reads stale for a
few samples, then its catch-up increment loses 2¹⁶ ticks, as a 16-bit counter that wraps in the
logger does; the count is off from then on) and ``reversal`` (one increment against the motion,
not made up afterwards). They are placed in steady motion at the log's typical speed or more.

An absolute encoder's glitches (a wheel's angle): ``steering_spike`` (one reading off by 0.1–0.5 rad of
the encoder's angle, either way, while the robot moves) and ``steering_stuck`` (the reading holds
for 4–8 records while the robot moves and the angle turns steadily by at least 0.05 rad, then
reads right again).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from nlp_calib.core.numeric import COUNTER_MODULUS, wrapped_difference
from nlp_calib.logs import LogHeader

COUNTER_FAULT_KINDS = ("stall_then_jump", "reversal")
WRAP_16 = 2**16
#: Records kept clear between faults and at the log's ends.
_GAP = 50


@dataclass(frozen=True)
class InjectedFault:
    """A fault put into the log: intervals ``first..record-1`` carry it, ``record`` shows it.

    ``true_ticks`` and ``logged_ticks`` are the counter's increment over those intervals before
    and after the fault (for an absolute encoder: the reading at ``record``; a stuck reading's
    first repeat).
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
        # The fault's own interval and the one after it move the same way too: at a reversal, a
        # fault would be a reversal a record late.
        steady = np.array(
            [
                r >= stall + 2
                and not taken[r - stall - 2 : r + 2].any()
                and abs(np.sign(step[r - stall - 2 : r + 2]).sum()) == stall + 4
                and abs(step[r]) >= typical
                for r in range(out.shape[0] - 2)
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


#: Spike sizes (rad of the encoder's angle) and the shortest steady turn a stuck reading hides.
SPIKE_RAD = (0.1, 0.5)
STUCK_RECORDS = (4, 8)
STUCK_MIN_RAD = 0.05


def inject_glitches(
    ticks: np.ndarray,
    header: LogHeader,
    encoder: str,
    counts: tuple[int, int],
    taken_by: Sequence[InjectedFault],
    rng: np.random.Generator,
) -> tuple[np.ndarray, tuple[InjectedFault, ...]]:
    """``ticks`` with ``counts`` = (spikes, stuck runs) in the absolute ``encoder``, clear of the
    faults ``taken_by`` and of each other, while the robot moves (a counter's increment)."""
    out = np.array(ticks, dtype=np.int64)
    col = header.encoder_index(encoder)
    vmax = header.encoder_max[col]
    counters = [j for j in range(out.shape[1]) if j != col]
    moving = np.all([wrapped_difference(out[:, j]) != 0 for j in counters], axis=0)
    angle = np.unwrap(2 * np.pi * out[:, col] / vmax) * vmax / (2 * np.pi)  # ticks, unwrapped
    step = np.diff(angle)
    taken = np.zeros(out.shape[0], dtype=bool)
    taken[:_GAP] = taken[-_GAP:] = True
    for f in taken_by:
        taken[max(f.first - _GAP, 0) : f.record + _GAP] = True
    faults = []
    for kind, n in zip(("steering_spike", "steering_stuck"), counts):
        for _ in range(n):
            length = (
                int(rng.integers(STUCK_RECORDS[0], STUCK_RECORDS[1] + 1)) if kind == "steering_stuck" else 1
            )
            places = [
                r
                for r in range(2, out.shape[0] - length - 2)
                if _fits(kind, r, length, taken, moving, step, vmax)
            ]
            if not places:
                break
            r = int(rng.choice(places))  # the first record read wrong
            true = int(out[r, col])
            if kind == "steering_spike":
                size = rng.uniform(*SPIKE_RAD) * rng.choice([-1.0, 1.0]) * vmax / (2 * np.pi)
                out[r, col] = np.mod(true + round(size), vmax)
            else:
                out[r : r + length - 1, col] = out[r - 1, col]
            taken[max(r - _GAP, 0) : r + length + _GAP] = True
            faults.append(InjectedFault(kind, encoder, r - 1, r, true, int(out[r, col])))
    return out, tuple(faults)


def _fits(
    kind: str, r: int, length: int, taken: np.ndarray, moving: np.ndarray, step: np.ndarray, vmax: int
) -> bool:
    """Whether a glitch of ``kind`` may start at record ``r``: clear, the robot moving, and for a stuck
    run a steady turn of the angle that the run hides (``step``: its increments, ticks)."""
    if taken[r - 2 : r + length + 2].any() or not moving[r - 1 : r + length].all():
        return False
    if kind == "steering_spike":
        return True
    hidden = float(np.sum(step[r - 1 : r + length - 1]))
    around = np.abs(np.r_[step[r - 2], step[r + length - 1 : r + length + 1]])
    return abs(hidden) >= STUCK_MIN_RAD * vmax / (2 * np.pi) and bool(np.all(around <= abs(hidden) / 3.0))
