"""Is the odometry's noise the drift its windows truly have, on real vehicles' drives (#43)?

    nice -n 10 python3 benchmarks/vehicle_noise.py --car 5 6 7 --skid 5 6 7

For each simulated highway car (given what a straight kilometre cannot determine, as
``tests/test_vehicles.py`` gives it) and fast-spinning skid-steer (pivot slip 0.1 unless
``--pivot-slip`` says) of the seeds the arguments name: every σ the run hands off, from the one
noise model, over the σ whose 2σ holds 95 % of the true errors, per component (x, y, θ in the base
frame at the span's start) and together: 1 where the σ is the drift the spans truly have. Rows:
``pose``, ros2_control.yaml's pose diagonal against every metre driven; ``twist``, its twist
diagonal (vx, wz; vy is not stated) against every moving interval; ``pose_all``, the pose
diagonal against every metre driven, the metres through a fault included (``pose`` leaves them out,
and so does the diagonal: a population it does not claim, the slipped pivots' drift is stated apart
as calibration.yaml's ``slipped_pivots``); ``pivots_all``, every metre too, against the rates
grown over each metre as a filter grows them at the joints' samples it integrates, with that
slipped pivots' heading variance per radian on every radian the base turns on the spot;
``rates``, calibration.yaml's rates per metre and per radian grown as a filter grows them
(``nlp-calib odometry``'s covariance) over the fit's windows. A case with no hand-off (no
converged solver) has no pose or twist row. Nothing here tunes anything: the seeds are whatever
the arguments say.

With ``--sigmas``, each case's parameters instead: each estimate's error over its σ to believe
(``run.std``; the truth is the simulator's), and over all the cases how many lie within 1σ and 2σ,
per parameter and together (parameters given as known, with no σ, are not counted). With
``--together K`` as well, the skid-steer seeds are fitted K consecutive ones at a time (a
``datasets:`` scenario each) and each joint estimate is scored so:

    nice -n 10 python3 benchmarks/vehicle_noise.py --sigmas --together 3 --skid 101 102 103
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np

#: This checkout (its code, not an installed one's, is what runs), and the tests' truth helper.
REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]

from odometry_truth import sigma_over_truth  # noqa: E402

from nlp_calib.pipeline import Calibration, scenario_from_mapping  # noqa: E402
from nlp_calib.pipeline.analyse import Wanted  # noqa: E402
from nlp_calib.simulation.vehicles import (  # noqa: E402
    EPOCH_NS,
    HighwayOptions,
    SkidSpinOptions,
    simulate_highway,
    simulate_skid_spins,
)

CAR_NAMES = {"k_traction": "traction_wheels_radius", "rear_track": "traction_track_width"}
#: Each vehicle's truth in the joint form's names (the simulators' defaults; no seed changes them).
TRUTH = {
    "car": {CAR_NAMES.get(n, n): v for n, v in HighwayOptions().truth.items()},
    "skid": {
        {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}.get(
            n, n
        ): v
        for n, v in SkidSpinOptions().truth.items()
    },
}
CAR_KNOWN = ("k_steer", "wheelbase", "rear_track", "sensor_x", "sensor_y")
SKID = {
    "model": "skid_steer",
    "initial_guess": "auto",
    "information": {"translation": 4.0e4, "rotation": 1.0e5},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}


def _car(folder: Path, seed: int, _: float) -> tuple[Any, Any, tuple[np.ndarray, np.ndarray, int]]:
    opts = HighwayOptions(seed=seed)
    sim = simulate_highway(opts)
    joints, poses, _truth = sim.write(folder / "car")
    wheels = ("steering", "rear_left_wheel", "rear_right_wheel")
    known = {CAR_NAMES.get(n, n): opts.truth[n] for n in CAR_KNOWN}
    dataset = {
        "joints": str(joints),
        "poses": str(poses),
        "form": "speeds",
        "encoders": dict(zip(wheels, wheels)),
    }
    sc = {"model": "car_like", "initial_guess": "auto", "solvers": ["gauss_newton"], "dataset": dataset}
    return (
        scenario_from_mapping({**sc, "known": known}, "car", folder),
        None,
        (sim.joint_time_s, sim.base_poses, EPOCH_NS),
    )


def _skid_drive(folder: Path, seed: int, pivot_slip: float) -> tuple[dict[str, Any], Any]:
    """A simulated skid-steer drive's ``dataset:`` entry, and the simulation."""
    sim = simulate_skid_spins(SkidSpinOptions(duration_s=240.0, seed=seed, pivot_slip=pivot_slip))
    joints, motions, _ = sim.write(folder / f"skid{seed}")
    encoders = {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
    return {"joints": str(joints), "motions": str(motions), "encoders": encoders}, sim


def _skid(folder: Path, seed: int, pivot_slip: float) -> tuple[Any, Any, tuple[np.ndarray, np.ndarray, int]]:
    dataset, sim = _skid_drive(folder, seed, pivot_slip)
    sc = scenario_from_mapping({**SKID, "dataset": dataset}, "skid", folder)
    return sc, Wanted(odometry="gauss_newton"), (sim.joint_time_s, sim.base_poses, EPOCH_NS)


def _together(seeds: list[int], k: int, pivot_slip: float, errors: dict[str, list[float]]) -> None:
    """The skid-steer seeds fitted ``k`` at a time (consecutive ones), each group one ``datasets:``
    scenario: each joint estimate's errors in its σ to believe (:func:`_sigmas`)."""
    for i in range(0, len(seeds) - k + 1, k):
        group = seeds[i : i + k]
        with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            entries = [_skid_drive(Path(tmp), seed, pivot_slip)[0] for seed in group]
            sc = scenario_from_mapping({**SKID, "datasets": entries}, "skid", Path(tmp))
            run = Calibration(sc).run()
        _sigmas("skid " + "+".join(map(str, group)), run, TRUTH["skid"], errors)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--car", type=int, nargs="*", default=[], help="highway car seeds")
    ap.add_argument("--skid", type=int, nargs="*", default=[], help="skid-steer seeds")
    ap.add_argument("--pivot-slip", type=float, default=0.1, help="the skid-steer's slip on pivots")
    ap.add_argument(
        "--multiples",
        type=int,
        nargs="*",
        default=[1],
        help="the rates also over these multiples of the fit's windows",
    )
    ap.add_argument("--sigmas", action="store_true", help="the parameters' errors in their σ instead")
    ap.add_argument(
        "--together",
        type=int,
        default=0,
        help="with --sigmas: the skid-steer seeds fitted this many at a time (one datasets: scenario)",
    )
    args = ap.parse_args()
    if args.together:
        errors_together: dict[str, list[float]] = {}
        _together(args.skid, args.together, args.pivot_slip, errors_together)
        _coverage(errors_together)
        return
    if not args.sigmas:
        print("case      way     x      y      θ      together   (σ over the σ holding 95 % of true errors)")
    errors: dict[str, list[float]] = {}
    for kind, build, seeds in (("car", _car, args.car), ("skid", _skid, args.skid)):
        for seed in seeds:
            with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sc, wanted, truth = build(Path(tmp), seed, args.pivot_slip)
                calib = Calibration(sc)
                run = calib.run(wanted=wanted) if wanted else calib.run()
                if args.sigmas:
                    _sigmas(f"{kind} {seed:<4d}", run, TRUTH[kind], errors)
                    continue
                found = sigma_over_truth(calib, run, truth, tuple(args.multiples), every_metre=True)
            for (way, length), r in found.items():
                label = f"{way} {length}" if way == "rates" and len(args.multiples) > 1 else way
                print(
                    f"{kind} {seed:<4d} {label:8s} "
                    + " ".join(f"{v:6.2f}" for v in r[:3])
                    + f"   {r[3]:6.2f}"
                )
    if errors:
        _coverage(errors)


def _sigmas(case: str, run: Any, truth: dict[str, float], errors: dict[str, list[float]]) -> None:
    """One case's errors in their σ to believe, printed and kept in ``errors`` by parameter."""
    solver = run.chosen_solver()
    if solver is None:
        print(f"{case} no converged solver")
        return
    estimate, std = run.reports[solver].result.param_dict(), run.std(solver)
    pivots = run.checks.pivots
    # A value given as known has σ 0 (exact by declaration): not counted, as the docstring says.
    stated = {n: std.get(n, np.nan) for n in truth}
    row = {
        n: (estimate[n] - v) / stated[n] for n, v in truth.items() if np.isfinite(stated[n]) and stated[n] > 0
    }
    for n, z in row.items():
        errors.setdefault(n, []).append(z)
    count = len(pivots.pivots) if pivots is not None else 0
    print(
        f"{case} {run.verdict.level:22s} pivots {count:3d}  "
        + "  ".join(f"{n} {z:+.2f}" for n, z in row.items())
    )


def _coverage(errors: dict[str, list[float]]) -> None:
    every = np.abs(np.concatenate([np.array(v) for v in errors.values()]))
    print(f"within 1σ {np.mean(every < 1):.0%}, within 2σ {np.mean(every < 2):.0%} of {every.size} estimates")
    for n, v in errors.items():
        z = np.abs(np.array(v))
        print(f"  {n:24s} within 1σ {np.mean(z < 1):4.0%}  2σ {np.mean(z < 2):4.0%}  largest {z.max():.1f}σ")


if __name__ == "__main__":
    main()
