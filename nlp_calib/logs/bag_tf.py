"""The sensor's nominal mount from a bag's ``/tf_static``: the fixed transforms from the base frame
to the sensor's frame, composed.

``robot_state_publisher`` publishes a robot's fixed joints there (latched, usually once at the
start of the recording). The mount is ``(x, y, z, roll, pitch, yaw)`` of the sensor's frame in the
base frame, angles as URDF has them (fixed axes, ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from nlp_calib.logs.bag_files import BagError, messages, opened

TF_STATIC = "/tf_static"
TF_TYPE = "tf2_msgs/msg/TFMessage"

#: A mount: x, y, z (m), roll, pitch, yaw (rad).
Mount = tuple[float, float, float, float, float, float]
#: tf2 refuses a transform whose quaternion's squared norm is farther than this from 1.
QUATERNION_TOLERANCE = 0.01
#: A fixed transform farther than this (m) places no sensor on a robot (a unit or a typo).
MAX_OFFSET_M = 100.0
#: REP 105's names of a mobile base's own frames: a sensor's mount is never one of them.
BASE_FRAMES = frozenset(("base_link", "base_footprint", "base_stabilized"))


def _frame(name: str) -> str:
    return name.strip().lstrip("/")


def is_base_frame(frame: str, base_frame: str) -> bool:
    """Whether ``frame`` is the base's own (``base_frame`` or one of REP 105's base frames)."""
    return _frame(frame) in BASE_FRAMES | {_frame(base_frame)}


def _problem(translation: object, rotation: object) -> str | None:
    """What makes a fixed transform one no robot has (None if nothing): a value not finite, a
    quaternion that is not a rotation (tf2's rule), an offset of more than :data:`MAX_OFFSET_M`."""
    q = [float(getattr(rotation, c)) for c in "xyzw"]
    t = [float(getattr(translation, c)) for c in "xyz"]
    if not np.isfinite(q + t).all():
        return "is not finite (NaN or inf)"
    norm2 = sum(c * c for c in q)
    if abs(norm2 - 1.0) > QUATERNION_TOLERANCE:
        shown = ", ".join(f"{c:.3g}" for c in q)
        return f"has the quaternion (x, y, z, w) = ({shown}) of norm {math.sqrt(norm2):.3g}: not a rotation"
    if max(abs(c) for c in t) > MAX_OFFSET_M:
        return f"places it {max(abs(c) for c in t):.3g} m away, farther than any sensor on a robot (a unit?)"
    return None


def _matrix(translation: object, rotation: object) -> np.ndarray:
    x, y, z, w = (float(getattr(rotation, c)) for c in "xyzw")
    norm = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    T[:3, 3] = [float(getattr(translation, c)) for c in "xyz"]
    return T


def mount_of(T: np.ndarray) -> Mount:
    """``(x, y, z, roll, pitch, yaw)`` of a 4x4 transform (URDF's fixed-axis angles)."""
    R = T[:3, :3]
    pitch = math.asin(max(-1.0, min(1.0, -float(R[2, 0]))))
    roll = math.atan2(float(R[2, 1]), float(R[2, 2]))
    yaw = math.atan2(float(R[1, 0]), float(R[0, 0]))
    return (float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), roll, pitch, yaw)


def static_transforms(path: Path) -> dict[str, tuple[str, np.ndarray, str | None]]:
    """Each child frame on the bag's ``/tf_static`` with its parent, transform and what makes the
    transform one no robot has (None if nothing; the last one published wins); empty when the bag
    has no such topic."""
    out: dict[str, tuple[str, np.ndarray, str | None]] = {}
    with opened(path) as reader:
        topics = {name: info.msgtype for name, info in reader.topics.items()}
        if topics.get(TF_STATIC) != TF_TYPE:
            return out
        for _, _, msg in messages(reader, path, (TF_STATIC,)):
            for tf in msg.transforms:
                child = _frame(tf.child_frame_id)
                out[child] = (
                    _frame(tf.header.frame_id),
                    _matrix(tf.transform.translation, tf.transform.rotation),
                    _problem(tf.transform.translation, tf.transform.rotation),
                )
    return out


def static_mount(path: Path, base_frame: str, sensor_frame: str) -> Mount | None:
    """The mount of ``sensor_frame`` in ``base_frame`` through ``/tf_static``, or None when the bag
    holds no chain of fixed transforms between them."""
    transforms = static_transforms(path)
    T = np.eye(4)
    frame, base = _frame(sensor_frame), _frame(base_frame)
    if is_base_frame(frame, base):
        raise BagError(
            path,
            f"the sensor's frame {frame!r} is the base frame{'' if frame == base else ' (REP 105)'}: a "
            "sensor's mount is a joint from the base to a frame of its own; set the sensor's frame "
            "(sensor_frame in ROBOT.yaml, the driver's frame_id) or the dataset's base_frame",
        )
    seen: set[str] = set()
    while frame != base:
        if frame not in transforms or frame in seen:
            return None
        seen.add(frame)
        parent, T_parent_frame, problem = transforms[frame]
        if problem is not None:
            raise BagError(
                path,
                f"{TF_STATIC}: the transform of {frame!r} in {parent!r} {problem}; fix the "
                "robot's description, or give the mount in ROBOT.yaml (sensor_pose)",
            )
        T = T_parent_frame @ T
        frame = parent
    return mount_of(T)
