"""A robot's own odometry, integrated with a wrong model, calibrated against a tracker: the
corrections to the vendor's model against the truth, on seeds no test uses::

    python3 benchmarks/vendor_study.py --seeds 201 202 203 204 205
    python3 benchmarks/vendor_study.py --model tricycle --seeds 201 202 203 204 205

A gain's or a length's error is its correction's relative error (%), an offset's the difference of
its correction from the truth's (mrad).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import warnings
from pathlib import Path

from nlp_calib.models import get_model
from nlp_calib.models.base import reference
from nlp_calib.models.radians import in_units
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.simulation.vendor import (
    VendorSimulationOptions,
    correction,
    vendor_models,
    write_vendor_simulation,
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[201, 202, 203, 204, 205])
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--model", choices=vendor_models(), default=vendor_models()[0])
    args = ap.parse_args(argv)
    print("seed  error of each correction (estimate over the vendor's, against the truth's)  verdict")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            opts = VendorSimulationOptions(model=args.model, duration_s=args.duration, seed=seed)
            odometry, tum, truth = write_vendor_simulation(opts, Path(tmp) / f"odom_{seed}.txt")
            doc = json.loads(truth.read_text())
            dataset = {"odometry": str(odometry), "vendor": doc["vendor"], "poses": str(tum)}
            sc = {
                "model": args.model,
                "dataset": dataset,
                "residual": {"horizon_s": 0.5},
                "solvers": ["gauss_newton"],
            }
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                run = Calibration(scenario_from_mapping(sc, f"vendor_{seed}", Path(tmp))).run()
            est = run.reports["gauss_newton"].result.param_dict()
            cells = "  ".join(
                _error(args.model, k, est[k], doc["vendor"][k], v) for k, v in doc["corrections"].items()
            )
            print(f"{seed:>4}  {cells}  {run.verdict.level}")
    return 0


def _error(model: str, name: str, estimate: float, vendor: float, truth: float) -> str:
    """The estimate's correction against the truth's: in % of it (a ratio), in mrad (an offset's)."""
    got = correction(model, name, estimate, vendor)
    if reference(in_units(get_model(model), "radians"), name)[0] == "absolute":
        return f"{name} {1e3 * (got - truth):+.3f} mrad"
    return f"{name} {100 * (got / truth - 1):+.3f} %"


if __name__ == "__main__":
    raise SystemExit(main())
