"""The closed-form start and the window selection of a 3-D sensor's problem, on its data.

:func:`camera_initial_guess` lays windows of about ``span_s`` seconds over the records (a second
of driving turns far more than one image interval, so the rotation axes show the floor normal
above the pose noise), takes the camera's motion over each and hands them, with the model's
planar prediction, to :func:`nlp_calib.models.camera_start.camera_start`. :func:`fit_selection`
applies the reasons that also concern the refinement to the fit's own windows.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from nlp_calib.core import poses3d
from nlp_calib.core.errors import ProblemError
from nlp_calib.models.camera_start import (
    REASONS,
    CameraStart,
    Selection,
    SelectionOptions,
    camera_start,
    rotation_vectors,
)
from nlp_calib.models.mount import length_params
from nlp_calib.problem.functions import ProblemFunctions, ProblemSpec, build
from nlp_calib.problem.sensors import Mount3D
from nlp_calib.problem.windows import ResidualData, over_columns


def _mount(fns: ProblemFunctions) -> Mount3D:
    if not isinstance(fns.sensor, Mount3D):
        raise ProblemError("the camera start needs a problem built with sensor '3d'")
    return fns.sensor


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


def camera_initial_guess(
    fns: ProblemFunctions,
    data: ResidualData,
    *,
    known: Mapping[str, float] | None = None,
    span_s: float = 1.0,
    options: SelectionOptions | None = None,
) -> CameraStart:
    """Every parameter of ``fns`` (a ``3d`` problem) from the records of ``data``, no guess needed;
    ``known`` holds the held values (``sensor_z``; with a free scale, one length in metres)."""
    sensor = _mount(fns)
    lengths = length_params(fns.model)
    if sensor.scale_free and not any(n in fns.fixed for n in lengths):
        # Every length times c, the mount's translation times c and the scale over c predict the
        # same motions: one length must be held at its value in metres.
        raise ProblemError(
            f"a free scale needs one known length: fix one of {', '.join(lengths)} at its measured "
            "value (the trajectory's scale and every length are otherwise one unknown)"
        )
    a, b = start_windows(data, span_s)
    span = int(b[0] - a[0]) if a.size else 1
    if a.size == 0 or any(log.n_records <= span for log in data.logs):
        raise ProblemError(f"the log is shorter than one start window of {span_s:g} s")
    n_in = fns.n_inputs
    U = np.empty((n_in * span, a.size))
    for j in range(span):
        U[j * n_in : (j + 1) * n_in] = data.inputs[:, a + j]
    z = poses3d.between(data.T_world_sensor[a], data.T_world_sensor[b]).T
    planar = build(fns.model, ProblemSpec(horizon=span, integration=fns.integration))

    def base_motion(params: Mapping[str, float]) -> np.ndarray:
        return over_columns(planar.predict_window, np.array([params[n] for n in planar.names]), U)[0]

    return camera_start(
        fns.model, U, z, base_motion, scale_free=sensor.scale_free, known=known, options=options
    )


def fit_selection(
    fns: ProblemFunctions, data: ResidualData, start: CameraStart, options: SelectionOptions | None = None
) -> Selection:
    """The fit's windows that ``FIT_REASONS`` (:mod:`nlp_calib.models.camera_start`) leave out, judged
    with the start's floor normal and parameters. Axes and turning senses are judged only where the
    camera turns by ``min_rotation`` or more (below that the axis is noise)."""
    options = options or SelectionOptions()
    finite = np.all(np.isfinite(data.z), axis=0)
    sel = Selection(np.where(finite, -1, REASONS.index("not_finite")))
    z = np.where(finite, data.z, np.array([[0.0]] * 6 + [[1.0]]))
    phi = rotation_vectors(z)
    angle = np.linalg.norm(phi, axis=1)
    turning = angle >= options.min_rotation
    cosine = np.abs(phi @ start.normal) / np.maximum(angle, 1e-300)
    sel = sel.drop(turning & (cosine < np.cos(options.max_axis_angle)), "axis_off_normal")
    k = np.array([start.params[n] for n in fns.model.kinematic_params])
    base_turn = _window_turn(fns, data, k)
    sel = sel.drop(turning & (np.sign(base_turn) != np.sign(phi @ start.normal)), "opposite_turning")
    return sel


def _window_turn(fns: ProblemFunctions, data: ResidualData, k: np.ndarray) -> np.ndarray:
    """The base's turn over each window the model predicts with kinematic parameters ``k`` (rad)."""
    planar = build(fns.model, ProblemSpec(horizon=1, integration=fns.integration))
    steps = over_columns(planar.predict, np.concatenate([k, np.zeros(3)]), data.inputs)[0][2]
    turned = np.concatenate([[0.0], np.cumsum(steps)])
    return turned[data.stops] - turned[data.starts]
