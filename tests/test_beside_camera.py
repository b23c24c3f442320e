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
from nlp_calib.pipeline.draft import TILTED_RAD, draft, turn_axis_tilt
from nlp_calib.pipeline.recording import recording
from nlp_calib.sensors import sensor_for
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


@pytest.fixture(scope="module")
def ran(drive: tuple[Path, dict[str, float]]) -> Path:
    """The run's output folder (beside the drive's files)."""
    scenario, _ = drive
    out = scenario.parent / "out"
    proc = cli("run", str(scenario), "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out


def test_a_gyro_beside_a_cameras_poses_fits_within_3_sigma_and_check_reads_it_back(
    drive: tuple[Path, dict[str, float]], ran: Path, tmp_path: Path
) -> None:
    scenario, truth = drive
    out = ran
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


def test_each_of_the_gyros_axes_carries_its_own_noise_beside_a_camera(ran: Path) -> None:
    """A gyro's increment beside a camera holds its noise on its three integrated rates (after the
    camera's seven rows: its third had fallen on its duration, so ∫ω_z's noise was left out and
    gyro_bias_z's white-noise σ was 600 times gyro_bias_x's too small, gyro_lag's 27 times)."""
    gn = json.loads((ran / "result.json").read_text())["solvers"]["gauss_newton"]
    white, angle = gn["std_white_noise"], gn["noise"]["gyro_angle"]
    # Each bias from its own axis's windows alone: σ_angle / √(Σ Δt²), 0.1 s intervals over 40 s.
    alone = angle / np.sqrt(400 * 0.1**2)
    for axis in "xyz":
        assert white[f"gyro_bias_{axis}"] == pytest.approx(alone, rel=0.15), axis
    assert sensor_for("3d_gyro").increment_noise_rows == (0, 1, 2, 3, 4, 5, 7, 8, 9)
    assert sensor_for("planar_gyro").increment_noise_rows == (0, 1, 2, 3, 4, 5)


def test_init_drafts_a_cameras_poses_beside_its_gyro_and_the_preflight_says_what_each_determines(
    drive: tuple[Path, dict[str, float]], tmp_path: Path
) -> None:
    """``init`` on the camera's TUM file: its poses turn about an axis 60° from their z (the
    camera's roll of −120°), so ``sensor: 3d``, with the gyro's CSV beside them; its height left as
    a commented line; the pre-flight's record of the recording says what each sensor determines."""
    scenario, _ = drive
    tum = scenario.parent / "drive.tum"
    assert turn_axis_tilt(tum) == pytest.approx(np.radians(60.0), abs=0.05)
    d = draft(tum, tmp_path / "drive.yaml")
    assert d.raw["sensor"] == {"mount": "3d", "beside": "gyro"}
    assert Path(d.raw["dataset"]["gyro"]).name == "drive.gyro.csv"
    assert "# known: {sensor_z: <metres>}" in d.text
    sc = scenario_from_mapping(yaml.safe_load(scenario.read_text()), "s", scenario.parent)
    rec = recording(sc, sc.log.source.read(sc.model_form(), strict=True))
    (said,) = [n for n in rec.notes if n.startswith("sensors: ")]
    assert "its mount (sensor_x, sensor_y, sensor_roll, sensor_pitch, sensor_yaw)" in said
    assert "its clock offset (gyro_lag)" in said and "sensor_z is held" in said


def test_a_level_trackers_tum_poses_are_drafted_planar(tmp_path: Path) -> None:
    """A tracker's level poses turn about their own z: no camera (a tilt below TILTED_RAD)."""
    t = np.arange(0.0, 20.0, 0.05)
    yaw = 0.6 * np.sin(0.5 * t)
    rows = [
        f"{s:.3f} {np.cos(y):.6f} {np.sin(y):.6f} 0.1 0 0 {np.sin(y / 2):.9f} {np.cos(y / 2):.9f}"
        for s, y in zip(1.7e9 + t, yaw)
    ]
    (tmp_path / "level.tum").write_text("\n".join(rows) + "\n")
    tilt = turn_axis_tilt(tmp_path / "level.tum")
    assert tilt is not None and tilt < 0.01 < TILTED_RAD
