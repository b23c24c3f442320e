"""Read-time screens of a recording: mistakes in how it was written that no calibration can fix.

Each is a test of the recording against itself, before anything is fitted, and speaks only when
the evidence is strong and the alternative clearly better:

- **Clocks seconds apart** (:func:`clock_shift`): the joints' speed and the tracker's motion rise
  and fall together when a robot drives. Both are put on one time grid and compared, as
  normalised cross-correlations, at every shift of one against the other up to
  :data:`MAX_SHIFT_S`; a best shift over :data:`MIN_SHIFT_S` that agrees far better than the
  recording as stamped means a stream is stamped that much late (a clock set wrong, stamps taken
  at processing time), which pairs images with the wrong joints. It must beat every other peak of
  the curve by the same margin: a drive that repeats matches itself a period on, and a shift the
  recording cannot tell from another is not a finding. The tracker lag the calibration
  estimates later is a fraction of a second: this is seconds.
- **Quaternions in another order** (:func:`quaternion_order`): a sensor on a robot driving on a
  floor turns about the floor's normal, and its positions lie in a plane across that normal. Read
  as ``qx qy qz qw`` (TUM), a file whose quaternions are ``qw qx qy qz`` turns much of the time
  about other axes; read the other way, it turns about that normal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlp_calib.core import poses3d

#: The time grid the streams are compared on (s), at its finest.
GRID_S = 0.05
#: At most this many grid points (a long recording is compared on a coarser grid).
MAX_POINTS = 1 << 16
#: Shifts tried, each way (s).
MAX_SHIFT_S = 120.0
#: A shift below this is the tracker lag's business (s).
MIN_SHIFT_S = 1.0
#: The streams must overlap by at least this much at a shift (s), and by this share of the shorter.
MIN_OVERLAP_S = 10.0
MIN_OVERLAP_SHARE = 0.5
#: A shift is believed when its correlation reaches this, and exceeds the stamped one's by this.
MIN_CORRELATION = 0.6
MIN_GAIN = 0.3
#: Quaternions are written ``w`` first when, read so, this share of the rotation (or more) is about
#: the normal of the positions' plane, and read as TUM's ``x y z w``, under this ratio of it.
MIN_SHARE = 0.6
ORDER_RATIO = 0.75
#: The steps must turn this much on average (rad) for the share to mean anything.
MIN_TURN_RAD = 0.01


def _on_grid(t: np.ndarray, y: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """``y`` (n, d) interpolated at ``grid`` (NaN outside ``t``'s span)."""
    out = np.stack([np.interp(grid, t, y[:, j]) for j in range(y.shape[1])], axis=1)
    out[(grid < t[0]) | (grid > t[-1])] = np.nan
    return out


def _rate(values: np.ndarray, step: float) -> np.ndarray:
    """The size of each grid step's change per second (NaN where either end is missing)."""
    d = np.diff(values, axis=0)
    return np.concatenate([np.linalg.norm(d, axis=1), [np.nan]]) / step


def _rotation_rate(q: np.ndarray, step: float) -> np.ndarray:
    """The angle turned per second over each grid step, from quaternions ``(n, 4)`` (NaN rows
    where missing)."""
    ok = np.all(np.isfinite(q), axis=1)
    safe = np.where(ok[:, None], q, [0.0, 0.0, 0.0, 1.0])
    safe /= np.linalg.norm(safe, axis=1, keepdims=True)
    rel = poses3d.quat_multiply(poses3d.quat_conjugate(safe[:-1]), safe[1:])
    angle = np.linalg.norm(poses3d.quat_to_rotvec(rel), axis=1) / step
    angle[~(ok[:-1] & ok[1:])] = np.nan
    return np.concatenate([angle, [np.nan]])


def _standard(x: np.ndarray) -> np.ndarray:
    ok = np.isfinite(x)
    if ok.sum() < 3:
        return np.full_like(x, np.nan)
    sd = float(np.std(x[ok]))
    return (x - float(np.mean(x[ok]))) / sd if sd > 0 else np.full_like(x, np.nan)


def _correlations(a: np.ndarray, b: np.ndarray, max_lag: int, min_overlap: int) -> np.ndarray:
    """Pearson correlation of ``a[i + k]`` with ``b[i]`` over their common finite samples, for
    ``k`` in ``[-max_lag, max_lag]`` (NaN where they overlap by fewer than ``min_overlap``)."""
    ma, mb = np.isfinite(a), np.isfinite(b)
    a0, b0 = np.where(ma, a, 0.0), np.where(mb, b, 0.0)
    n = a.size + b.size
    size = 1 << int(np.ceil(np.log2(n)))

    def xcorr(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        full = np.fft.irfft(np.fft.rfft(x, size) * np.conj(np.fft.rfft(y, size)), size)
        return np.concatenate([full[-max_lag:], full[: max_lag + 1]])  # lags -max_lag..max_lag

    fa, fb = ma.astype(float), mb.astype(float)
    count = np.rint(xcorr(fa, fb))
    sa, sb = xcorr(a0, fb), xcorr(fa, b0)
    saa, sbb, sab = xcorr(a0 * a0, fb), xcorr(fa, b0 * b0), xcorr(a0, b0)
    with np.errstate(invalid="ignore", divide="ignore"):
        cov = sab - sa * sb / count
        var = (saa - sa * sa / count) * (sbb - sb * sb / count)
        rho = cov / np.sqrt(var)
    rho[(count < min_overlap) | ~np.isfinite(rho)] = np.nan
    return rho


@dataclass(frozen=True)
class ClockShift:
    """A shift of the joints' times (s) that agrees better than the stamps: ``best`` its agreement,
    ``stamped`` the stamps', ``rival``/``rival_s`` the best separate peak's (another shift the
    curve cannot tell from it within :data:`MIN_GAIN`: the drive repeats; None when none)."""

    shift: float
    best: float
    stamped: float
    rival: float | None = None
    rival_s: float | None = None

    @property
    def ambiguous(self) -> bool:
        return self.rival is not None


def _agreement_curve(
    joint_ns: np.ndarray, joints: np.ndarray, tracker_ns: np.ndarray, tracker: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(lags, correlation)``: the joints' speed against the tracker's motion at each shift of the
    joints' times (s; see :func:`clock_shift`)."""
    lo, hi = min(joint_ns[0], tracker_ns[0]), max(joint_ns[-1], tracker_ns[-1])
    step = max(GRID_S, (hi - lo) * 1e-9 / MAX_POINTS)
    grid = np.arange(0.0, (hi - lo) * 1e-9 + step, step)
    tj, tt = (joint_ns - lo) * 1e-9, (tracker_ns - lo) * 1e-9
    speed = _rate(_on_grid(tj, joints, grid), step)
    position = tracker[:, [0, 1, 3]] if np.all(np.isfinite(tracker[:, 3])) else tracker[:, :2]
    moving = _rate(_on_grid(tt, position, grid), step)
    quat = tracker[:, 4:8] if np.all(np.isfinite(tracker[:, 4:8])) else None
    turning = (
        _rotation_rate(_on_grid(tt, quat, grid), step)
        if quat is not None
        else _rate(_on_grid(tt, np.unwrap(tracker[:, 2])[:, None], grid), step)
    )
    motion = np.nansum([_standard(moving), _standard(turning)], axis=0)
    motion[~(np.isfinite(moving) & np.isfinite(turning))] = np.nan
    shorter = min(tj[-1] - tj[0], tt[-1] - tt[0])
    min_overlap = int(max(MIN_OVERLAP_S, MIN_OVERLAP_SHARE * shorter) / step)
    max_lag = int(min(MAX_SHIFT_S, hi * 1e-9 - lo * 1e-9) / step)
    rho = _correlations(motion, _standard(speed), max_lag, min_overlap)
    if not np.any(np.isfinite(rho)):
        return None
    return np.arange(-max_lag, max_lag + 1) * step, rho


def _peak(lags: np.ndarray, rho: np.ndarray, best: int) -> float:
    """The shift at the peak between grid points (a parabola through the three around ``best``)."""
    shift = float(lags[best])
    if 0 < best < rho.size - 1 and np.all(np.isfinite(rho[best - 1 : best + 2])):
        a, b, c = rho[best - 1 : best + 2]
        curvature = a - 2 * b + c
        shift += float(0.5 * (a - c) / curvature * (lags[1] - lags[0])) if curvature < 0 else 0.0
    return shift


def clock_shift(
    joint_ns: np.ndarray, joints: np.ndarray, tracker_ns: np.ndarray, tracker: np.ndarray
) -> ClockShift | None:
    """The seconds to add to the joints' times that make their speed agree best with the
    tracker's motion, when that shift is over :data:`MIN_SHIFT_S`, agrees at least
    :data:`MIN_CORRELATION` and :data:`MIN_GAIN` more than the stamps (None otherwise, or when the
    recording cannot tell). Another peak of the curve within :data:`MIN_GAIN` of it (a drive that
    repeats matches itself a period on) is its ``rival``: the recording cannot tell the two apart.
    ``joints`` ``(n, J)``: positions; ``tracker`` ``(m, 8)``: ``x, y, yaw, z, qx, qy, qz, qw`` (the
    3-D part may be NaN)."""
    curve = _agreement_curve(joint_ns, joints, tracker_ns, tracker)
    if curve is None:
        return None
    lags, rho = curve
    best = int(np.nanargmax(rho))
    near = np.abs(lags) <= MIN_SHIFT_S
    stamped = float(np.nanmax(rho[near])) if np.any(np.isfinite(rho[near])) else -1.0
    top = float(rho[best])
    if abs(lags[best]) <= MIN_SHIFT_S or top < MIN_CORRELATION or top - stamped < MIN_GAIN:
        return None
    # Separate peaks: local maxima over MIN_SHIFT_S from the best (not its own shoulders).
    filled = np.where(np.isfinite(rho), rho, -np.inf)
    local = np.r_[False, (filled[1:-1] >= filled[:-2]) & (filled[1:-1] >= filled[2:]), False]
    others = np.flatnonzero(local & (np.abs(lags - lags[best]) > MIN_SHIFT_S) & ~near)
    close = others[top - filled[others] < MIN_GAIN]
    if close.size:
        rival = int(close[np.argmax(filled[close])])
        return ClockShift(_peak(lags, rho, best), top, stamped, float(rho[rival]), _peak(lags, rho, rival))
    return ClockShift(_peak(lags, rho, best), top, stamped)


def _plane_normal(p: np.ndarray) -> np.ndarray | None:
    """The normal of the plane the positions ``(n, 3)`` lie in (None: they lie on a line or a blob)."""
    centred = p - p.mean(axis=0)
    lam, vecs = np.linalg.eigh(centred.T @ centred)
    if lam[1] <= 0 or lam[0] > 0.05 * lam[1]:
        return None
    return vecs[:, 0]


def _about_normal(q: np.ndarray, normal: np.ndarray, stride: int) -> float:
    """The share of the rotations over ``stride`` poses (their squared angles) about ``normal``."""
    phi = poses3d.quat_to_rotvec(poses3d.quat_multiply(q[stride:], poses3d.quat_conjugate(q[:-stride])))
    total = float(np.sum(phi * phi))
    return float(np.sum((phi @ normal) ** 2)) / total if total > MIN_TURN_RAD**2 * len(phi) else np.nan


def quaternion_order(time_s: np.ndarray, poses: np.ndarray) -> tuple[float, float] | None:
    """``(as read, w first)``: the share of the rotation of poses ``(n, 7)`` ``(x, y, z, qx, qy,
    qz, qw)`` about the normal of the plane their positions lie in, read as they are and read as
    ``qw qx qy qz``, when the second says ``w`` comes first (it is :data:`MIN_SHARE` or more and
    the first under :data:`ORDER_RATIO` of it); else None (the order read, or the recording cannot
    tell)."""
    if poses.shape[0] < 10:
        return None
    normal = _plane_normal(poses[:, :3])
    if normal is None:
        return None
    dt = float(np.median(np.diff(time_s)))
    stride = int(max(1, min(round(0.5 / dt) if dt > 0 else 1, poses.shape[0] // 5)))
    read, w_first = (_about_normal(q, normal, stride) for q in (poses[:, 3:7], poses[:, [4, 5, 6, 3]]))
    if np.isfinite(w_first) and w_first >= MIN_SHARE and read < ORDER_RATIO * w_first:
        return read, w_first
    return None
