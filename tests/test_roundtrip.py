"""Every file ``run`` writes is one ``check`` reads back: ``calibration.yaml`` holds its parameter
layout, and a check of the same data is STILL GOOD, over what the registries combine.

Two levels. The layout of every model (in counts and in radians) × sensor × clock offset (none,
one, one per log) × mount (shared, one per log) is written as ``calibration.yaml`` writes it and
read back by the reader ``check`` uses: each combination costs nothing. Then ``run`` and ``check``
end to end on a covering set: each model, each reference (a tracker's poses from a text log and
from a ROS 2 bag, a camera's 3-D poses, a lidar's scan matches, vendor odometry, a gyro), the lag
held and fitted, one log and several with a mount and a lag each.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from conftest import write_sim

from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.logs.motions import format_motions
from nlp_calib.models import MODELS, get_model
from nlp_calib.models.radians import in_units
from nlp_calib.outputs.handoff import calibration_dict, write_calibration
from nlp_calib.pipeline import Calibration, load_scenario
from nlp_calib.pipeline.check import check, check_scenario
from nlp_calib.pipeline.stored import read_calibration
from nlp_calib.problem import ProblemSpec
from nlp_calib.problem.functions import problem_layout
from nlp_calib.results import codec
from nlp_calib.results.check import CANNOT_TELL, STILL_GOOD
from nlp_calib.results.layout import CLOCK, LAYOUT_VERSION, MOUNT, Layout
from nlp_calib.sensors import SENSORS, sensor_for
from nlp_calib.simulation.lidar import LidarSimulationOptions, simulate_lidar

# --- the layout of every combination, written and read back ------------------------------------

LAYOUTS = [
    (model, units, sensor, lags, mounts)
    for model in MODELS
    for units in ("counts", "radians")
    for sensor in SENSORS
    for lags, mounts in ((0, 1), (1, 1), (3, 1), (3, 3), (0, 3))
]


def _document(layout: Layout, model: str, sensor: str) -> dict[str, Any]:
    """A calibration.yaml as ``run`` writes its parameters: each value inside its range."""
    values = {}
    for p in layout.parameters:
        lo, hi = p.range
        values[p.name] = 0.5 * (lo + hi) if math.isfinite(lo) and math.isfinite(hi) else 0.01
    std = dict.fromkeys(values, 1e-6)
    return {
        "tool": {"name": "nlp_calib", "version": "x"},
        "layout": {"version": LAYOUT_VERSION, **codec.to_data(layout)},
        "model": model,
        "sensor": {"kind": sensor},
        "solver": "gauss_newton",
        "parameters": values,
        "std": std,
        "std_white_noise": std,
    }


@pytest.mark.parametrize(("model", "units", "sensor", "lags", "mounts"), LAYOUTS)
def test_every_layout_is_read_back_as_written(
    tmp_path: Path, model: str, units: str, sensor: str, lags: int, mounts: int
) -> None:
    kinematic = in_units(get_model(model), units)
    spec = ProblemSpec(sensor=sensor, lags=lags, mounts=mounts)
    layout = problem_layout(kinematic, sensor_for(sensor), spec)
    path = tmp_path / "calibration.yaml"
    path.write_text(yaml.safe_dump(_document(layout, model, sensor)))
    stored = read_calibration(path)
    assert stored.layout == layout
    # What each parameter is comes from the layout, never from its name's spelling.
    # Each of the sensor's clocks (a gyro beside a reference: two) has an offset per log.
    clocks = len(sensor_for(sensor).clocks)
    assert len(layout.block(CLOCK)) == lags * clocks
    assert len(layout.block(MOUNT)) == len(sensor_for(sensor).params) * mounts
    for i in range(max(lags, mounts, 1)):
        own = layout.owned(i)
        assert all(layout.param(n).log == i for n in own)
        assert len(own) == (lags > 1) * clocks + (mounts > 1) * len(sensor_for(sensor).params)
    # A check starts a new log from the robot's shared parameters only, by the keys scenarios use.
    start = stored.start()
    assert not set(start) & {p.key for p in layout.parameters if p.block == CLOCK}
    assert set(start) <= {p.key for p in layout.parameters}


def test_a_model_parameter_ending_in_a_number_is_no_log_of_its_own() -> None:
    # A parameter named like a per-log one keeps its own role: the layout, not the name, says it.
    layout = Layout.of(
        [
            *(
                dataclasses.replace(b, keys=(*b.keys, "gain_2") if b.kind == "model" else b.keys)
                for b in _blocks()
            ),
        ],
        n_logs=2,
    )
    assert layout.param("gain_2").log is None and layout.param("gain_2").block == "model"
    assert layout.param("sensor_x_2").log == 1 and layout.key("sensor_x_2") == "sensor_x"
    assert layout.own("gain_2", 0) == "gain_2" and layout.own("sensor_x_2", 0) == ""


def _blocks() -> list[Any]:
    from nlp_calib.results.layout import BlockSpec

    return [BlockSpec("model", ("gain",)), BlockSpec("mount", ("sensor_x",), per_log=True)]


# --- run, then check the same data -------------------------------------------------------------


def _run_and_check(scenario: Path) -> tuple[Any, Any]:
    """``run`` then ``check`` of ``scenario`` on its own data, as the commands do."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(load_scenario(scenario)).run()
        folder = scenario.parent / "out"
        folder.mkdir()
        (written,) = write_calibration(run, folder, "calibration.yaml")
        stored = read_calibration(written)
        checked = check(stored, check_scenario(stored, scenario))
    return run, checked


