"""A robot's own odometry, integrated with a wrong model, calibrated against a tracker: the
corrections to the vendor's model against the truth, on seeds no test uses::

    python3 benchmarks/vendor_study.py --seeds 201 202 203 204 205
"""

from __future__ import annotations

import argparse
import json
import tempfile
import warnings
from pathlib import Path

from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.simulation.vendor import VendorSimulationOptions, write_vendor_simulation


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[201, 202, 203, 204, 205])
    ap.add_argument("--duration", type=float, default=120.0)
    args = ap.parse_args(argv)
    print("seed  error of each correction (estimate over the vendor's, against the truth's)  verdict")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            opts = VendorSimulationOptions(duration_s=args.duration, seed=seed)
            odometry, tum, truth = write_vendor_simulation(opts, Path(tmp) / f"odom_{seed}.txt")
            doc = json.loads(truth.read_text())
            dataset = {"odometry": str(odometry), "vendor": doc["vendor"], "poses": str(tum)}
            sc = {
                "model": "diff_drive",
                "dataset": dataset,
                "residual": {"horizon_s": 0.5},
                "solvers": ["gauss_newton"],
            }
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                run = Calibration(scenario_from_mapping(sc, f"vendor_{seed}", Path(tmp))).run()
            est = run.reports["gauss_newton"].result.param_dict()
            cells = "  ".join(
                f"{k} {100 * (est[k] / doc['vendor'][k] / v - 1):+.3f} %"
                for k, v in doc["corrections"].items()
            )
            print(f"{seed:>4}  {cells}  {run.verdict.level}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
