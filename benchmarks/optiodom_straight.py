"""A wheel radius from straight stretches alone: the tracked point's distance over the wheels' angle.

    python3 benchmarks/optiodom_straight.py ROOT [--window 1.0] [--turn-deg 0.3] [--steady 0.05]

``ROOT``: the output of ``benchmarks/optiodom_convert.py`` (or the project's shared OptiOdom
folder). On a stretch where the robot does not turn, every point of the body moves by the same
distance, so the tracked point's displacement over the wheels' angle is the wheel radius whatever
the tracker's mount and whatever the wheelbase or track: a scale check independent of any model
fit. A stretch is a window of ``--window`` seconds whose heading changes by less than
``--turn-deg`` degrees, whose wheels' speed changes between its halves by less than ``--steady``
of itself (and, on the tricycle, whose steering stays within 1° of its median on such
stretches) and whose wheels roll forward by at least a tenth of a turn. Prints, per session, the
radius (the ratio of summed distance to summed angle), the spread of its runs' values, and the
number of stretches: the differential drive's from its wheels' mean angle (the mean radius).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def _read(run: Path) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    names = run.read_text().splitlines()[1].split(",")
    joints = np.loadtxt(run, delimiter=",", skiprows=2)
    tum = np.loadtxt(run.with_suffix(".tum"))
    qz, qw = tum[:, 6], tum[:, 7]
    pose = np.column_stack([tum[:, 1], tum[:, 2], np.unwrap(2 * np.arctan2(qz, qw))])
    assert np.allclose(tum[:, 0], joints[:, 0]), run
    return joints[:, 0], {n: joints[:, i] for i, n in enumerate(names) if i}, pose


def stretches(run: Path, window: float, turn: float, steady: float) -> tuple[np.ndarray, np.ndarray]:
    """Each straight stretch's tracked distance and rolled wheel angle (the diff drive's mean)."""
    t, joints, pose = _read(run)
    step = max(1, round(window / np.median(np.diff(t))))
    a, b = np.arange(0, len(t) - step, step), np.arange(step, len(t), step)
    wheels = [joints[n] for n in joints if n != "steer_joint"]
    angle = np.mean([w[b] - w[a] for w in wheels], axis=0)
    dist = np.hypot(pose[b, 0] - pose[a, 0], pose[b, 1] - pose[a, 1])
    keep = (np.abs(pose[b, 2] - pose[a, 2]) < np.radians(turn)) & (angle > 2 * np.pi / 10)
    # At a steady speed only: a wheel that spins up or locks while the robot starts or stops (a
    # square's corners) rolls by more or less than the ground it covers, and a clock offset between
    # the wheels and the tracker moves the distance by the change of speed times the offset.
    half = (a + b) // 2
    first, second = (np.mean([w[m] - w[n] for w in wheels], axis=0) for n, m in ((a, half), (half, b)))
    keep &= np.abs(second - first) < steady * np.maximum(np.abs(first), 1e-12)
    if "steer_joint" in joints:
        steer = joints["steer_joint"]
        spread = np.maximum.reduceat(steer, a) - np.minimum.reduceat(steer, a)
        keep &= spread[: len(a)] < np.radians(1.0)
        mid = np.median(steer[a[keep]]) if keep.any() else 0.0
        keep &= np.abs(steer[a] - mid) < np.radians(1.0)
    return dist[keep], angle[keep]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("root", type=Path)
    p.add_argument("--window", type=float, default=1.0)
    p.add_argument("--turn-deg", type=float, default=0.3)
    p.add_argument("--steady", type=float, default=0.05, help="largest change of speed within a stretch")
    args = p.parse_args()
    print("session\truns\tstretches\tradius_m\truns_min\truns_max")
    for session in sorted({r.parent for r in args.root.rglob("*_run-*.csv")}):
        runs = sorted(session.glob("*_run-*.csv"))
        per_run = [stretches(r, args.window, args.turn_deg, args.steady) for r in runs]
        per_run = [(d, a) for d, a in per_run if len(d)]
        if not per_run:
            continue
        radii = [d.sum() / a.sum() for d, a in per_run]
        d, a = (np.concatenate(c) for c in zip(*per_run))
        rel = session.relative_to(args.root)
        print(f"{rel}\t{len(per_run)}\t{len(d)}\t{d.sum() / a.sum():.6f}\t{min(radii):.6f}\t{max(radii):.6f}")


if __name__ == "__main__":
    main()
