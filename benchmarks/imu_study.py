"""A gyro as the reference, on simulated bags: every parameter against the truth in its σ.

Each seed: ``nlp-calib simulate --imu`` (the gyro stamped ``--latency`` late; ``--roll`` sets the
IMU's roll), then docs/imu.md's scenario with the wheel separation known, and the estimate −
truth in σ of every fitted parameter; at the end the share within 1σ and 2σ. A gyro alone (no
known length) must be refused by the pre-flight as not determining the lengths::

    python3 benchmarks/imu_study.py --seeds 201 202 203 --roll 0.0873 --latency 0.02
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

SCENARIO = """name: gyro
model: diff_drive
sensor: gyro
dataset: {{bag: gyro, joint_states: /joint_states,
          joints: [left_wheel_joint, right_wheel_joint], imu: /imu}}
initial_guess: auto
alignment: {{tracker_lag: auto}}
information: {{translation: 1.0e8, rotation: 1.0e8}}
robust: {{kernel: huber, delta: 3.0}}
solvers: [gauss_newton]
{known}"""
#: The simulator's names of the truth and the fit's (a model in radians).
NAMES = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "nlp_calib", *args], capture_output=True, text=True, check=False
    )


def one(seed: int, roll: float, latency: float, folder: Path) -> list[tuple[str, float]]:
    """The estimate − truth in σ of every fitted parameter of one seed's bag."""
    (folder / "sim.yaml").write_text(yaml.safe_dump({"truth": {"imu_roll": roll}}))
    sim = _cli(
        "simulate",
        "--imu",
        "--out",
        str(folder / "gyro"),
        "--seed",
        str(seed),
        "--duration",
        "120",
        "--latency",
        str(latency),
        "--config",
        str(folder / "sim.yaml"),
    )
    assert sim.returncode == 0, sim.stderr
    truth = {
        NAMES.get(k, k): v for k, v in json.loads((folder / "gyro.truth.json").read_text())["params"].items()
    }
    (folder / "alone.yaml").write_text(SCENARIO.format(known=""))
    alone = _cli("preflight", str(folder / "alone.yaml"))
    refused = "only the ratios of" in alone.stdout
    (folder / "known.yaml").write_text(
        SCENARIO.format(known=f"known: {{wheel_separation: {truth['wheel_separation']}}}")
    )
    run = _cli("run", str(folder / "known.yaml"), "--out", str(folder / "out"), "--force")
    assert run.returncode == 0, run.stderr
    cal = yaml.safe_load((folder / "out" / "calibration.yaml").read_text())
    z = [(n, (v - truth[n]) / cal["std"][n]) for n, v in cal["parameters"].items() if cal["std"][n] > 0]
    lag_ms = 1000 * (cal["parameters"]["tracker_lag"] - truth["tracker_lag"])
    print(
        f"{seed:5d}  lengths not determined alone: {refused}  lag error {lag_ms:+.2f} ms  "
        + "  ".join(f"{n} {v:+.2f}σ" for n, v in z),
        flush=True,
    )
    return z


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, nargs="+", default=[201, 202, 203])
    ap.add_argument("--roll", type=float, default=0.02)
    ap.add_argument("--latency", type=float, default=0.02)
    args = ap.parse_args()
    scores = []
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            scores += [abs(v) for _, v in one(seed, args.roll, args.latency, Path(tmp))]
    n = len(scores)
    within = [sum(s <= k for s in scores) / n for k in (1, 2)]
    print(
        f"{n} estimates: {within[0]:.0%} within 1σ, {within[1]:.0%} "
        f"within 2σ, {sum(s <= 3 for s in scores) / n:.0%} within 3σ, largest {max(scores):.2f}σ"
    )


if __name__ == "__main__":
    main()
