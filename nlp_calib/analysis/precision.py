"""The precision a calibration must reach on this vehicle, from its own drive.

A model's reference precision (:func:`~nlp_calib.models.base.reference`) is written for a robot of
about a metre driving about half a metre a second. A parameter whose reference is an amount in its
unit (an offset: a steer offset, a gyro's bias) turns the heading by the same amount every
second the vehicle drives, whatever it drives; on a car at highway speed the reference robot's 5 mrad
of steer offset turns the heading a hundred degrees a kilometre. So such a parameter must resolve
the change that turns the dead-reckoned heading by no more than :data:`HEADING_BUDGET` a second at
the drive's own speed while it drives straight: the reference robot's (5 mrad at half a metre a
second over a metre of wheelbase). The effect is measured on the drive itself (the model's
predicted motion over the intervals turning slower than :data:`STRAIGHT_RATE`, with the parameter
moved by its reference), so nothing is read from a parameter's name; what errs only in turns (a
skid-steer's slip with the turn rate) is no offset and keeps its reference.
A parameter whose reference is a fraction of its value (a gain, a length) errs in proportion to
what the vehicle drives (a wheel scale's 1 % is 1 % of the drive's distance), and keeps it.

A clock offset misplaces the reference by what the sensor moves in that time: its reference (2 ms)
is the reference robot's 2 mm at a metre a second and 2 mrad at a radian a second, so it needs
what keeps the sensor's own speed and turn rate on this drive (their :data:`FAST_QUANTILE`, over
steps of the path as the drive's description takes them: not the tracker's noise) to that
(:func:`lag_precision`); a slow robot needs less of it, a car at speed more.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from nlp_calib.analysis.excitation import STEP_S, taken
from nlp_calib.analysis.metrics import steps
from nlp_calib.logs import Log
from nlp_calib.problem import ProblemFunctions
from nlp_calib.results.layout import CLOCK, FREE, Layout

#: The heading an offset's needed precision may turn a second (rad/s): the reference robot's.
HEADING_BUDGET = 0.0025
#: Intervals turning slower than this (rad/s) drive straight.
STRAIGHT_RATE = 0.05
#: The share of a drive's intervals that must drive straight for its offsets' effect to be measured.
STRAIGHT_SHARE = 0.1
#: The reference robot's speed (m/s) and turn rate (rad/s) a clock offset's reference is written for.
REFERENCE_SPEED, REFERENCE_RATE = 1.0, 1.0
#: The quantile of the drive's speeds and turn rates (over the intervals it moves) judged by.
FAST_QUANTILE = 0.9


def drive_precision(
    layout: Layout, fns: ProblemFunctions, view: np.ndarray, inputs: np.ndarray, duration_s: float
) -> Layout:
    """``layout`` (one log's view of ``fns``' parameters at ``view``) with the precision of each
    free parameter of an absolute reference tightened to what this drive needs (see the module's
    docstring): its reference times :data:`HEADING_BUDGET` over the heading it turns a second."""
    n = inputs.shape[1]
    if duration_s <= 0.0 or n == 0:
        return layout
    dt = duration_s / n
    turned = steps(fns, view, inputs)[:, 2]
    straight = np.abs(turned) < STRAIGHT_RATE * dt
    if np.mean(straight) < STRAIGHT_SHARE:
        return layout
    inputs, base = inputs[:, straight], float(np.sum(turned[straight]))
    out = []
    for p in layout.parameters:
        # (A log's own parameter, a mount or a clock per log, is left as its sensor states it.)
        if (
            p.status != FREE
            or p.precision[0] != "absolute"
            or p.log is not None
            or p.key not in fns.view_names
        ):
            out.append(p)
            continue
        moved = np.array(view, dtype=float)
        moved[fns.view_names.index(p.key)] += p.precision[1]
        rate = abs(float(np.sum(steps(fns, moved, inputs)[:, 2])) - base) / (dt * inputs.shape[1])
        needed = p.precision[1] * min(1.0, HEADING_BUDGET / rate) if rate > 0 else p.precision[1]
        out.append(dataclasses.replace(p, precision=("absolute", float(needed))))
    return dataclasses.replace(layout, parameters=tuple(out))


def lag_precision(layout: Layout, track: np.ndarray, time_s: np.ndarray, log: int, metric: bool) -> Layout:
    """``layout`` with the precision of log ``log``'s free clock offsets (and a shared one) from
    the sensor's track on the floor ``(x, y, heading)`` at ``time_s`` (see the module docstring);
    without ``metric`` positions (a track in its own units) only the turn rate counts."""
    # Steps of a quarter second at least, as the drive's description takes the path: the speed of
    # each record's noise is not the sensor's (6 mm of noise at 25 Hz moves it 0.2 m/s, over a
    # quarter second 0.03 m/s); unsmoothed, so that an arc keeps its speed (a chord's shortfall).
    time_s = np.asarray(time_s, dtype=float)
    k = taken(time_s, STEP_S)
    path = np.asarray(track, dtype=float)[k]
    dt = np.diff(time_s[k])
    step = np.diff(path, axis=0)[dt > 0]
    dt = dt[dt > 0]
    speed = np.hypot(step[:, 0], step[:, 1]) / dt / REFERENCE_SPEED if metric else np.zeros(dt.size)
    fast = max(_fast(speed), _fast(np.abs(step[:, 2]) / dt / REFERENCE_RATE))
    if fast <= 0:
        return layout
    out = []
    for p in layout.parameters:
        if p.block == CLOCK and p.status == FREE and p.log in (None, log) and p.precision[0] == "absolute":
            p = dataclasses.replace(p, precision=("absolute", p.precision[1] / fast))
        out.append(p)
    return dataclasses.replace(layout, parameters=tuple(out))


def _fast(rates: np.ndarray) -> float:
    """The :data:`FAST_QUANTILE` of the ``rates`` of the intervals that move (0 without any)."""
    moving = rates[rates > 0]
    return float(np.quantile(moving, FAST_QUANTILE)) if moving.size else 0.0


def log_precision(
    layout: Layout,
    fns: ProblemFunctions,
    view: np.ndarray,
    inputs: np.ndarray,
    drive_s: np.ndarray,
    log: Log,
    index: int,
) -> Layout:
    """``layout`` with what log ``index`` needs: its drive's (:func:`drive_precision`, ``inputs`` at
    the times ``drive_s``) and its clock offset's from the sensor's own track on ``log``
    (:func:`lag_precision`). One rule for the pre-flight and the run."""
    duration = float(drive_s[-1] - drive_s[0]) if drive_s.size else 0.0
    layout = drive_precision(layout, fns, view, inputs, duration)
    track = fns.sensor.floor_track(log)
    return lag_precision(layout, track, log.time_s, index, fns.sensor.length_unit == "m")


def tightest(layout: Layout, logs: Sequence[Layout], shared: bool = True) -> Layout:
    """``layout`` (several logs' together) with each parameter's precision the tightest any log's
    drive needs of it (``logs``: each log's layout of the whole calibration, as its drive sets it);
    a log's own parameter (its clock offset) as its own log's drive sets it. Without ``shared``,
    only the logs' own parameters: one log's view of a joint fit (its drive's needs of the shared
    ones, every other log's of its own clock offset, not a constant 2 ms)."""
    out = []
    for p in layout.parameters:
        if p.log is None and not shared:
            out.append(p)
            continue
        mine = logs if p.log is None else logs[p.log : p.log + 1]
        needed = [o.param(p.name).precision for o in mine if p.name in o]
        if needed and all(kind == "absolute" for kind, _ in needed):
            p = dataclasses.replace(p, precision=("absolute", min(amount for _, amount in needed)))
        out.append(p)
    return dataclasses.replace(layout, parameters=tuple(out))


def clock_needed(layout: Layout) -> dict[str, float]:
    """The precision each free clock offset of ``layout`` needs (s): the drive's, where ``layout``
    is set by :func:`log_precision` (:func:`lag_precision`), so that no check reads a lag by the
    reference robot's constant 2 ms."""
    return {p.name: p.needed(0.0) for p in layout.parameters if p.block == CLOCK and p.status == FREE}


def with_clocks(scales: np.ndarray, names: Sequence[str], clocks: Mapping[str, float]) -> np.ndarray:
    """``scales`` (per parameter of ``names``, a precision in its unit) with each clock offset's the
    drive's (``clocks``: :func:`clock_needed`)."""
    return np.array([clocks.get(n, s) for n, s in zip(names, np.asarray(scales, dtype=float))])
