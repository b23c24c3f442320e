"""Does every time offset's σ cover its error? One function per reference kind, a z per log.

    nice -n 10 python3 benchmarks/lag_coverage.py --first 700 --seeds 3          # study set
    nice -n 10 python3 benchmarks/lag_coverage.py --first 800 --seeds 3          # confirmation set
    nice -n 10 python3 benchmarks/lag_coverage.py --kinds camera lidar --first 700 --seeds 2
    nice -n 10 python3 benchmarks/lag_coverage.py --kinds tracker --first 900 --seeds 16 --noise-scale 0.1

Kinds: ``tracker`` (a simulated text log of each of ``--models``: s-curves, the tracker's stamps
late by 0–30 ms, the scenario a user writes first with ``tracker_lag: auto``), ``camera`` (a
camera's TUM file and joints, 40 s, stamps off by ±30 ms, ``docs/camera.md``'s scenario),
``lidar`` (a bag of scans, 40 s, stamps 0–30 ms late, the lidar scenario of ``docs/lidar.md``),
``beside`` (a gyro beside that lidar, its own clock 0–60 ms late: ``tracker_lag`` and
``gyro_lag`` both), ``tracker_gyro`` and ``camera_gyro`` (the gyro beside a tracker's poses or a
camera's, ``docs/imu.md``'s scenarios). Each log's every fitted offset: the error, the white-noise
σ, the block jackknife σ and the σ to believe (``run.std``), its z; at the end the share within 1σ
and 2σ and the RMS z, overall and by the white σ alone. Nothing here tunes anything: the seeds are
whatever the arguments say.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

#: This checkout (its code, not an installed one's, is what runs).
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from nlp_calib import Calibration, scenario_from_mapping  # noqa: E402
from nlp_calib.results import CalibrationRun  # noqa: E402
from nlp_calib.simulation import SimulationOptions, simulate_to_file  # noqa: E402
from nlp_calib.simulation.camera import (  # noqa: E402
    CameraNoise,
    CameraSimulationOptions,
    simulate_camera,
    write_camera_simulation,
)
from nlp_calib.simulation.options import DriveShape, TrackerSim  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lag_study import camera_doc  # noqa: E402

#: Each row: label, offset's name, error (s), white σ, block σ (NaN: none), σ to believe.
Row = tuple[str, str, float, float, float, float]
LAGS = ("tracker_lag", "gyro_lag")
#: ``--every-model``: every model on each seed's drive (as ``gate_study.py`` does), to show that
#: such logs are not independent draws.
EVERY_MODEL = False
#: ``--noise-scale``: the text logs' tracker noise in the simulator's (0.1: a tracker ten times
#: finer, where the re-sampling's bias across a start from rest is as large as the lag's σ).
NOISE_SCALE = 1.0


def _run(doc: dict[str, Any], name: str, folder: Path) -> CalibrationRun:
    sc = scenario_from_mapping(doc, name, folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Calibration(sc).run(["gauss_newton"])


def _rows(run: CalibrationRun, label: str, truth: dict[str, float]) -> list[Row]:
    report = run.reports["gauss_newton"]
    est = report.result.param_dict()
    white = dict(zip(report.uncertainty.names, map(float, report.uncertainty.std)))
    blocks = run.std_blocks() or {}
    told = run.std("gauss_newton")
    return [
        (label, n, est[n] - truth[n], white[n], blocks.get(n, float("nan")), told[n])
        for n in LAGS
        if n in truth and n in est and n in report.uncertainty.free
    ]


def tracker(folder: Path, seed: int, models: list[str]) -> list[Row]:
    """A text log of one of ``models`` (in turn by seed: one seed's models would share its drive and
    noise, their z one draw), the tracker 0–30 ms late."""
    out: list[Row] = []
    lag = float(np.random.default_rng(seed).uniform(0.0, 0.03))
    for model in models if EVERY_MODEL else models[seed % len(models) : seed % len(models) + 1]:
        opts = SimulationOptions(
            seed=seed,
            model=model,
            drive=DriveShape(trajectory="s_curves"),
            tracker=TrackerSim(
                latency_s=lag,
                tracker_noise_xy=NOISE_SCALE * TrackerSim().tracker_noise_xy,
                tracker_noise_theta=NOISE_SCALE * TrackerSim().tracker_noise_theta,
            ),
        )
        log, _ = simulate_to_file(opts, folder / f"{model}_{seed}.txt")
        doc: dict[str, Any] = {"dataset": str(log), "model": model, "initial_guess": "from_file"}
        doc |= {"solvers": ["gauss_newton"], "alignment": {"tracker_lag": "auto"}}
        run = _run(doc, f"{model}_{seed}", folder)
        out += _rows(run, f"{model} {seed}", {"tracker_lag": lag})
    return out


def camera(folder: Path, seed: int, models: list[str]) -> list[Row]:
    """``docs/camera.md``'s scenario on a simulated camera, stamps off by ±30 ms."""
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
    doc = camera_doc(tum)
    return _rows(_run(doc, f"cam{seed}", folder), f"camera {seed}", {"tracker_lag": lag})


