"""Censi et al.'s Khepera III intervals fitted with nlp_calib, against the authors' own estimates.

The public data of "Simultaneous calibration of odometry and sensor parameters for mobile robots"
(Censi, Franchi, Marchionni, Oriolo; IEEE T-RO 2013; github AndreaCensi/calibration,
``reference-output/``) hold, for three placements of the laser on one robot (``lstraight``,
``l90``, ``lmov``), one "tuple" per interval of about 0.8 s: its duration ``T``, the wheels' mean
angular speeds ``phi_l``, ``phi_r`` (rad/s) and the laser's scan-matched motion ``sm``
``(x, y, θ)`` in its own frame; ``<set>_results.json`` holds the authors' estimate of each set on
its own with its covariance (wheel radii, ``axle``, the laser's pose).

This script writes each set as nlp_calib reads any robot's data (a joint CSV of wheel increments
per cycle, ``form: increments`` in radians, and a motions file; the intervals laid end to end on
one clock), fits the three sets together with one laser mount each and the wheels shared, and
prints every estimate beside the authors', the difference in the authors' σ, in nlp_calib's own
and in the combined σ. Nothing of the data is kept in this repository: fetch the repository and
give its ``reference-output``::

    python3 benchmarks/censi_khepera.py /path/to/calibration/reference-output

``--own`` also fits each set on its own.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.logs.motions import format_motions
from nlp_calib.pipeline import Calibration, scenario_from_mapping

SETS = ("lstraight", "l90", "lmov")
#: The authors' parameters, in their covariance's order, as nlp_calib names them.
THEIRS = (
    ("left_wheel_radius", lambda r: r["l_diam"] / 2),
    ("right_wheel_radius", lambda r: r["r_diam"] / 2),
    ("wheel_separation", lambda r: r["axle"]),
    ("sensor_x", lambda r: r["l_x"]),
    ("sensor_y", lambda r: r["l_y"]),
    ("sensor_theta", lambda r: r["l_theta"]),
)
EPOCH_NS = 1_000_000_000_000_000_000


def tuples(path: Path) -> list[dict[str, Any]]:
    """Every tuple of a ``.tuple`` file (one JSON object each; some lines hold several)."""
    return [json.loads(o) for o in re.findall(r"\{[^{}]*\}", path.read_text())]


def write_set(folder: Path, name: str, rows: list[dict[str, Any]]) -> tuple[Path, Path]:
    """One set as a joint CSV (wheel increments per interval, rad) and a motions file."""
    T = np.array([r["T"] for r in rows])
    ends = EPOCH_NS + np.round(np.cumsum(T) * 1e9).astype(np.int64)
    starts = np.concatenate([[EPOCH_NS], ends[:-1]])
    stamps = np.concatenate([[EPOCH_NS], ends])
    turns = np.array([[r["phi_l"] * r["T"], r["phi_r"] * r["T"]] for r in rows])
    joints = folder / f"{name}.csv"
    motions = folder / f"{name}.motions.csv"
    joints.write_text(format_joint_csv(stamps, ("left", "right"), np.vstack([[0.0, 0.0], turns])))
    motions.write_text(format_motions(starts, ends, np.array([r["sm"] for r in rows])))
    return joints, motions


def entry(joints: Path, motions: Path) -> dict[str, Any]:
    return {
        "joints": str(joints),
        "motions": str(motions),
        "form": "increments",
        "encoders": {"left_wheel": "left", "right_wheel": "right"},
        "sensor_frame": "laser",
    }


SCENARIO: dict[str, Any] = {
    "model": "diff_drive",
    "initial_guess": "auto",
    "solvers": ["gauss_newton"],
    # Scan matching's noise: about a millimetre and a few milliradians per interval.
    "information": {"translation": 1.0e6, "rotation": 1.0e4},
    "robust": {"kernel": "huber", "delta": 3.0},
}


def compare(values: dict[str, float], std: dict[str, float], refs: dict[str, Any]) -> None:
    """Each estimate beside the authors' for each set: the difference in their σ, in ours (``σn``:
    is our value right within the σ we state?) and in the combined σ (``σc``: both in quadrature)."""
    print(
        f"{'set':<10}{'parameter':<20}{'nlp_calib':>12}{'1σ':>10}{'authors':>12}{'1σ':>10}{'Δ/σ':>7}"
        f"{'Δ/σn':>7}{'Δ/σc':>7}"
    )
    for s, ref in refs.items():
        for i, (name, theirs_of) in enumerate(THEIRS):
            key = name if name in values else f"{name}_{SETS.index(s) + 1}"
            mine, sd = values[key], std[key]
            theirs, their_sd = theirs_of(ref), float(np.sqrt(ref["covariance"][i][i]))
            d = mine - theirs
            print(
                f"{s:<10}{key:<20}{mine:>12.6g}{sd:>10.2g}{theirs:>12.6g}{their_sd:>10.2g}"
                f"{d / their_sd:>+7.1f}{d / sd:>+7.1f}{d / np.hypot(sd, their_sd):>+7.1f}"
            )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reference_output", type=Path)
    ap.add_argument("--out", type=Path, default=Path("/tmp/censi_khepera"))
    ap.add_argument("--own", action="store_true", help="also fit each set on its own")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    refs = {s: json.loads((args.reference_output / f"{s}_results.json").read_text()) for s in SETS}
    entries = [entry(*write_set(args.out, s, tuples(args.reference_output / f"{s}.tuple"))) for s in SETS]
    sc = scenario_from_mapping(
        {**SCENARIO, "datasets": entries, "sensor": {"mount": "planar", "mounts": "per_log"}},
        "censi",
        args.out,
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = Calibration(sc).run()
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    part = run.logs[0]
    report = part.reports["gauss_newton"]
    values, std = report.result.param_dict(), part.std("gauss_newton")
    print(f"joint fit of {len(SETS)} sets, {run.data.n_residuals} increments; verdict: {part.verdict.level}")
    for reason in part.verdict.reasons:
        print(f"  - {reason}")
    faults = sum(len(p.checks.findings.report.faults) for p in run.logs if p.checks.findings is not None)
    print(f"increments named and left out: {faults}")
    compare(values, std, refs)
    if args.own:
        for s, e in zip(SETS, entries):
            own = Calibration(scenario_from_mapping({**SCENARIO, "dataset": e}, s, args.out)).run()
            r = own.reports["gauss_newton"]
            print(f"\n{s} on its own: verdict {own.verdict.level}")
            for reason in own.verdict.reasons:
                print(f"  - {reason}")
            compare(r.result.param_dict(), own.std("gauss_newton"), {s: refs[s]})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
