"""A ROS 2 robot's recording, simulated: JointState in radians at ~100 Hz and a PoseStamped tracker at
~120 Hz on unsynchronised stamps (1 % outliers), from the project's own simulator's truth.

The simulator drives the robot on a 1 kHz grid; its encoders, read as joint angles, are the joints
(every 10th sample: 100 Hz); the tracker sees its sensor pose (noise-free on the grid, interpolated
between samples 1 ms apart) at 120 Hz from a phase that never meets a joint's stamp, with 1 mm and
1 mrad of noise and 1 % outliers. A wheel's angle is its
counter unwrapped, times 2π over its counts per turn, from an arbitrary start; the steering joint's
angle is its encoder's. The parameters in radians follow from the counts form's truth:
``wheel_radius = k_traction / 2π`` (tricycle), ``radius = k · N / 2π`` for a gain ``k`` in metres
per tick (every other model, N counts a turn).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from test_bags import JS, POSE, Message, _header, _quat, write_bag

from nlp_calib.core.numeric import wrap_angle, wrapped_difference
from nlp_calib.models import get_model
from nlp_calib.models.clock import LAG_PARAM
from nlp_calib.simulation import SimulationOptions, simulate

T0_NS = 1_700_000_000 * 10**9
GRID_HZ = 1000.0
JOINT_EVERY, TRACKER_HZ, TRACKER_PHASE = 10, 120.0, 0.37
SENSOR_Z = 0.42
TRICYCLE_JOINTS = ("front_steer_joint", "front_wheel_joint")
DIFF_DRIVE_JOINTS = ("left_wheel_joint", "right_wheel_joint")
#: Each model's joints, in its encoders' order.
JOINTS = {
    "tricycle": TRICYCLE_JOINTS,
    "diff_drive": DIFF_DRIVE_JOINTS,
    "skid_steer": DIFF_DRIVE_JOINTS,
    "car_like": ("front_steer_joint", "rear_left_wheel_joint", "rear_right_wheel_joint"),
    "car_like_ackermann": (
        "front_left_steer_joint",
        "front_right_steer_joint",
        "rear_left_wheel_joint",
        "rear_right_wheel_joint",
    ),
    "car_like_bicycle": ("front_steer_joint", "traction_motor_joint"),
}
#: Each model's gains in metres per tick, with the encoder whose counts per turn make them radii.
PER_TICK = {
    "diff_drive": {"k_left": "left_wheel", "k_right": "right_wheel"},
    "skid_steer": {"k_left": "left_wheel", "k_right": "right_wheel"},
    "car_like": {"k_traction": "rear_left_wheel"},
    "car_like_ackermann": {"k_traction": "rear_left_wheel"},
    "car_like_bicycle": {"k_traction": "traction_motor"},
}


@dataclass(frozen=True)
class Recording:
    """What a robot recorded, with the truth in the radians form's names."""

    joint_ns: np.ndarray
    joints: np.ndarray
    joint_names: tuple[str, ...]
    tracker_ns: np.ndarray
    tracker: np.ndarray
    tracker_z: np.ndarray
    truth: dict[str, float]


def tricycle_truth(radius: float = 0.125, wheelbase: float = 1.2) -> dict[str, float]:
    return {
        "k_steer": 1.0,
        "k_traction": 2 * math.pi * radius,
        "axis_length": wheelbase,
        "steer_offset": 0.02,
        "sensor_x": 0.85,
        "sensor_y": -0.12,
        "sensor_theta": 0.06,
    }


def record(
    model: str = "tricycle",
    seconds: float = 60.0,
    seed: int = 5,
    truth: dict[str, float] | None = None,
    tracker_noise: float = 0.001,
    latency_s: float = 0.0,
) -> Recording:
    """Simulate ``seconds`` of driving and record it as a ROS 2 robot would (the tracker's noise
    ``tracker_noise`` m and rad; its poses seen ``latency_s`` late)."""
    counts_truth = truth or (tricycle_truth() if model == "tricycle" else {})
    opts = SimulationOptions.of(
        records=int(seconds * GRID_HZ),
        seed=seed,
        model=model,
        truth=counts_truth,
        rate_hz=GRID_HZ,
        jitter_s=0.0,
        substeps=2,
        tracker_noise_xy=0.0,
        tracker_noise_theta=0.0,
        latency_s=latency_s,
    )
    sim = simulate(opts)
    names = get_model(model).encoder_kinds
    angles = []
    for j, (name, kind) in enumerate(names.items()):
        per_turn = opts.encoder_ranges[name]
        if kind == "counter":
            counts = np.concatenate([[0], np.cumsum(wrapped_difference(sim.ticks[:, j]))])
            angles.append(1.3 + 2 * math.pi * counts / per_turn)
        else:
            angles.append(wrap_angle(2 * math.pi * sim.ticks[:, j] / per_turn))
    joints = np.stack(angles, axis=1)
    j_idx = np.arange(0, sim.time_ns.size, JOINT_EVERY)
    ns = sim.time_ns - sim.time_ns[0]
    tracker_ns = np.round((np.arange(int(seconds * TRACKER_HZ) - 1) + TRACKER_PHASE) / TRACKER_HZ * 1e9)
    tracker_ns = tracker_ns[tracker_ns <= ns[-1]].astype(np.int64)
    radians = get_model(model).in_radians()
    return Recording(
        joint_ns=ns[j_idx] + T0_NS,
        joints=joints[j_idx],
        joint_names=JOINTS[model],
        tracker_ns=tracker_ns + T0_NS,
        tracker=_seen(sim.T_world_sensor, ns, tracker_ns, np.random.default_rng(seed + 100), tracker_noise),
        tracker_z=SENSOR_Z + np.zeros(tracker_ns.size),
        # The tracker's stamps are the times it saw the poses: its time offset is the simulator's.
        truth={
            **radians.from_counts(_per_turn(model, dict(opts.truth), opts.encoder_ranges)),
            LAG_PARAM: opts.tracker.latency_s,
        },
    )