LIDAR: dict[str, Any] = {
    "model": "diff_drive",
    "initial_guess": "auto",
    "information": {"translation": 1.0e6, "rotation": 1.0e5},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}
JOINTS = {"joint_states": "/joint_states", "joints": ["left_wheel_joint", "right_wheel_joint"]}


def lidar(folder: Path, seed: int, models: list[str]) -> list[Row]:
    """The lidar scenario of ``docs/lidar.md`` on a simulated bag, the scans 0–30 ms late."""
    from nlp_calib.simulation.lidar import LidarSimulationOptions, simulate_lidar, write_lidar_simulation

    late = float(np.random.default_rng(seed).uniform(0.0, 0.03))
    sim = simulate_lidar(LidarSimulationOptions(duration_s=40.0, seed=seed, stamp_offset_s=late))
    bag, _ = write_lidar_simulation(sim, folder / f"lidar_{seed}")
    doc = {**LIDAR, "dataset": {"bag": str(bag), **JOINTS, "scan": "/scan"}}
    return _rows(_run(doc, f"lidar_{seed}", folder), f"lidar {seed}", {"tracker_lag": late})


def beside(folder: Path, seed: int, models: list[str]) -> list[Row]:
    """A gyro beside the lidar, each on its own clock (as ``tests/test_beside.py`` writes it)."""
    from nlp_calib.simulation.beside import simulate_beside, write_beside_simulation
    from nlp_calib.simulation.imu import ImuSimulationOptions
    from nlp_calib.simulation.lidar import LidarSimulationOptions

    rng = np.random.default_rng(seed)
    late, gyro_late = float(rng.uniform(0.0, 0.03)), float(rng.uniform(0.0, 0.06))
    lid = LidarSimulationOptions(duration_s=30.0, seed=seed, stamp_offset_s=late)
    gyro = ImuSimulationOptions(seed=seed, truth={"imu_roll": 0.0873}, stamp_offset_s=gyro_late)
    bag, truth_file = write_beside_simulation(simulate_beside(lid, gyro), folder / f"beside_{seed}")
    truth = json.loads(truth_file.read_text())["params"]
    doc = {
        **LIDAR,
        "sensor": {"mount": "planar", "beside": "gyro"},
        "alignment": {"tracker_lag": "auto"},
        "information": {"translation": 1.0e6, "rotation": 1.0e5, "gyro": 1.0e8},
        "dataset": {"bag": str(bag), **JOINTS, "scan": "/scan", "imu": "/imu"},
    }
    lags = {n: float(truth.get(n, v)) for n, v in (("tracker_lag", late), ("gyro_lag", gyro_late))}
    return _rows(_run(doc, f"beside_{seed}", folder), f"beside {seed}", lags)


def _gyro_lags(seed: int) -> tuple[float, float, Any]:
    """A reference 0–30 ms late, a gyro 0–60 ms (its own clock), a 5° rolled IMU's options."""
    from nlp_calib.simulation.imu import ImuSimulationOptions

    rng = np.random.default_rng(seed)
    late, gyro_late = float(rng.uniform(0.0, 0.03)), float(rng.uniform(0.0, 0.06))
    return (
        late,
        gyro_late,
        ImuSimulationOptions(seed=seed, truth={"imu_roll": 0.0873}, stamp_offset_s=gyro_late),
    )


def _gyro_rows(doc: dict[str, Any], name: str, folder: Path, truth_file: Path, label: str) -> list[Row]:
    truth = json.loads(truth_file.read_text())["params"]
    return _rows(_run(doc, name, folder), label, {n: float(truth[n]) for n in LAGS})


