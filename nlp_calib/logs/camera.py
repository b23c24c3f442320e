"""A camera's own trajectory paired with the robot's joint log: the records of a 3-D fit.

The images are the records: interval ``k`` joins image ``k`` and ``k + 1``, and its model inputs
come from the joint positions interpolated linearly at the two images' stamps. A lag ``lag_s``
(the camera stamps an image ``lag_s`` after the joints read the same instant) re-samples the
joints at ``stamp − lag_s``: the camera's poses, and so its motions, stay as recorded, which keeps
fit costs comparable across lags (as :func:`nlp_calib.logs.resample_encoders` does for encoders).
Only images whose stamps lie inside the joints' time span, by ``reach_s`` (the largest lag that
will be tried) on either side, are paired; no overlap at all is an error naming both files.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from nlp_calib.core import poses3d
from nlp_calib.core.errors import DatasetError
from nlp_calib.logs.joint_log import JointTable
from nlp_calib.logs.log import Log, LogHeader, frozen
from nlp_calib.logs.tum import Trajectory3D

#: How a joint drives an input row: its change over the interval, or its angle at the start.
JointUse = Literal["increment", "angle"]


@dataclass(frozen=True)
class JointInput:
    """One row of a model's interval inputs: ``factor ×`` the joint's increment or start angle."""

    joint: str
    use: JointUse = "increment"
    factor: float = 1.0


@dataclass(frozen=True)
class CameraRecording:
    """The images paired with the joint log (``images``: those inside its span) and how many
    images fell outside it."""

    images: Trajectory3D
    joints: JointTable
    outside: int

    @property
    def n_records(self) -> int:
        return self.images.n_poses

    def inputs(self, rows: Sequence[JointInput], lag_s: float = 0.0) -> np.ndarray:
        """Interval inputs ``(len(rows), n_records - 1)`` from the joints at ``stamps − lag_s``."""
        return interval_inputs(self.joints, self.images.time_s - lag_s, rows)


def pair(images: Trajectory3D, joints: JointTable, reach_s: float = 0.0) -> CameraRecording:
    """The images whose stamps, shifted by up to ``reach_s`` either way, lie inside the joints'
    span. Raises :class:`DatasetError` when fewer than two do."""
    lo, hi = joints.time_s[0] + reach_s, joints.time_s[-1] - reach_s
    inside = (images.time_s >= lo) & (images.time_s <= hi)
    if int(inside.sum()) < 2:
        t, j = images.time_s, joints.time_s
        raise DatasetError(
            images.path,
            None,
            f"no overlap in time with the joint log {joints.path}: the images span "
            f"[{t[0]:.3f}, {t[-1]:.3f}] s, the joints [{j[0]:.3f}, {j[-1]:.3f}] s"
            + (f" (less {reach_s:g} s at each end for the lag search)" if reach_s else "")
            + "; record both on one clock, or shift one file's stamps",
        )
    first, last = np.flatnonzero(inside)[[0, -1]]
    keep = np.arange(first, last + 1)  # a contiguous run: intervals join consecutive images
    return CameraRecording(images.select(keep), joints, int(images.n_poses - keep.size))


def positions_at(joints: JointTable, names: Sequence[str], stamps: np.ndarray) -> np.ndarray:
    """Joint positions ``(len(names), len(stamps))`` interpolated linearly at ``stamps``."""
    t = joints.time_s
    if stamps.size and (stamps[0] < t[0] or stamps[-1] > t[-1]):
        raise DatasetError(
            joints.path,
            None,
            f"stamps in [{stamps[0]:.3f}, {stamps[-1]:.3f}] s reach outside the joints' span "
            f"[{t[0]:.3f}, {t[-1]:.3f}] s; pair the images with a larger reach",
        )
    return np.stack([np.interp(stamps, t, joints.column(n)) for n in names])


def interval_inputs(joints: JointTable, stamps: np.ndarray, rows: Sequence[JointInput]) -> np.ndarray:
    """Each interval's inputs between consecutive ``stamps``, one row per :class:`JointInput`."""
    at = positions_at(joints, [r.joint for r in rows], np.asarray(stamps, dtype=float))
    out = np.empty((len(rows), at.shape[1] - 1))
    for i, row in enumerate(rows):
        out[i] = row.factor * (np.diff(at[i]) if row.use == "increment" else at[i, :-1])
    return out


def floor_normal_in_world(poses: np.ndarray) -> np.ndarray:
    """The axis the trajectory turns about, in its world frame (the principal axis of the
    consecutive rotations), or the world's z axis when it never turns."""
    q = poses[:, 3:7]
    steps = poses3d.quat_multiply(q[1:], poses3d.quat_conjugate(q[:-1]))  # R_{k+1}·R_kᵀ: world frame
    phi = poses3d.quat_to_rotvec(steps)
    scatter = phi.T @ phi
    lam, vecs = np.linalg.eigh(scatter)
    if lam[-1] <= 1e-12:
        return np.array([0.0, 0.0, 1.0])
    n = vecs[:, -1]
    return n if n @ phi.sum(axis=0) >= 0 else -n


def planar_track(poses: np.ndarray) -> np.ndarray:
    """The 3-D track levelled onto the floor plane: ``(x, y, theta)`` per pose, positions in a
    frame of that plane and the heading turned about its normal since the first pose."""
    n = floor_normal_in_world(poses)
    seed = np.eye(3)[int(np.argmin(np.abs(n)))]
    ex = np.cross(seed, n)
    ex /= np.linalg.norm(ex)
    ey = np.cross(n, ex)
    rel = poses3d.quat_multiply(poses[:, 3:7], poses3d.quat_conjugate(poses[0, 3:7]))
    heading = np.unwrap(poses3d.quat_to_rotvec(rel) @ n)
    return np.stack([poses[:, :3] @ ex, poses[:, :3] @ ey, heading], axis=1)


def camera_log(recording: CameraRecording, kinematic_model: str, sensor_frame: str = "camera") -> Log:
    """The recording as a :class:`Log`: one record per image, ``T_world_sensor_3d`` the camera's
    poses and ``T_world_sensor`` their levelled track; no encoder ticks (the joints give the
    inputs, see :meth:`CameraRecording.inputs`)."""
    images = recording.images
    n = images.n_poses
    header = LogHeader(
        kinematic_model=kinematic_model,
        parameters={},
        encoder_names=(),
        encoder_max=(),
        sensor_frame=sensor_frame,
        T_base_sensor=(0.0, 0.0, 0.0),
        nominal={},
    )
    return Log(
        path=images.path,
        header=header,
        time_s=frozen((images.time_ns - images.time_ns[0]).astype(float) * 1e-9),
        ticks=frozen(np.zeros((n, 0), dtype=np.int64)),
        model_pose=frozen(np.zeros((n, 3))),
        T_world_sensor=frozen(planar_track(images.poses)),
        line_numbers=images.line_numbers,
        T_world_sensor_3d=images.poses,
    )
