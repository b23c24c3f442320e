"""A closed-form start for a 3-D sensor (a camera) on a planar base, from its own motions alone.

On a flat floor the base turns about the floor normal ``n``; seen from the camera every window's
rotation turns about the same axis ``n_c = R_Xᵀ·e_z``, the third row of the mount's rotation
``R_X = Rz(yaw)·Ry(pitch)·Rx(roll)``, which does not depend on the yaw. So:

1. **Selection.** Windows are dropped, each for the first reason that applies (counted by
   reason): ``not_finite`` values; a ``tiny_translation`` (below a fraction of the median);
   a ``small_rotation`` (its axis is noise); a rotation axis further than an angle from the floor
   normal (``axis_off_normal``: an uneven floor, or a bad pose); ``opposite_turning`` of camera
   and wheels (a timing error where the motion changes).
2. **Roll and pitch** from the floor normal: ``n_c`` is the principal axis of the windows'
   rotation vectors (Σφφᵀ); ``roll = atan2(n_y, n_z)``, ``pitch = atan2(−n_x, √(n_y² + n_z²))``.
   Its sign (up or down) is the one for which the model's start below gives plausible parameters.
3. **The planar hand-eye** ``AX = XB`` on the motions levelled by ``Ry(pitch)·Rx(roll)``: the
   model's own planar closed-form start (:meth:`~nlp_calib.models.base.KinematicModel.
   initial_guess`) gives the wheel intrinsics by linear least squares and the mount's ``x, y`` and
   yaw (Guo et al. 2012, Censi et al. 2013 solve the same equations).
4. **Scale.** Poses known up to scale give every length in the trajectory's units; one length
   known in metres (a held parameter in ``known``) fixes ``scale``, the metres per unit.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from nlp_calib.core import poses, poses3d
from nlp_calib.core.errors import ProblemError
from nlp_calib.models.base import SENSOR_PARAMS, KinematicModel
from nlp_calib.sensors.mount import HELD_PARAMS, SCALE_PARAM, length_params

#: Why a window is left out of the start, in the order the reasons are tried.
REASONS = ("not_finite", "tiny_translation", "small_rotation", "axis_off_normal", "opposite_turning")
#: The reasons that also leave a window out of the refinement (straight and slow driving carry
#: the scale and the lever arm; only the start needs rotation in every window).
FIT_REASONS = ("not_finite", "axis_off_normal", "opposite_turning")
BaseMotion = Callable[[Mapping[str, float]], np.ndarray]


@dataclass(frozen=True)
class SelectionOptions:
    """Thresholds of the selection: a translation below ``min_translation`` times the median is
    tiny; a rotation below ``min_rotation`` rad is small; an axis more than ``max_axis_angle`` rad
    off the floor normal is off; fewer than ``min_turning`` turning windows cannot show the normal."""

    min_translation: float = 0.05
    min_rotation: float = 0.02
    max_axis_angle: float = 0.2
    min_turning: int = 10

    def __post_init__(self) -> None:
        for name in ("min_translation", "min_rotation", "max_axis_angle"):
            if not 0.0 <= getattr(self, name) < np.pi:
                raise ProblemError(f"selection {name} must lie in [0, π), got {getattr(self, name)}")
        if self.min_turning < 3:
            raise ProblemError(f"selection min_turning must be >= 3, got {self.min_turning}")


@dataclass(frozen=True)
class Selection:
    """Per window: the index of the reason it was dropped for (``-1``: kept)."""

    reason: np.ndarray

    def kept(self, reasons: tuple[str, ...] = REASONS) -> np.ndarray:
        """Windows dropped for none of ``reasons``."""
        codes = [REASONS.index(r) for r in reasons]
        return ~np.isin(self.reason, codes)

    def counts(self) -> dict[str, int]:
        """How many windows each reason dropped."""
        return {r: int(np.sum(self.reason == i)) for i, r in enumerate(REASONS)}

    def drop(self, mask: np.ndarray, reason: str) -> Selection:
        """The windows of ``mask`` still kept, dropped for ``reason``."""
        out = self.reason.copy()
        out[mask & (out < 0)] = REASONS.index(reason)
        return Selection(out)


@dataclass(frozen=True)
class CameraStart:
    """The start's parameters (kinematic, then the mount, then the scale when free), the floor
    normal in the camera frame and the selection of the windows (None: a given mount's, none)."""

    params: dict[str, float]
    normal: np.ndarray
    selection: Selection | None


def rotation_vectors(z: np.ndarray) -> np.ndarray:
    """Rotation vectors ``(M, 3)`` of the camera motions ``z`` ``(7, M)``."""
    return poses3d.quat_to_rotvec(z[3:7].T)


def preselect(z: np.ndarray, U: np.ndarray, options: SelectionOptions) -> Selection:
    """The reasons that need no floor normal: values, translation and rotation size."""
    finite = np.all(np.isfinite(z), axis=0) & np.all(np.isfinite(U), axis=0)
    sel = Selection(np.where(finite, -1, REASONS.index("not_finite")))
    z = np.where(finite, z, 0.0)
    z[6, ~finite] = 1.0
    travel = np.linalg.norm(z[:3], axis=0)
    median = float(np.median(travel[finite])) if finite.any() else 0.0
    sel = sel.drop(travel <= options.min_translation * median, "tiny_translation")
    return sel.drop(np.linalg.norm(rotation_vectors(z), axis=1) < options.min_rotation, "small_rotation")


def floor_normal(phi: np.ndarray, keep: np.ndarray, options: SelectionOptions) -> np.ndarray:
    """The principal axis of the kept rotation vectors (unit, sign arbitrary)."""
    if int(keep.sum()) < options.min_turning:
        raise ProblemError(
            f"too little rotation to see the floor normal: only {int(keep.sum())} of {keep.size} windows "
            f"turn by {np.degrees(options.min_rotation):.2g}° or more (at least {options.min_turning} "
            "needed); drive curves or turn on the spot, both ways"
        )
    _, vecs = np.linalg.eigh(phi[keep].T @ phi[keep])
    return vecs[:, -1]


def roll_pitch(normal: np.ndarray) -> tuple[float, float]:
    """The roll and pitch whose ``Ry(pitch)·Rx(roll)`` turns ``normal`` onto z."""
    nx, ny, nz = normal
    return float(np.arctan2(ny, nz)), float(np.arctan2(-nx, np.hypot(ny, nz)))


def levelled(z: np.ndarray, roll: float, pitch: float) -> np.ndarray:
    """Planar motions ``(3, M)`` of the camera motions seen in the levelled frame."""
    q_l = poses3d.matrix_to_quat(poses3d.rpy_to_matrix(np.array([roll, pitch, 0.0])))
    q = poses3d.quat_multiply(poses3d.quat_multiply(q_l, z[3:7].T), poses3d.quat_conjugate(q_l))
    R = poses3d.quat_to_matrix(q)
    t = poses3d.rotate(np.broadcast_to(q_l, (z.shape[1], 4)), z[:3].T)
    return np.stack([t[:, 0], t[:, 1], np.arctan2(R[:, 1, 0], R[:, 0, 0])])


def planar_misfit(predicted: np.ndarray, z: np.ndarray) -> float:
    """Median size of the predicted planar sensor motions ``(3, M)`` against the levelled ones
    (translation plus angle)."""
    err = poses.between(z.T, predicted.T)
    return float(np.median(np.linalg.norm(err[:, :2], axis=1) + np.abs(err[:, 2])))


def plausible(model: KinematicModel, params: Mapping[str, float]) -> bool:
    """Whether the kinematic parameters have the signs of their physical ranges, and the ones that
    are not lengths (whose unit the scale may change) lie inside them."""
    lengths = length_params(model)
    for name in model.kinematic_params:
        lo, hi = model.physical_ranges[name]
        v = params[name]
        if name in lengths:
            if (lo > 0 and v <= 0) or (hi < 0 and v >= 0):
                return False
        elif not lo <= v <= hi:
            return False
    return True


def _planar(
    model: KinematicModel, U: np.ndarray, zl: np.ndarray, base_motion: BaseMotion, keep: np.ndarray
) -> tuple[dict[str, float], np.ndarray]:
    """The model's planar start on the kept windows, and its predicted motion of every window."""

    def on_kept(params: Mapping[str, float]) -> np.ndarray:
        return base_motion(params)[:, keep]

    guess = model.initial_guess(U[:, keep], zl[:, keep], on_kept)
    return guess, base_motion(guess)


def _assemble(
    model: KinematicModel,
    planar: Mapping[str, float],
    tilt: tuple[float, float],
    known: Mapping[str, float],
    scale_free: bool,
) -> dict[str, float]:
    """The 3-D parameters from the planar start, the roll and pitch and the known values."""
    x, y, yaw = (planar[n] for n in SENSOR_PARAMS)
    out = {n: float(planar[n]) for n in model.kinematic_params}
    out.update(sensor_x=x, sensor_y=y, sensor_z=float(known.get(HELD_PARAMS[0], 0.0)))
    out.update(
        sensor_roll=tilt[0], sensor_pitch=tilt[1], sensor_yaw=float(np.arctan2(np.sin(yaw), np.cos(yaw)))
    )
    if not scale_free:
        return out
    lengths = length_params(model)
    anchors = [n for n in lengths if n in known]
    if not anchors:
        raise ProblemError(
            f"a free scale needs one known length: fix one of {', '.join(lengths)} at its measured "
            "value (the trajectory's scale and every length are otherwise one unknown)"
        )
    c = float(known[anchors[0]]) / out[anchors[0]]
    for name in (*lengths, "sensor_x", "sensor_y"):
        out[name] *= c
    out[SCALE_PARAM] = c
    return out


def camera_start(
    model: KinematicModel,
    U: np.ndarray,
    z: np.ndarray,
    base_motion: BaseMotion,
    *,
    scale_free: bool = False,
    known: Mapping[str, float] | None = None,
    options: SelectionOptions | None = None,
) -> CameraStart:
    """All parameters from windows: inputs ``U`` ``(n_inputs·H, M)``, camera motions ``z``
    ``(7, M)`` (``p_a⁻¹·p_b``, trajectory units) and ``base_motion(planar params)`` → the planar
    sensor motions ``(3, M)`` the model predicts (as for
    :meth:`~nlp_calib.models.base.KinematicModel.initial_guess`). ``known`` holds the values of
    held parameters (``sensor_z``; with ``scale_free``, one length in metres)."""
    options = options or SelectionOptions()
    known = dict(known or {})
    sel = preselect(z, U, options)
    z = np.where(np.all(np.isfinite(z), axis=0), z, np.array([[0.0]] * 6 + [[1.0]]))
    U = np.nan_to_num(U)
    phi = rotation_vectors(z)
    n = floor_normal(phi, sel.kept(), options)
    cosine = np.abs(phi @ n) / np.maximum(np.linalg.norm(phi, axis=1), 1e-300)
    sel = sel.drop(cosine < np.cos(options.max_axis_angle), "axis_off_normal")
    n = floor_normal(phi, sel.kept(), options)
    ranked = []
    for normal in (n, -n):
        tilt = roll_pitch(normal)
        zl = levelled(z, *tilt)
        guess, predicted = _planar(model, U, zl, base_motion, sel.kept())
        misfit = planar_misfit(predicted[:, sel.kept()], zl[:, sel.kept()])
        ranked.append(((not plausible(model, guess), misfit), normal, tilt, zl, predicted))
    _, normal, tilt, zl, predicted = min(ranked, key=lambda r: r[0])
    sel = sel.drop(np.sign(predicted[2]) != np.sign(zl[2]), "opposite_turning")
    guess, _ = _planar(model, U, zl, base_motion, sel.kept())
    return CameraStart(_assemble(model, guess, tilt, known, scale_free), normal, sel)


def fit_selection(
    z: np.ndarray, normal: np.ndarray, base_turn: np.ndarray, options: SelectionOptions | None = None
) -> Selection:
    """The fit's windows (camera motions ``z`` ``(7, M)``) that ``FIT_REASONS`` leave out, judged with
    the start's floor ``normal`` and the base's turn over each window the start's parameters
    predict (``base_turn``, rad). Axes and turning senses are judged only where the camera turns
    by ``min_rotation`` or more (below that the axis is noise)."""
    options = options or SelectionOptions()
    finite = np.all(np.isfinite(z), axis=0)
    sel = Selection(np.where(finite, -1, REASONS.index("not_finite")))
    z = np.where(finite, z, np.array([[0.0]] * 6 + [[1.0]]))
    phi = rotation_vectors(z)
    angle = np.linalg.norm(phi, axis=1)
    turning = angle >= options.min_rotation
    cosine = np.abs(phi @ normal) / np.maximum(angle, 1e-300)
    sel = sel.drop(turning & (cosine < np.cos(options.max_axis_angle)), "axis_off_normal")
    return sel.drop(turning & (np.sign(base_turn) != np.sign(phi @ normal)), "opposite_turning")
