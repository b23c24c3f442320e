"""Does the verdict trust a camera's calibration when it should: 10 noisy camera recordings.

    python benchmarks/camera_trust.py [--seeds 10] [--first 100]

The shipped camera demo's scenario (``scenarios/camera_demo.yaml``) on recordings of its noise
(1 mm and 0.1° of pose noise, 40 s, a 10 ms stamp offset) from seeds the tests never use (100 on).
Per seed: the largest |estimate − truth| in σ, whether the fit is within 2σ of the truth for every
parameter, the verdict, whether it says "no better than" the start, the fit against the start by
held-out cost, and whether the direction check raised an alarm (the truth does not depend on the
direction of travel: every alarm is false). Prints a table; nothing is written.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from nlp_calib.pipeline import Calibration, load_scenario
from nlp_calib.simulation.camera import (
    CameraNoise,
    CameraSimulationOptions,
    simulate_camera,
    write_camera_simulation,
)

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first", type=int, default=100)
    args = ap.parse_args()
    t0 = time.perf_counter()
    demo = (REPO / "scenarios" / "camera_demo.yaml").read_text().replace("data/camera_demo", "cam")
    head = "| seed | largest error / σ | within 2σ | verdict | 'no better than' | against the start |"
    print(head + " direction alarm |")
    print("|---|---|---|---|---|---|---|")
    counts = {"within": 0, "caveat_within": 0, "alarms": 0}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.first, args.first + args.seeds):
            folder = Path(tmp) / f"seed{seed}"
            folder.mkdir()
            opts = CameraSimulationOptions(
                duration_s=40.0, seed=seed, stamp_offset_s=0.01, noise=CameraNoise(0.001, 0.0017)
            )
            write_camera_simulation(simulate_camera(opts), folder / "cam.tum")
            (folder / "c.yaml").write_text(demo)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                run = Calibration.setup(load_scenario(folder / "c.yaml")).run()
            truth = run.checks.truth
            assert truth is not None
            worst = float(np.nanmax(np.abs(truth.z)))
            within = worst <= 2.0
            said = any("no better than" in r for r in run.verdict.reasons)
            alarm = run.checks.direction is not None and run.checks.direction.significant
            start = run.checks.start.words() if run.checks.start is not None else "-"
            counts["within"] += within
            counts["caveat_within"] += within and said
            counts["alarms"] += alarm
            print(
                f"| {seed} | {worst:.2f} | {'yes' if within else 'no'} | {run.verdict.level} | "
                f"{'yes' if said else 'no'} | {start} | {'yes' if alarm else 'no'} |"
            )
    print(
        f"\n{counts['within']} of {args.seeds} fits within 2σ of the truth; 'no better than' the start on "
        f"{counts['caveat_within']} of them; direction alarms: {counts['alarms']}"
    )
    print(f"_Run time: {time.perf_counter() - t0:.0f} s._")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
