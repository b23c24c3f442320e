"""How a drive excites the robot, from the tracker's path and the encoders: numbers a reader can
check against what they drove.

The path is smoothed over about a second and taken every :data:`STEP_S` before anything is summed,
so that the tracker's noise does not add up over thousands of records into distance or turning
that was never driven. Turning counts where the heading turns faster than :data:`MIN_TURN_RATE`;
a turn's radius is the path's length over its heading change there, signed by the way it turns.
Reversals are changes of the direction of travel the model reads from the encoders, between runs
of at least :data:`MIN_RUN_S`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from nlp_calib.analysis.observability import MIN_TURNING
from nlp_calib.logs import Log
from nlp_calib.models import KinematicModel
from nlp_calib.results.preflight import Excitation
from nlp_calib.sensors import Sensor

#: The path is taken at this step (s) after smoothing over :data:`SMOOTH_S`.
STEP_S = 0.25
SMOOTH_S = 1.0
#: The heading turns when it changes faster than this (rad/s) ...
MIN_TURN_RATE = 0.05
#: ... and the base moves when the path grows faster than this (m/s).
MIN_SPEED = 0.01
#: A run of travel in one direction shorter than this (s) is not a reversal.
MIN_RUN_S = 0.5


def smoothed(t: np.ndarray, y: np.ndarray, seconds: float) -> np.ndarray:
    """``y`` ``(n, d)`` averaged over the records within a sliding window of ``seconds`` (records at
    the ends, or beside a gap, average what they have)."""
    # A window of records, not of time, would average across a gap in the reference: a car's GNSS
    # outage of 20 s put a few records 300 m apart into one mean and read 110 m/s off a 16 m/s drive.
    n = y.shape[0]
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    # Edges a quarter record early: on evenly spaced records, k = round(seconds/dt) of them, the
    # record's own k//2 before it and the rest after, whatever the stamps' rounding.
    edge = 0.25 * dt
    c = np.vstack([np.zeros((1, y.shape[1])), np.cumsum(y, axis=0)])
    lo = np.searchsorted(t, t - seconds / 2 - edge)
    hi = np.maximum(np.searchsorted(t, t + seconds / 2 - edge), np.arange(n) + 1)
    return np.asarray((c[hi] - c[lo]) / (hi - lo)[:, None])


def taken(t: np.ndarray, step: float) -> np.ndarray:
    """Indices of records about ``step`` apart (the first and last included)."""
    if t.size < 2:
        return np.arange(t.size)
    marks = np.arange(t[0], t[-1], step)
    idx = np.unique(np.searchsorted(t, marks))
    return np.unique(np.concatenate([idx[idx < t.size], [t.size - 1]]))


def _percentiles(r: np.ndarray) -> tuple[float, ...]:
    return tuple(float(v) for v in np.percentile(r, [10, 50, 90])) if r.size else ()


def reversals(direction: np.ndarray, time_s: np.ndarray) -> int:
    """Changes of the direction of travel (``direction`` per interval: +1, −1, 0) between runs of at
    least :data:`MIN_RUN_S`."""
    moving = np.flatnonzero(direction != 0)
    if moving.size == 0:
        return 0
    d = direction[moving]
    starts = np.flatnonzero(np.concatenate([[True], d[1:] != d[:-1]]))
    ends = np.concatenate([starts[1:], [d.size]])
    t = time_s[moving]
    t_end = time_s[np.minimum(moving[ends - 1] + 1, time_s.size - 1)]
    long = (t_end - t[starts]) >= MIN_RUN_S
    kept = d[starts][long]
    return int(np.sum(kept[1:] != kept[:-1])) if kept.size else 0


def _wheels_travel(direction: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Per step between the records ``k``, whether the wheels drive the base along on any interval
    of it (``direction`` per interval between records: +1, −1, 0)."""
    c = np.concatenate([[0], np.cumsum(direction != 0)])
    return np.asarray(c[k[1:]] - c[k[:-1]] > 0)


