"""Numeric SE(3) on arrays of pose vectors ``(x, y, z, qx, qy, qz, qw)``, one pose per row (numpy only).

Quaternions are Hamilton, ordered ``(qx, qy, qz, qw)`` as TUM files, ROS messages and evo write
them; rotation vectors ``φ`` are axis times angle. Roll, pitch and yaw follow URDF (fixed axes):
``R = Rz(yaw)·Ry(pitch)·Rx(roll)``. The symbolic twins live in :mod:`nlp_calib.symbolic.se3`;
these serve readers, the simulator, the closed-form start and post-processing, vectorised.
"""

from __future__ import annotations

import array

import numpy as np

#: Below this rotation angle (rad) series replace the closed forms that divide by it.
SMALL_ANGLE = 1e-6


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a ⊗ b`` row by row."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """The inverse rotation of unit quaternions."""
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions."""
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (``qw >= 0``) of rotation matrices, by the largest of the four pivots."""
    R = np.asarray(R, dtype=float)
    t = np.stack(
        [
            1 + R[..., 0, 0] - R[..., 1, 1] - R[..., 2, 2],
            1 - R[..., 0, 0] + R[..., 1, 1] - R[..., 2, 2],
            1 - R[..., 0, 0] - R[..., 1, 1] + R[..., 2, 2],
            1 + R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2],
        ],
        axis=-1,
    )
    k = np.argmax(t, axis=-1)
    s = 0.5 / np.sqrt(np.take_along_axis(t, k[..., None], axis=-1)[..., 0])
    d = {
        "yz": R[..., 2, 1] - R[..., 1, 2],
        "zx": R[..., 0, 2] - R[..., 2, 0],
        "xy": R[..., 1, 0] - R[..., 0, 1],
        "xy+": R[..., 0, 1] + R[..., 1, 0],
        "xz+": R[..., 0, 2] + R[..., 2, 0],
        "yz+": R[..., 1, 2] + R[..., 2, 1],
    }
    tk = 0.25 / s
    rows = [
        np.stack([tk, d["xy+"] * s, d["xz+"] * s, d["yz"] * s], axis=-1),
        np.stack([d["xy+"] * s, tk, d["yz+"] * s, d["zx"] * s], axis=-1),
        np.stack([d["xz+"] * s, d["yz+"] * s, tk, d["xy"] * s], axis=-1),
        np.stack([d["yz"] * s, d["zx"] * s, d["xy"] * s, tk], axis=-1),
    ]
    q = np.choose(k[..., None], rows)
    return q * np.where(q[..., 3:4] < 0, -1.0, 1.0)


def rotvec_to_quat(phi: np.ndarray) -> np.ndarray:
    """``Exp(φ)`` as unit quaternions."""
    phi = np.asarray(phi, dtype=float)
    theta = np.linalg.norm(phi, axis=-1, keepdims=True)
    small = theta < SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    half = np.where(small, 0.5 - theta**2 / 48.0, np.sin(0.5 * safe) / safe)
    return np.concatenate([half * phi, np.cos(0.5 * theta)], axis=-1)


def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    """``Log(q)``: rotation vectors of angle in ``[0, π]`` (``q`` and ``−q`` give the same)."""
    q = np.asarray(q, dtype=float)
    q = q * np.where(q[..., 3:4] < 0, -1.0, 1.0)
    s = np.linalg.norm(q[..., :3], axis=-1, keepdims=True)
    w = q[..., 3:4]
    small = s < SMALL_ANGLE
    w_small = np.where(small, w, 1.0)
    series = 2.0 / w_small * (1.0 - s * s / (3.0 * w_small * w_small))
    factor = np.where(small, series, 2.0 * np.arctan2(s, w) / np.where(small, 1.0, s))
    return factor * q[..., :3]


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """``Rz(yaw)·Ry(pitch)·Rx(roll)`` of ``(roll, pitch, yaw)`` rows (URDF)."""
    r, p, y = np.moveaxis(np.asarray(rpy, dtype=float), -1, 0)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], axis=-1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], axis=-1),
            np.stack([-sp, cp * sr, cp * cr], axis=-1),
        ],
        axis=-2,
    )


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """``(roll, pitch, yaw)`` with pitch in ``[−π/2, π/2]`` (URDF; undefined at pitch ±π/2)."""
    R = np.asarray(R, dtype=float)
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    pitch = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 2, 1], R[..., 2, 2]))
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R(q)·v`` row by row."""
    return np.einsum("...ij,...j->...i", quat_to_matrix(q), v)


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a · b`` for pose vectors ``(x, y, z, qx, qy, qz, qw)``."""
    return np.concatenate(
        [a[..., :3] + rotate(a[..., 3:], b[..., :3]), quat_multiply(a[..., 3:], b[..., 3:])], -1
    )


def inverse(a: np.ndarray) -> np.ndarray:
    """``a⁻¹`` for pose vectors."""
    qi = quat_conjugate(a[..., 3:])
    return np.concatenate([-rotate(qi, a[..., :3]), qi], axis=-1)


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a⁻¹ · b`` row by row: the motion from ``a`` to ``b`` in ``a``'s frame."""
    return compose(inverse(a), b)


def moved(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The translation of ``a⁻¹ · b`` row by row, ``(..., 3)``: :func:`between`'s to the bit (the
    same rotations of the same numbers, summed alike), without its rotation's product."""
    qi = quat_conjugate(a[..., 3:])
    return -rotate(qi, a[..., :3]) + rotate(qi, b[..., :3])


