"""A ROS 2 robot's data as it records it (issue 21): joints in radians, each stream on its own clock.

Bags are written with rosbags' own writers from the project's simulator's truth
(:mod:`ros2_bags`): JointState in radians at 100 Hz, a PoseStamped tracker at 120 Hz on stamps
that never meet the joints', 1 % tracker outliers, the nominal mount on ``/tf_static``.
"""

from __future__ import annotations

import functools
import json
import math
import re
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import ros2_bags as rb
import yaml
from conftest import cli

from nlp_calib.core.errors import ModelError, NlpCalibWarning, ScenarioError
from nlp_calib.logs import BagError, JointStream, Log, resample_encoders
from nlp_calib.logs.joint_log import read_joint_csv
from nlp_calib.models import canonical, get_model
from nlp_calib.models.controllers import EncoderScales
from nlp_calib.models.radians import WHEEL_RADIUS
from nlp_calib.outputs.handoff import urdf_joint
from nlp_calib.pipeline import Calibration, load_scenario
from nlp_calib.pipeline.build import initial_parameters
from nlp_calib.sources import BagSource
from nlp_calib.sources.robot import robot_header

TRICYCLE = get_model("tricycle")


@pytest.fixture(scope="module")
def recording() -> rb.Recording:
    return rb.record("tricycle", seconds=60.0, seed=5)


