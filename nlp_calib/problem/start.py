"""A sensor's closed-form start on a problem's data, and the selection of the fit's windows it implies.

:func:`closed_form_start` lays windows over the records (the residual's own, three quarters
overlapping, or windows of the sensor's ``start_span_s``: a camera's second of driving, whose
rotation axes show the floor normal above the pose noise), takes the sensor's motion over each
and the model's planar prediction, and hands them to the sensor's
:meth:`~nlp_calib.sensors.base.Sensor.closed_form`. :func:`fit_windows` applies what that start
says of the fit's own windows.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.problem.functions import ProblemFunctions, ProblemSpec, build
from nlp_calib.problem.windows import ResidualData, over_columns, tracker_motions
from nlp_calib.sensors import SensorStart


def start_windows(data: ResidualData, span_s: float) -> tuple[np.ndarray, np.ndarray]:
    """First and last records of windows of about ``span_s`` seconds inside each log, overlapping
    by three quarters."""
    starts = []
    for log, offset in zip(data.logs, data.offsets):
        n = log.n_records
        dt = float(np.median(np.diff(log.time_s))) if n > 1 else 1.0
        span = int(min(max(1, round(span_s / dt)), n - 1))
        starts.append(offset + np.arange(0, n - span, max(1, span // 4)))
    first = np.concatenate(starts).astype(np.int64)
    return first, first + span


def _own_windows(data: ResidualData, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """The data's own windows, three quarters overlapping: nearly all the information at a fraction
    of the cost of every window."""
    step = max(1, data.horizon // (4 * stride))
    keep = np.arange(0, data.n_residuals, step)
    return data.starts[keep], data.stops[keep]


def closed_form_start(
    fns: ProblemFunctions, data: ResidualData, known: Mapping[str, float] | None = None, stride: int = 1
) -> SensorStart:
    """Every parameter of ``fns`` from the records of ``data`` by the sensor's closed form, no guess
    needed; ``known`` holds the fixed values (a camera's held height; with a free scale, one
    length in metres)."""
    span_s = fns.sensor.start_span_s
    a, b = _own_windows(data, stride) if span_s is None else start_windows(data, span_s)
    span = int(b[0] - a[0]) if a.size else 1
    if a.size == 0 or np.any(b - a != span) or any(log.n_records <= span for log in data.logs):
        raise ProblemError(f"the log is shorter than one start window of {span} records")
    n_in = fns.n_inputs
    U = np.empty((n_in * span, a.size))
    for j in range(span):
        U[j * n_in : (j + 1) * n_in] = data.inputs[:, a + j]
    z = tracker_motions(fns, data.T_world_sensor, a, b)
    planar = build(fns.model, ProblemSpec(horizon=span, integration=fns.integration))

    def base_motion(params: Mapping[str, float]) -> np.ndarray:
        full = np.array([params.get(n, 0.0) for n in planar.names])  # a sensor's own do not move the base
        return over_columns(planar.predict_window, full, U)[0]

    # Only what the problem holds is known: a value it fits is not.
    held = {n: v for n, v in (known or {}).items() if n in fns.fixed}
    return fns.sensor.closed_form(fns.model, U, z, base_motion, held)


def fit_windows(
    fns: ProblemFunctions, data: ResidualData, start: SensorStart
) -> tuple[np.ndarray, dict[str, int]]:
    """Which of the fit's windows the sensor's ``start`` keeps, and how many it left out by reason."""
    k = np.array([start.params[n] for n in fns.model.kinematic_params])
    return fns.sensor.fit_windows(start, data.z, _window_turn(fns, data, k))


def _window_turn(fns: ProblemFunctions, data: ResidualData, k: np.ndarray) -> np.ndarray:
    """The base's turn over each window the model predicts with kinematic parameters ``k`` (rad)."""
    planar = build(fns.model, ProblemSpec(horizon=1, integration=fns.integration))
    steps = over_columns(planar.predict, np.concatenate([k, np.zeros(3)]), data.inputs)[0][2]
    turned = np.concatenate([[0.0], np.cumsum(steps)])
    return turned[data.stops] - turned[data.starts]
