"""Convert a real car's recording (speed, steering wheel, two GNSS antennas) into a joint log and TUM.

    python benchmarks/polimi_car_convert.py BAG OUT

``BAG``: the ROS 1 bag ``project.bag`` of the Politecnico di Milano robotics course's first project
(2025: a car driven around the Monza circuit's grounds, about 7 minutes), as students' repositories
on GitHub commit it (e.g. tadzio8425/first_project; no licence is stated). It holds
``/speedsteer`` (``geometry_msgs/PointStamped``: ``point.x`` the steering wheel's angle in
degrees, ``point.y`` the car's speed in km/h, about 20 Hz) and two Swift Navigation receivers'
``NavSatFix`` (``/swiftnav/front/gps_pose``, ``/swiftnav/rear/gps_pose``, 10 Hz; ``status.status``
4 for a fixed RTK solution, 3 for a float one, as in parts of 126-336 s). The course gives the
car's nominal values: 1.765 m from the front to the rear axle, 1.30 m between the rear wheels, a
steering ratio of about 32 (steering wheel to road wheel).

Writes into ``OUT``:

- ``car.csv``: ``time,steering_wheel,speed``: the steering wheel's angle in rad and the car's speed
  as the angular speed (rad/s) of a virtual wheel of 1 m radius (``form: speeds``), so that the
  fitted ``traction_wheel_radius`` is the speedometer's scale;
- ``car.tum``: the front antenna's position in a local east-north-up frame at its first fix, its
  heading the direction from the rear antenna to the front one at the same receiver epoch (the
  stamps snapped to the receivers' 10 Hz grid), z the front antenna's height; only epochs where both
  receivers have a fixed RTK solution and their distance is the rigid mount's;
- ``car.yaml``: a ``car_like_bicycle`` scenario over the two with the course's nominal values as the
  initial guess.

Nothing of the recording belongs in this repository.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.logs.tum import format_tum

SPEED_STEER = "/speedsteer"
FRONT, REAR = "/swiftnav/front/gps_pose", "/swiftnav/rear/gps_pose"
#: WGS84's semi-major axis (m) and first eccentricity squared.
WGS84_A, WGS84_E2 = 6378137.0, 6.69437999014e-3
#: The Swift receivers' status of a fixed RTK solution (3: float RTK, decimetres off; 0° when lost).
RTK_FIXED = 4
#: The receivers' fix period (s), and how far the antennas' distance may stray from its median (m).
EPOCH_S, RIGID_TOLERANCE_M = 0.1, 0.05
#: The course's nominal values (steering ratio about 32; the virtual wheel of 1 m: speeds in m/s).
NOMINAL = {"k_steer": 1.0 / 32.0, "steer_offset": 0.0, "traction_wheel_radius": 1.0, "wheelbase": 1.765}


def read_bag(path: Path) -> dict[str, np.ndarray]:
    """Each topic's rows: header stamp (ns) and its values."""
    from rosbags.rosbag1 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    rows: dict[str, list[tuple[float, ...]]] = {SPEED_STEER: [], FRONT: [], REAR: []}
    with Reader(path) as reader:
        wanted = [c for c in reader.connections if c.topic in rows]
        for conn, _, raw in reader.messages(connections=wanted):
            msg: Any = store.deserialize_ros1(raw, conn.msgtype)  # a message class per type
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            if conn.topic == SPEED_STEER:
                rows[conn.topic].append((stamp, msg.point.x, msg.point.y))
            else:
                rows[conn.topic].append((stamp, msg.latitude, msg.longitude, msg.altitude, msg.status.status))
    return {k: np.array(v, dtype=float) for k, v in rows.items()}


def ecef(fix: np.ndarray) -> np.ndarray:
    """Earth-centred coordinates (m) of ``(lat°, lon°, height m)`` rows."""
    lat, lon, h = np.radians(fix[:, 0]), np.radians(fix[:, 1]), fix[:, 2]
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.column_stack(
        [
            (n + h) * np.cos(lat) * np.cos(lon),
            (n + h) * np.cos(lat) * np.sin(lon),
            (n * (1 - WGS84_E2) + h) * np.sin(lat),
        ]
    )