def _assert_still_good(run: Any, checked: Any) -> None:
    """The check of the data ``run`` calibrated: STILL GOOD, or, where the run itself named a
    parameter as loose, CANNOT TELL for that parameter alone; never a drift."""
    assert calibration_dict(run) is not None, run.verdict.line()
    drift = checked.checks.drift
    assert drift is not None, checked.verdict.line()
    assert not drift.drifted, [(c.name, c.z, c.threshold) for c in drift.drifted]
    untested = [c.name for c in drift.changes if c.untested]
    named = " ".join(run.verdict.reasons)
    assert all(n in named for n in untested), (untested, run.verdict.line())
    assert drift.verdict == (CANNOT_TELL if untested else STILL_GOOD), drift.reasons
    # Every parameter of the robot the calibration holds was judged (a recording's clock is not).
    robot = set(run.scenario.layout.robot())
    judged = {c.name for c in drift.changes}
    assert judged <= robot and judged, judged


def _assert_held_lag_counted(run: Any, lag: str) -> None:
    """A held lag's plausible error is in the σ the calibration states (and ``check`` reads back)."""
    held = [c.record.get("std_held") for c in run.checks.more if c.name == "held"]
    assert bool(held and held[0]) == (lag == "held"), held


def _scenario(folder: Path, body: dict[str, Any]) -> Path:
    path = folder / "scenario.yaml"
    path.write_text(yaml.safe_dump({"name": "roundtrip", "solvers": ["gauss_newton"], **body}))
    return path


LIGHT = {"validation": {"blocks": 4}}


@pytest.mark.parametrize("model", list(MODELS))
def test_run_then_check_a_text_log_of_every_model(tmp_path: Path, model: str) -> None:
    # The tricycle's lag fitted as set (a simulated latency, a narrower search), the others' as
    # by default; the diff drive's held at the clock as logged.
    lagged = model != "diff_drive"
    log = write_sim(
        tmp_path,
        "drive.txt",
        records=900,
        seed=17,
        model=model,
        latency_s=0.03 if model == "tricycle" else 0.0,
    )
    body = {"dataset": str(log), "model": model, "residual": {"horizon": 10}, **LIGHT}
    if model == "tricycle":
        body["alignment"] = {"tracker_lag": "auto", "search": [-0.1, 0.1]}
    if not lagged:
        body["alignment"] = {"tracker_lag": 0.0}
    run, checked = _run_and_check(_scenario(tmp_path, body))
    assert (CLOCK in run.scenario.layout.blocks()) == lagged
    _assert_still_good(run, checked)


