"""The facts of the reference's clock: the time offset between the encoders and the reference.

The reference (a tracker, a camera) reports a pose ``tracker_lag`` seconds after the encoders read
the robot there: the encoders are read at ``t − tracker_lag`` for a reference stamp ``t``. It is a
parameter of the problem like any other (:mod:`nlp_calib.problem.clock`), one per log; a fit of
one log calls it ``tracker_lag``, a fit of several ``tracker_lag_1``, ``tracker_lag_2``, … in the
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


def lag_names(n_logs: int) -> tuple[str, ...]:
    """The time offsets' parameter names of a fit of ``n_logs`` logs (none when 0)."""
    if n_logs <= 1:
        return (LAG_PARAM,) * n_logs
    return tuple(f"{LAG_PARAM}_{i + 1}" for i in range(n_logs))


def is_lag(name: str) -> bool:
    """Whether ``name`` is a time offset's parameter."""
    return name == LAG_PARAM or (name.startswith(LAG_PARAM + "_") and name[len(LAG_PARAM) + 1 :].isdigit())


def base_name(name: str) -> str:
    """The name a scenario's keys give a per-log parameter (``tracker_lag_2`` → ``tracker_lag``)."""
    return LAG_PARAM if is_lag(name) else name
