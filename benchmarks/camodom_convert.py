"""Convert CamOdomCalibraTool's simulated camera-odometry data into a joint log, a TUM file and a scenario.

    python benchmarks/camodom_convert.py SOURCE OUT

``SOURCE``: a clone of github.com/MegviiRobot/CamOdomCalibraTool (no licence is stated), or its
bare git directory. Its ``simulateData/`` holds a differential drive's simulation
(``simulateOdoCam.cpp``, settings in ``simulateData/config.yaml``), run as published into
``output/odo_sinSpeed.txt`` and ``output/cam_sinSpeed.txt``:

- the odometry at 100 Hz: ``time,lin_vel,ang_vel,distance,theta`` (s, m/s, rad/s, m, rad), the
  base's speed and turn rate from wheel speeds ``velocity_left·cos t`` and ``velocity_right·sin t``
  (rad/s) through radii ``radius_l``, ``radius_r`` and the separation ``axle``; the pose the
  camera follows advances by one arc per row at that row's rates;
- the camera at 50 Hz: one row per two odometry rows, ``start_t,end_t`` and the camera's motion
  over them in its frame at the start (``qcl``: w, x, y, z of the rotation from the end's frame to
  the start's, ``tlc``: the translation), the camera mounted at ``Rz(euler_z)·Ry(euler_y)·
  Rx(euler_x)`` (URDF's roll-pitch-yaw) and ``(t0, t1, t2)`` on the base. Neither stream carries
  the noise the simulator draws (it is drawn and not written).

Writes into ``OUT``, per sequence ``NAME``: ``sinSpeed``, and ``sinSpeed1`` (``sinSpeed2`` is the
same file), 6.3 s of driving ahead at an uneven speed, whose generator is not published; the
camera's track of each agrees with what ``config.yaml``'s mount makes of its own odometry to
2·10⁻⁵ m and rad (printed), so the one truth serves both:

- ``NAME.joints.csv``: ``time,left_wheel_joint,right_wheel_joint``, each wheel's angle in rad:
  the rows' rates turned back into the wheels' speeds by ``config.yaml``'s radii and separation
  (the data hold the base's rates, not the wheels': the radii and separation in the converted
  files are ``config.yaml``'s by construction, as in the simulator before it wrote the rates),
  each held over its row as the simulator holds it and summed, so the angle at ``t_i`` is the
  wheels' after row ``i − 1``: exactly the simulator's, linear between rows. With ``--speeds``,
  the speeds themselves (``form: speeds``, as a user of the tool would feed them), which the
  tool integrates by trapezoids: rates held over a row are then read half a row late, and
  rates that jump from row to row are not followed within a row;
- ``NAME.tum``: the camera's poses, its motions chained from the identity at the first
  ``start_t``, stamped at their ``end_t``;
- ``NAME.truth.json``: the simulator's truth in the names ``nlp-calib simulate`` writes, and the
  offset of the camera's stamps (``lag_s``): the camera's pose after odometry row ``i`` (at
  ``t_{i+1}``) is stamped ``t_i``, one row (10 ms) early; with ``--speeds``, half a row (5 ms), the
  trapezoids' own half-row delay taken off;
- ``NAME.yaml``: a ``diff_drive`` scenario with a ``3d`` sensor over the pair, the start
  closed-form and the camera's height known (planar driving cannot see it), everything else the
  tool's defaults.

Nothing of the data set belongs in this repository.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from nlp_calib.core import poses3d
from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.logs.tum import format_tum

sys.path.insert(0, str(Path(__file__).resolve().parent))
from optiodom_convert import Source

DATA = "simulateData"
SEQUENCES = ("sinSpeed", "sinSpeed1")
JOINTS = ("left_wheel_joint", "right_wheel_joint")
#: ``config.yaml``'s keys of the truth, as ``nlp-calib simulate`` names them.
TRUTH_KEYS = {
    "radius_l": "k_left",
    "radius_r": "k_right",
    "axle": "baseline",
    "t0": "sensor_x",
    "t1": "sensor_y",
    "t2": "sensor_z",
    "euler_x": "sensor_roll",
    "euler_y": "sensor_pitch",
    "euler_z": "sensor_yaw",
}


def read_config(text: str) -> dict[str, float]:
    """``config.yaml``'s numbers (an OpenCV FileStorage file: a ``%YAML:1.0`` line PyYAML refuses)."""
    body = "\n".join(line for line in text.splitlines() if not line.startswith("%"))
    return {str(k): float(v) for k, v in yaml.safe_load(body).items()}


def table(text: str) -> np.ndarray:
    """A CSV file's rows after its header."""
    return np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2)


def wheel_speeds(odo: np.ndarray, config: dict[str, float]) -> np.ndarray:
    """Each wheel's speed (rad/s) from the rows' speed and turn rate, inverting the simulator's
    ``v = (ω_l·r_l + ω_r·r_r)/2``, ``w = (ω_r·r_r − ω_l·r_l)/axle``."""
    v, w = odo[:, 1], odo[:, 2]
    half = 0.5 * config["axle"] * w
    return np.column_stack([(v - half) / config["radius_l"], (v + half) / config["radius_r"]])


