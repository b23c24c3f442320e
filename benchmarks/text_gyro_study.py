"""A gyro beside a text log, on simulated drives: every parameter against the truth in its σ, the
clock offsets in ms.

Each seed: a 60 s text log of a differential drive at 25 Hz (``simulate``; its tracker ``--latency``
late), a gyro's CSV of its base's turning beside it
(:func:`nlp_calib.simulation.beside.write_text_log_gyro`: rolled 3°, stamped ``--gyro-late`` late),
run with docs/imu.md's ``text_gyro.yaml`` (its clock offsets fitted); each fitted parameter's
estimate, σ and estimate − truth in σ::

    nice -n 10 python3 benchmarks/text_gyro_study.py --seeds 4 5 6 7 8 9
    nice -n 10 python3 benchmarks/text_gyro_study.py --seeds 10 11 12 13 --latency 0.03 --gyro-late 0.02

``--alone`` fits the same text logs without the gyro (the counts' own model, its lengths read as
radii over ``COUNTS``), for what the tracker alone gives.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

#: This checkout (its code, not an installed one's, is what runs).
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from nlp_calib.simulation.beside import write_text_log_gyro  # noqa: E402
from nlp_calib.simulation.options import SimulationOptions  # noqa: E402
from nlp_calib.simulation.simulate import simulate, write_simulation  # noqa: E402

#: Each wheel's counts per turn (a text log states none).
COUNTS = 4096.0
GYRO = {
    "gyro_bias_x": 0.003,
    "gyro_bias_y": -0.002,
    "gyro_bias_z": 0.004,
    "imu_roll": math.radians(3.0),
    "imu_pitch": 0.0,
}
RATE_NOISE = 0.002
#: docs/imu.md's text_gyro.yaml.
SCENARIO = {
    "name": "text_gyro",
    "model": "diff_drive",
    "sensor": {"mount": "planar", "beside": "gyro"},
    "dataset": {
        "text": "run.log",
        "gyro": "gyro.csv",
        "counts_per_turn": {"left_wheel": COUNTS, "right_wheel": COUNTS},
    },
    "initial_guess": "auto",
    "alignment": {"tracker_lag": "auto"},
    "information": {"translation": 1.25e5, "rotation": 1.25e5, "gyro": 1.0e8},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}
#: ``--alone``: the same text log without the gyro (its counts' own model, k_left in m per count).
ALONE = {
    **{k: v for k, v in SCENARIO.items() if k not in ("sensor", "dataset", "information")},
    "name": "text_alone",
    "dataset": "run.log",
    "information": {"translation": 1.25e5, "rotation": 1.25e5},
}
#: The counts model's names for the radians model's lengths.
PER_COUNT = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}


def one(
    seed: int, latency: float, gyro_late: float, folder: Path, alone: bool = False
) -> dict[str, tuple[float, float, float]]:
    """Each parameter's estimate, σ and truth on one seed's drive (none where the run failed: its
    last line printed); ``alone``: the text log's own fit, without the gyro."""
    sim = simulate(SimulationOptions.of(records=1500, seed=seed, model="diff_drive", latency_s=latency))
    write_simulation(sim, folder / "run.log")
    write_text_log_gyro(sim, folder / "gyro.csv", GYRO, RATE_NOISE, seed, gyro_late)
    (folder / "text_gyro.yaml").write_text(yaml.safe_dump(ALONE if alone else SCENARIO))
    run = subprocess.run(
        [sys.executable, "-m", "nlp_calib", "run", str(folder / "text_gyro.yaml"),
         "--out", str(folder / "out")],
        capture_output=True, text=True, check=False, cwd=REPO,
    )  # fmt: skip
    if run.returncode != 0:
        last = (run.stdout + run.stderr).strip().splitlines()[-1]
        print(f"seed {seed}: the run failed (exit {run.returncode}): {last}")
        return {}
    t, per_rad = sim.options.truth, COUNTS / (2.0 * math.pi)
    truth = {
        "left_wheel_radius": t["k_left"] * per_rad,
        "right_wheel_radius": t["k_right"] * per_rad,
        "wheel_separation": t["baseline"],
        **{n: t[n] for n in ("sensor_x", "sensor_y", "sensor_theta")},
        **GYRO,
        "tracker_lag": latency,
        "gyro_lag": gyro_late,
    }
    stored = yaml.safe_load((folder / "out" / "calibration.yaml").read_text())
    est, std = stored["parameters"], stored["std"]
    if alone:
        unit = {"k_left": per_rad, "k_right": per_rad, "baseline": 1.0}
        est = {PER_COUNT.get(n, n): v * unit.get(n, 1.0) for n, v in est.items()}
        std = {PER_COUNT.get(n, n): v * unit.get(n, 1.0) for n, v in std.items() if v is not None}
    return {n: (est[n], std[n], v) for n, v in truth.items() if std.get(n)}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, nargs="+", required=True)
    parser.add_argument("--latency", type=float, default=0.0, help="the text log's tracker latency (s)")
    parser.add_argument("--gyro-late", type=float, default=0.0, help="how late the gyro is stamped (s)")
    parser.add_argument("--alone", action="store_true", help="the text log's own fit, without the gyro")
    args = parser.parse_args()
    scores: list[float] = []
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            for name, (est, std, true) in one(
                seed, args.latency, args.gyro_late, Path(tmp), args.alone
            ).items():
                z = (est - true) / std
                scores.append(abs(z))
                unit = 1e3 if name.endswith("_lag") else 1.0
                figures = f"{est * unit:+.6g} ± {std * unit:.3g} (truth {true * unit:.6g})"
                print(f"seed {seed} {name:20s} {figures} {z:+.2f}σ")
    a = np.asarray(scores)
    shares = ", ".join(f"{np.mean(a <= k):.0%} within {k}σ" for k in (1, 2, 3))
    print(f"{a.size} estimates: {shares}")


if __name__ == "__main__":
    main()
