"""Convert a skid-steer's motor-speed CSVs and a motion-capture pose CSV into a joint log and a TUM file.

    python benchmarks/scout_convert.py SOURCE OUT/STEM [--reduction 40] [--negate fl,rl] [--burst-gap 0.05]

``SOURCE``: a folder (or a bare git directory) holding ``motor_speed_fl.csv``, ``motor_speed_fr.csv``,
``motor_speed_rl.csv``, ``motor_speed_rr.csv`` (rostopic CSV exports with ``header.stamp.secs``,
``header.stamp.nsecs`` and ``rpm`` columns: each motor's speed) and ``gt_pose.csv`` (a
``geometry_msgs/PoseStamped`` export: ``header.stamp.*``, ``pose.position.*``,
``pose.orientation.*``), as in github.com/AlessioGalluccio/Bag1_robotics_data (an AgileX Scout 2.0,
motors at 50 Hz, OptiTrack poses). Writes:

- ``STEM.csv``: ``time,left_wheel_joint,right_wheel_joint``, each side's wheel speed in rad/s (the
  mean of its front and rear motor, rpm·2π/60 over the gear ``--reduction``; the motors named in
  ``--negate`` turn the other way when the base drives forward, as a mirrored side's do): read it
  with ``form: speeds``;
- ``STEM.tum``: one pose per burst of the tracker. A tracker whose poses arrive in bursts (stamps
  ``--burst-gap`` or less apart) stamps them on arrival, not when they were measured: within a
  burst the stamps are a few ms apart while the poses move as far from one to the next as between
  bursts. Only each burst's last pose, the one measured nearest its stamp, is kept.

Nothing of the data set belongs in this repository.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import subprocess
from pathlib import Path

import numpy as np

MOTORS = ("fl", "fr", "rl", "rr")


def read_text(source: Path, name: str) -> str:
    """A file of ``source``: a folder, or a bare git directory's HEAD."""
    if (source / name).is_file():
        return (source / name).read_text()
    out = subprocess.run(
        ["git", "-C", str(source), "show", f"HEAD:{name}"], capture_output=True, text=True, check=True
    )
    return out.stdout


def columns(text: str, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The named columns of a CSV export as float arrays, plus ``stamp`` (s) from the header's stamp."""
    rows = list(csv.DictReader(io.StringIO(text)))
    out = {n: np.array([float(r[n]) for r in rows]) for n in names}
    secs = np.array([int(r["header.stamp.secs"]) for r in rows], dtype=np.int64)
    nsecs = np.array([int(r["header.stamp.nsecs"]) for r in rows], dtype=np.int64)
    out["stamp"] = (secs - secs[0]).astype(float) + nsecs * 1e-9 + float(secs[0])
    return out


def wheel_speeds(source: Path, reduction: float, negate: set[str]) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (s) and each side's wheel speed (rad/s), left then right: the mean of its motors."""
    motors = {m: columns(read_text(source, f"motor_speed_{m}.csv"), ("rpm",)) for m in MOTORS}
    stamps = motors["fl"]["stamp"]
    for m in MOTORS:
        if motors[m]["stamp"].shape != stamps.shape or np.any(np.abs(motors[m]["stamp"] - stamps) > 1e-3):
            raise SystemExit(f"motor {m}'s stamps are not motor fl's: this converter pairs them row by row")
    rad = {
        m: (-1.0 if m in negate else 1.0) * motors[m]["rpm"] * 2 * math.pi / 60 / reduction for m in MOTORS
    }
    return stamps, np.stack([(rad["fl"] + rad["rl"]) / 2, (rad["fr"] + rad["rr"]) / 2], axis=1)


def burst_ends(stamps: np.ndarray, gap: float) -> np.ndarray:
    """Indices of each burst's last pose: those followed by one over ``gap`` s later, and the last."""
    return np.append(np.flatnonzero(np.diff(stamps) > gap), stamps.size - 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("source", type=Path)
    ap.add_argument("stem", type=Path)
    ap.add_argument("--reduction", type=float, default=40.0, help="motor turns per wheel turn")
    ap.add_argument("--negate", default="fl,rl", help="motors that turn backwards when driving forward")
    ap.add_argument("--burst-gap", type=float, default=0.05, help="s: stamps closer than this are one burst")
    args = ap.parse_args()
    stamps, speeds = wheel_speeds(args.source, args.reduction, set(filter(None, args.negate.split(","))))
    names = tuple(f"pose.position.{a}" for a in "xyz") + tuple(f"pose.orientation.{a}" for a in "xyzw")
    pose = columns(read_text(args.source, "gt_pose.csv"), names)
    keep = burst_ends(pose["stamp"], args.burst_gap)
    args.stem.parent.mkdir(parents=True, exist_ok=True)
    lines = [f"# from {args.source}: wheel speeds (rad/s), motors over a {args.reduction:g}:1 reduction"]
    lines += ["time,left_wheel_joint,right_wheel_joint"]
    lines += [f"{t:.9f},{float(s[0])!r},{float(s[1])!r}" for t, s in zip(stamps, speeds)]
    args.stem.with_suffix(".csv").write_text("\n".join(lines) + "\n")
    tum = [f"# from {args.source}: the last pose of each of {keep.size} bursts of {pose['stamp'].size} poses"]
    tum += [f"{pose['stamp'][i]:.9f} " + " ".join(repr(float(pose[n][i])) for n in names) for i in keep]
    args.stem.with_suffix(".tum").write_text("\n".join(tum) + "\n")


if __name__ == "__main__":
    main()