@pytest.fixture(scope="module")
def bags(recording: rb.Recording, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("ros2")
    return {fmt: rb.write(recording, folder / f"drive_{fmt}", fmt) for fmt in ("sqlite3", "mcap")}


@pytest.fixture(scope="module")
def bag_run(
    recording: rb.Recording, bags: dict[str, Path], tmp_path_factory: pytest.TempPathFactory
) -> Callable[[str], tuple[subprocess.CompletedProcess[str], Path]]:
    """``run`` on each bag as it is (the scenario of :func:`_scenario`): its process and output
    folder, run once for the tests that read it. The sqlite3 bag's with ``--report``: evo reads its
    trajectory, and the report adds files, never a figure of result.json."""

    @functools.cache
    def made(fmt: str) -> tuple[subprocess.CompletedProcess[str], Path]:
        folder = tmp_path_factory.mktemp(f"run_{fmt}")
        sc = _scenario(folder, rb.dataset_block(bags[fmt], recording))
        report = ("--report",) if fmt == "sqlite3" else ()
        return cli("run", str(sc), "--out", str(folder / "out"), *report), folder / "out"

    return made


def _scenario(folder: Path, dataset: str, extra: str = "", name: str = "robot") -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(
        f"name: {name}\nmodel: tricycle\n{dataset}\ninitial_guess: auto\nresidual: {{horizon_s: 0.5}}\n"
        f"solvers: [gauss_newton]\nvalidation: {{blocks: 0}}\n{extra}"
    )
    return path


def _assert_recovered(params: dict[str, float], truth: dict[str, float]) -> None:
    """The targets of issue 21 on the simulated truth."""
    assert abs(params["wheel_radius"] / truth["wheel_radius"] - 1) < 0.005
    assert abs(params["wheelbase"] / truth["wheelbase"] - 1) < 0.01
    assert abs(params["sensor_x"] - truth["sensor_x"]) < 0.01
    assert abs(params["sensor_y"] - truth["sensor_y"]) < 0.01
    assert abs(params["sensor_theta"] - truth["sensor_theta"]) < 0.005


# --- the target: a recording as it is, calibrated in the robot's own units ---------------------


@pytest.mark.parametrize("fmt", ["sqlite3", "mcap"])
def test_a_recording_calibrates_in_robot_units_with_only_topics_and_joints(
    fmt: str, recording: rb.Recording, bag_run: Callable[[str], tuple[subprocess.CompletedProcess[str], Path]]
) -> None:
    proc, out = bag_run(fmt)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((out / "result.json").read_text())
    params = doc["solvers"]["gauss_newton"]["params"]
    for name, value in params.items():
        t = recording.truth[name]
        print(f"{fmt} {name}: {value:.6g} (truth {t:.6g}; off by {value - t:+.2e})")
    _assert_recovered(params, recording.truth)
    # The time offset, fitted by default, is found where the stamps put it.
    lag_std = doc["solvers"]["gauss_newton"]["std"]["tracker_lag"]
    assert abs(params["tracker_lag"] - recording.truth["tracker_lag"]) <= 3 * lag_std
    faults = doc["faults"]["found"]
    assert [f for f in faults if f["kind"] != "tracker_jump"] == []  # no encoder fault
    assert sum(f["kind"] == "tracker_jump" for f in faults) >= 0.8 * 0.01 * recording.tracker_ns.size
    controller = yaml.safe_load((out / "ros2_control.yaml").read_text())
    held = dict(controller["tricycle_controller"]["ros__parameters"])
    covariances = [held.pop(k) for k in ("pose_covariance_diagonal", "twist_covariance_diagonal")]
    assert held == {"wheelbase": params["wheelbase"], "wheel_radius": params["wheel_radius"]}
    assert all(len(c) == 6 and all(v > 0 for v in c) for c in covariances)
    calibration = yaml.safe_load((out / "calibration.yaml").read_text())
    assert {e["unit"] for e in calibration["encoders"]} == {"rad"}
    print(f"{fmt}: {(out / 'ros2_control.yaml').read_text()}")


def test_the_residuals_are_formed_at_the_trackers_stamps(
    recording: rb.Recording, bags: dict[str, Path]
) -> None:
    """A record at every tracker pose the joints cover, the pose as published, the joints
    interpolated at its stamp: no pose is made up between two tracker poses."""
    log = BagSource(bags["sqlite3"], "/joint_states", recording.joint_names, "/mocap/robot/pose").read(
        TRICYCLE, strict=True
    )
    inside = (recording.tracker_ns >= recording.joint_ns[0]) & (
        recording.tracker_ns <= recording.joint_ns[-1]
    )
    stamps = log.start_ns + np.round(log.time_s * 1e9).astype(np.int64)
    assert np.array_equal(stamps, recording.tracker_ns[inside])
    assert np.allclose(log.T_world_sensor[:, :2], recording.tracker[inside, :2], rtol=0, atol=1e-12)
    assert log.T_world_sensor_3d is not None
    assert np.allclose(log.T_world_sensor_3d[:, 2], rb.SENSOR_Z)
    yaw_quaternion = np.stack(
        [np.sin(0.5 * log.T_world_sensor[:, 2]), np.cos(0.5 * log.T_world_sensor[:, 2])], 1
    )
    assert np.allclose(np.abs(np.sum(log.T_world_sensor_3d[:, 5:] * yaw_quaternion, axis=1)), 1.0, atol=1e-12)
    t_joint = (recording.joint_ns - log.start_ns) * 1e-9
    for j in range(2):
        expected = np.interp(log.time_s, t_joint, recording.joints[:, j])
        assert np.allclose(log.joint_positions[:, j], expected, rtol=0, atol=1e-12)
    assert log.header.encoder_units == "radians" and log.ticks.shape == (log.n_records, 0)
    # Joints quantised like a 5000-count encoder: the resolution is the step, the noise floor.
    assert math.isclose(log.joint_stream.resolution[1], 2 * math.pi / 5000, rel_tol=1e-9)


def test_a_lag_resamples_the_joints_at_their_own_stamps() -> None:
    """Shifted stamps take the joints from their own messages, never from values already
    interpolated at the tracker's stamps."""
    t_joint = np.arange(0.0, 2.0, 0.01)
    positions = np.stack([np.sin(3 * t_joint), t_joint**2], axis=1)
    stream = JointStream(t_joint, positions, (0.0, 0.0))
    time_s = np.arange(0.05, 1.9, 1 / 120)
    header = robot_header(TRICYCLE.in_radians())
    log = Log(
        path="x",
        header=header,
        time_s=time_s,
        ticks=np.zeros((time_s.size, 0), dtype=np.int64),
        model_pose=np.zeros((time_s.size, 3)),
        T_world_sensor=np.zeros((time_s.size, 3)),
        line_numbers=np.arange(time_s.size),
        joint_positions=stream.at(time_s),
        joint_stream=stream,
    )
    shifted, (a, b) = resample_encoders(log, 0.0137, TRICYCLE.encoder_kinds)
    for j in range(2):
        assert np.allclose(
            shifted.joint_positions[:, j], np.interp(time_s - 0.0137, t_joint, positions[:, j])
        )
    assert (a, b) == (0, time_s.size)  # every shifted stamp lies inside the joints' stream
    assert resample_encoders(log, 0.1, TRICYCLE.encoder_kinds)[1][0] > 0
    # Issue 41: records 40..90 alone re-sampled are the whole re-sampling's, to the bit; the others
    # as logged.
    part, _ = resample_encoders(log, 0.0137, TRICYCLE.encoder_kinds, records=(40, 90))
    assert np.array_equal(part.joint_positions[40:90], shifted.joint_positions[40:90])
    assert np.array_equal(part.joint_positions[:40], log.joint_positions[:40])
    assert np.array_equal(part.joint_positions[90:], log.joint_positions[90:])
    assert part.encoder_lag_s == shifted.encoder_lag_s


# --- the models in radians -----------------------------------------------------------------------


def test_a_model_in_radians_moves_by_its_radius_times_the_angle() -> None:
    dd = get_model("diff_drive").in_radians()
    assert dd.kinematic_params == ("left_wheel_radius", "right_wheel_radius", "wheel_separation")
    assert dd.input_names == ("left_angle", "right_angle") and dd.units["left_wheel_radius"] == "m"
    import casadi as ca

    k, u = ca.SX.sym("k", 3), ca.SX.sym("u", 2)
    f = ca.Function("f", [k, u], [dd.increment(k, u, "euler")])
    r_l, r_r, b, a_l, a_r = 0.1, 0.12, 0.5, 0.3, 0.4
    got = np.asarray(f([r_l, r_r, b], [a_l, a_r])).ravel()
    expected = [0.5 * (r_l * a_l + r_r * a_r), 0.0, (r_r * a_r - r_l * a_l) / b]  # written out
    assert np.allclose(got, expected, rtol=0, atol=1e-15)
    tri = TRICYCLE.in_radians()
    assert tri.kinematic_params == ("k_steer", "wheel_radius", "wheelbase", "steer_offset")
    lo, hi = tri.physical_ranges["wheel_radius"]
    # The counts form's range per radian (1e-4 to 10 m a wheel turn), its top widened to the 2 m
    # wheel the form calls a real robot's.
    assert math.isclose(lo, 1e-4 / (2 * math.pi)) and 10 / (2 * math.pi) < hi == WHEEL_RADIUS[1]
    # The symmetries in the new names: the wheel turned round flips the radius.
    flipped = canonical(
        tri,
        {
            "k_steer": 1.0,
            "wheel_radius": -0.1,
            "wheelbase": 1.2,
            "steer_offset": 0.0,
            "sensor_x": 0.5,
            "sensor_y": 0.0,
            "sensor_theta": 0.0,
        },
    )
    assert flipped["wheel_radius"] == 0.1 and math.isclose(abs(flipped["steer_offset"]), math.pi)


def test_the_controller_of_a_model_in_radians_takes_its_parameters_as_they_are() -> None:
    dd = get_model("diff_drive").in_radians()
    found = dd.controller(
        {"left_wheel_radius": 0.1, "right_wheel_radius": 0.11, "wheel_separation": 0.5}, EncoderScales({})
    )
    values = found.parameters
    assert found.controller == "diff_drive_controller" and values["wheel_separation"] == 0.5
    assert math.isclose(values["wheel_radius"], 0.105)
    assert math.isclose(values["left_wheel_radius_multiplier"] * values["wheel_radius"], 0.1)
    assert "radians" in found.assumes and "ticks" not in found.assumes
    trike = (
        get_model("tricycle_reverse")
        .in_radians()
        .controller(
            {
                "k_steer": 1.0,
                "wheel_radius": 0.2,
                "wheelbase": 1.1,
                "steer_offset": 0.0,
                "k_steer_reverse": 0.0,
            },
            EncoderScales({}),
        )
    )
    assert trike.parameters == {"wheelbase": 1.1, "wheel_radius": 0.2}
    assert set(trike.places) == {"k_steer", "steer_offset", "k_steer_reverse"}
    assert not trike.omitted


def test_a_scenario_names_the_parameters_of_the_joints_units(
    recording: rb.Recording, bags: dict[str, Path], tmp_path: Path
) -> None:
    block = rb.dataset_block(bags["sqlite3"], recording)
    with pytest.raises(
        ScenarioError, match=r"fixed: 'k_traction' is not one of k_steer, wheel_radius, wheelbase"
    ):
        load_scenario(_scenario(tmp_path, block, "fixed: [k_traction]\n"))
    counts = block.replace("}", ", joint_units: counts}")
    mixed = f"datasets: [{block.split(': ', 1)[1]}, {counts.split(': ', 1)[1]}]"
    with pytest.raises(ScenarioError, match=r"datasets: logs fitted together need their joints in one unit"):
        load_scenario(_scenario(tmp_path, mixed))


# --- clocks and stamps --------------------------------------------------------------------------


def test_joints_on_another_clock_are_refused_then_read_with_an_estimated_offset(
    recording: rb.Recording, tmp_path: Path
) -> None:
    since_boot = -int(recording.joint_ns[0]) + 123 * 10**9  # the joints count from the robot's boot
    bag = rb.write(recording, tmp_path / "boot", "mcap", joint_shift_ns=since_boot)
    source = BagSource(bag, "/joint_states", recording.joint_names, "/mocap/robot/pose")
    with pytest.raises(BagError, match=r"do not overlap: .*clock_offset: auto"):
        source.read(TRICYCLE, strict=True)
    from dataclasses import replace

    with pytest.warns(NlpCalibWarning, match=r"clock_offset auto: the stamps of '/joint_states' lie"):
        log = replace(source, clock_offset="auto").read(TRICYCLE, strict=True)
    direct = BagSource(
        rb.write(recording, tmp_path / "same", "mcap"),
        "/joint_states",
        recording.joint_names,
        "/mocap/robot/pose",
    ).read(TRICYCLE, strict=True)
    # Both topics are recorded 2 ms after their stamps: the offset is found to the nanosecond.
    assert np.allclose(log.joint_positions, direct.joint_positions, rtol=0, atol=1e-9)


def test_zero_stamps_are_said_and_receive_times_are_asked_for(
    recording: rb.Recording, tmp_path: Path
) -> None:
    bag = rb.write(recording, tmp_path / "zeros", "sqlite3", zero_stamps=True)
    source = BagSource(bag, "/joint_states", recording.joint_names, "/mocap/robot/pose")
    with pytest.warns(
        NlpCalibWarning, match=r"every header stamp on '/joint_states' is zero; .*record times"
    ):
        source.read(TRICYCLE, strict=True)
    import warnings
    from dataclasses import replace

    with warnings.catch_warnings():
        warnings.simplefilter("error", NlpCalibWarning)  # asked for: nothing to say
        log = replace(source, stamps={"/joint_states": "receive"}).read(TRICYCLE, strict=True)
    assert log.n_records > 0.99 * recording.tracker_ns.size


def test_wheels_that_publish_only_velocities_are_integrated(tmp_path: Path) -> None:
    rec = rb.record("diff_drive", seconds=40.0, seed=7)
    bag = rb.write(rec, tmp_path / "vel", "mcap", velocities=True)
    sc = tmp_path / "dd.yaml"
    sc.write_text(
        f"name: dd\nmodel: diff_drive\n{rb.dataset_block(bag, rec)}\ninitial_guess: auto\n"
        "residual: {horizon_s: 0.5}\nsolvers: [gauss_newton]\nvalidation: {blocks: 0}\n"
    )
    with pytest.warns(NlpCalibWarning, match=r"joints integrated from their velocities: left_wheel_joint"):
        run = Calibration(load_scenario(sc)).run()
    params = run.reports["gauss_newton"].result.param_dict()
    for name in ("left_wheel_radius", "right_wheel_radius", "wheel_separation"):
        assert abs(params[name] / rec.truth[name] - 1) < 0.005, name


def test_a_steering_angle_cannot_come_from_velocities(recording: rb.Recording, tmp_path: Path) -> None:
    bag = rb.write(recording, tmp_path / "vel", "sqlite3", velocities=True)
    sc = load_scenario(_scenario(tmp_path, rb.dataset_block(bag, recording)))
    with (
        pytest.warns(NlpCalibWarning),
        pytest.raises(ModelError, match=r"'steering' publishes only its velocity"),
    ):
        Calibration(sc)


def test_a_horizon_in_seconds_and_a_short_one_at_a_high_rate(
    recording: rb.Recording, bags: dict[str, Path], tmp_path: Path
) -> None:
    sc = load_scenario(_scenario(tmp_path, rb.dataset_block(bags["mcap"], recording)))
    cal = Calibration(sc)
    assert cal.fns.spec.horizon == 60  # 0.5 s at 120 Hz
    short = sc.with_options(residual=type(sc.objective.residual)(horizon=2))
    with pytest.warns(NlpCalibWarning, match=r"residual\.horizon 2 record\(s\) spans 17 ms at 120 Hz"):
        Calibration(short)


def test_tf_static_gives_the_nominal_mount(
    recording: rb.Recording, bags: dict[str, Path], tmp_path: Path
) -> None:
    source = BagSource(
        bags["sqlite3"],
        "/joint_states",
        recording.joint_names,
        "/mocap/robot/pose",
        sensor_frame="mocap_marker",
    )
    header = source.header(TRICYCLE)
    x, y, z, roll, pitch, yaw = rb.NOMINAL_MOUNT
    assert np.allclose(header.T_base_sensor, (x, y, yaw), rtol=0, atol=1e-12)
    assert np.allclose(header.sensor_z_roll_pitch, (z, roll, pitch), rtol=0, atol=1e-12)
    assert header.sensor_frame == "mocap_marker"
    plain = BagSource(bags["sqlite3"], "/joint_states", recording.joint_names, "/mocap/robot/pose").header(
        TRICYCLE
    )
    assert plain.sensor_z_roll_pitch is None  # no sensor frame named: nothing to look up
    block = rb.dataset_block(bags["sqlite3"], recording, ", sensor_frame: mocap_marker")
    sc = load_scenario(_scenario(tmp_path, block, name="mounted"))
    cal = Calibration(sc)
    assert [cal.initial[n] for n in ("sensor_x", "sensor_y", "sensor_theta")] != [x, y, yaw]  # auto
    run = cal.run()
    joint = urdf_joint(run, "gauss_newton")
    p = run.reports["gauss_newton"].result.param_dict()
    origin = dict(re.findall(r'(xyz|rpy)="([^"]*)"', joint))
    xyz, rpy = (np.array(origin[k].split(), dtype=float) for k in ("xyz", "rpy"))
    # x, y, yaw calibrated; z, roll, pitch the nominal mount's (through a quaternion and back)
    assert np.allclose(xyz, [p["sensor_x"], p["sensor_y"], z], rtol=0, atol=1e-12)
    assert np.allclose(rpy, [roll, pitch, p["sensor_theta"]], rtol=0, atol=1e-12)
    initial = initial_parameters(sc.with_options(initial_guess="from_file"), cal.model, cal.log)
    got = [initial[n] for n in ("sensor_x", "sensor_y", "sensor_theta")]
    assert np.allclose(got, [x, y, yaw], rtol=0, atol=1e-12)


# --- the CSV joint log and the tracker's TUM file -------------------------------------------------


def test_import_bag_writes_joints_and_poses_that_calibrate_as_the_bag(
    recording: rb.Recording,
    bags: dict[str, Path],
    bag_run: Callable[[str], tuple[subprocess.CompletedProcess[str], Path]],
    tmp_path: Path,
) -> None:
    out = tmp_path / "drive.csv"
    args = ["import-bag", str(bags["mcap"]), "--out", str(out), "--model", "tricycle", "--joint-states"]
    args += ["/joint_states", "--joints", ",".join(recording.joint_names), "--tracker", "/mocap/robot/pose"]
    proc = cli(*args)
    assert proc.returncode == 0, proc.stderr
    assert "dataset: {joints: " in proc.stdout and "encoders: {steering: front_steer_joint" in proc.stdout
    table = read_joint_csv(out)
    assert np.array_equal(table.time_ns, recording.joint_ns) and table.names == recording.joint_names
    assert np.array_equal(table.positions, recording.joints)
    block = (
        f"dataset: {{joints: {out}, poses: {out.with_suffix('.tum')}, encoders: "
        f"{{steering: {recording.joint_names[0]}, traction_wheel: {recording.joint_names[1]}}}}}"
    )
    files = Calibration(load_scenario(_scenario(tmp_path, block, name="files"))).run()
    fitted = files.reports["gauss_newton"].result.param_dict()
    proc, bag_out = bag_run("mcap")  # the same scenario on the bag itself
    assert proc.returncode == 0, proc.stderr
    read = json.loads((bag_out / "result.json").read_text())["solvers"]["gauss_newton"]["params"]
    assert list(read) == list(fitted)
    a, e = np.array(list(fitted.values())), np.array(list(read.values()))
    assert np.max(np.abs(a - e) / np.maximum(np.abs(e), 1e-3)) < 1e-9


def test_a_joint_log_block_names_its_keys(tmp_path: Path) -> None:
    with pytest.raises(
        ScenarioError, match=r"dataset: a joint-log block needs joints, poses, encoders; missing poses"
    ):
        load_scenario(
            _scenario(tmp_path, "dataset: {joints: a.csv, encoders: {steering: s, traction_wheel: t}}")
        )
    with pytest.raises(
        ScenarioError, match=r"dataset\.encoders: name the joint of each of tricycle's encoders"
    ):
        load_scenario(_scenario(tmp_path, "dataset: {joints: a.csv, poses: p.tum, encoders: {left: l}}"))
    bad = tmp_path / "j.csv"
    bad.write_text("time,a,b\n1.0,0,0\n0.5,0,0\n")
    with pytest.raises(Exception, match=r"j\.csv:3: timestamp .* is not after the previous one .* on line 2"):
        read_joint_csv(bad)


# --- what other tools compare ---------------------------------------------------------------------


def test_evo_reproduces_the_reported_ate_against_the_bags_own_topic(
    bags: dict[str, Path], bag_run: Callable[[str], tuple[subprocess.CompletedProcess[str], Path]]
) -> None:
    evo = pytest.importorskip("evo")
    from evo.core import metrics, sync
    from evo.tools import file_interface
    from rosbags.rosbag2 import Reader

    proc, out = bag_run("sqlite3")  # with --report: the trajectories
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((out / "result.json").read_text())
    with Reader(bags["sqlite3"]) as reader:
        reference = file_interface.read_bag_trajectory(reader, "/mocap/robot/pose")
    estimate = file_interface.read_tum_trajectory_file(str(out / "trajectories" / "gauss_newton.tum"))
    reference, estimate = sync.associate_trajectories(reference, estimate)  # evo_ape's defaults
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((reference, estimate))
    mean = ape.get_statistic(metrics.StatisticsType.mean)
    reported = doc["solvers"]["gauss_newton"]["metrics"]["ate"]["mean"]
    print(f"evo {evo.__version__}: ATE mean {mean:.9f} m against the bag's topic; reported {reported:.9f} m")
    assert estimate.num_poses == doc["solvers"]["gauss_newton"]["metrics"]["ate"]["n"]
    assert math.isclose(mean, reported, rel_tol=1e-6)


def test_the_tracker_lag_is_found_on_the_joints_own_stamps(recording: rb.Recording, tmp_path: Path) -> None:
    from dataclasses import replace

    late = replace(recording, tracker_ns=recording.tracker_ns + 30_000_000)  # poses stamped 30 ms late
    bag = rb.write(late, tmp_path / "late", "mcap")
    extra = "alignment: {tracker_lag: auto, search: [-0.05, 0.08], step: 0.005}\n"
    cal = Calibration(load_scenario(_scenario(tmp_path, rb.dataset_block(bag, late), extra)))
    print(f"tracker lag estimated {1e3 * cal.alignment.lag_s:.2f} ms (stamped 30 ms late)")
    assert abs(cal.alignment.lag_s - 0.030) < 0.003
    _assert_recovered(cal.run().reports["gauss_newton"].result.param_dict(), recording.truth)


def test_a_wheel_fault_is_told_in_radians_never_in_counter_widths(
    recording: rb.Recording, tmp_path: Path
) -> None:
    from dataclasses import replace

    joints = recording.joints.copy()
    jump = np.searchsorted(recording.joint_ns, recording.joint_ns[0] + 30 * 10**9)
    joints[jump:, 1] += 3.0  # the wheel's angle jumps by 3 rad and stays there
    bag = rb.write(replace(recording, joints=joints), tmp_path / "jump", "sqlite3")
    cal = Calibration(load_scenario(_scenario(tmp_path, rb.dataset_block(bag, recording))))
    counter = cal.findings.report.counter_faults
    assert [f.encoder for f in counter] == ["traction_wheel"]
    evidence = counter[0].evidence
    print(evidence)
    assert "rad" in evidence and "2^16" not in evidence and "ticks" not in evidence
    assert abs(counter[0].implied - counter[0].logged + 3.0) < 0.1  # the tracker implies 3 rad less


def test_logs_fitted_together_take_one_record_horizon() -> None:
    from types import SimpleNamespace

    from nlp_calib.pipeline.prepare import joint_residual
    from nlp_calib.problem import ResidualOptions

    def part(rate: float, horizon: int) -> SimpleNamespace:
        sc = SimpleNamespace(
            objective=SimpleNamespace(residual=ResidualOptions(horizon=horizon)),
            log=SimpleNamespace(samples=SimpleNamespace(start=0, stop=None)),
        )
        return SimpleNamespace(scenario=sc, log=SimpleNamespace(time_s=np.arange(500) / rate))

    def joint(residual: ResidualOptions) -> SimpleNamespace:
        return SimpleNamespace(objective=SimpleNamespace(residual=residual), path=None, name="j")

    with pytest.raises(
        ScenarioError, match=r"horizon_s 0\.5 s is 60 records, 0\.5 s on datasets\[0\], 12 records"
    ):
        joint_residual(joint(ResidualOptions(horizon_s=0.5)), [part(120.0, 60), part(25.0, 12)])  # type: ignore[arg-type]
    with pytest.warns(NlpCalibWarning, match=r"residual\.horizon 25 records spans very different durations"):
        got = joint_residual(joint(ResidualOptions(horizon=25)), [part(120.0, 25), part(25.0, 25)])  # type: ignore[arg-type]
    assert got.horizon == 25


def test_a_steering_spike_in_radians_is_found_and_repaired_in_the_joints_stream(
    recording: rb.Recording, tmp_path: Path
) -> None:
    """One steering message off by 0.4 rad: the joint's own screen finds it (in radians, at the
    record the message falls on) and ``repair`` interpolates it out of the stream the lag re-samples."""
    from dataclasses import replace

    from nlp_calib.analysis.faults import repair

    joints = recording.joints.copy()
    k = int(np.searchsorted(recording.joint_ns, recording.joint_ns[0] + 20 * 10**9))
    joints[k, 0] += 0.4
    bag = rb.write(replace(recording, joints=joints), tmp_path / "spike", "sqlite3")
    cal = Calibration(load_scenario(_scenario(tmp_path, rb.dataset_block(bag, recording))))
    report = cal.findings.report
    spikes = [f for f in report.faults if f.kind == "steering_spike"]
    assert report.unit == "rad" and [f.encoder for f in spikes] == ["steering"], report.faults
    assert "rad" in spikes[0].evidence and "ticks" not in spikes[0].evidence
    assert "logged_rad" in spikes[0].as_dict(report.unit)
    fixed, changes = repair(cal.log, report)
    assert fixed.joint_stream is not None and cal.log.joint_stream is not None
    col = cal.log.header.encoder_index("steering")
    moved = np.abs(fixed.joint_stream.positions[:, col] - cal.log.joint_stream.positions[:, col])
    assert 0.3 < moved.max() < 0.5 and np.sum(moved > 0.01) == 1  # that message, and only it
    assert len(changes) == 1 and "spike interpolated" in changes[0]


def test_a_bags_faults_are_named_by_topic_and_message(recording: rb.Recording, tmp_path: Path) -> None:
    """A fault in a bag is placed by its tracker topic's message number (the message at the
    fault's record, found from the recording's own stamps), in the evidence, the terminal and
    report.md: no 'line' of a file that has none; a text log's faults keep their lines."""
    from dataclasses import replace

    from nlp_calib.outputs.markdown import report_markdown
    from nlp_calib.outputs.terminal import check_lines

    joints = recording.joints.copy()
    jump = np.searchsorted(recording.joint_ns, recording.joint_ns[0] + 30 * 10**9)
    joints[jump:, 1] += 3.0
    bag = rb.write(replace(recording, joints=joints), tmp_path / "jump", "sqlite3")
    cal = Calibration(load_scenario(_scenario(tmp_path, rb.dataset_block(bag, recording))))
    (fault,) = cal.findings.report.counter_faults
    stamp = cal.log.start_ns + round(float(cal.log.time_s[fault.record]) * 1e9)
    message = int(np.argmin(np.abs(recording.tracker_ns - stamp))) + 1
    assert fault.line == message
    topic = "/mocap/robot/pose message"
    assert f"({topic}s " in fault.evidence and "line" not in fault.evidence
    run = cal.run()
    shown = [line for line in check_lines(run) if f"record {fault.record} " in line]
    assert shown and f"({topic} {message}, t = " in shown[0]
    assert f"| record | {topic} | time [s] |" in report_markdown(run, [])
    assert f"| {fault.record} | {message} |" in report_markdown(run, [])
    text = replace(cal.log, reference=replace(cal.log.reference, numbered="line"))
    assert text.where(4) == "line 4" and text.where(4, 9) == "lines 4-9"
