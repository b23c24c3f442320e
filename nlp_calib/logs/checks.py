"""Value checks of a log's records, and which records a non-strict read drops.

:func:`value_problems` finds records whose values cannot be used: NaN, infinite or implausibly
large poses, encoder readings outside their range, timestamps that do not increase.

A traction counter's increment between two records is the wheel's travel. A corrupted reading
(a bit error, a garbled serial frame, a counter reset) shows up as an increment far beyond
anything the log's own motion produces. "Far beyond" is measured against the log itself:

- the *typical* increment is the 95th percentile of the non-zero increments, each scaled to the
  median record interval (an interval twice as long may travel twice as far); a percentile
  (nearest rank, so it is always a real increment) stays put while up to 5% of the moving
  intervals are corrupt;
- an increment is a *jump* when it exceeds :data:`JUMP_FACTOR` times that, scaled by its own
  interval's duration. On the real robot's log the largest increment is 3.0 times the typical
  one, on simulated logs at most 1.3 times; a corrupted uint32 reading is typically off by
  thousands of times. A factor of 10 leaves a wide margin on both sides.

A single glitched reading makes two jumps of opposite sign; dropping that one record restores a
normal increment across it (its neighbours bridge it). A jump that does not come back within
:data:`MAX_GLITCH_RECORDS` records is a counter reset or an offset: no record can be dropped to
repair it, so the read keeps the longest stretch of the log between such jumps.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.core.numeric import wrapped_difference
from nlp_calib.logs.header import MAX_MAGNITUDE
from nlp_calib.logs.log import DroppedRecord
from nlp_calib.logs.writer import format_time

#: A jump is an increment beyond this many typical increments (see the module docstring).
JUMP_FACTOR = 10.0
#: Percentile of the moving intervals' scaled increments that defines the typical increment.
TYPICAL_PERCENTILE = 95.0
#: With fewer moving intervals the log has no reliable typical increment: no jumps are flagged.
MIN_MOVING_INTERVALS = 20
#: Floor of the typical increment (ticks): a creeping robot's few-tick steps are too coarse to
#: define a speed, and a jump of under 100 ticks cannot be told from quantisation anyway.
MIN_TYPICAL_TICKS = 10.0
#: Longest run of consecutive glitched readings a non-strict read bridges by dropping them.
MAX_GLITCH_RECORDS = 5


def counter_drops(
    t_ns: np.ndarray,
    ticks: np.ndarray,
    linenos: np.ndarray,
    keep: np.ndarray,
    counters: Sequence[tuple[int, str]],
    path: str,
    strict: bool,
    modulus: int,
) -> dict[int, str]:
    """Jumps of the ``counters`` (column, name) among the ``keep`` records: raise naming the first
    (strict), or drop records (returns line -> reason and clears their ``keep``)."""
    drops: dict[int, str] = {}
    for j, name in counters:
        idx = np.flatnonzero(keep)
        if strict:
            jumps = counter_jumps(ticks[idx, j], t_ns[idx], modulus)
            if jumps:
                k = jumps[0].index
                a, b = idx[k], idx[k + 1]
                raise DatasetError(
                    path,
                    int(linenos[b]),
                    jumps[0].describe(name, (int(ticks[a, j]), int(ticks[b, j])), int(linenos[a])),
                    droppable=True,
                )
            continue
        bad = records_to_drop(ticks[idx, j], t_ns[idx], modulus, linenos[idx], name)
        for i, reason in bad.items():
            keep[idx[i]] = False
            drops[int(linenos[idx[i]])] = reason
    return drops


def drop_summary(dropped: Sequence[DroppedRecord], n_records: int) -> str:
    """One line on the records a non-strict read dropped: how many, where, and the first reason."""
    shown = ", ".join(str(d.line) for d in dropped[:5]) + (", ..." if len(dropped) > 5 else "")
    return (
        f"dropped {len(dropped)} of {n_records} records (strict: false) at line(s) {shown}; "
        f"line {dropped[0].line}: {dropped[0].reason}"
    )


def value_problems(
    t_ns: np.ndarray,
    ticks: np.ndarray,
    poses: np.ndarray,
    linenos: np.ndarray,
    encoders: Sequence[tuple[str, int]],
    last: tuple[int, int] | None = None,
) -> tuple[dict[int, str], tuple[int, int] | None]:
    """Unusable records (index -> reason): non-finite or implausibly large poses, readings outside
    ``[0, limit)`` (``encoders`` gives each column's name and limit), timestamps that do not
    increase. ``last`` is the time and line of the last usable record before these (records come
    in blocks); the same for these is returned."""
    reasons: dict[int, str] = {}
    finite = np.isfinite(poses)
    plausible = np.abs(np.where(finite, poses, 0.0)) <= MAX_MAGNITUDE
    for i in np.flatnonzero(~(finite & plausible).all(axis=1)).tolist():
        tracker = not (finite[i, 3:6] & plausible[i, 3:6]).all()
        which, values = ("tracker_pose", poses[i, 3:6]) if tracker else ("model_pose", poses[i, 0:3])
        text = " ".join(str(v) for v in values)
        if np.isfinite(values).all():
            reasons[i] = (
                f"{which} is {text}; a value beyond ±{MAX_MAGNITUDE:g} (metres or radians) is not a "
                "measurement (a corrupt reading?)"
            )
        else:
            reasons[i] = f"{which} is {text}; expected finite numbers (a tracker that lost its target?)"
    for j, (name, limit) in enumerate(encoders):
        out = (ticks[:, j] < 0) | (ticks[:, j] >= limit)
        for i in np.flatnonzero(out).tolist():
            reasons.setdefault(int(i), f"encoder {name!r} reads {ticks[i, j]}, outside [0, {limit})")
    # Time must increase; compare against the last kept record so one glitch drops one record. The
    # last kept time is the running maximum (kept times increase), so this is one pass.
    usable = np.ones(t_ns.shape[0], dtype=bool)
    usable[list(reasons)] = False
    idx = np.flatnonzero(usable)
    t = t_ns[idx]
    start_t, start_line = last if last is not None else (np.iinfo(np.int64).min, -1)
    before = np.maximum.accumulate(np.concatenate([[start_t], t]))[:-1]
    kept = t > before
    # Where the running maximum was set: the last kept record before each one.
    kept_at = np.maximum.accumulate(np.where(kept, np.arange(t.size), -1))
    prior = np.concatenate([[-1], kept_at[:-1]])
    for k in np.flatnonzero(~kept).tolist():
        p = int(prior[k])
        t_prev, line_prev = (int(t[p]), int(linenos[idx[p]])) if p >= 0 else (int(start_t), int(start_line))
        what = "duplicates" if t[k] == t_prev else "goes back from"
        reasons[int(idx[k])] = (
            f"time {format_time(int(t[k]))} {what} the previous record's {format_time(t_prev)} "
            f"(line {line_prev}); expected increasing timestamps"
        )
    if kept.any():
        k = int(np.flatnonzero(kept)[-1])
        last = (int(t[k]), int(linenos[idx[k]]))
    return reasons, last


def _step(t: np.ndarray, a: int, b: int, modulus: int) -> int:
    half = modulus // 2
    return ((int(t[b]) - int(t[a]) + half) % modulus) - half


@dataclass(frozen=True)
class CounterScale:
    """The typical increment of a counter, in ticks per median record interval."""

    typical: float
    median_dt_ns: float

    def limit(self, dt_ns: np.ndarray | float) -> np.ndarray:
        """Largest plausible ``|increment|`` over intervals of ``dt_ns`` nanoseconds."""
        return (
            JUMP_FACTOR * self.typical * np.maximum(np.asarray(dt_ns, dtype=float) / self.median_dt_ns, 1.0)
        )


def counter_scale(steps: np.ndarray, dt_ns: np.ndarray) -> CounterScale | None:
    """The typical increment of ``steps`` over intervals ``dt_ns``; None when the log barely moves."""
    moving = steps != 0
    if int(moving.sum()) < MIN_MOVING_INTERVALS:
        return None
    median_dt = float(np.median(dt_ns))
    if not median_dt > 0:
        return None
    scaled = np.abs(steps[moving]) / np.maximum(dt_ns[moving] / median_dt, 1.0)
    typical = float(np.percentile(scaled, TYPICAL_PERCENTILE, method="inverted_cdf"))
    return CounterScale(max(typical, MIN_TYPICAL_TICKS), median_dt)


@dataclass(frozen=True)
class CounterJump:
    """Interval ``index`` (records ``index`` to ``index + 1``) of a counter steps implausibly far."""

    index: int
    step: int
    ratio: float
    scale: CounterScale

    def describe(self, name: str, readings: tuple[int, int], previous_line: int) -> str:
        ms = self.scale.median_dt_ns * 1e-6
        return (
            f"counter {name!r} steps {self.step:+d} ticks from line {previous_line} to this one (reads "
            f"{readings[0]}, then {readings[1]}): {self.ratio:.0f}× the log's typical step of "
            f"{self.scale.typical:.0f} ticks per {ms:.0f} ms (95th percentile of its moving intervals); "
            "no wheel moves that fast, so a reading is corrupt or the counter was reset"
        )


def counter_jumps(ticks: np.ndarray, t_ns: np.ndarray, modulus: int) -> list[CounterJump]:
    """Every interval whose increment exceeds the plausible limit (records in time order)."""
    steps = wrapped_difference(ticks, modulus)
    dt = np.diff(np.asarray(t_ns, dtype=np.int64)).astype(float)
    scale = counter_scale(steps, dt)
    if scale is None:
        return []
    limit = scale.limit(dt)
    return [
        CounterJump(int(i), int(steps[i]), float(abs(steps[i]) / (limit[i] / JUMP_FACTOR)), scale)
        for i in np.flatnonzero(np.abs(steps) > limit)
    ]


def records_to_drop(
    ticks: np.ndarray, t_ns: np.ndarray, modulus: int, linenos: np.ndarray, name: str
) -> dict[int, str]:
    """Records (indices) a non-strict read drops so that no counter jump remains, with reasons.

    Glitched readings that the neighbours bridge are dropped alone; across a jump that does not
    come back, every record outside the longest stretch between such jumps is dropped.
    """
    jumps = counter_jumps(ticks, t_ns, modulus)
    if not jumps:
        return {}
    scale = jumps[0].scale
    t = np.asarray(ticks, dtype=np.int64)
    n = t.shape[0]
    drop: dict[int, str] = {}
    cuts: list[int] = []
    flagged = [jump.index for jump in jumps]
    k = 0
    while k < len(flagged):
        i = flagged[k]
        bridge = None
        # A bridge must be plausible and far smaller than the jump: across a reset (an offset
        # that stays), the step over a longer stretch is as large as the jump itself.
        for j in range(i + 2, min(i + 2 + MAX_GLITCH_RECORDS, n)):
            step = abs(_step(t, i, j, modulus))
            if step <= float(scale.limit(float(t_ns[j] - t_ns[i]))) and 2 * step <= abs(jumps[k].step):
                bridge = j
                break
        if bridge is None:
            cuts.append(i)
            k += 1
            continue
        for r in range(i + 1, bridge):
            drop[r] = (
                f"counter {name!r} reads {int(t[r])}, out of line with its neighbours (lines "
                f"{int(linenos[i])} and {int(linenos[bridge])} step {_step(t, i, bridge, modulus):+d} "
                f"ticks between them); a corrupt reading"
            )
        while k < len(flagged) and flagged[k] < bridge:
            k += 1
    if cuts:
        # Stretches between persistent jumps: keep the longest, drop the others.
        bounds = [0, *(c + 1 for c in cuts), n]
        stretches = [(bounds[s], bounds[s + 1]) for s in range(len(bounds) - 1)]
        best = max(stretches, key=lambda ab: sum(1 for r in range(*ab) if r not in drop))
        for a, b in stretches:
            if (a, b) == best:
                continue
            at = b - 1 if b <= best[0] else a - 1  # the jump on this stretch's side facing the kept one
            for r in range(a, b):
                drop.setdefault(
                    r,
                    f"counter {name!r} steps {_step(t, at, at + 1, modulus):+d} ticks between lines "
                    f"{int(linenos[at])} and {int(linenos[at + 1])}, beyond any motion of the log, and "
                    f"does not step back within {MAX_GLITCH_RECORDS} records (a corrupt reading or a "
                    f"counter reset); kept the longest part of the log, lines "
                    f"{int(linenos[best[0]])}-{int(linenos[best[1] - 1])}",
                )
    return drop