def test_run_then_check_several_logs_each_with_its_own_mount_and_lag(tmp_path: Path) -> None:
    logs = [
        write_sim(tmp_path, f"drive{i}.txt", records=700, seed=30 + i, latency_s=0.02 * i) for i in range(2)
    ]
    body = {
        "datasets": [str(p) for p in logs],
        "model": "tricycle",
        "sensor": {"mounts": "per_log"},
        "alignment": {"tracker_lag": "auto", "search": [-0.1, 0.1]},
        "residual": {"horizon": 10},
        **LIGHT,
    }
    run, checked = _run_and_check(_scenario(tmp_path, body))
    layout = run.scenario.layout
    assert layout.n_logs == 2 and len(run.logs) == 2
    assert [layout.param(n).log for n in layout.block(CLOCK)] == [0, 1]
    assert {layout.param(n).log for n in layout.block(MOUNT)} == {0, 1}
    _assert_still_good(run, checked)
    assert {"sensor_x_1", "sensor_x_2"} <= {c.name for c in checked.checks.drift.changes}


def test_run_then_check_a_ros2_bag(tmp_path: Path) -> None:
    ros2 = pytest.importorskip("ros2_bags")
    rec = ros2.record("tricycle", seconds=40.0, seed=9)
    bag = ros2.write(rec, tmp_path / "bag")
    block = yaml.safe_load(ros2.dataset_block(bag, rec))
    body = {**block, "model": "tricycle", "initial_guess": "auto", "residual": {"horizon_s": 0.5}, **LIGHT}
    body["alignment"] = {"tracker_lag": "auto"}
    run, checked = _run_and_check(_scenario(tmp_path, body))
    assert run.log.encoders[0].unit == "rad"  # the radians form's parameters, read back as such
    _assert_still_good(run, checked)


