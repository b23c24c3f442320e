"""A gyro beside a lidar: one simulated drive, one bag of scans and rates; both sensors' residuals in
one objective. The lengths a gyro alone leaves NOT DETERMINED are determined beside the lidar, every
parameter lands within 3σ of the truth, and ``check`` reads the run's calibration.yaml back."""

from __future__ import annotations

import json
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import cli

from nlp_calib import Calibration
from nlp_calib.core.errors import ConfigError
from nlp_calib.logs import resample_encoders
from nlp_calib.pipeline import scenario_from_mapping
from nlp_calib.pipeline.preflight import preflight
from nlp_calib.pipeline.prepare import read
from nlp_calib.results.preflight import NOT_DETERMINED
from nlp_calib.simulation.beside import simulate_beside, write_beside_simulation
from nlp_calib.simulation.imu import ImuSimulationOptions
from nlp_calib.simulation.lidar import LidarSimulationOptions

pytest.importorskip("rosbags")
pytest.importorskip("small_gicp")

RADIANS = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}
LENGTHS = {"left_wheel_radius", "right_wheel_radius", "wheel_separation"}
JOINTS = {"joint_states": "/joint_states", "joints": ["left_wheel_joint", "right_wheel_joint"]}
BESIDE = {
    "model": "diff_drive",
    "sensor": {"mount": "planar", "beside": "gyro"},
    "initial_guess": "auto",
    "alignment": {"tracker_lag": "auto"},
    # The lidar's matches (mm, mrad) and the gyro's integrated angle (a 2 mrad/s white rate noise).
    "information": {"translation": 1.0e6, "rotation": 1.0e5, "gyro": 1.0e8},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}
#: A 5° roll; the lidar's driver stamps 20 ms late, the IMU's 45 ms (two clocks).
ROLL, LATE, GYRO_LATE = float(np.radians(5.0)), 0.02, 0.045


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, float]]:
    """30 s in a room, a lidar and a rolled IMU on the base (seed never tuned on)."""
    folder = tmp_path_factory.mktemp("beside")
    lidar = LidarSimulationOptions(duration_s=30.0, seed=29, stamp_offset_s=LATE)
    gyro = ImuSimulationOptions(seed=29, truth={"imu_roll": ROLL}, stamp_offset_s=GYRO_LATE)
    sim = simulate_beside(lidar, gyro)
    bag, truth_file = write_beside_simulation(sim, folder / "drive")
    truth = {RADIANS.get(k, k): v for k, v in json.loads(truth_file.read_text())["params"].items()}
    return bag, truth


def _mapping(bag: Path, **dataset: object) -> dict[str, object]:
    return {**BESIDE, "dataset": {"bag": str(bag), **JOINTS, "scan": "/scan", "imu": "/imu", **dataset}}


