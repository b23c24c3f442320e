"""How often ``nlp-calib check`` is right: false alarms on fresh drives of an unchanged robot, and
detections when one parameter of the robot has changed.

    python benchmarks/check_study.py                  # 5 calibrations × 12 fresh drives per case
    python benchmarks/check_study.py --calibrations 2 --drives 3   # a quick look

One simulated tricycle (the simulator's default truth), calibrated with the demo scenario's
formulation on drives with seeds 1000 + c; each calibration is then checked, exactly as the
command does (its calibration.yaml read back, the new log refitted from it), on fresh drives with
seeds 5000 + 100·c + k, once with the robot unchanged and once with each change below (the cases
share their drives' seeds: the same drives, another robot). The check's
thresholds come from its statistics (analysis/drift.py: Student-t at a 1 % family-wise false-alarm
rate); nothing here tunes them. Writes ``results/check_study.{json,md}`` (``--records N``:
``check_study_N.*``).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from nlp_calib.models import MODELS  # noqa: E402

TRUTH = dict(MODELS["tricycle"].drive.default_truth)
#: The robot unchanged, and each change the check should see (on the parameter it names).
CASES: dict[str, tuple[str | None, dict[str, float]]] = {
    "unchanged": (None, {}),
    "k_traction +1 %": ("k_traction", {"k_traction": TRUTH["k_traction"] * 1.01}),
    "sensor_x +2 cm": ("sensor_x", {"sensor_x": TRUTH["sensor_x"] + 0.02}),
    "sensor_y +2 cm": ("sensor_y", {"sensor_y": TRUTH["sensor_y"] + 0.02}),
}
#: Records of every drive (``--records``): the σ, and so what a check can see, shrink with it.
RECORDS = int(os.environ.get("CHECK_STUDY_RECORDS", "1500"))


def _simulate(seed: int, truth: dict[str, float], path: Path) -> Path:
    from nlp_calib.simulation import SimulationOptions, simulate, write_simulation

    opts = SimulationOptions.of(records=RECORDS, seed=seed, truth=truth, outlier_fraction=0.01)
    log, _ = write_simulation(simulate(opts), path)
    return log


def calibrate(c: int, tmp: Path) -> str:
    """Calibration ``c``: the demo scenario's formulation on drive 1000 + c; its calibration.yaml."""
    from nlp_calib.outputs.handoff import write_calibration
    from nlp_calib.pipeline import Calibration, load_scenario

    log = _simulate(1000 + c, {}, tmp / f"cal{c}.txt")
    scenario = load_scenario(REPO / "scenarios" / "demo.yaml").with_dataset(log)
    run = Calibration.setup(scenario, solvers=("gauss_newton",)).run(("gauss_newton",))
    folder = tmp / f"cal{c}"
    folder.mkdir(exist_ok=True)
    (path,) = write_calibration(run, folder, "calibration.yaml")
    return str(path)


def check_one(job: tuple[str, int, int, str, str]) -> dict[str, Any]:
    """One check: calibration ``c`` on fresh drive ``k`` of ``case``."""
    from nlp_calib.pipeline.check import check, check_scenario
    from nlp_calib.pipeline.stored import read_calibration

    calibration, c, k, case, tmp = job
    seed = 5000 + 100 * c + k
    log = _simulate(seed, CASES[case][1], Path(tmp) / f"fresh_{case.split()[0]}_{seed}.txt")
    stored = read_calibration(Path(calibration))
    drift = check(stored, check_scenario(stored, log)).checks.drift
    assert drift is not None
    return {
        "case": case,
        "calibration": c,
        "seed": seed,
        "verdict": drift.verdict,
        "moved": [ch.name for ch in drift.drifted],
        "z": {ch.name: ch.z for ch in drift.changes},
        "threshold": {ch.name: ch.threshold for ch in drift.changes},
    }


def table(results: list[dict[str, Any]]) -> str:
    """Per case: the checks, how many said each verdict, and how many named the changed parameter."""
    lines = [
        "| case | checks | still good | drifted | cannot tell | named the changed parameter "
        "| flagged another parameter |",
        "|---|---|---|---|---|---|---|",
    ]
    for case, (name, _) in CASES.items():
        rows = [r for r in results if r["case"] == case]
        verdicts = Counter(r["verdict"] for r in rows)
        named = sum(name in r["moved"] for r in rows) if name else 0
        other = sum(any(m != name for m in r["moved"]) for r in rows)
        n = len(rows)
        lines.append(
            f"| {case} | {n} | {verdicts['still good']} ({100 * verdicts['still good'] / n:.0f} %) | "
            f"{verdicts['drifted']} ({100 * verdicts['drifted'] / n:.0f} %) | {verdicts['cannot tell']} | "
            + (f"{named} ({100 * named / n:.0f} %)" if name else "-")
            + f" | {other} |"
        )
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calibrations", type=int, default=5)
    ap.add_argument("--drives", type=int, default=12, help="fresh drives per calibration and case")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--records", type=int, default=RECORDS, help="records of every drive (default 1500)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args()
    if args.records != RECORDS:  # the worker processes read it from the environment
        os.environ["CHECK_STUDY_RECORDS"] = str(args.records)
        os.execv(sys.executable, [sys.executable, *sys.argv])
    t0 = time.perf_counter()
    load = os.getloadavg()
    spawn = multiprocessing.get_context("spawn")  # fresh workers: nothing forked from a busy process
    with tempfile.TemporaryDirectory() as tmp, ProcessPoolExecutor(args.jobs, mp_context=spawn) as pool:
        cals = list(pool.map(calibrate, range(args.calibrations), [Path(tmp)] * args.calibrations))
        jobs = [
            (cal, c, k, case, tmp) for case in CASES for c, cal in enumerate(cals) for k in range(args.drives)
        ]
        results = list(pool.map(check_one, jobs))
    text = (
        f"{args.calibrations} calibrations (drives 1000–{999 + args.calibrations}) × {args.drives} fresh "
        f"drives per case, {RECORDS} records each, tricycle, the demo scenario's formulation; "
        f"{time.perf_counter() - t0:.0f} s on {args.jobs} processes (load average {load[0]:.2f}).\n\n"
        + table(results)
    )
    args.out.mkdir(parents=True, exist_ok=True)
    doc = {"calibrations": args.calibrations, "drives": args.drives, "records": RECORDS, "results": results}
    stem = "check_study" if RECORDS == 1500 else f"check_study_{RECORDS}"
    head = json.dumps({k: v for k, v in doc.items() if k != "results"})[:-1]
    rows = ",\n".join("  " + json.dumps(r) for r in results)  # one check a line
    (args.out / f"{stem}.json").write_text(f'{head}, "results": [\n{rows}\n]}}\n')
    (args.out / f"{stem}.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
