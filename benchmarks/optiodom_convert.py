"""Convert sessions of the public OptiOdom data set into CSV joint logs and TUM trajectories.

    python benchmarks/optiodom_convert.py SOURCE OUT

``SOURCE``: a clone of github.com/sousarbarb/optiodom (MIT), or its bare git directory. Each run
``data/<robot>/<path>/<ID>/<ID>_run-NN.csv`` of the differential drive and the tricycle (time,
tracked pose x, y, θ of the robot's centre, encoder ticks per 50 ms cycle) becomes
``OUT/<robot>/<path>/<ID>/<ID>_run-NN.csv`` (time, joint angles in rad: each wheel's ticks summed
and turned into radians by the session's metadata, gear ratio × encoder resolution per turn; the
tricycle's steering angle as published) and ``.tum`` beside it (the tracked pose, planar), the
times shifted by 1000 s. This is how the runs in the project's shared data folder were converted:
``benchmarks/optiodom_study.py --root OUT`` fits every session. Nothing of the data set belongs in
this repository.
"""

from __future__ import annotations

import argparse
import io
import math
import subprocess
from pathlib import Path

import numpy as np

#: Joint columns per robot: each is (name, column of the run's file, ticks summed?).
JOINTS = {
    "diff": (("left_wheel_joint", 5, True), ("right_wheel_joint", 4, True)),
    "tricyc": (("steer_joint", 5, False), ("traction_joint", 4, True)),
}


class Source:
    """Files of the data set, from a clone or from its bare git directory."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.git = not (path / "data").is_dir()

    def files(self) -> list[str]:
        if not self.git:
            return [p.relative_to(self.path).as_posix() for p in (self.path / "data").rglob("*.csv")]
        out = subprocess.run(
            ["git", "-C", str(self.path), "ls-tree", "-r", "--name-only", "HEAD", "data/"],
            capture_output=True,
            text=True,
            check=True,
        )
        return out.stdout.split()

    def text(self, name: str) -> str:
        if not self.git:
            return (self.path / name).read_text()
        out = subprocess.run(
            ["git", "-C", str(self.path), "show", f"HEAD:{name}"], capture_output=True, text=True, check=True
        )
        return out.stdout


def metadata(text: str) -> dict[str, list[str]]:
    rows = [line.split(",") for line in text.splitlines() if line.strip()]
    return {r[0]: [v for v in r[1:] if v] for r in rows}


def convert_run(rows: np.ndarray, robot: str, ticks_per_turn: float, stem: Path, source: str) -> None:
    """One run's joint CSV and TUM file."""
    time_s = 1000.0 + rows[:, 0]
    columns = []
    for _, col, summed in JOINTS[robot]:
        columns.append(np.cumsum(rows[:, col]) * 2 * math.pi / ticks_per_turn if summed else rows[:, col])
    names = ",".join(name for name, _, _ in JOINTS[robot])
    lines = [f"# from {source} ({robot}; {ticks_per_turn:g} ticks per wheel turn)", f"time,{names}"]
    lines += [f"{t:.6f}," + ",".join(f"{c[i]:.9f}" for c in columns) for i, t in enumerate(time_s)]
    stem.with_suffix(".csv").write_text("\n".join(lines) + "\n")
    tum = [f"# OptiTrack pose of the robot centre from {source}"]
    tum += [
        f"{t:.6f} {r[1]:.9f} {r[2]:.9f} 0 0 0 {math.sin(r[3] / 2):.12f} {math.cos(r[3] / 2):.12f}"
        for t, r in zip(time_s, rows)
    ]
    stem.with_suffix(".tum").write_text("\n".join(tum) + "\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("source", type=Path)
    ap.add_argument("out", type=Path)
    args = ap.parse_args()
    src = Source(args.source)
    files = src.files()
    for meta in sorted(f for f in files if f.endswith("_metadata.csv")):
        folder = meta.rsplit("/", 1)[0]
        robot = folder.split("/")[1]
        if robot not in JOINTS:
            continue
        md = metadata(src.text(meta))
        ticks = float(md["ngear"][0]) * float(md["encRes"][0])
        rel = folder[len("data/") :]
        runs = sorted(f for f in files if f.startswith(folder + "/") and "_run-" in f and f.endswith(".csv"))
        runs = [f for f in runs if not f.endswith(("_odo.csv", "_opti.csv"))]
        (args.out / rel).mkdir(parents=True, exist_ok=True)
        for run in runs:
            rows = np.loadtxt(io.StringIO(src.text(run)), delimiter=",", ndmin=2)
            name = run.rsplit("/", 1)[1]
            convert_run(rows, robot, ticks, args.out / rel / Path(name).stem, f"{rel}/{name}")
        print(f"{rel}: {len(runs)} runs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
