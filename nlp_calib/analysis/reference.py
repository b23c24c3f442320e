"""Reference precision per parameter: the scale that uncertainty and observability are judged in.

What a useful calibration must resolve: 1% of a gain or length, 1 cm of the sensor position,
5 mrad of an angle. Scaling by it makes "large" and "small" mean the same across units.
"""

from __future__ import annotations

import numpy as np

#: Reference precision per parameter: ("relative", fraction of |value|) or ("absolute", value).
REFERENCE: dict[str, tuple[str, float]] = {
    "sensor_x": ("absolute", 0.01),
    "sensor_y": ("absolute", 0.01),
    "sensor_theta": ("absolute", 0.005),
}
_DEFAULT_REFERENCE = ("relative", 0.01)
_ANGLE_REFERENCE = ("absolute", 0.005)


def reference_scale(name: str, value: float) -> float:
    """The precision a calibration should reach on ``name`` (see :data:`REFERENCE`)."""
    kind, amount = REFERENCE.get(name, _ANGLE_REFERENCE if "offset" in name else _DEFAULT_REFERENCE)
    return amount * max(abs(value), 1e-9) if kind == "relative" else amount


def reference_scales(names: tuple[str, ...], values: np.ndarray) -> np.ndarray:
    """:func:`reference_scale` of each parameter."""
    return np.array([reference_scale(n, float(v)) for n, v in zip(names, values)])