def test_the_lengths_a_gyro_alone_cannot_see_are_determined_beside_a_lidar(
    drive: tuple[Path, dict[str, float]],
) -> None:
    bag, _ = drive
    alone = {**BESIDE, "sensor": "gyro", "dataset": {"bag": str(bag), **JOINTS, "imu": "/imu"}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gyro = preflight(scenario_from_mapping(alone, "gyro", bag.parent))
        both = preflight(scenario_from_mapping(_mapping(bag), "beside", bag.parent))
    assert LENGTHS <= {p.name for p in gyro.parameters if p.status == NOT_DETERMINED}
    # The way out names the key that fits a reference beside the gyro.
    assert "or fit it beside a reference that measures distance (sensor: {mount: planar, beside: gyro}" in (
        gyro.way_out
    )
    status = {p.name: p.status for p in both.parameters}
    assert LENGTHS | {"sensor_x", "gyro_bias_z", "imu_roll", "tracker_lag"} <= set(status)
    assert NOT_DETERMINED not in status.values(), status


def test_a_gyro_and_a_lidar_fit_within_3_sigma_and_check_reads_it_back(
    drive: tuple[Path, dict[str, float]], tmp_path: Path
) -> None:
    bag, truth = drive
    scenario = tmp_path / "beside.yaml"
    scenario.write_text(yaml.safe_dump(_mapping(bag)))
    proc = cli("run", str(scenario), "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    stored = yaml.safe_load((tmp_path / "out" / "calibration.yaml").read_text())
    est, std = stored["parameters"], stored["std"]
    fitted = LENGTHS | {"sensor_x", "sensor_y", "sensor_theta", "imu_roll", "imu_pitch"}
    fitted |= {"gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "tracker_lag", "gyro_lag"}
    assert fitted <= set(est)
    for name in sorted(fitted):
        assert abs(est[name] - truth[name]) < 3 * std[name], (name, est[name], truth[name], std[name])
    # Each clock its own offset: the gyro's found within 2 ms, 25 ms from the lidar's.
    assert truth["tracker_lag"] == LATE and truth["gyro_lag"] == GYRO_LATE
    assert abs(est["gyro_lag"] - GYRO_LATE) < 0.002 and abs(est["imu_roll"] - ROLL) < 0.005
    # Each sensor's parameters in the layout's blocks: its mount, each clock's offset.
    blocks = {p["name"]: p["block"] for p in stored["layout"]["parameters"]}
    assert blocks["sensor_x"] == blocks["gyro_bias_z"] == "mount"
    assert blocks["tracker_lag"] == blocks["gyro_lag"] == "clock"
    # One URDF joint per sensor: the lidar's and the IMU's (its roll the fit's).
    joints = {j.get("name"): j for j in ET.parse(tmp_path / "out" / "sensor_mount.urdf.xml").getroot()}
    assert set(joints) == {"base_link_to_laser", "base_link_to_imu_link"}, set(joints)
    rpy = joints["base_link_to_imu_link"].find("origin").get("rpy").split()  # type: ignore[union-attr]
    assert float(rpy[0]) == pytest.approx(est["imu_roll"])
    assert stored["beside"]["child"] == "imu_link"
    check = cli(
        "check", str(tmp_path / "out" / "calibration.yaml"), str(scenario), "--out", str(tmp_path / "c")
    )
    assert check.returncode == 0, check.stdout + check.stderr
    assert "STILL GOOD" in check.stdout
    # On the run's own data the check aligns where the run did and fits its records: both clocks
    # come out as the run's.
    ran, checked = (json.loads((tmp_path / d / "result.json").read_text()) for d in ("out", "c"))
    assert checked["alignment"]["estimate"]["lag_s"] == ran["alignment"]["estimate"]["lag_s"]
    assert checked["dataset"]["used"] == ran["dataset"]["used"]
    assert checked["dataset"]["residuals"] == ran["dataset"]["residuals"]
    own, again = (doc["solvers"]["gauss_newton"]["params"] for doc in (ran, checked))
    assert again["gyro_lag"] == pytest.approx(own["gyro_lag"], abs=1e-9)
    assert again["tracker_lag"] == pytest.approx(own["tracker_lag"], abs=1e-9)


def test_each_sensors_records_are_read_on_its_own_clock(drive: tuple[Path, dict[str, float]]) -> None:
    bag, _ = drive
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, log = read(scenario_from_mapping(_mapping(bag), "beside", bag.parent))
    mine, inc = log.reference.beside, log.motions
    assert mine is not None and inc is not None
    # Each record is one sensor's: the gyro's increments end at its records, the lidar's at others.
    g = inc.z[:, -1] > 0.5
    assert g.any() and (~g).any()
    assert mine[inc.first[g]].all() and mine[inc.last[g]].all()
    assert not mine[inc.first[~g]].any() and not mine[inc.last[~g]].any()
    # Re-sampled at both clocks' offsets: the gyro's records read at its own, the lidar's at its own
    # (not the gyro's moved there by the problem's first-order clock correction).
    shifted, _ = resample_encoders(log, LATE, model.encoder_kinds, beside_lag_s=GYRO_LATE - LATE)
    assert log.joint_stream is not None and shifted.joint_positions is not None
    expected = log.joint_stream.at(log.time_s - np.where(mine, GYRO_LATE, LATE))
    np.testing.assert_allclose(shifted.joint_positions, expected, rtol=0, atol=1e-12)
    # ...and so by the run's alignment: the encoders where each clock's fitted offset reads them.
    assert shifted.clock.beside_lag_s == pytest.approx(GYRO_LATE - LATE)


def test_the_gyros_clock_offset_is_not_biased_where_the_turn_rate_jumps(tmp_path: Path) -> None:
    """The case found by ``benchmarks/lag_coverage.py --kinds beside --first 2202 --seeds 1``: the
    encoders were re-sampled at the lidar's offset alone and the gyro's records moved 23 ms on by the
    first-order clock correction, which a jump of the turn rate breaks: gyro_lag −1.40 ± 0.21 ms."""
    lidar = LidarSimulationOptions(duration_s=30.0, seed=2202, stamp_offset_s=0.021)
    gyro = ImuSimulationOptions(seed=2202, truth={"imu_roll": 0.0873}, stamp_offset_s=0.045)
    bag, _ = write_beside_simulation(simulate_beside(lidar, gyro), tmp_path / "jump")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(scenario_from_mapping(_mapping(bag), "jump", tmp_path)).run(["gauss_newton"])
    est, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    for name, truth in (("tracker_lag", 0.021), ("gyro_lag", 0.045)):
        assert abs(est[name] - truth) < 2 * std[name], (name, est[name], std[name])


def test_a_sensor_beside_is_refused_where_none_fits(drive: tuple[Path, dict[str, float]]) -> None:
    bag, _ = drive
    bad = {**_mapping(bag), "sensor": {"mount": "3d", "beside": "gyro"}}
    # A camera's 3-D mount beside a gyro reads 3-D poses, not a lidar's planar scan matches.
    with pytest.raises(
        ConfigError, match=r"dataset: sensor: \{mount: 3d, beside: gyro\} reads a camera's 3-D poses"
    ):
        scenario_from_mapping(bad, "bad", bag.parent)
    with pytest.raises(ConfigError, match=r"sensor\.beside.*mount: planar, beside: gyro"):
        scenario_from_mapping({**bad, "sensor": {"mount": "gyro", "beside": "gyro"}}, "bad", bag.parent)
    # On load, not at the fit: a gyro beside a dataset that names no reference beside it ...
    gyro_only = {**BESIDE, "dataset": {"bag": str(bag), **JOINTS, "imu": "/imu"}}
    with pytest.raises(
        ConfigError, match=r"dataset: sensor: \{mount: planar, beside: gyro\} reads .*scan: …, imu: …"
    ):
        scenario_from_mapping(gyro_only, "bad", bag.parent)
    # ... and a dataset naming both read by one sensor.
    with pytest.raises(
        ConfigError, match=r"dataset: it names .* fit both with sensor: \{mount: planar, beside: gyro\}"
    ):
        scenario_from_mapping({**_mapping(bag), "sensor": "planar"}, "bad", bag.parent)
    # The beside source's joints are the model's (each of its two sources reads them).
    wrong = _mapping(bag, joints=["left_wheel_joint", "right_wheel_joint", "caster_joint"])
    with pytest.raises(ConfigError, match=r"dataset\.joints: 3 joint\(s\)"):
        scenario_from_mapping(wrong, "bad", bag.parent)


def test_init_drafts_a_gyro_beside_the_lidar(drive: tuple[Path, dict[str, float]], tmp_path: Path) -> None:
    """A bag of scans and an Imu topic: ``init`` drafts both in one objective (was: the scans alone,
    the gyro named 'too')."""
    bag, _ = drive
    drafted = tmp_path / "drive.yaml"
    proc = cli("init", str(bag), "--out", str(drafted))
    assert proc.returncode == 0, proc.stderr
    assert "reference: the scans on /scan; gyro beside it /imu" in proc.stdout
    raw = yaml.safe_load(drafted.read_text())
    assert raw["sensor"] == {"mount": "planar", "beside": "gyro"}
    assert raw["dataset"]["scan"] == "/scan" and raw["dataset"]["imu"] == "/imu"
    assert "sensor: {mount: planar, beside: gyro}: its bias, tilt and clock offset" in drafted.read_text()


def test_simulate_writes_a_lidar_and_gyro_bag_a_scenario_reads(tmp_path: Path) -> None:
    proc = cli("simulate", "--lidar", "--imu", "--out", str(tmp_path / "d"), "--duration", "3", "--seed", "4")
    assert proc.returncode == 0, proc.stderr
    truth = json.loads((tmp_path / "d.truth.json").read_text())["params"]
    assert {"sensor_x", "gyro_bias_z", "imu_roll", "k_left", "tracker_lag"} <= set(truth)
    assert "scan: /scan, imu: /imu" in proc.stdout and "beside: gyro" in proc.stdout


def test_codegen_exports_the_two_sensors_residual(
    drive: tuple[Path, dict[str, float]], tmp_path: Path
) -> None:
    """The C export of a problem whose windows are either sensor's (was: a KeyError on its z's rows)."""
    bag, _ = drive
    scenario = tmp_path / "beside.yaml"
    scenario.write_text(yaml.safe_dump(_mapping(bag)))
    proc = cli("codegen", str(scenario), "--out", str(tmp_path / "c"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "in 8 rows, as sensor planar_gyro lays out its z" in (tmp_path / "c" / "example.c").read_text()