def camera_poses(cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (s) and TUM poses of the camera: the identity at the first ``start_t``, then each
    row's motion ``(tlc, qcl⁻¹)`` composed on, stamped at its ``end_t``."""
    if np.any(np.abs(cam[1:, 0] - cam[:-1, 1]) > 1e-9):
        raise ValueError("the camera's motions do not chain: a start_t differs from the end_t before it")
    q_cl = cam[:, [6, 7, 8, 5]]  # written w, x, y, z
    q_lc = poses3d.quat_conjugate(q_cl / np.linalg.norm(q_cl, axis=1, keepdims=True))
    steps = np.column_stack([cam[:, 9:12], q_lc])
    start = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    return np.concatenate([cam[:1, 0], cam[:, 1]]), poses3d.accumulate(start, steps)


def predicted(odo: np.ndarray, config: dict[str, float], n_poses: int) -> np.ndarray:
    """The camera's poses as the simulator makes them from ``config``'s mount: the base advanced by
    one arc per odometry row at its rates, the camera's pose ``k`` the one after row ``2k``, in
    the camera's frame after row 0 (the frame the chained track starts in)."""
    dt = np.diff(odo[:, 0], append=odo[-1, 0] + np.median(np.diff(odo[:, 0])))
    turn, travel = odo[:, 2] * dt, odo[:, 1] * dt
    small = np.abs(turn) < 1e-12
    safe = np.where(small, 1.0, turn)
    ahead = travel * np.where(small, 1.0, np.sin(turn) / safe)
    aside = travel * np.where(small, 0.0, (1.0 - np.cos(turn)) / safe)
    before = np.concatenate([[0.0], np.cumsum(turn)[:-1]])
    x = np.cumsum(np.cos(before) * ahead - np.sin(before) * aside)
    y = np.cumsum(np.sin(before) * ahead + np.cos(before) * aside)
    base = poses3d.from_planar(np.column_stack([x, y, np.cumsum(turn)])[: 2 * n_poses - 1 : 2])
    mount = np.array([config[k] for k in ("t0", "t1", "t2", "euler_x", "euler_y", "euler_z")])
    camera = poses3d.compose(base, np.broadcast_to(poses3d.mount_pose(mount), base.shape))
    return poses3d.between(np.broadcast_to(camera[0], camera.shape), camera)


def mismatch(poses: np.ndarray, expected: np.ndarray) -> tuple[float, float]:
    """The largest position (m) and rotation (rad) difference between two tracks, pose by pose."""
    d = poses3d.between(expected, poses)
    turn = np.linalg.norm(poses3d.quat_to_rotvec(d[:, 3:]), axis=1)
    return float(np.abs(d[:, :3]).max()), float(turn.max())


def wheel_angles(odo: np.ndarray, speeds: np.ndarray) -> np.ndarray:
    """Each wheel's angle (rad) at each row's stamp: the speeds held over their rows and summed."""
    dt = np.diff(odo[:, 0])[:, None]
    return np.vstack([np.zeros((1, speeds.shape[1])), np.cumsum(speeds[:-1] * dt, axis=0)])


def truth(config: dict[str, float], lag_s: float) -> dict[str, Any]:
    params = {name: config[key] for key, name in TRUTH_KEYS.items()}
    return {"params": params, "lag_s": round(lag_s, 9), "source": f"{DATA}/config.yaml"}


def scenario(name: str, sensor_z: float, form: str) -> dict[str, Any]:
    return {
        "name": f"camodom_{name}",
        "model": "diff_drive",
        "sensor": "3d",
        "dataset": {
            "poses": f"{name}.tum",
            "joints": f"{name}.joints.csv",
            "form": form,
            "encoders": {"left_wheel": JOINTS[0], "right_wheel": JOINTS[1]},
        },
        "initial_guess": "auto",
        "known": {"sensor_z": sensor_z},
    }


def ns(time_s: np.ndarray) -> np.ndarray:
    return np.round(time_s * 1e9).astype(np.int64)


def convert(src: Source, name: str, config: dict[str, float], out: Path, as_speeds: bool) -> str:
    """One sequence's files (the wheels as angles, or ``as_speeds``); a line saying what was written."""
    odo = table(src.text(f"{DATA}/output/odo_{name}.txt"))
    cam = table(src.text(f"{DATA}/output/cam_{name}.txt"))
    speeds = wheel_speeds(odo, config)
    wheels = speeds if as_speeds else wheel_angles(odo, speeds)
    (out / f"{name}.joints.csv").write_text(format_joint_csv(ns(odo[:, 0]), JOINTS, wheels))
    stamps, poses = camera_poses(cam)
    (out / f"{name}.tum").write_text(format_tum(ns(stamps), poses))
    form = "speeds" if as_speeds else "positions"
    (out / f"{name}.yaml").write_text(yaml.safe_dump(scenario(name, config["t2"], form), sort_keys=False))
    period = float(np.median(np.diff(odo[:, 0])))
    lag = -(0.5 if as_speeds else 1.0) * period
    (out / f"{name}.truth.json").write_text(json.dumps(truth(config, lag), indent=2) + "\n")
    travel = float(np.sum(np.linalg.norm(np.diff(poses[:, :3], axis=0), axis=1)))
    off_m, off_rad = mismatch(poses, predicted(odo, config, len(poses)))
    return (
        f"{name}: {len(odo)} odometry rows over {odo[-1, 0] - odo[0, 0]:.2f} s, {len(cam)} camera "
        f"motions, the camera travelling {travel:.2f} m; wheel speeds within "
        f"{np.abs(speeds).max():.3f} rad/s; the camera's track against the one config.yaml's mount "
        f"makes of the odometry: {off_m:.2g} m, {off_rad:.2g} rad at most"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("source", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--speeds", action="store_true", help="the wheels as speeds (form: speeds), not angles")
    args = ap.parse_args(argv)
    src = Source(args.source)
    config = read_config(src.text(f"{DATA}/config.yaml"))
    args.out.mkdir(parents=True, exist_ok=True)
    for name in SEQUENCES:
        print(convert(src, name, config, args.out, args.speeds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