def excitation(
    time_s: np.ndarray, xy: np.ndarray, heading: np.ndarray, model: KinematicModel, inputs: np.ndarray
) -> Excitation:
    """The excitation of a drive: the tracker's positions ``xy`` ``(n, 2)`` and unwrapped heading
    at the records' ``time_s``, and the model's interval ``inputs`` (see the module docstring)."""
    # The times smoothed with the path: a window cut short by a gap or an end averages positions
    # from before (or after) its record, and their mean time goes with them.
    path = smoothed(time_s, np.column_stack([xy, heading, time_s - time_s[0]]), SMOOTH_S)
    k = taken(time_s, STEP_S)
    p = path[k]
    dt = np.maximum(np.diff(p[:, 3]), 1e-9)
    ds = np.hypot(*np.diff(p[:, :2], axis=0).T)
    dth = np.diff(p[:, 2])
    turning = np.abs(dth) / dt > MIN_TURN_RATE
    moving = ds / dt > MIN_SPEED
    bends = turning & moving
    radii = ds[bends] / np.abs(dth[bends])
    left, right = dth[bends] > 0, dth[bends] < 0
    direction = model.travel_direction(inputs) if inputs.shape[1] else np.zeros(0)
    step_t = time_s[1:] - time_s[:-1]
    moved = direction != 0
    total = float(np.sum(step_t)) if step_t.size else 0.0
    speed = ds / dt
    # The median speed over the time the wheels drive the base along, as the share moving counts
    # it (over the tracker's fast steps alone it was a scan matcher's slips on a drive turning on
    # the spot: 0.12 m/s median on a drive of 21 m in 44 min, 100 % moving).
    turned = _wheels_travel(direction, k) if direction.size == time_s.size - 1 else moving
    return Excitation(
        distance_m=float(np.sum(ds)),
        duration_s=float(time_s[-1] - time_s[0]) if time_s.size else 0.0,
        moving_fraction=float(np.sum(step_t[moved]) / total) if total > 0 else 0.0,
        heading_span_rad=float(np.ptp(heading)) if heading.size else 0.0,
        turned_left_rad=abs(float(np.sum(dth[turning & (dth > 0)]))),
        turned_right_rad=abs(float(np.sum(dth[turning & (dth < 0)]))),
        radii_left_m=_percentiles(radii[left]),
        radii_right_m=_percentiles(radii[right]),
        reversals=reversals(direction, time_s[:-1]) if direction.size else 0,
        reverse_fraction=float(np.sum(step_t[direction < 0]) / max(np.sum(step_t[moved]), 1e-9)),
        speed_median_mps=float(np.median(speed[turned])) if turned.any() else 0.0,
        speed_max_mps=float(np.percentile(speed, 99)) if speed.size else 0.0,
    )


def of_log(log: Log, sensor: Sensor, model: KinematicModel, steering_sample: str) -> Excitation:
    """The excitation of ``log``'s records as ``sensor`` tracks them on the floor (a 3-D reference
    levelled from its own poses); a track without positions (a gyro's) has no distance or speed.
    The one reading of a drive the pre-flight and the run's verdict share."""
    T = sensor.floor_track(log)
    ex = excitation(log.time_s, T[:, :2], T[:, 2], model, model.inputs(log, steering_sample))
    if sensor.lengths_unseen:
        ex = replace(ex, distance_m=math.nan, speed_median_mps=math.nan, speed_max_mps=math.nan)
    return ex


def turns_both_ways(ex: Excitation | None) -> bool:
    """Whether the drive turns both ways, each at least :data:`MIN_TURNING` (so that "turn both
    ways" is no advice for it). A heading that never leaves a band under it has not turned for the
    turning parameters, however often it swings both ways inside it."""
    return ex is not None and min(ex.heading_span_rad, ex.turned_left_rad, ex.turned_right_rad) >= MIN_TURNING


def words(ex: Excitation) -> list[str]:
    """The excitation in a few lines."""
    lines = [
        f"{ex.distance_m:.1f} m in {ex.duration_s:.1f} s (travelling {100 * ex.moving_fraction:.0f} % of "
        f"it, by the wheels), speed {ex.speed_median_mps:.2g} m/s median while travelling, "
        f"{ex.speed_max_mps:.2g} m/s at most",
        f"heading spans {ex.heading_span_rad:.2f} rad; turned {ex.turned_left_rad:.1f} rad left, "
        f"{ex.turned_right_rad:.1f} rad right",
    ]
    for side, radii in (("left", ex.radii_left_m), ("right", ex.radii_right_m)):
        if radii:
            lines.append(
                f"turn radii to the {side}: {radii[1]:.2g} m typical ({radii[0]:.2g} to {radii[2]:.2g} m)"
            )
    lines.append(
        f"{ex.reversals} reversal(s) of travel, {100 * ex.reverse_fraction:.0f} % of the driving backwards"
    )
    return lines


def combined(parts: Sequence[Excitation]) -> Excitation:
    """Several logs' excitation as one drive's: sums and extremes, the radii's spread over all."""
    if len(parts) == 1:
        return parts[0]

    def radii(side: str) -> tuple[float, ...]:
        given = [getattr(p, side) for p in parts if getattr(p, side)]
        if not given:
            return ()
        return (min(r[0] for r in given), float(np.median([r[1] for r in given])), max(r[2] for r in given))

    duration = sum(p.duration_s for p in parts)
    moving = sum(p.moving_fraction * p.duration_s for p in parts)
    return Excitation(
        distance_m=sum(p.distance_m for p in parts),
        duration_s=duration,
        moving_fraction=moving / duration if duration > 0 else 0.0,
        heading_span_rad=max(p.heading_span_rad for p in parts),
        turned_left_rad=sum(p.turned_left_rad for p in parts),
        turned_right_rad=sum(p.turned_right_rad for p in parts),
        radii_left_m=radii("radii_left_m"),
        radii_right_m=radii("radii_right_m"),
        reversals=sum(p.reversals for p in parts),
        reverse_fraction=float(
            np.average([p.reverse_fraction for p in parts], weights=[max(p.duration_s, 1e-9) for p in parts])
        ),
        speed_median_mps=float(np.median([p.speed_median_mps for p in parts])),
        speed_max_mps=max(p.speed_max_mps for p in parts),
    )
