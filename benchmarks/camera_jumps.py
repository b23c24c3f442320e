"""How well the tracker-jump screen finds a camera pose glitch, and how often it cries wolf.

    python benchmarks/camera_jumps.py              # 20 glitches per size, 10 noisy seeds
    python benchmarks/camera_jumps.py --trials 5 --seeds 3   # a quick look

Glitches: one pose of the shipped camera demo (1 mm and 0.1° of pose noise) moved by a size in a
random direction (world frame) and/or turned by an angle about a random axis (the camera's own),
at a random pose (seed 0 draws them all); detected when the screen names that pose's line,
false when it names another. False alarms: the clean demo and the demo's noise on seeds
0..seeds-1 (``simulate_camera``, 40 s). The screen is ``analysis.faults.tracker_faults`` with
``spatial=True``, as a run of a 3-D sensor calls it; nothing here tunes it. Prints the figures.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from nlp_calib.analysis.faults import tracker_faults
from nlp_calib.core import poses3d
from nlp_calib.logs import Log
from nlp_calib.models import get_model
from nlp_calib.sensors import sensor_for
from nlp_calib.simulation.camera import (
    CameraNoise,
    CameraSimulationOptions,
    simulate_camera,
    write_camera_simulation,
)
from nlp_calib.sources import JointLogSource

DATA = Path(__file__).resolve().parents[1] / "scenarios" / "data"
ENCODERS = {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
#: Glitch sizes: (label, metres, degrees).
SIZES = (
    ("5 cm and 2°", 0.05, 2.0),
    ("5 cm", 0.05, 0.0),
    ("3 cm", 0.03, 0.0),
    ("2 cm", 0.02, 0.0),
    ("5°", 0.0, 5.0),
    ("4°", 0.0, 4.0),
    ("2°", 0.0, 2.0),
)


def read(tum: Path, joints: Path) -> Log:
    return JointLogSource(joints=joints, poses=tum, encoders=ENCODERS).read(
        get_model("diff_drive"), strict=True
    )


def flagged_lines(tum: Path, joints: Path) -> list[int]:
    return [f.line for f in tracker_faults(read(tum, joints), sensor_for("3d"))]


def glitched(lines: list[str], index: int, shift: np.ndarray, turn: np.ndarray) -> str:
    """The TUM text with pose ``index`` moved by ``shift`` and turned by ``turn`` (on the right)."""
    stamp, *values = lines[index].split()
    p = np.array(values, dtype=float)
    q = poses3d.quat_multiply(p[3:], poses3d.rotvec_to_quat(turn))
    out = list(lines)
    out[index] = " ".join([stamp, *(repr(float(v)) for v in np.r_[p[:3] + shift, q])])
    return "\n".join(out) + "\n"


def unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return np.asarray(v / np.linalg.norm(v))


def detections(folder: Path, trials: int) -> None:
    tum, joints = DATA / "camera_demo.tum", DATA / "camera_demo.joints.csv"
    lines = tum.read_text().splitlines()
    rng = np.random.default_rng(0)
    for label, metres, degrees in SIZES:
        found = other = 0
        for _ in range(trials):
            index = int(rng.integers(100, len(lines) - 100))
            shift, turn = metres * unit(rng), np.radians(degrees) * unit(rng)
            (folder / "g.tum").write_text(glitched(lines, index, shift, turn))
            flagged = flagged_lines(folder / "g.tum", joints)
            found += (index + 1) in flagged
            other += sum(1 for line in flagged if line != index + 1)
        print(f"glitch {label:12s} found {found}/{trials}, other poses flagged {other}")


def false_alarms(folder: Path, seeds: int) -> None:
    demo = flagged_lines(DATA / "camera_demo.tum", DATA / "camera_demo.joints.csv")
    print(f"clean demo: {len(demo)} poses flagged")
    per_seed = []
    for seed in range(seeds):
        options = CameraSimulationOptions(
            duration_s=40.0, seed=seed, stamp_offset_s=0.01, noise=CameraNoise(0.001, 0.0017)
        )
        tum, joints, _ = write_camera_simulation(simulate_camera(options), folder / f"s{seed}.tum")
        per_seed.append(len(flagged_lines(tum, joints)))
    print(f"noisy simulations (1 mm, 0.1°, seeds 0-{seeds - 1}): poses flagged per seed {per_seed}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        detections(Path(tmp), args.trials)
        false_alarms(Path(tmp), args.seeds)


if __name__ == "__main__":
    main()