def enu(fix: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """East-north-up coordinates (m) of fixes about the fix ``origin``."""
    lat, lon = math.radians(origin[0]), math.radians(origin[1])
    rot = np.array(
        [
            [-math.sin(lon), math.cos(lon), 0.0],
            [-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)],
            [math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)],
        ]
    )
    return (ecef(fix) - ecef(origin[None, :])) @ rot.T


def epochs(stamps: np.ndarray, origin: float) -> tuple[np.ndarray, float]:
    """Each fix's receiver epoch (an integer count of ``EPOCH_S`` from ``origin``, ns) and the
    stamps' mean delay after the epoch grid (ns).

    A receiver fixes at whole epochs of its clock; the bag stamps each fix on arrival, ±30 ms
    around its epoch. At 16 m/s those 30 ms are half a metre along the road, so the two antennas'
    fixes are paired by epoch, not by stamp."""
    period = EPOCH_S * 1e9
    phase = float(np.angle(np.mean(np.exp(2j * np.pi * (stamps - origin) / period)))) / (2 * np.pi) * period
    return np.round((stamps - origin - phase) / period).astype(np.int64), phase


def paired_fixes(front: np.ndarray, rear: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Epoch stamps (ns, on the front receiver's delay) and both antennas' ENU positions at them."""
    front = front[front[:, 4] == RTK_FIXED, :4]
    rear = rear[rear[:, 4] == RTK_FIXED, :4]
    origin = front[0, 0]
    k_front, phase = epochs(front[:, 0], origin)
    k_rear, _ = epochs(rear[:, 0], origin)
    common, i, j = np.intersect1d(k_front, k_rear, return_indices=True)
    stamps = (origin + phase + common * EPOCH_S * 1e9).astype(np.int64)
    return stamps, enu(front[i, 1:], front[0, 1:]), enu(rear[j, 1:], front[0, 1:])


def poses(front: np.ndarray, rear: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """TUM stamps and poses of the front antenna headed from the rear one, where the antennas' distance
    is the rigid mount's (a pair of fixes from different epochs is not); every pair's distance."""
    stamps, p_front, p_rear = paired_fixes(front, rear)
    d = p_front[:, :2] - p_rear[:, :2]
    dist = np.hypot(d[:, 0], d[:, 1])
    keep = np.abs(dist - np.median(dist)) < RIGID_TOLERANCE_M
    yaw = np.arctan2(d[keep, 1], d[keep, 0])
    zero = np.zeros_like(yaw)
    rows = np.column_stack([p_front[keep], zero, zero, np.sin(yaw / 2), np.cos(yaw / 2)])
    return stamps[keep], rows, dist


def scenario(name: str) -> dict[str, Any]:
    return {
        "name": "polimi_car",
        "model": "car_like_bicycle",
        "dataset": {
            "joints": f"{name}.csv",
            "poses": f"{name}.tum",
            "form": "speeds",
            "encoders": {"steering": "steering_wheel", "traction_motor": "speed"},
        },
        "initial_guess": dict(NOMINAL),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bag", type=Path)
    ap.add_argument("out", type=Path)
    args = ap.parse_args(argv)
    topics = read_bag(args.bag)
    ss = topics[SPEED_STEER]
    joints = np.column_stack([np.radians(ss[:, 1]), ss[:, 2] / 3.6])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "car.csv").write_text(
        format_joint_csv(ss[:, 0].astype(np.int64), ("steering_wheel", "speed"), joints)
    )
    stamps, rows, baseline = poses(topics[FRONT], topics[REAR])
    (args.out / "car.tum").write_text(format_tum(stamps, rows))
    (args.out / "car.yaml").write_text(yaml.safe_dump(scenario("car"), sort_keys=False))
    span = (ss[-1, 0] - ss[0, 0]) * 1e-9
    dist = float(np.sum(np.hypot(*np.diff(rows[:, :2], axis=0).T)))
    print(f"{len(ss)} speed/steering rows over {span:.1f} s; {len(stamps)} poses over {dist:.0f} m")
    q = np.percentile(baseline, [1, 25, 50, 75, 99])
    print(
        f"antennas' distance over {len(baseline)} paired epochs: median {q[2]:.3f} m, quartiles {q[1]:.3f}-"
        f"{q[3]:.3f} m, 1-99 % {q[0]:.3f}-{q[4]:.3f} m; {len(baseline) - len(stamps)} pairs off it left out"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
