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
from dataclasses import replace

import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.problem.functions import ProblemFunctions, ProblemSpec, build
from nlp_calib.problem.windows import ResidualData, over_columns, tracker_motions
from nlp_calib.sensors import SensorStart
from nlp_calib.sensors.base import BaseMotion


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


def _own_windows(data: ResidualData, stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The data's own windows, three quarters overlapping: nearly all the information at a fraction
    of the cost of every window (measured increments: those of the commonest length), and their
    measured motions."""
    step = max(1, data.horizon // (4 * stride))
    keep = np.arange(0, data.n_residuals, step)
    if data.increment is not None and data.increment.any():
        spans = data.stops - data.starts
        keep = np.flatnonzero(spans == np.bincount(spans).argmax())
    return data.starts[keep], data.stops[keep], data.z[:, keep]


def closed_form_start(
    fns: ProblemFunctions,
    data: ResidualData,
    known: Mapping[str, float] | None = None,
    stride: int = 1,
    nominal: Mapping[str, float] | None = None,
) -> SensorStart:
    """Every parameter of ``fns`` from the records of ``data`` by the sensor's closed form, no guess
    needed; ``known`` holds the fixed values (a camera's held height; with a free scale, one
    length in metres). A planar sensor's start survives windows turning more than π and gives
    way to the ``nominal`` robot where that explains the windows better (:func:`unwrapped_start`)."""
    span_s = fns.sensor.start_span_s
    if span_s is None:
        a, b, z = _own_windows(data, stride)
    else:
        a, b = start_windows(data, span_s)
        z = tracker_motions(fns, data.T_world_sensor, a, b)
    span = int(b[0] - a[0]) if a.size else 1
    if a.size == 0 or np.any(b - a != span) or any(log.n_records <= span for log in data.logs):
        raise ProblemError(f"the log is shorter than one start window of {span} records")
    n_in = fns.n_inputs
    U = np.empty((n_in * span, a.size))
    for j in range(span):
        U[j * n_in : (j + 1) * n_in] = data.inputs[:, a + j]
    planar = build(fns.model, ProblemSpec(horizon=span, integration=fns.integration))

    def base_motion(params: Mapping[str, float]) -> np.ndarray:
        full = np.array([params.get(n, 0.0) for n in planar.names])  # a sensor's own do not move the base
        return over_columns(planar.predict_window, full, U)[0]

    # Only what the problem holds is known: a value it fits is not.
    held = {n: v for n, v in (known or {}).items() if n in fns.fixed}
    if not fns.sensor.planar_base or z.shape[0] != 3:
        return fns.sensor.closed_form(fns.model, U, z, base_motion, held)
    return unwrapped_start(fns, (U, z), base_motion, held, nominal)


#: The subsets of windows a planar start is first drawn from, by how far their measured heading
#: change lies from ±π (rad): a window that turned more than π reads as wrapped, and only the
#: wheels' prediction can tell it; one of these subsets holds few enough of those to start from.
_FIRST_TURNS = (np.inf, 0.5 * np.pi, 0.25 * np.pi)
#: Rounds of unwrapping the measured heading changes towards a start's prediction.
_UNWRAP_ROUNDS = 6


def unwrapped_start(
    fns: ProblemFunctions,
    windows: tuple[np.ndarray, np.ndarray],
    base_motion: BaseMotion,
    held: Mapping[str, float],
    nominal: Mapping[str, float] | None,
) -> SensorStart:
    """A planar sensor's closed form that survives windows turning more than π: drawn from each of
    :data:`_FIRST_TURNS`' subsets, then again on every window with its heading change unwrapped
    to the start's own prediction until that stops changing; the start that explains the windows
    best (:func:`explained`) wins, and the ``nominal`` robot (every parameter, when known) in its
    place if it explains them better."""
    U, z = windows
    sensor, model = fns.sensor, fns.model
    best: tuple[float, SensorStart] | None = None
    drawn: list[np.ndarray] = []
    for limit in _FIRST_TURNS:
        keep = np.abs(z[2]) < limit
        # A subset drawn before gives the same start: most drives never turn a quarter turn in a
        # window, and the closed form is most of a run's start.
        if keep.sum() < max(8, 2 * len(model.kinematic_params)) or any(
            np.array_equal(keep, k) for k in drawn
        ):
            continue
        drawn.append(keep)
        try:
            start = sensor.closed_form(model, U[:, keep], z[:, keep], _columns(base_motion, keep), held)
            start = _unwrapped(start, (U, z), base_motion, held, bool(keep.all()), fns)
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError):
            continue
        cost = explained({**start.params, **held}, z, base_motion)
        if best is None or cost < best[0]:
            best = (cost, start)
    if best is None:
        return sensor.closed_form(model, U, z, base_motion, held)
    full = set(model.kinematic_params) | set(sensor.params)
    if nominal is not None and full <= set(nominal) | set(held):
        given = {**nominal, **held}
        worse = explained(given, z, base_motion)
        if worse < best[0]:
            return replace(
                best[1],
                params={n: float(given[n]) for n in best[1].params},
                note=(
                    f"the closed-form start explains the windows worse than the nominal robot "
                    f"({best[0]:.3g} against {worse:.3g} of {z.shape[1]}, each window's share at most "
                    "1): the fit starts from the nominal values"
                ),
            )
    return best[1]


def _unwrapped(
    start: SensorStart,
    windows: tuple[np.ndarray, np.ndarray],
    base_motion: BaseMotion,
    held: Mapping[str, float],
    from_every_window: bool,
    fns: ProblemFunctions,
) -> SensorStart:
    """``start`` drawn again on every window, each heading change unwrapped to the start's own
    prediction, until that stops changing (at most :data:`_UNWRAP_ROUNDS` draws). A start
    ``from_every_window`` already is the first draw where nothing unwraps."""
    U, z = windows
    current = z[2] if from_every_window else None
    for _ in range(_UNWRAP_ROUNDS):
        turned = base_motion({**start.params, **held})[2]
        unwrapped = z[2] + 2.0 * np.pi * np.round((turned - z[2]) / (2.0 * np.pi))
        if current is not None and np.array_equal(unwrapped, current):
            break
        current = unwrapped
        start = fns.sensor.closed_form(fns.model, U, np.vstack([z[:2], unwrapped]), base_motion, held)
    return start


def _columns(base_motion: BaseMotion, keep: np.ndarray) -> BaseMotion:
    return lambda params: base_motion(params)[:, keep]


def explained(params: Mapping[str, float], z: np.ndarray, base_motion: BaseMotion) -> float:
    """How badly ``params`` explain the planar windows ``z`` ``(3, M)``: over the windows, the
    squared translation error relative to the window's length (at least the median length) plus
    ``1 − cos`` of the heading error (blind to whole turns), each window's share at most 1."""
    # ``base_motion`` of a full set of parameters is already the sensor's motion over each window
    # (its mount among them): applying the mount again would judge a start by another robot.
    predicted = base_motion(params).T
    length = np.hypot(z[0], z[1])
    scale = np.maximum(length, np.median(length) + 1e-9)
    e_xy = np.hypot(*(predicted[:, :2] - z[:2].T).T) / scale
    e_theta = 1.0 - np.cos(predicted[:, 2] - z[2])
    return float(np.sum(np.minimum(e_xy**2 + e_theta, 1.0)))


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