def tracker_gyro(folder: Path, seed: int, models: list[str]) -> list[Row]:
    """A gyro beside a tracker's poses (``docs/imu.md``'s scenario), each on its own clock."""
    from nlp_calib.simulation.beside import simulate_beside, write_beside_simulation
    from nlp_calib.simulation.lidar import LidarSimulationOptions

    late, _, gyro = _gyro_lags(seed)
    lid = LidarSimulationOptions(duration_s=30.0, seed=seed, stamp_offset_s=late)
    bag, truth = write_beside_simulation(simulate_beside(lid, gyro), folder / f"tg_{seed}", tracker=True)
    doc = {
        **LIDAR,
        "sensor": {"mount": "planar", "beside": "gyro"},
        "alignment": {"tracker_lag": "auto"},
        "information": {"translation": 1.25e5, "rotation": 1.25e5, "gyro": 1.0e8},
        "dataset": {"bag": str(bag), **JOINTS, "tracker": "/tracker", "imu": "/imu"},
    }
    return _gyro_rows(doc, f"tg_{seed}", folder, truth, f"tracker+gyro {seed}")


def camera_gyro(folder: Path, seed: int, models: list[str]) -> list[Row]:
    """A gyro beside a camera's TUM poses (``docs/imu.md``'s scenario), each on its own clock."""
    from nlp_calib.simulation.beside import simulate_camera_beside, write_camera_beside_simulation

    late, _, gyro = _gyro_lags(seed)
    options = CameraSimulationOptions(
        duration_s=40.0, seed=seed, image_rate_hz=30.0, stamp_offset_s=late, noise=CameraNoise(0.001, 0.0017)
    )
    tum, joints, rates, truth = write_camera_beside_simulation(
        simulate_camera_beside(options, gyro), folder / f"cg{seed}.tum"
    )
    encoders = {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
    doc = {
        **LIDAR,
        "sensor": {"mount": "3d", "beside": "gyro"},
        "known": {"sensor_z": 0.30},
        "alignment": {"tracker_lag": "auto"},
        "information": {"translation": 5.0e5, "rotation": 1.7e5, "gyro": 1.0e8},
        "dataset": {"poses": str(tum), "joints": str(joints), "gyro": str(rates), "encoders": encoders},
    }
    return _gyro_rows(doc, f"cg{seed}", folder, truth, f"camera+gyro {seed}")


KINDS: dict[str, Callable[[Path, int, list[str]], list[Row]]] = {
    "tracker": tracker,
    "camera": camera,
    "lidar": lidar,
    "beside": beside,
    "tracker_gyro": tracker_gyro,
    "camera_gyro": camera_gyro,
}


def summary(label: str, z: np.ndarray) -> str:
    """The share of ``|z|`` within 1σ and 2σ and the RMS z."""
    return (
        f"{label}: {np.mean(z <= 1):.3f} within 1σ, {np.mean(z <= 2):.3f} within 2σ, "
        f"RMS z {np.sqrt(np.mean(z**2)):.2f} ({z.size} offsets)"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=700)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=list(KINDS))
    ap.add_argument("--models", nargs="+", default=["tricycle", "diff_drive", "car_like", "skid_steer"])
    ap.add_argument("--every-model", action="store_true", help="tracker: every model on each seed")
    ap.add_argument("--noise-scale", type=float, default=1.0, help="tracker: its noise, in the simulator's")
    args = ap.parse_args()
    global EVERY_MODEL, NOISE_SCALE
    EVERY_MODEL, NOISE_SCALE = args.every_model, args.noise_scale
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds:
            for seed in range(args.first, args.first + args.seeds):
                for row in KINDS[kind](Path(tmp), seed, args.models):
                    label, name, e, white, blocks, told = row
                    print(
                        f"{label:22s} {name:11s} error {1e3 * e:+7.2f} ms  σ white {1e3 * white:5.2f} "
                        f"blocks {1e3 * blocks:5.2f} told {1e3 * told:5.2f} ms  z {e / told:+6.2f}",
                        flush=True,
                    )
                    rows.append(row)
    err = np.array([r[2] for r in rows])
    print(summary("the σ to believe", np.abs(err / np.array([r[5] for r in rows]))))
    print(summary("the white σ alone", np.abs(err / np.array([r[3] for r in rows]))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