def between_at(a: np.ndarray, b: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Poses a fraction ``s`` ``(..., 1)`` of the way from ``a`` to ``b``: the position on the line,
    the rotation along the shorter arc (``s`` 0 gives ``a``, 1 gives ``b``)."""
    turn = quat_to_rotvec(quat_multiply(quat_conjugate(a[..., 3:]), b[..., 3:]))
    q = quat_multiply(a[..., 3:], rotvec_to_quat(s * turn))
    return np.concatenate([a[..., :3] + s * (b[..., :3] - a[..., :3]), q], axis=-1)


def turned(q: np.ndarray) -> np.ndarray:
    """The rotation of unit quaternions ``(n, 4)`` accumulated step by step about the fixed axes
    (``(n, 3)``, 0 at the first): a turn about one axis is its angle unwrapped along that axis, a
    rotation off its neighbours departs from the path as an unwrapped angle does."""
    steps = quat_to_rotvec(quat_multiply(q[1:], quat_conjugate(q[:-1])))
    return np.vstack([np.zeros((1, 3)), np.cumsum(steps, axis=0)])


def accumulate(start: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Poses ``(n + 1, 7)`` of ``start · steps[0] · … · steps[n-1]`` (a sequential pass).

    Each step is :func:`compose` of one pose, with the same operations in the same order, so the
    same doubles: the rotations' chain on Python floats (array calls on four numbers cost ten
    times as much), then each step's rotated translation over arrays (each coordinate summed as
    numpy's ``einsum`` sums three products, the first and the third, then the second) and the
    positions as their running sum, which adds one step after the other as the chain does. A block
    of steps at a time: the Python floats of every step at once were ~200 MB at 10^6 steps."""
    n = steps.shape[0]
    out = np.empty((n + 1, 7))
    out[0] = start
    for lo in range(0, n, _BLOCK):
        hi = min(n, lo + _BLOCK)
        out[lo + 1 : hi + 1, 3:] = _chained(out[lo, 3:], steps[lo:hi, 3:])
        _translated(out, steps, lo, hi)
    out[:, 3:] /= np.linalg.norm(out[:, 3:], axis=1, keepdims=True)
    return out


#: Steps per block of :func:`accumulate` (its temporaries stay small and in the cache).
_BLOCK = 1 << 14


def _chained(q: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """The rotations ``q · steps[0] · … · steps[k]`` (unnormalised) of each ``k``, ``(k, 4)``, as
    :func:`quat_multiply` gives each product, on Python floats (written to a buffer of doubles as
    they come: a list of tuples cost a third of the loop again to become an array)."""
    ax, ay, az, aw = (float(v) for v in q)
    chain = array.array("d")
    extend = chain.extend
    for bx, by, bz, bw in steps.tolist():
        ax, ay, az, aw = (
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        )
        extend((ax, ay, az, aw))
    return np.frombuffer(chain, dtype=float).reshape(-1, 4)


def _translated(out: np.ndarray, steps: np.ndarray, lo: int, hi: int) -> None:
    """Positions ``lo + 1 .. hi`` of :func:`accumulate`'s ``out`` from position ``lo``: each step's
    translation rotated by the pose before it (``out``'s rotations, not yet normalised) and added on."""
    ax, ay, az, aw = out[lo:hi, 3:].T
    px, py, pz = steps[lo:hi, :3].T
    rotated = np.empty((hi - lo + 1, 3))
    rotated[0] = out[lo, :3]
    r00, r01, r02 = 1 - 2 * (ay * ay + az * az), 2 * (ax * ay - az * aw), 2 * (ax * az + ay * aw)
    r10, r11, r12 = 2 * (ax * ay + az * aw), 1 - 2 * (ax * ax + az * az), 2 * (ay * az - ax * aw)
    r20, r21, r22 = 2 * (ax * az - ay * aw), 2 * (ay * az + ax * aw), 1 - 2 * (ax * ax + ay * ay)
    rotated[1:, 0] = (r00 * px + r02 * pz) + r01 * py
    rotated[1:, 1] = (r10 * px + r12 * pz) + r11 * py
    rotated[1:, 2] = (r20 * px + r22 * pz) + r21 * py
    out[lo : hi + 1, :3] = np.cumsum(rotated, axis=0)


def from_planar(T: np.ndarray) -> np.ndarray:
    """Planar poses ``(x, y, theta)`` lifted to pose vectors (``z = 0``, rotation about z)."""
    T = np.asarray(T, dtype=float)
    zero = np.zeros(T.shape[:-1])
    half = 0.5 * T[..., 2]
    return np.stack([T[..., 0], T[..., 1], zero, zero, zero, np.sin(half), np.cos(half)], axis=-1)


def mount_pose(mount: np.ndarray) -> np.ndarray:
    """The pose vector of a mount ``(x, y, z, roll, pitch, yaw)``."""
    mount = np.asarray(mount, dtype=float)
    return np.concatenate([mount[..., :3], matrix_to_quat(rpy_to_matrix(mount[..., 3:6]))], axis=-1)


def align(est: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation ``R`` (3×3) and translation ``t`` minimising ``Σ |R·est + t − ref|²`` (Umeyama,
    no scale, a proper rotation)."""
    mu_r = ref.mean(axis=0)
    return align_centred(est, ref - mu_r, mu_r)


def align_centred(
    est: np.ndarray, ref_centred: np.ndarray, mu_r: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`align` with the reference's side given: its positions less their mean ``mu_r``."""
    mu_e = est.mean(axis=0)
    U, _, Vt = np.linalg.svd(ref_centred.T @ (est - mu_e))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ D @ Vt
    return R, mu_r - R @ mu_e
