"""The facts of the reference's clock: the time offset between the encoders and the reference.

The reference (a tracker, a camera) reports a pose ``tracker_lag`` seconds after the encoders read
the robot there: the encoders are read at ``t − tracker_lag`` for a reference stamp ``t``. It is a
parameter of the problem like any other (:mod:`nlp_calib.problem.clock`), one per log: the
``clock`` block of a calibration's layout (:mod:`nlp_calib.results.layout`), whose names a fit of
one log calls ``tracker_lag`` and a fit of several ``tracker_lag_1``, ``tracker_lag_2``, … in the
order of the logs.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Literal

LAG_PARAM = "tracker_lag"
LAG_UNIT = "s"
#: What a useful calibration must resolve of the time offset: 2 ms (at 1 m/s, 2 mm of travel).
LAG_REFERENCE: Mapping[str, tuple[Literal["relative", "absolute"], float]] = MappingProxyType(
    {LAG_PARAM: ("absolute", 0.002)}
)
