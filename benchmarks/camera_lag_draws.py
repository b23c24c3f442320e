"""The camera's clock offset beside a gyro: is it the camera's alone, is it biased, how do its noise's
draws scatter?

Each seed's drive is docs/imu.md's ``camera_gyro.sim.yaml`` (40 s of 30 Hz images, the camera and
the gyro stamped 20 ms late), fitted with its ``camera_gyro.yaml`` (``--alone``: by the camera
alone, ``sensor: 3d`` without the gyro). ``--scale S`` multiplies the poses' noise the simulator
drew by ``S`` (the information by ``1/S²``, so the kernel sees the same residuals), ``--flip``
turns its sign round, ``--draws N`` replaces it by ``N`` other draws of the same noise. Each fit's
offset error (ms), its white-noise σ and σ to believe, and its z; at the end the errors' mean and
spread and the z's::

    nice -n 10 python3 benchmarks/camera_lag_draws.py --seeds 901 902 903 --beside
    nice -n 10 python3 benchmarks/camera_lag_draws.py --seeds 912 924 919 901 --scale 0.01
    nice -n 10 python3 benchmarks/camera_lag_draws.py --seeds 912 --flip
    nice -n 10 python3 benchmarks/camera_lag_draws.py --seeds 912 --draws 12
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

#: This checkout (its code, not an installed one's, is what runs).
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from nlp_calib.core import poses3d  # noqa: E402
from nlp_calib.simulation.beside import simulate_camera_beside, write_camera_beside_simulation  # noqa: E402
from nlp_calib.simulation.camera import CameraNoise, CameraSimulationOptions  # noqa: E402
from nlp_calib.simulation.imu import ImuSimulationOptions  # noqa: E402

LAG_S = 0.02
NOISE = CameraNoise(position=0.001, rotation=0.0017)
INFORMATION = {"translation": 5.0e5, "rotation": 1.7e5}


def _scenario(folder: Path, alone: bool, scale: float) -> Path:
    """docs/imu.md's camera_gyro.yaml on the files in ``folder`` (``alone``: the camera's own)."""
    dataset: dict[str, Any] = {
        "poses": str(folder / "d.tum"),
        "joints": str(folder / "d.joints.csv"),
        "encoders": {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"},
    }
    information = {k: v / scale**2 for k, v in INFORMATION.items()}
    sensor: Any = "3d" if alone else {"mount": "3d", "beside": "gyro"}
    if not alone:
        dataset["gyro"] = str(folder / "d.gyro.csv")
        information["gyro"] = 1.0e8
    raw = {
        "name": "camera_lag", "model": "diff_drive", "sensor": sensor, "dataset": dataset,
        "known": {"sensor_z": 0.30}, "initial_guess": "auto", "alignment": {"tracker_lag": "auto"},
        "information": information, "robust": {"kernel": "huber", "delta": 3.0}, "solvers": ["gauss_newton"],
    }  # fmt: skip
    path = folder / ("alone.yaml" if alone else "beside.yaml")
    path.write_text(yaml.safe_dump(raw))
    return path


def _fit(scenario: Path) -> tuple[float, float, float]:
    """The offset's error (s), white-noise σ and σ to believe of one run."""
    out = scenario.with_suffix("")
    cmd = [sys.executable, "-m", "nlp_calib", "run", str(scenario), "--out", str(out), "--force"]
    run = subprocess.run(cmd, capture_output=True, text=True, check=False, cwd=REPO)
    assert run.returncode == 0, run.stdout + run.stderr
    fit = json.loads((out / "result.json").read_text())["solvers"]["gauss_newton"]
    return (
        fit["params"]["tracker_lag"] - LAG_S,
        fit["std_white_noise"]["tracker_lag"],
        fit["std"]["tracker_lag"],
    )


def _noise(noisy: np.ndarray, clean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The poses' noise as the simulator drew it: position (world frame), rotation on the right."""
    turn = poses3d.quat_multiply(poses3d.quat_conjugate(clean[:, 3:]), noisy[:, 3:])
    return noisy[:, :3] - clean[:, :3], poses3d.quat_to_rotvec(turn)


def _noisy(clean: np.ndarray, position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    out = clean.copy()
    out[:, :3] += position
    out[:, 3:] = poses3d.quat_multiply(clean[:, 3:], poses3d.rotvec_to_quat(rotation))
    return out


def one_seed(seed: int, args: argparse.Namespace, folder: Path) -> list[tuple[str, float, float, float]]:
    """Each fit's label, offset error, white-noise σ and σ to believe on ``seed``'s drive."""
    options = CameraSimulationOptions(
        model="diff_drive", duration_s=40.0, seed=seed, stamp_offset_s=LAG_S, image_rate_hz=30.0, noise=NOISE
    )
    imu = ImuSimulationOptions(seed=seed, stamp_offset_s=LAG_S)
    sim = simulate_camera_beside(options, imu)
    clean = simulate_camera_beside(dataclasses.replace(options, noise=CameraNoise()), imu).camera.camera_poses
    position, rotation = _noise(sim.camera.camera_poses, clean)
    rng = np.random.default_rng([seed, 77])
    draws = [("own", position, rotation)]
    if args.flip:
        draws.append(("flipped", -position, -rotation))
    for j in range(args.draws):
        n = clean.shape[0]
        draws.append(
            (f"draw {j}", rng.normal(0.0, NOISE.position, (n, 3)), rng.normal(0.0, NOISE.rotation, (n, 3)))
        )
    fits = []
    for label, p, r in draws:
        camera = dataclasses.replace(sim.camera, camera_poses=_noisy(clean, args.scale * p, args.scale * r))
        write_camera_beside_simulation(dataclasses.replace(sim, camera=camera), folder / "d.tum")
        kinds = (
            [("beside", False), ("alone", True)]
            if args.beside
            else [("alone" if args.alone else "beside", args.alone)]
        )
        for kind, alone in kinds:
            fits.append((f"{label} {kind}", *_fit(_scenario(folder, alone, args.scale))))
    return fits


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="+", default=[901])
    ap.add_argument("--alone", action="store_true", help="the camera alone, without the gyro")
    ap.add_argument("--beside", action="store_true", help="both: beside the gyro and the camera alone")
    ap.add_argument("--scale", type=float, default=1.0, help="the poses' noise times this")
    ap.add_argument("--flip", action="store_true", help="also the noise with its sign turned round")
    ap.add_argument("--draws", type=int, default=0, help="other draws of the poses' noise on each drive")
    args = ap.parse_args()
    z, errors = [], []
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            for label, error, white, std in one_seed(seed, args, Path(tmp)):
                ms = f"{1e3 * error:+8.4f} ms  white σ {1e3 * white:.4f}  σ {1e3 * std:.4f}"
                print(f"{seed:5d} {label:16s} {ms}  z {error / std:+.2f}", flush=True)
                z.append(error / std)
                errors.append(1e3 * error)
    e, zz = np.array(errors), np.array(z)
    spread = e.std(ddof=1) if e.size > 1 else 0.0
    within = [f"{np.mean(np.abs(zz) <= k):.0%} within {k}σ" for k in (1, 2)]
    print(
        f"{e.size} fits: error {e.mean():+.3f} ms mean, {spread:.3f} ms spread; z mean {zz.mean():+.2f}, "
        f"rms {np.sqrt(np.mean(zz**2)):.2f}, " + ", ".join(within)
    )


if __name__ == "__main__":
    main()
