"""A gyro beside a camera's 3-D poses (``sensor: {mount: 3d, beside: gyro}``): a TUM file, a joint
CSV and a gyro's CSV of one simulated drive fitted in one objective; every parameter within 3σ of
the truth on a seed never tuned on, the gyro's clock offset within 2 ms, and ``check`` reads the
run's calibration.yaml back."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import cli

from nlp_calib.pipeline import scenario_from_mapping
from nlp_calib.simulation.beside import simulate_camera_beside, write_camera_beside_simulation
from nlp_calib.simulation.camera import CameraNoise, CameraSimulationOptions
from nlp_calib.simulation.imu import ImuSimulationOptions

RADIANS = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}
ENCODERS = {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
FITTED = {"left_wheel_radius", "right_wheel_radius", "wheel_separation"}
FITTED |= {"sensor_x", "sensor_y", "sensor_roll", "sensor_pitch", "sensor_yaw"}
FITTED |= {"gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "imu_roll", "imu_pitch", "tracker_lag", "gyro_lag"}
#: A 5° roll; the camera stamps its images 20 ms late, the IMU's driver its rates 45 ms (two clocks).
ROLL, LATE, GYRO_LATE = float(np.radians(5.0)), 0.02, 0.045
#: 1 mm and 0.1° of noise a pose; a motion between two poses has twice its variance.
NOISE = CameraNoise(position=0.001, rotation=0.0017)
SCENARIO = {
    "model": "diff_drive",
    "sensor": {"mount": "3d", "beside": "gyro"},
    "known": {"sensor_z": 0.30},
    "initial_guess": "auto",
    "alignment": {"tracker_lag": "auto"},
    "information": {"translation": 5.0e5, "rotation": 1.7e5, "gyro": 1.0e8},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, float]]:
    """40 s of a camera (30 Hz) on a differential drive with a rolled IMU beside it (seed 43, never
    tuned on): the scenario and the truth."""
    folder = tmp_path_factory.mktemp("camera_gyro")
    camera = CameraSimulationOptions(
        duration_s=40.0, seed=43, image_rate_hz=30.0, stamp_offset_s=LATE, noise=NOISE
    )
    gyro = ImuSimulationOptions(seed=43, truth={"imu_roll": ROLL}, stamp_offset_s=GYRO_LATE)
    tum, joints, rates, truth_file = write_camera_beside_simulation(
        simulate_camera_beside(camera, gyro), folder / "drive.tum"
    )
    dataset = {"poses": str(tum), "joints": str(joints), "gyro": str(rates), "encoders": ENCODERS}
    scenario = folder / "camera_gyro.yaml"
    scenario.write_text(yaml.safe_dump({**SCENARIO, "dataset": dataset}))
    truth = {RADIANS.get(k, k): v for k, v in json.loads(truth_file.read_text())["params"].items()}
    return scenario, truth


def test_a_gyro_beside_a_cameras_poses_fits_within_3_sigma_and_check_reads_it_back(
    drive: tuple[Path, dict[str, float]], tmp_path: Path
) -> None:
    scenario, truth = drive
    out = tmp_path / "out"
    proc = cli("run", str(scenario), "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    stored = yaml.safe_load((out / "calibration.yaml").read_text())
    est, std = stored["parameters"], stored["std"]
    assert FITTED <= set(est)
    for name in sorted(FITTED):
        assert abs(est[name] - truth[name]) < 3 * std[name], (name, est[name], truth[name], std[name])
    assert abs(est["gyro_lag"] - GYRO_LATE) < 0.002
    # The camera's joint calibrated in all but its held height; the IMU's beside it, its tilt fitted.
    assert stored["beside"]["child"] == "imu_link"
    assert stored["beside"]["rpy"][0] == pytest.approx(est["imu_roll"])
    check = cli("check", str(out / "calibration.yaml"), str(scenario), cwd=tmp_path)
    assert check.returncode == 0, check.stdout + check.stderr
    assert "STILL GOOD" in check.stdout


def test_a_gyro_beside_a_planar_reference_reads_no_3d_motions(drive: tuple[Path, dict[str, float]]) -> None:
    """The same dataset with ``mount: planar`` reads the camera's levelled track, not its 3-D poses
    (the dataset's reading is the sensor's, set on load)."""
    scenario, _ = drive
    raw = yaml.safe_load(scenario.read_text())
    flat = {k: v for k, v in raw.items() if k != "known"}  # a planar mount has no height
    planar = scenario_from_mapping(
        {**flat, "sensor": {"mount": "planar", "beside": "gyro"}}, "s", scenario.parent
    )
    spatial = scenario_from_mapping(raw, "s", scenario.parent)
    assert not planar.log.source.in_3d  # type: ignore[attr-defined]
    assert spatial.log.source.in_3d  # type: ignore[attr-defined]
