"""The tracker lag as a parameter: is it right, and does every σ cover its error?

    python benchmarks/lag_study.py                    # seeds 100-119
    python benchmarks/lag_study.py --first 200 --seeds 5

Camera simulations (``simulate_camera``, 40 s, a differential drive, 1 mm and 0.1° of pose noise)
with unequal wheel radii (each within ±3 % of 0.1 m) and a stamp offset drawn in ±30 ms per seed,
run as a camera user writes the scenario (``docs/camera.md``: ``initial_guess: auto``, the lag
searched in ±50 ms). Prints per seed the lag's error, the verdict and the largest |estimate −
truth| in σ; then how many (parameter, seed) pairs lie within 1σ and 2σ of the truth (the lag
included), and how many runs ended with a mirrored answer (a negative radius). Nothing here tunes
anything: the seeds are whatever the arguments say.
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from nlp_calib import Calibration, load_scenario
from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.simulation.camera import (
    CameraNoise,
    CameraSimulationOptions,
    simulate_camera,
    write_camera_simulation,
)

#: |z| of each parameter by the white-noise σ alone and by the blocks' alone.
SPLIT: dict[str, list[float]] = {}
#: |z| of the lag itself, in the σ to believe.
LAG_Z: list[float] = []


def camera_doc(tum: Path) -> dict[str, Any]:
    """The scenario of docs/camera.md on ``tum`` and its joints, as a mapping."""
    return {
        "name": tum.stem,
        "model": "diff_drive",
        "sensor": "3d",
        "dataset": {
            "poses": str(tum),
            "joints": str(tum.with_suffix(".joints.csv")),
            "encoders": {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"},
        },
        "initial_guess": "auto",
        "known": {"sensor_z": 0.30},
        "alignment": {"tracker_lag": "auto", "search": [-0.05, 0.05]},
        "residual": {"horizon_s": 0.25},
        "information": {"translation": 1.0e6, "rotation": 3.0e5},
        "robust": {"kernel": "huber", "delta": 10.0},
        "solvers": ["gauss_newton"],
    }


def scenario(folder: Path, tum: Path) -> Path:
    """The scenario of docs/camera.md on ``tum`` and its joints, written to ``folder``."""
    path = folder / f"{tum.stem}.yaml"
    path.write_text(yaml.safe_dump(camera_doc(tum)))
    return path


def one(folder: Path, seed: int) -> tuple[list[float], float, str, bool]:
    """The run's |z| of every parameter with a truth, its lag error (s), verdict and mirror flag."""
    rng = np.random.default_rng(seed)
    lag = float(rng.uniform(-0.03, 0.03))
    truth = {n: 0.1 * (1.0 + float(rng.uniform(-0.03, 0.03))) for n in ("k_left", "k_right")}
    options = CameraSimulationOptions(
        model="diff_drive",
        duration_s=40.0,
        seed=seed,
        stamp_offset_s=lag,
        truth=truth,
        noise=CameraNoise(0.001, 0.0017),
    )
    tum, _, _ = write_camera_simulation(simulate_camera(options), folder / f"cam{seed}.tum")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NlpCalibWarning)
        run = Calibration.setup(load_scenario(scenario(folder, tum))).run(["gauss_newton"])
    check = run.checks.truth
    params = run.reports["gauss_newton"].result.param_dict()
    mirrored = any(params[n] < 0 for n in ("left_wheel_radius", "right_wheel_radius"))
    if check is None:
        return [], float("nan"), run.verdict.level, mirrored
    zs = [float(abs(z)) for z in check.z if np.isfinite(z)]
    lag_error = float(dict(zip(check.names, check.error)).get("tracker_lag", np.nan))
    LAG_Z.append(float(abs(dict(zip(check.names, check.z)).get("tracker_lag", np.nan))))
    report, cv = run.reports["gauss_newton"], run.checks.crossval
    for label, std in (("white", report.uncertainty.std), ("blocks", cv.std if cv is not None else None)):
        if std is not None:
            sd = dict(zip(report.uncertainty.names, std))
            z = [
                abs(e) / sd[n]
                for n, e in zip(check.names, check.error)
                if sd.get(n, 0) > 0 and np.isfinite(e)
            ]
            SPLIT.setdefault(label, []).extend(z)
    return zs, lag_error, run.verdict.level, mirrored


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first", type=int, default=100)
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args()
    all_z: list[float] = []
    mirrors = 0
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.first, args.first + args.seeds):
            zs, lag_error, level, mirrored = one(Path(tmp), seed)
            all_z += zs
            mirrors += mirrored
            worst = max(zs, default=float("nan"))
            print(
                f"seed {seed}: lag error {1e3 * lag_error:+.2f} ms, {level}, worst |z| {worst:.2f}",
                flush=True,
            )
    z = np.array(all_z)
    for label, values in SPLIT.items():
        v = np.array(values)
        print(f"by the {label} σ alone: {np.mean(v <= 1):.3f} within 1σ, {np.mean(v <= 2):.3f} within 2σ")
    lz = np.array(LAG_Z)
    print(
        f"the lag alone: {np.mean(lz <= 1):.3f} within 1σ, {np.mean(lz <= 2):.3f} within 2σ ({lz.size} seeds)"
    )
    print(
        f"coverage: {np.mean(z <= 1):.3f} within 1σ, {np.mean(z <= 2):.3f} within 2σ, {np.mean(z <= 3):.3f} "
        f"within 3σ ({z.size} parameter-seed pairs); mirrored answers {mirrors}/{args.seeds}"
    )


if __name__ == "__main__":
    main()
