"""Simulated recordings written as real ROS 2 bags, with rosbags' own writer (the ``ros`` extra).

Messages are given as ``(topic, type, record time ns, build)``, ``build`` making the message from
rosbags' type store; they are written in record-time order into a ROS 2 bag folder (sqlite3).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core.errors import UsageError

JOINT_STATE = "sensor_msgs/msg/JointState"
LASER_SCAN = "sensor_msgs/msg/LaserScan"
IMU = "sensor_msgs/msg/Imu"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE = "geometry_msgs/msg/PoseStamped"
TF = "tf2_msgs/msg/TFMessage"
#: A message to write: topic, type, record time (ns) and how to make it from the type store.
Message = tuple[str, str, int, Callable[[Any], Any]]
_INSTALL = "writing a bag needs rosbags: install the ros extra: pip install 'nlp_calib[ros]'"


def header(ts: Any, ns: int, frame: str) -> Any:
    stamp = ts.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    return ts.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def quaternion(ts: Any, yaw: float) -> Any:
    return ts.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def joint_state(ns: int, names: Sequence[str], position: Sequence[float]) -> Message:
    """A JointState of positions (rad) stamped ``ns``."""

    def build(ts: Any) -> Any:
        empty = np.zeros(0)
        return ts.types[JOINT_STATE](
            header=header(ts, ns, ""),
            name=list(names),
            position=np.asarray(position, float),
            velocity=empty,
            effort=empty,
        )

    return ("/joint_states", JOINT_STATE, ns, build)


def laser_scan(
    ns: int, frame: str, angles: np.ndarray, ranges: np.ndarray, range_max: float, period_s: float
) -> Message:
    """A LaserScan stamped ``ns`` (every beam at that instant), no intensities."""

    def build(ts: Any) -> Any:
        return ts.types[LASER_SCAN](
            header=header(ts, ns, frame),
            angle_min=float(angles[0]),
            angle_max=float(angles[-1]),
            angle_increment=float(angles[1] - angles[0]),
            time_increment=0.0,
            scan_time=float(period_s),
            range_min=0.05,
            range_max=float(range_max),
            ranges=np.asarray(ranges, dtype=np.float32),
            intensities=np.zeros(0, dtype=np.float32),
        )

    return ("/scan", LASER_SCAN, ns, build)


def imu(ns: int, frame: str, rate: Sequence[float], accel: Sequence[float]) -> Message:
    """An Imu stamped ``ns``: angular velocity (rad/s) and linear acceleration (m/s²) in its frame,
    no orientation (its covariance's first element −1, as REP 145 says)."""

    def build(ts: Any) -> Any:
        vec = ts.types["geometry_msgs/msg/Vector3"]
        unknown = np.zeros(9)
        unknown[0] = -1.0
        return ts.types[IMU](
            header=header(ts, ns, frame),
            orientation=ts.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=unknown,
            angular_velocity=vec(x=float(rate[0]), y=float(rate[1]), z=float(rate[2])),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vec(x=float(accel[0]), y=float(accel[1]), z=float(accel[2])),
            linear_acceleration_covariance=np.zeros(9),
        )

    return ("/imu", IMU, ns, build)


def _transform(ts: Any, ns: int, parent: str, child: str, xyz: Sequence[float], yaw: float) -> Any:
    v = ts.types["geometry_msgs/msg/Vector3"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
    tf = ts.types["geometry_msgs/msg/Transform"](translation=v, rotation=quaternion(ts, yaw))
    return ts.types["geometry_msgs/msg/TransformStamped"](
        header=header(ts, ns, parent), child_frame_id=child, transform=tf
    )


def tf_static(ns: int, parent: str, child: str, xyz: Sequence[float], yaw: float) -> Message:
    """One fixed transform on ``/tf_static``."""
    return (
        "/tf_static",
        TF,
        ns,
        lambda ts: ts.types[TF](transforms=[_transform(ts, ns, parent, child, xyz, yaw)]),
    )


def pose_stamped(ns: int, topic: str, frame: str, pose: Sequence[float]) -> Message:
    """A planar pose ``(x, y, θ)`` in ``frame`` as geometry_msgs/PoseStamped on ``topic`` (a tracker's)."""

    def build(ts: Any) -> Any:
        point = ts.types["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=0.0)
        body = ts.types["geometry_msgs/msg/Pose"](position=point, orientation=quaternion(ts, float(pose[2])))
        return ts.types[POSE](header=header(ts, ns, frame), pose=body)

    return (topic, POSE, ns, build)


def odometry(ns: int, frame: str, child: str, pose: Sequence[float]) -> Message:
    """A planar pose ``(x, y, θ)`` of ``child`` in ``frame`` as nav_msgs/Odometry (no twist)."""

    def build(ts: Any) -> Any:
        point = ts.types["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=0.0)
        body = ts.types["geometry_msgs/msg/Pose"](position=point, orientation=quaternion(ts, float(pose[2])))
        zero = ts.types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        cov = np.zeros(36)
        return ts.types[ODOMETRY](
            header=header(ts, ns, frame),
            child_frame_id=child,
            pose=ts.types["geometry_msgs/msg/PoseWithCovariance"](pose=body, covariance=cov),
            twist=ts.types["geometry_msgs/msg/TwistWithCovariance"](
                twist=ts.types["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov
            ),
        )

    return ("/odom", ODOMETRY, ns, build)


def write_bag(path: Path, messages: Iterable[Message]) -> Path:
    """A ROS 2 bag folder at ``path`` holding ``messages`` in record-time order."""
    try:
        from rosbags.rosbag2 import Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise UsageError(_INSTALL) from None
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(path, version=9) as writer:
        conns: dict[str, Any] = {}
        for topic, msgtype, recorded, build in sorted(messages, key=lambda m: m[2]):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], recorded, ts.serialize_cdr(build(ts), msgtype))
    return path
