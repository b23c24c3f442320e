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
"""

from __future__ import annotations

import dataclasses

import numpy as np

from nlp_calib.analysis.metrics import steps
from nlp_calib.problem import ProblemFunctions
from nlp_calib.results.layout import FREE, Layout

#: The heading an offset's needed precision may turn a second (rad/s): the reference robot's.
HEADING_BUDGET = 0.0025
#: Intervals turning slower than this (rad/s) drive straight.
STRAIGHT_RATE = 0.05
#: The share of a drive's intervals that must drive straight for its offsets' effect to be measured.
STRAIGHT_SHARE = 0.1


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
