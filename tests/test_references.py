"""References that are not a tracker's poses: a file of the sensor's own motions (a scan matcher's),
wheels read as speeds or counts per cycle, a mount per log in a joint fit, and the vendor's
odometry turned back into wheel angles; each against a simulator's truth."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from nlp_calib.cli.main import main
from nlp_calib.core.errors import ConfigError, DatasetError, ModelError
from nlp_calib.logs.bag_joints import joint_positions
from nlp_calib.logs.bag_reader import Stamped
from nlp_calib.logs.joint_log import format_joint_csv, wheel_positions
from nlp_calib.logs.motions import format_motions, read_motions
from nlp_calib.models import MODELS, get_model
from nlp_calib.models.drives import integrate_base
from nlp_calib.models.joints import joint_map
from nlp_calib.models.radians import in_units
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.problem import ProblemSpec, build, build_residual_data, joined
from nlp_calib.problem.windows import ResidualOptions
from nlp_calib.simulation.camera import base_motion
from nlp_calib.simulation.lidar import LidarSimulationOptions, simulate_lidar
from nlp_calib.simulation.vendor import (
    VendorSimulationOptions,
    correction,
    vendor_models,
    write_vendor_simulation,
)
from nlp_calib.solvers import ProblemEvaluator
from nlp_calib.sources import MotionsSource

RADIANS = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}
#: The scan matcher's noise per increment (m, rad), and the information weights that go with it.
NOISE = (0.001, 0.0005)
BASE: dict[str, Any] = {
    "model": "diff_drive",
    "initial_guess": "auto",
    "information": {"translation": 1.0e6, "rotation": 4.0e6},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}


def recording(
    folder: Path,
    seed: int,
    mount: dict[str, float] | None = None,
    wrong: tuple[int, ...] = (),
    duration: float = 40.0,
    name: str = "drive",
) -> tuple[Path, Path, dict[str, float]]:
    """A drive's joints (CSV, radians) and its lidar's motions between scans (noisy; those of
    ``wrong`` off by 3 cm and 20 mrad), with the truth in the radians form's names."""
    sim = simulate_lidar(
        LidarSimulationOptions(
            duration_s=duration, seed=seed, beams=16, degraded_fraction=0.0, truth=mount or {}
        )
    )
    rng = np.random.default_rng(seed)
    z = sim.true_motions()
    z[:, :2] += rng.normal(0.0, NOISE[0], (z.shape[0], 2))
    z[:, 2] += rng.normal(0.0, NOISE[1], z.shape[0])
    for k in wrong:
        z[k] += (0.03, -0.02, 0.02)
    ns = np.round(sim.scan_time_s * 1e9).astype(np.int64)
    joints, motions = folder / f"{name}.csv", folder / f"{name}.motions.csv"
    joints.write_text(
        format_joint_csv(
            np.round(sim.joint_time_s * 1e9).astype(np.int64), sim.joint_names, sim.joint_positions
        )
    )
    motions.write_text(format_motions(ns[:-1], ns[1:], z, {"converged": np.ones(z.shape[0])}))
    truth = {RADIANS.get(k, k): v for k, v in sim.options.truth.items()}
    return joints, motions, truth


