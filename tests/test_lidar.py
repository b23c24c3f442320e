"""A 2-D lidar as the reference: simulated bags in a room of walls, scans matched by small_gicp, the
lidar's mount and the wheels calibrated together, bad matches named and left out."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import cli

from nlp_calib.logs.bag_reader import BagError, bag_inventory
from nlp_calib.logs.scans import LaserScans, match_scans, read_scans
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.simulation.lidar import (
    LidarSimulationOptions,
    ray_cast,
    room,
    simulate_lidar,
    write_lidar_simulation,
)

pytest.importorskip("small_gicp")

RADIANS = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}
SCENARIO = {
    "model": "diff_drive",
    "initial_guess": "auto",
    "information": {"translation": 1.0e6, "rotation": 1.0e5},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, object]:
    """40 s in a room, 5 % of the scans degraded (crowds and late sweeps)."""
    folder = tmp_path_factory.mktemp("lidar")
    sim = simulate_lidar(LidarSimulationOptions(duration_s=40.0, seed=13, degraded_fraction=0.05))
    bag, truth = write_lidar_simulation(sim, folder / "drive")
    return bag, truth, sim


def test_consecutive_scans_match_to_the_millimetre() -> None:
    rng = np.random.default_rng(0)
    path = np.array([[0.0, 0.0], [3.0, 2.0]])
    walls = room(rng, path)
    angles = -np.pi + 2 * np.pi * np.arange(720) / 720
    poses = np.array([[1.0, 1.0, 0.3], [1.04, 1.015, 0.33], [1.08, 1.03, 0.36]])
    ranges = np.array([ray_cast(walls, p, angles) for p in poses]) + rng.normal(0, 0.005, (3, 720))
    scans = LaserScans("/scan", np.arange(3) * 10**8, ranges, angles, 0.05, 15.0, "laser")
    table = match_scans(scans)
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    d = poses[1:, :2] - poses[:-1, :2]
    truth = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], np.diff(poses[:, 2])])
    np.testing.assert_allclose(table.z, truth, atol=3e-3)
    assert np.all(table.quality["converged"] == 1.0) and np.all(table.quality["inliers"] > 0.9)


def test_the_lidar_and_the_wheels_calibrate_together(drive: tuple[Path, Path, object]) -> None:
    bag, truth_file, sim = drive
    dataset = {
        "bag": str(bag),
        "joint_states": "/joint_states",
        "joints": ["left_wheel_joint", "right_wheel_joint"],
    }
    sc = scenario_from_mapping({**SCENARIO, "dataset": {**dataset, "scan": "/scan"}}, "lidar", bag.parent)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    est, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    truth = {RADIANS.get(k, k): v for k, v in json.loads(truth_file.read_text())["params"].items()}
    assert abs(est["sensor_x"] - truth["sensor_x"]) < 0.01 and abs(est["sensor_y"] - truth["sensor_y"]) < 0.01
    assert abs(est["sensor_theta"] - truth["sensor_theta"]) < np.radians(0.5)
    for name in RADIANS.values():
        assert abs(est[name] / truth[name] - 1.0) < 0.005, name
    for name, value in truth.items():
        assert abs(est[name] - value) < 4 * std[name], name
    # Every match into a crowd's scan is named, and named matches are the degraded scans' own.
    named = {f.first for f in run.checks.findings.report.faults if f.kind == "bad_match"}
    degraded = set(sim.degraded.tolist())  # type: ignore[attr-defined]
    touching = {k - 1 for k in degraded} | degraded
    assert named and named <= touching, (named, touching)
    crowds = [k for k in degraded if np.isinf(sim.ranges[k]).mean() > 0.05]  # type: ignore[attr-defined]
    assert {k - 1 for k in crowds} <= named
    assert run.data.dropped_faulty == len(named)
    # The hand-off: the lidar's frame, its height from /tf_static.
    assert run.log.sensor_frame == "laser"
    assert run.reports["gauss_newton"].mount.xyz[2] == pytest.approx(0.25)


def test_the_bag_holds_what_a_lidar_recording_does(drive: tuple[Path, Path, object]) -> None:
    bag, _, sim = drive
    found = bag_inventory(bag)
    assert found.of_type("sensor_msgs/msg/LaserScan") == ["/scan"]
    assert found.joints["/joint_states"] == ("left_wheel_joint", "right_wheel_joint")
    scans = read_scans(bag, "/scan")
    assert scans.n == sim.scan_time_s.size and scans.frame == "laser"  # type: ignore[attr-defined]
    with pytest.raises(BagError, match="LaserScan"):
        read_scans(bag, "/joint_states")


def test_import_bag_lists_the_bag_when_it_cannot_choose(drive: tuple[Path, Path, object]) -> None:
    bag, _, _ = drive
    proc = cli("import-bag", str(bag), "--model", "diff_drive", "--out", str(bag.parent / "x.csv"))
    code, err = proc.returncode, proc.stderr
    assert code == 2
    assert "cannot choose --tracker" in err and "/scan (sensor_msgs/msg/LaserScan" in err
    assert "joints left_wheel_joint, right_wheel_joint" in err


def test_simulate_writes_a_lidar_bag_a_scenario_reads(tmp_path: Path) -> None:
    proc = cli("simulate", "--lidar", "--out", str(tmp_path / "drive"), "--duration", "5", "--seed", "2")
    assert proc.returncode == 0 and "scan: /scan" in proc.stdout
    assert (tmp_path / "drive" / "metadata.yaml").is_file()
    assert json.loads((tmp_path / "drive.truth.json").read_text())["params"]["sensor_x"] == 0.18