def test_run_then_check_a_camera(tmp_path: Path) -> None:
    from nlp_calib.simulation.camera import CameraSimulationOptions, simulate_camera, write_camera_simulation

    sim = simulate_camera(CameraSimulationOptions(duration_s=25.0, seed=5, stamp_offset_s=0.01))
    write_camera_simulation(sim, tmp_path / "cam.tum")
    body = {
        "model": "diff_drive",
        "sensor": "3d",
        "dataset": {
            "poses": "cam.tum",
            "joints": "cam.joints.csv",
            "encoders": {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"},
        },
        "initial_guess": "auto",
        "known": {"sensor_z": 0.3},
        "alignment": {"tracker_lag": "auto", "search": [-0.05, 0.05]},
        "residual": {"horizon_s": 0.25},
        "information": {"translation": 1.0e6, "rotation": 3.0e5},
        "robust": {"kernel": "huber", "delta": 10.0},
        **LIGHT,
    }
    run, checked = _run_and_check(_scenario(tmp_path, body))
    assert run.scenario.sensor.kind != "planar"
    _assert_still_good(run, checked)


def test_run_then_check_a_lidars_scan_matches(tmp_path: Path) -> None:
    sim = simulate_lidar(LidarSimulationOptions(duration_s=40.0, seed=8, beams=16, degraded_fraction=0.0))
    rng = np.random.default_rng(8)
    z = sim.true_motions()
    z[:, :2] += rng.normal(0.0, 0.001, (z.shape[0], 2))
    z[:, 2] += rng.normal(0.0, 0.0005, z.shape[0])
    ns = np.round(sim.scan_time_s * 1e9).astype(np.int64)
    joint_ns = np.round(sim.joint_time_s * 1e9).astype(np.int64)
    (tmp_path / "drive.csv").write_text(format_joint_csv(joint_ns, sim.joint_names, sim.joint_positions))
    (tmp_path / "drive.motions.csv").write_text(
        format_motions(ns[:-1], ns[1:], z, {"converged": np.ones(z.shape[0])})
    )
    body = {
        "model": "diff_drive",
        "dataset": {
            "joints": "drive.csv",
            "motions": "drive.motions.csv",
            "encoders": {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"},
            "sensor_frame": "laser",
        },
        "initial_guess": "auto",
        "information": {"translation": 1.0e6, "rotation": 4.0e6},
        "robust": {"kernel": "huber", "delta": 3.0},
        **LIGHT,
    }
    run, checked = _run_and_check(_scenario(tmp_path, body))
    _assert_still_good(run, checked)


#: The lag as the scenario leaves it (fitted by default), and held at the clocks as logged: a held
#: lag's plausible error enters the σ, which ``check`` reads back and judges by alike.
LAGS = {"fitted": {}, "held": {"alignment": {"tracker_lag": 0.0}}}


@pytest.mark.parametrize("lag", list(LAGS))
def test_run_then_check_vendor_odometry(tmp_path: Path, lag: str) -> None:
    import json

    from nlp_calib.simulation.vendor import VendorSimulationOptions, write_vendor_simulation

    odometry, tum, truth_file = write_vendor_simulation(
        VendorSimulationOptions(duration_s=60.0, seed=23), tmp_path / "odom.txt"
    )
    vendor = json.loads(truth_file.read_text())["vendor"]
    body = {
        "model": "diff_drive",
        "dataset": {"odometry": odometry.name, "vendor": vendor, "poses": tum.name},
        "residual": {"horizon_s": 0.5},
        **LIGHT,
        **LAGS[lag],
    }
    run, checked = _run_and_check(_scenario(tmp_path, body))
    _assert_still_good(run, checked)
    _assert_held_lag_counted(run, lag)


@pytest.mark.parametrize("lag", list(LAGS))
def test_run_then_check_a_lidar_bag(tmp_path: Path, lag: str) -> None:
    pytest.importorskip("small_gicp")
    from nlp_calib.simulation.lidar import write_lidar_simulation

    sim = simulate_lidar(LidarSimulationOptions(duration_s=30.0, seed=4, degraded_fraction=0.0))
    write_lidar_simulation(sim, tmp_path / "lidar_drive")
    body = {
        "model": "diff_drive",
        "dataset": {
            "bag": "lidar_drive",
            "joint_states": "/joint_states",
            "joints": ["left_wheel_joint", "right_wheel_joint"],
            "scan": "/scan",
        },
        "initial_guess": "auto",
        "information": {"translation": 1.0e6, "rotation": 1.0e5},
        "robust": {"kernel": "huber", "delta": 3.0},
        **LIGHT,
        **LAGS[lag],
    }
    run, checked = _run_and_check(_scenario(tmp_path, body))
    _assert_still_good(run, checked)
    _assert_held_lag_counted(run, lag)


def test_a_batch_runs_a_scenario_of_several_logs(tmp_path: Path) -> None:
    from conftest import cli

    logs = [write_sim(tmp_path, f"drive{i}.txt", records=600, seed=50 + i) for i in range(2)]
    scenario = _scenario(
        tmp_path,
        {"datasets": [str(p) for p in logs], "model": "tricycle", "residual": {"horizon": 10}, **LIGHT},
    )
    proc = cli("batch", str(scenario), "--out", str(tmp_path / "batch"), "--jobs", "1")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (folder,) = [p for p in (tmp_path / "batch").iterdir() if p.is_dir()]
    # The joint fit's files once, each log's in its subfolder, as `run` writes them.
    assert (folder / "calibration.yaml").is_file() and (folder / "result.json").is_file()
    assert all((folder / p.stem / "result.json").is_file() for p in logs)
    assert "1 of 1 logs ran to the end" in proc.stdout