def entry(joints: Path, motions: Path) -> dict[str, Any]:
    return {
        "joints": str(joints),
        "motions": str(motions),
        "encoders": {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"},
        "sensor_frame": "laser",
    }


def quiet_run(calibration: Any) -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibration.run()


def test_the_windows_are_exactly_the_increments(tmp_path: Path) -> None:
    joints, motions, _ = recording(tmp_path, 3, duration=10.0)
    model = in_units(get_model("diff_drive"), "radians")
    log = MotionsSource(
        joints, motions, {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
    ).read(model, strict=True)
    table = read_motions(motions)
    assert log.motions is not None and log.motions.n == table.n
    fns = build(model, ProblemSpec())
    data = build_residual_data(fns, log, ResidualOptions())
    # One window per increment, over exactly its two stamps, its z the increment as written.
    start_ns = log.start_ns + np.round(log.time_s * 1e9).astype(np.int64)
    np.testing.assert_array_equal(start_ns[data.starts], table.start_ns)
    np.testing.assert_array_equal(start_ns[data.stops], table.end_ns)
    np.testing.assert_array_equal(data.z.T, table.z)
    assert data.increment is not None and data.increment.all()


def test_a_motions_file_calibrates_and_names_its_bad_increments(tmp_path: Path) -> None:
    wrong = (40, 41, 150, 250)
    joints, motions, truth = recording(tmp_path, 5, wrong=wrong)
    run = quiet_run(
        Calibration(scenario_from_mapping({**BASE, "dataset": entry(joints, motions)}, "m", tmp_path))
    )
    est, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    for name, value in truth.items():
        assert abs(est[name] - value) < 4 * std[name], (name, est[name], value, std[name])
    found = run.checks.findings.report.faults
    named = {f.first for f in found if f.kind == "bad_match"}
    assert set(wrong) <= named and len(named - set(wrong)) <= 2, named
    # Left out of the fit, one window each, never a neighbour of theirs.
    assert run.data.dropped_faulty == len(named)
    assert all("disagrees with the wheels" in f.evidence for f in found if f.first in wrong)


def test_increment_noise_is_each_increments_own(tmp_path: Path) -> None:
    """Independent increments: the white-noise σ is the classical σ²(JᵀJ)⁻¹ of independent windows
    (a chain of poses' noise would telescope and give far less)."""
    joints, motions, _ = recording(tmp_path, 7)
    sc = scenario_from_mapping(
        {**BASE, "dataset": entry(joints, motions), "robust": {"kernel": "none"}}, "m", tmp_path
    )
    calib = Calibration(sc)
    run = quiet_run(calib)
    result = run.reports["gauss_newton"]
    ev: ProblemEvaluator = calib.evaluator
    ne = ev.normal_equations(result.result.x)
    dof = ev.n_residuals * 3 - calib.fns.n_free
    classical = np.sqrt(np.diag(np.linalg.inv(ne.H)) * ne.chi2 / dof)
    white = np.array([result.uncertainty.std[result.uncertainty.names.index(n)] for n in calib.fns.free])
    np.testing.assert_allclose(white, classical, rtol=0.25)


def test_wheels_as_speeds_or_counts_per_cycle_are_positions() -> None:
    t = np.arange(0, 11) * 100_000_000  # 10 Hz
    angle = 0.3 * np.arange(11.0) + 0.02 * np.arange(11.0) ** 2
    speeds = np.gradient(angle, t * 1e-9)
    # A speeds column is the joints' stream's velocities (NaN positions), integrated as a bag's are.
    none = np.full(t.size, np.nan)
    stream = Stamped("joints.csv", t, np.column_stack([none, angle, speeds, none]))
    _, from_speeds, integrated, _ = joint_positions(Path("joints.csv"), stream, ("wheel", "steer"))
    assert integrated == ["wheel"]
    # Trapezoids integrate a quadratic's sampled derivative exactly (central differences inside).
    assert np.allclose(from_speeds[1:-1, 0] - from_speeds[1, 0], angle[1:-1] - angle[1], atol=0.011)
    assert np.array_equal(from_speeds[:, 1], angle)  # an absolute joint's column is its position
    with pytest.raises(ValueError, match="integrated with the joints' stream"):
        wheel_positions(t, np.column_stack([speeds, angle]), [True, False], "speeds", None)
    counts = np.concatenate([[0.0], np.diff(angle)]) * 4096 / (2 * np.pi)
    from_counts = wheel_positions(t, counts[:, None], [True], "increments", 4096)
    np.testing.assert_allclose(from_counts[:, 0], angle - angle[0], atol=1e-12)


def test_a_wheel_form_is_checked_where_it_is_given(tmp_path: Path) -> None:
    joints, motions, _ = recording(tmp_path, 3, duration=5.0)
    bad = {**entry(joints, motions), "form": "positions", "counts_per_turn": 4096}
    with pytest.raises(Exception, match="counts_per_turn"):
        scenario_from_mapping({**BASE, "dataset": bad}, "m", tmp_path)
    (tmp_path / "bad.motions.csv").write_text("t_start,t_end,x,y,theta\n2.0,1.0,0,0,0\n")
    with pytest.raises(DatasetError, match="not after t_start"):
        read_motions(tmp_path / "bad.motions.csv")
    with pytest.raises(ConfigError, match="form"):
        MotionsSource(joints, motions, {"left_wheel": "a", "right_wheel": "b"}, form="rad")


def test_a_mount_per_log_shares_the_wheels(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    first = recording(tmp_path, 11, name="front")
    second = recording(tmp_path, 12, {"sensor_x": -0.2, "sensor_y": 0.05, "sensor_theta": 3.0}, name="rear")
    sc = {
        **BASE,
        "datasets": [entry(*first[:2]), entry(*second[:2])],
        "sensor": {"mount": "planar", "mounts": "per_log"},
    }
    path = tmp_path / "two.yaml"
    path.write_text(yaml.safe_dump(sc))
    # The pre-flight starts each log's mount where its own start puts it, as the run does.
    assert main(["preflight", str(path)]) == 0
    assert "ENOUGH: the drive determines every parameter" in capsys.readouterr().out
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 0
    doc = json.loads((tmp_path / "out" / "front" / "result.json").read_text())
    est = doc["solvers"]["gauss_newton"]["params"]
    std = doc["solvers"]["gauss_newton"]["std"]
    for i, (_, _, truth) in enumerate((first, second), start=1):
        for name in ("sensor_x", "sensor_y", "sensor_theta"):
            assert abs(est[f"{name}_{i}"] - truth[name]) < 4 * std[f"{name}_{i}"], (name, i)
    for name in RADIANS.values():
        assert abs(est[name] - first[2][name]) < 4 * std[name], name
    # One URDF joint per mount, each log's own; the consistency check compared each log's own fit.
    urdf = (tmp_path / "out" / "sensor_mount.urdf.xml").read_text()
    assert urdf.count("<joint ") == 2 and "laser_1" in urdf and "laser_2" in urdf
    assert doc["verdict"]["level"] != "not usable", doc["verdict"]
    # The user's URDF re-poses one link: a mount per log is refused before any work.
    robot = tmp_path / "robot.urdf"
    robot.write_text((tmp_path / "out" / "robot.urdf").read_text())
    args = [
        "run",
        str(path),
        "--out",
        str(tmp_path / "again"),
        "--urdf",
        str(robot),
        "--sensor-link",
        "laser_1",
    ]
    capsys.readouterr()
    assert main(args) != 0
    assert "fits a mount per log" in capsys.readouterr().err and not (tmp_path / "again").exists()


def test_a_mount_and_a_lag_per_log_together(tmp_path: Path) -> None:
    """Two logs of one tricycle, each with its own tracker mount and its own tracker latency: each
    log's mount and lag come out its own, the wheels shared (the lag seam and the mount seam
    select by the same row of a window's data)."""
    from conftest import write_sim

    mounts = ({"sensor_x": 1.6, "sensor_y": 0.1, "sensor_theta": 0.05}, {"sensor_x": -0.4, "sensor_y": 0.3})
    logs = [
        write_sim(tmp_path, f"l{i}.txt", records=900, seed=61 + i, latency_s=lag, truth=mounts[i])
        for i, lag in enumerate((0.02, 0.06))
    ]
    raw = {
        "model": "tricycle",
        "datasets": [str(p) for p in logs],
        "initial_guess": "from_file",
        "residual": {"horizon": 10},
        "alignment": {"tracker_lag": "auto", "search": [-0.1, 0.1]},
        "sensor": {"mounts": "per_log"},
        "solvers": ["gauss_newton"],
    }
    run = Calibration(scenario_from_mapping(raw, "j", tmp_path)).run(["gauss_newton"])
    part = run.logs[1]
    params, std = part.reports["gauss_newton"].result.param_dict(), part.std("gauss_newton")
    truth = {
        "tracker_lag_1": 0.02,
        "tracker_lag_2": 0.06,
        **{f"{n}_{i + 1}": v for i, m in enumerate(mounts) for n, v in m.items()},
    }
    for name, true in truth.items():
        assert abs(params[name] - true) < 4 * std[name], (name, params[name], true, std[name])
    # Each log's report gives its own mount; the second log's link named apart from the first's.
    mine = part.reports["gauss_newton"]
    assert mine.mount is not None and mine.mount.pose["x"] == pytest.approx(params["sensor_x_2"])
    assert [m.mount.child for m in mine.mounts] == ["laser_1", "laser_2"]


def test_each_log_s_mount_enters_only_its_own_windows(tmp_path: Path) -> None:
    """A problem with a mount per log: each window's residual is that of a one-mount problem with
    its own log's mount."""
    model = in_units(get_model("diff_drive"), "radians")
    source = {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
    logs = [
        MotionsSource(*recording(tmp_path, s, duration=5.0, name=f"d{s}")[:2], source).read(
            model, strict=True
        )
        for s in (1, 2)
    ]
    one, two = build(model, ProblemSpec()), build(model, ProblemSpec(mounts=2))
    parts = [build_residual_data(one, log, ResidualOptions()) for log in logs]
    data = joined(parts).with_selector()
    mounts = [np.array([0.1, -0.02, 0.3]), np.array([-0.2, 0.04, 2.9])]
    k = np.array([0.1, 0.1005, 0.45])
    ev2 = ProblemEvaluator(two, data, x_fixed=np.zeros(0), omega=np.ones(3), delta=1.0)
    e2 = ev2.robust_terms(np.concatenate([k, *mounts]))[0]
    for i, part in enumerate(parts):
        ev1 = ProblemEvaluator(one, part, x_fixed=np.zeros(0), omega=np.ones(3), delta=1.0)
        e1 = ev1.robust_terms(np.concatenate([k, mounts[i]]))[0]
        mine = data.log_of(data.starts) == i
        np.testing.assert_allclose(e2[:, mine], e1, rtol=0, atol=1e-12)


def test_vendor_odometry_gives_the_corrections_to_its_model(tmp_path: Path) -> None:
    opts = VendorSimulationOptions(duration_s=90.0, seed=21)
    odometry, tum, truth_file = write_vendor_simulation(opts, tmp_path / "odom.txt")
    truth = json.loads(truth_file.read_text())
    vendor = truth["vendor"]
    dataset = {"odometry": str(odometry), "vendor": vendor, "poses": str(tum)}
    sc = {
        "model": "diff_drive",
        "dataset": dataset,
        "residual": {"horizon_s": 0.5},
        "solvers": ["gauss_newton"],
    }
    run = quiet_run(Calibration(scenario_from_mapping(sc, "v", tmp_path)))
    est = run.reports["gauss_newton"].result.param_dict()
    for name, value in truth["corrections"].items():
        assert abs(est[name] / vendor[name] / value - 1.0) < 0.002, (name, est[name] / vendor[name], value)
    # The run starts from the vendor's own model; a model that cannot invert its odometry says so.
    assert all(run.initial[n] == v for n, v in vendor.items())
    wrong = scenario_from_mapping(
        {**sc, "dataset": {**dataset, "vendor": {"wheel_radius": 0.1}}}, "v", tmp_path
    )
    with pytest.raises(Exception, match="vendor: give the vendor's left_wheel_radius"):
        Calibration(wrong)


@pytest.mark.parametrize("name", ["diff_drive", "tricycle"])
def test_each_model_turns_its_controllers_odometry_back_into_its_joints(name: str) -> None:
    # The controller's odometry of a drive that stops, reverses and turns, turned back by the
    # model with the controller's own values: the very joint readings (a steering angle where the
    # wheel rolls; the traction's and the wheels' running sums from 0).
    assert name in vendor_models()
    opts = VendorSimulationOptions(model=name, duration_s=40.0, seed=3)
    t = np.arange(0.0, 40.0, 0.02)
    _, channels = base_motion(name, opts.truth, opts.drive, np.random.default_rng(3), t)
    joints = joint_map(name).angles(opts.truth, channels)
    base = MODELS[name].drive.odometry(joints, opts.vendor)  # type: ignore[attr-defined]
    model = in_units(get_model(name), "radians")
    back = model.readings_from_odometry(base, opts.vendor_in_radians())
    drives = next(iter(joints.values()))
    moved = np.concatenate([[False], np.abs(np.diff(drives)) > 1e-9])
    assert moved.mean() > 0.5 and (np.diff(drives) < 0).any()
    for row, input_name in zip(joint_map(name).rows, get_model(name).input_names):
        angle, encoder = joints[row.joint], model.form.inputs[input_name].encoder
        want = angle if row.use == "angle" else angle - angle[0]
        np.testing.assert_allclose(back[encoder][moved], want[moved], rtol=0, atol=1e-8, err_msg=row.joint)


def test_a_tricycle_steered_apart_in_reverse_turns_its_odometry_back() -> None:
    # Forward, a stop, backwards with its own steering gain, forward again: the controller's arcs
    # turned back give the very readings (the steering held through the stop is not compared).
    d = np.concatenate([np.full(100, 0.02), np.zeros(20), np.full(100, -0.015), np.full(180, 0.01)])
    angle = 0.4 * np.sin(np.linspace(0.0, 6.0, d.size + 1))
    p = {
        "k_steer": 0.55,
        "k_traction": 0.5,
        "axis_length": 1.5,
        "steer_offset": -0.05,
        "k_steer_reverse": 0.1,
    }
    phi = p["k_steer"] * (1.0 + p["k_steer_reverse"] * (d < 0)) * angle[1:] + p["steer_offset"]
    base = integrate_base(d * np.cos(phi), d * np.sin(phi) / p["axis_length"])
    back = MODELS["tricycle_reverse"].readings_from_odometry(base, p)  # type: ignore[attr-defined]
    moved = np.concatenate([[False], d != 0])
    np.testing.assert_allclose(back["steering"][moved], angle[moved], rtol=0, atol=1e-12)
    np.testing.assert_allclose(back["traction_wheel"], np.cumsum(np.r_[0.0, d]) / 0.5, rtol=0, atol=1e-12)
    # The skid-steer's controller knows no slip: it says which model turns its odometry back.
    with pytest.raises(ModelError, match="with model: diff_drive"):
        MODELS["skid_steer"].readings_from_odometry(base, {})  # type: ignore[attr-defined]


def test_a_tricycles_vendor_odometry_gives_its_corrections(tmp_path: Path) -> None:
    opts = VendorSimulationOptions(model="tricycle", duration_s=60.0, seed=23)
    odometry, tum, truth_file = write_vendor_simulation(opts, tmp_path / "odom.txt")
    truth = json.loads(truth_file.read_text())
    vendor = truth["vendor"]
    sc = {
        "model": "tricycle",
        "dataset": {"odometry": str(odometry), "vendor": vendor, "poses": str(tum)},
        "residual": {"horizon_s": 0.5, "steering_sample": "end"},
        "solvers": ["gauss_newton"],
    }
    run = quiet_run(Calibration(scenario_from_mapping(sc, "v", tmp_path)))
    est, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    assert set(truth["corrections"]) == set(vendor) and vendor["steer_offset"] == 0.0
    for name, value in truth["corrections"].items():
        got = correction("tricycle", name, est[name], vendor[name])
        if name == "steer_offset":  # an angle's correction is a difference
            assert abs(got - value) < 3 * std[name] < 0.002, (name, got, value)
        else:
            assert abs(got / value - 1.0) < 0.002, (name, got, value)
    # A model that cannot turn its odometry back says so.
    car_like = in_units(get_model("car_like"), "radians").kinematic_params
    car = {**sc, "model": "car_like", "dataset": {**sc["dataset"], "vendor": dict.fromkeys(car_like, 1.0)}}
    with pytest.raises(ModelError, match="car_like model cannot turn a robot's odometry back"):
        Calibration(scenario_from_mapping(car, "c", tmp_path))


def test_figures_never_compose_across_a_gap(tmp_path: Path) -> None:
    joints, motions, truth = recording(tmp_path, 9, duration=30.0)
    lines = motions.read_text().splitlines()
    # Every tenth increment missing: a gap the wheels drive across and no increment measures.
    motions.write_text("\n".join(line for i, line in enumerate(lines) if i == 0 or i % 10) + "\n")
    run = quiet_run(
        Calibration(scenario_from_mapping({**BASE, "dataset": entry(joints, motions)}, "g", tmp_path))
    )
    metrics = run.reports["gauss_newton"].metrics
    assert metrics.segments >= 25
    # Restarted at each gap, the track stays on the increments' chain to the millimetre.
    assert metrics.segment_ate.rmse < 0.01
    est = run.reports["gauss_newton"].result.param_dict()
    assert abs(est["wheel_separation"] / truth["wheel_separation"] - 1) < 0.01


def test_priors_in_a_joint_fit_with_a_lag_per_log(tmp_path: Path) -> None:
    """The priors' noise scale of a joint fit whose logs have their own lags comes from every log's
    windows (one log's alone cannot say which lag is whose)."""
    from test_joint import BASE as JOINT
    from test_joint import drives

    paths, _ = drives(tmp_path, 3, records=300)
    raw = {**JOINT, "datasets": [str(p) for p in paths], "alignment": {"tracker_lag": "auto"}}
    sc = scenario_from_mapping({**raw, "priors": {"axis_length": {"mean": 1.5, "std": 0.1}}}, "j", tmp_path)
    run = quiet_run(Calibration(sc))
    assert run.logs[0].reports["gauss_newton"].result.converged
