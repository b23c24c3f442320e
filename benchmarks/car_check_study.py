"""A car on a road with bends, calibrated on one half of its drive and checked on the other (the
drift check's false alarms and detections when the model lacks what a real car has at speed).

    python3 benchmarks/car_check_study.py OUT SEED [SEED ...] [--slip G] [--noise-time S]
        [--moved sensor_y=0.1]

For each seed: the highway simulator's car (nlp_calib.simulation.vehicles) driving ``--duration``
seconds with bends, its rear axle sliding out of them (``--slip``, rad per m/s²) and the device's
noise correlated in time (``--noise-time``); ``car_like`` with the axle distance and track given.
The first half is calibrated with ``nlp-calib run``; the second half (with ``--moved`` its mount
moved: the same drive's second half simulated with the changed truth) checked with
``nlp-calib check``; prints each parameter's truth, both halves' estimates and σ, the z and the
verdict, from the files the commands write.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

import yaml

from nlp_calib.simulation.vehicles import HighwayOptions, RoadOptions, simulate_highway

NAMES = {"k_traction": "traction_wheels_radius", "rear_track": "traction_track_width"}
KNOWN = ("wheelbase", "rear_track")


def scenario(joints: Path, poses: Path, truth: dict[str, float], start: int, stop: int | None) -> dict:
    wheels = ("steering", "rear_left_wheel", "rear_right_wheel")
    return {
        "name": f"car_{start}",
        "model": "car_like",
        "initial_guess": "auto",
        "solvers": ["gauss_newton"],
        "dataset": {
            "joints": str(joints),
            "poses": str(poses),
            "form": "speeds",
            "encoders": dict(zip(wheels, wheels)),
        },
        "known": {NAMES.get(n, n): truth[n] for n in KNOWN},
        "samples": {"start": start, "stop": stop},
    }


def one(out: Path, seed: int, args: argparse.Namespace) -> None:
    out.mkdir(parents=True, exist_ok=True)
    road = RoadOptions(
        heading_change=args.heading,
        bend_angle=args.bend,
        slip_gain=args.slip,
        pose_noise_time_s=args.noise_time,
    )
    base = dict(duration_s=args.duration, seed=seed, road=road, pose_noise=(args.noise, 0.002))
    first = simulate_highway(HighwayOptions(**base))
    j1, p1, _ = first.write(out / "car")
    truth = dict(first.options.truth)
    half = int(first.pose_time_s.size // 2)
    second_truth = {**truth, **args.moved}
    j2, p2 = j1, p1
    if args.moved:
        j2, p2, _ = simulate_highway(HighwayOptions(**base, truth=second_truth)).write(out / "moved")
    for name, sc in (
        ("first", scenario(j1, p1, truth, 0, half)),
        ("second", scenario(j2, p2, truth, half, None)),
    ):
        (out / f"{name}.yaml").write_text(yaml.safe_dump(sc))
    run = [sys.executable, "-m", "nlp_calib"]
    if not (out / "first" / "calibration.yaml").is_file():  # the first half's calibration is kept
        subprocess.run(
            [*run, "run", str(out / "first.yaml"), "--out", str(out / "first"), "--skip-preflight"],
            capture_output=True,
            text=True,
            check=False,
        )
    chk = subprocess.run(
        [
            *run,
            "check",
            str(out / "first" / "calibration.yaml"),
            str(out / "second.yaml"),
            "--out",
            str(out / "check"),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    (out / "check.txt").write_text(chk.stdout + chk.stderr)
    report(out, seed, second_truth, chk.stdout)


def report(out: Path, seed: int, truth: dict[str, float], stdout: str) -> None:
    check = json.loads((out / "check" / "check.json").read_text())
    print(f"seed {seed}: {check['verdict']}: {'; '.join(check['reasons'])}")
    named = {NAMES.get(n, n): v for n, v in truth.items()}
    for name, c in check["parameters"].items():
        t = named.get(name, float("nan"))
        print(
            f"  {name:24s} truth {t: .5f} stored {c['stored']: .5f} ± {c['std_stored']:.2g} "
            f"refit {c['refit']: .5f} ± {c['std_refit']:.2g} z {c['z']:+.1f} "
            f"(shared {c['z_shared'] or math.nan:+.1f}) "
            f"limit {c['threshold']:.1f} "
            f"dof {c['dof']:.1f} {(c['untested'] or '')[:40]}"
        )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=Path)
    ap.add_argument("seeds", type=int, nargs="+")
    ap.add_argument("--duration", type=float, default=400.0)
    ap.add_argument("--bend", type=float, default=0.03)
    ap.add_argument("--slip", type=float, default=0.0)
    ap.add_argument("--heading", type=float, default=0.0)
    ap.add_argument("--noise", type=float, default=0.02)
    ap.add_argument("--noise-time", type=float, default=0.0)
    ap.add_argument("--moved", type=lambda s: dict([(k, float(v)) for k, v in [s.split("=")]]), default={})
    args = ap.parse_args()
    for seed in args.seeds:
        one(args.out / str(seed), seed, args)


if __name__ == "__main__":
    main()