def _seen(
    poses: np.ndarray, ns: np.ndarray, at: np.ndarray, rng: np.random.Generator, noise: float = 0.001
) -> np.ndarray:
    """The noise-free poses interpolated at ``at`` (ns), with ``noise`` and 1 % outliers."""
    heading = np.unwrap(poses[:, 2])
    out = np.stack(
        [np.interp(at, ns, poses[:, 0]), np.interp(at, ns, poses[:, 1]), np.interp(at, ns, heading)], 1
    )
    out += rng.normal(0.0, 1.0, out.shape) * noise
    outliers = rng.random(at.size) < 0.01
    out[outliers] += rng.normal(0.0, 0.2, (int(outliers.sum()), 3))
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def _per_turn(model: str, truth: dict[str, float], ranges: Any) -> dict[str, float]:
    """The counts form's truth with the gains per tick made per radian."""
    for name, encoder in PER_TICK.get(model, {}).items():
        truth[name] *= ranges[encoder] / (2 * math.pi)
    return truth


def joint_state(
    ns: int, names: Sequence[str], position: Sequence[float], velocity: Sequence[float] = ()
) -> Callable[[Any], Any]:
    def build(ts: Any) -> Any:
        return ts.types[JS](
            header=_header(ts, ns),
            name=list(names),
            position=np.asarray(position, dtype=float),
            velocity=np.asarray(velocity, dtype=float),
            effort=np.zeros(0),
        )

    return build


def pose_stamped(ns: int, pose: Sequence[float], z: float) -> Callable[[Any], Any]:
    def build(ts: Any) -> Any:
        point = ts.types["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=float(z))
        body = ts.types["geometry_msgs/msg/Pose"](position=point, orientation=_quat(ts, float(pose[2])))
        return ts.types[POSE](header=_header(ts, ns, "map"), pose=body)

    return build


#: The nominal mount ``/tf_static`` gives (x, y, z, roll, pitch, yaw): near the truth, not on it.
NOMINAL_MOUNT = (0.8, -0.1, SENSOR_Z, 0.01, -0.02, 0.05)


def tf_static(ns: int, parent: str, child: str, mount: Sequence[float]) -> Callable[[Any], Any]:
    """A TFMessage with one fixed transform (URDF angles: ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``)."""
    x, y, z, roll, pitch, yaw = mount
    cr, sr, cp, sp = math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    q = (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )

    def build(ts: Any) -> Any:
        v = ts.types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)
        r = ts.types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])
        tf = ts.types["geometry_msgs/msg/Transform"](translation=v, rotation=r)
        stamped = ts.types["geometry_msgs/msg/TransformStamped"](
            header=_header(ts, ns, parent), child_frame_id=child, transform=tf
        )
        return ts.types["tf2_msgs/msg/TFMessage"](transforms=[stamped])

    return build


def messages(
    rec: Recording, joint_shift_ns: int = 0, velocities: bool = False, zero_stamps: bool = False
) -> list[Message]:
    """The recording as messages, recorded 2 ms after their stamps, with the nominal mount on
    ``/tf_static`` (``base_link`` to ``mocap_marker``). ``joint_shift_ns``: the joints' stamps on
    another clock; ``velocities``: the wheels publish only their velocities (central differences);
    ``zero_stamps``: the joints' header stamps are all zero."""
    out: list[Message] = [
        (
            "/tf_static",
            "tf2_msgs/msg/TFMessage",
            int(rec.tracker_ns[0]) - 10**9,
            tf_static(int(rec.tracker_ns[0]), "base_link", "mocap_marker", NOMINAL_MOUNT),
        )
    ]
    rates = np.gradient(rec.joints, rec.joint_ns * 1e-9, axis=0)
    for k, ns in enumerate(rec.joint_ns.tolist()):
        stamp = 0 if zero_stamps else ns + joint_shift_ns
        if velocities:
            build = joint_state(stamp, rec.joint_names, [], rates[k].tolist())
        else:
            build = joint_state(stamp, rec.joint_names, rec.joints[k].tolist())
        out.append(("/joint_states", JS, ns + 2_000_000, build))
    for k, ns in enumerate(rec.tracker_ns.tolist()):
        build = pose_stamped(ns, rec.tracker[k].tolist(), float(rec.tracker_z[k]))
        out.append(("/mocap/robot/pose", POSE, ns + 2_000_000, build))
    return out


def write(rec: Recording, path: Path, fmt: str = "sqlite3", **kwargs: Any) -> Path:
    """The recording as a ROS 2 bag (``sqlite3`` or ``mcap``)."""
    return write_bag(path, fmt, messages(rec, **kwargs))


def dataset_block(bag: Path, rec: Recording, extra: str = "") -> str:
    """A scenario's dataset block naming only the topics and the joints."""
    return (
        f"dataset: {{bag: {bag}, joint_states: /joint_states, joints: [{', '.join(rec.joint_names)}], "
        f"tracker: /mocap/robot/pose{extra}}}"
    )
