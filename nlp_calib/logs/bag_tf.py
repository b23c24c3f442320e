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


def _frame(name: str) -> str:
    return name.strip().lstrip("/")


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


def static_transforms(path: Path) -> dict[str, tuple[str, np.ndarray]]:
    """Each child frame on the bag's ``/tf_static`` with its parent and transform (the last one
    published wins); empty when the bag has no such topic."""
    out: dict[str, tuple[str, np.ndarray]] = {}
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
                )
    return out


def static_mount(path: Path, base_frame: str, sensor_frame: str) -> Mount | None:
    """The mount of ``sensor_frame`` in ``base_frame`` through ``/tf_static``, or None when the bag
    holds no chain of fixed transforms between them."""
    transforms = static_transforms(path)
    T = np.eye(4)
    frame, base = _frame(sensor_frame), _frame(base_frame)
    if frame == base:
        raise BagError(
            path,
            f"the sensor's frame {frame!r} is the base frame: a sensor's mount is a joint from the base to "
            "a frame of its own; set the sensor's frame (sensor_frame in ROBOT.yaml, the driver's frame_id) "
            "or the dataset's base_frame",
        )
    seen: set[str] = set()
    while frame != base:
        if frame not in transforms or frame in seen:
            return None
        seen.add(frame)
        parent, T_parent_frame = transforms[frame]
        if not np.isfinite(T_parent_frame).all():
            raise BagError(
                path,
                f"{TF_STATIC}: the transform of {frame!r} in {parent!r} is not finite (NaN or inf); fix the "
                "robot's description, or give the mount in ROBOT.yaml (sensor_pose)",
            )
        T = T_parent_frame @ T
        frame = parent
    return mount_of(T)
