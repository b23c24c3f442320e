"""How far two wheels' difference turns a base: the track it turns with, measured.

A differential drive turns by its wheels' difference over the distance between them; a skid-steer's
sides drag across the ground as it turns, so that it turns less, as if its wheels were farther
apart than they are (its effective track: 1.5 to 2 times the geometric one on a real base). The
drive tells the effective track: the median, over the steps of :data:`TURN_STEP_S` that turn beyond
a tracker's noise, of the wheels' difference (rad) per radian of the base's heading, times the
wheels' radius that the travel on gentle curves gives (a median: a tracker's jumps and repeated
poses pass it by). On its own it is a track like any other; against the geometric one (a
``ROBOT.yaml``'s) it tells whether the base skids.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis.excitation import STEP_S, taken
from nlp_calib.logs import Log
from nlp_calib.models import KinematicModel

#: The steps (s) over which the heading's change is set against the wheels' difference.
TURN_STEP_S = 0.5
#: A step turns where the heading changes by this much (rad) at this rate (rad/s) or more.
MIN_TURN, MIN_TURN_RATE = 0.05, 0.1
#: Fewer turning steps than this tell no track.
MIN_TURN_STEPS = 20
#: A curve is gentle where the heading turns less than this per metre (rad/m): the wheels' mean
#: turning is then the base's travel.
GENTLE_CURVATURE = 1.0


@dataclass(frozen=True)
class Turning:
    """The wheels' radius (m per rad, by the travel on gentle curves), the median wheels'
    difference (rad) per radian of heading over the turning steps, its quartiles, and the number
    of those steps."""

    radius: float
    per_heading: float
    quartiles: tuple[float, float]
    steps: int

    @property
    def track(self) -> float:
        """The effective track (m): the distance between the wheels that turns the base as it turned."""
        return self.radius * self.per_heading


def _radius(log: Log, wheels: np.ndarray, xy: np.ndarray, heading: np.ndarray) -> float | None:
    """The base's travel per radian of its wheels' mean turning on gentle curves (m)."""
    k = taken(log.time_s, STEP_S)
    ds = np.hypot(*np.diff(xy[k], axis=0).T)
    gentle = (ds > 1e-3) & (np.abs(np.diff(heading[k])) < GENTLE_CURVATURE * ds)
    turned = float(np.sum(np.abs(np.diff(wheels[k].mean(axis=1)))[gentle]))
    if gentle.sum() < 3 or not turned > 0:
        return None
    return float(np.sum(ds[gentle])) / turned


def turning(log: Log, model: KinematicModel, track: tuple[np.ndarray, np.ndarray]) -> Turning | None:
    """The track ``log``'s two wheels (the model's counters, left then right) turn the base with,
    by the reference's ``track`` (positions ``(n, 2)`` and unwrapped heading at the records); None
    without two wheels, :data:`MIN_TURN_STEPS` turning steps, or a positive median (a mirrored
    wheel's: the pre-flight's to say)."""
    counters = [n for n in log.header.encoder_names if model.encoder_kinds.get(n) == "counter"]
    if len(counters) != 2:
        return None
    xy, heading = track
    wheels = np.column_stack([log.running_position(n) for n in counters])
    k = taken(log.time_s, TURN_STEP_S)
    dth = np.diff(heading[k])
    apart = np.diff(wheels[k, 1] - wheels[k, 0])
    rate = np.abs(dth) / np.maximum(np.diff(log.time_s[k]), 1e-9)
    turns = (np.abs(dth) >= MIN_TURN) & (rate >= MIN_TURN_RATE) & np.isfinite(apart)
    radius = _radius(log, wheels, xy, heading)
    if turns.sum() < MIN_TURN_STEPS or radius is None:
        return None
    ratio = apart[turns] / dth[turns]
    low, median, high = (float(q) for q in np.quantile(ratio, [0.25, 0.5, 0.75]))
    if not median > 0:
        return None
    return Turning(radius, median, (low, high), int(turns.sum()))
