"""A car whose rear axle slides out of bends, calibrated on the first half of its drive: sensor_x
against its truth, in its σ, and what the run says of it (the ``slip`` check).

    python3 benchmarks/car_slip_study.py OUT SEED [SEED ...] [--slip G] [--horizon-s S] [--circuit]

For each seed: the highway simulator's car (nlp_calib.simulation.vehicles) on the road of
benchmarks/car_check_study.py (400 s at 8-20 m/s, ``--bend 0.03 --heading -4.7``, the device's noise
correlated over 5 s), its rear axle sliding out of the bends at ``--slip`` rad per m/s² of lateral
acceleration (0: the control); ``car_like`` with the axle distance and track given, the first half
calibrated with ``nlp-calib run``. Prints sensor_x's truth, estimate, σ, |error|/σ, the verdict,
the slip check's slope in σ and its value at zero speed (and the σ of the slip in the σ to
believe), and whether sensor_x is handed off as calibrated (no verdict concern names it) or said
not determined; then how many seeds' sensor_x lie within 2σ of the truth, and for every parameter
with a truth how many lie within 2σ and 3σ, the largest |error|/σ, how much the slip's σ widens
its σ, and how far the drive's fit lies from the value at zero speed beside the line's distance.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import yaml
from car_check_study import scenario

from nlp_calib.simulation.vehicles import HighwayOptions, RoadOptions, simulate_highway

#: ``--circuit``: a small car (an F1/10's size) on a circuit: 1 to 5 m/s, braking and accelerating
#: every 3 to 10 s, bends loading its tyres to several m/s², records at 18.4 Hz, poses at 19.6 Hz.
CIRCUIT: dict[str, Any] = {
    "duration_s": 240.0,
    "road": {"heading_change": 12.0, "bend_angle": 0.15, "speed_periods_s": (3.0, 10.0)},
    "min_speed": 1.0,
    "max_speed": 5.0,
    "steer_max": 0.05,
    "wheel_rate_hz": 18.4,
    "pose_rate_hz": 19.6,
    "pose_noise": (0.01, 0.005),
    "truth": {
        "wheelbase": 0.32,
        "rear_track": 0.25,
        "sensor_x": 0.2,
        "sensor_y": 0.0,
        "sensor_theta": 0.01,
        "k_traction": 0.05,
        "steer_offset": -0.006,
    },
}


def options(seed: int, slip: float, circuit: bool) -> HighwayOptions:
    """The highway car of the module docstring, or the ``--circuit`` car."""
    if circuit:
        road = RoadOptions(**CIRCUIT["road"], slip_gain=slip)
        return HighwayOptions(**{**CIRCUIT, "road": road, "seed": seed})
    road = RoadOptions(heading_change=-4.7, bend_angle=0.03, slip_gain=slip, pose_noise_time_s=5.0)
    return HighwayOptions(duration_s=400.0, seed=seed, road=road, pose_noise=(0.02, 0.002))


def one(out: Path, seed: int, slip: float, horizon_s: float | None, circuit: bool) -> tuple[float, bool]:
    out.mkdir(parents=True, exist_ok=True)
    sim = simulate_highway(options(seed, slip, circuit))
    joints, poses, _ = sim.write(out / "car")
    truth = dict(sim.options.truth)
    half = int(sim.pose_time_s.size // 2)
    first = scenario(joints, poses, truth, 0, half)
    if horizon_s is not None:  # windows of several records, as `init` drafts them
        first["residual"] = {"horizon_s": horizon_s}
    (out / "first.yaml").write_text(yaml.safe_dump(first))
    cmd = [sys.executable, "-m", "nlp_calib", "run", str(out / "first.yaml"), "--out", str(out / "first")]
    subprocess.run([*cmd, "--skip-preflight"], capture_output=True, text=True, check=False)
    return report(out, seed, truth["sensor_x"])


def report(out: Path, seed: int, truth: float) -> tuple[float, bool]:
    """Prints the seed's line; returns sensor_x's |error|/σ and whether it is said not determined."""
    r = json.loads((out / "first" / "result.json").read_text())
    gn = r["solvers"]["gauss_newton"]
    x, std = gn["params"]["sensor_x"], gn["std"]["sensor_x"]
    slip = r.get("slip") or {}
    t = (slip.get("slope_in_sigma") or {}).get("sensor_x")
    zero = (slip.get("at_zero_speed") or {}).get("sensor_x")
    added = (slip.get("std_slip") or {}).get("sensor_x")
    concern = r["verdict"]["concerns"].get("sensor_x", "")
    said = "NOT DETERMINED (slip)" if "NOT DETERMINED" in concern else "doubtful"
    said = said if concern else "calibrated"
    slope = "no slip check" if t is None else f"slope {t:+.1f}σ, {zero:.3f} m at zero speed"
    own = "" if added is None else f" (slip's σ {added:.3f}, without it {(std**2 - added**2) ** 0.5:.3f})"
    print(
        f"seed {seed}: sensor_x truth {truth:.3f} estimate {x:.3f} ± {std:.3f}{own} |error|/σ "
        f"{abs(x - truth) / std:.1f}; {r['verdict']['level']}; {slope}; sensor_x {said}"
    )
    return abs(x - truth) / std, said.startswith("NOT")


def every_parameter(out: Path, seeds: list[int]) -> None:
    """Per parameter over the seeds (the truth check's errors): how many lie within 2σ and 3σ of
    the truth, the largest |error|/σ, the σ over the σ without the slip's, and the drive's fit's
    distance to the value at zero speed beside the line's (``lever·slope``)."""
    docs = [json.loads((out / str(seed) / "first" / "result.json").read_text()) for seed in seeds]
    for name, error in docs[0]["truth"]["error"].items():
        if error is None or docs[0]["solvers"]["gauss_newton"]["std"].get(name) is None:
            continue  # no truth, or held
        z, grown, fit, line = [], [], [], []
        for r in docs:
            gn, slip = r["solvers"]["gauss_newton"], r.get("slip") or {}
            std, added = gn["std"][name], (slip.get("std_slip") or {}).get(name) or 0.0
            z.append(abs(r["truth"]["error"][name]) / std)
            grown.append(std / max(std**2 - added**2, 1e-300) ** 0.5)
            if slip.get("made", True) and slip.get("at_zero_speed", {}).get(name) is not None:
                zero, t = slip["at_zero_speed"][name], slip["slope_in_sigma"][name]
                fit.append(gn["params"][name] - zero)
                lever = slip["lever_speed_squared"][name]
                # Before the record held the slope, the slip's σ was lever·√(slope² + σ_slope²).
                slope = (slip.get("slope") or {}).get(name)
                old = abs(t) * added / (1.0 + t * t) ** 0.5
                line.append(abs(lever * slope) if slope is not None else old)
        print(
            f"{name}: within 2σ {sum(v <= 2 for v in z)} of {len(z)}, 3σ {sum(v <= 3 for v in z)}, "
            f"largest |error|/σ {max(z):.2f}; σ {min(grown):.1f}-{max(grown):.1f}× the σ without the slip's; "
            f"fit − value at zero speed {min(fit, default=0):+.3g} to {max(fit, default=0):+.3g}, "
            f"|lever·slope| up to {max(line, default=0):.3g}"
        )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=Path)
    ap.add_argument("seeds", type=int, nargs="+")
    ap.add_argument("--slip", type=float, default=0.004)
    ap.add_argument("--horizon-s", type=float, default=None, help="windows of this duration (s)")
    ap.add_argument("--circuit", action="store_true", help="the small car on a circuit (CIRCUIT)")
    args = ap.parse_args()
    found = [one(args.out / str(seed), seed, args.slip, args.horizon_s, args.circuit) for seed in args.seeds]
    within = sum(z <= 2.0 for z, _ in found)
    told = sum(said for _, said in found)
    print(f"sensor_x within 2σ of truth: {within} of {len(found)}; NOT DETERMINED: {told}")
    every_parameter(args.out, args.seeds)


if __name__ == "__main__":
    main()
