"""A camera on a planar robot end to end through a scenario (issue 22): ``sensor: 3d`` on a TUM
trajectory with a CSV joint log, ``initial_guess: auto``, the lag estimated, both solvers, the
outputs, ``nlp-calib simulate`` of a camera and the shipped demo."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO, cli

from nlp_calib.core import poses3d
from nlp_calib.core.errors import NlpCalibError, ScenarioError
from nlp_calib.models import get_model
from nlp_calib.outputs.handoff import calibration_dict, urdf_joint
from nlp_calib.outputs.results import result_document
from nlp_calib.pipeline import Calibration, Scenario, load_scenario
from nlp_calib.results import CalibrationRun
from nlp_calib.sensors import sensor_for
from nlp_calib.simulation.camera import CameraSimulationOptions, simulate_camera, write_camera_simulation

#: The target recording of issue 22: roll −120° (30° down), yaw −90°, images stamped 10 ms late,
#: 50 Hz images over 100 Hz joints, no noise.
TARGET = {"stamp_offset_s": 0.010, "image_rate_hz": 50.0, "joint_rate_hz": 100.0, "duration_s": 60.0}
ENCODERS = "{left_wheel: left_wheel_joint, right_wheel: right_wheel_joint}"
ANGLES = ("sensor_roll", "sensor_pitch", "sensor_yaw")


@dataclass
class Case:
    truth: dict[str, float]
    run: CalibrationRun

    def params(self, solver: str = "gauss_newton") -> dict[str, float]:
        return self.run.reports[solver].result.param_dict()


def recording(folder: Path, **options: object) -> dict[str, float]:
    """Simulate a camera and write its files as ``folder/cam.tum`` (+ joints, truth); the truth in
    the scenario's names."""
    sim = simulate_camera(CameraSimulationOptions(**options))  # type: ignore[arg-type]
    write_camera_simulation(sim, folder / "cam.tum")
    names = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}
    return {names.get(n, n): v for n, v in sim.truth.items()}


def scenario(folder: Path, extra: str = "", sensor: str = "3d", name: str = "cam") -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(
        f"name: {name}\nmodel: diff_drive\nsensor: {sensor}\n"
        f"dataset: {{poses: cam.tum, joints: cam.joints.csv, encoders: {ENCODERS}}}\n"
        "initial_guess: auto\nalignment: {tracker_lag: auto, search: [-0.05, 0.05], step: 0.005}\n"
        "robust: {kernel: none}\nvalidation: {blocks: 0}\n" + extra
    )
    return path


def rotation_error_deg(params: dict[str, float], truth: dict[str, float]) -> float:
    R = poses3d.rpy_to_matrix(np.array([params[n] for n in ANGLES]))
    R_true = poses3d.rpy_to_matrix(np.array([truth[n] for n in ANGLES]))
    return float(np.degrees(np.linalg.norm(poses3d.quat_to_rotvec(poses3d.matrix_to_quat(R_true.T @ R)))))


def check_targets(params: dict[str, float], truth: dict[str, float]) -> None:
    """Mount rotation within 0.05°, x/y within 1 mm, radii and separation within 0.05 %."""
    errors = {n: params[n] - truth[n] for n in ("sensor_x", "sensor_y")}
    relative = {
        n: params[n] / truth[n] - 1 for n in ("left_wheel_radius", "right_wheel_radius", "wheel_separation")
    }
    print(f"rotation {rotation_error_deg(params, truth):.2e} deg, lever {errors}, relative {relative}")
    assert rotation_error_deg(params, truth) < 0.05
    assert all(abs(e) < 1e-3 for e in errors.values())
    assert all(abs(r) < 5e-4 for r in relative.values())


@pytest.fixture(scope="module")
def target(tmp_path_factory: pytest.TempPathFactory) -> Case:
    folder = tmp_path_factory.mktemp("camera_target")
    truth = recording(folder, **TARGET)
    return Case(truth, Calibration.setup(load_scenario(scenario(folder))).run())


@pytest.fixture(scope="module")
def monocular(tmp_path_factory: pytest.TempPathFactory) -> Case:
    folder = tmp_path_factory.mktemp("camera_mono")
    truth = recording(folder, **TARGET, scale=3.7)
    known = "known: {wheel_separation: 0.45, sensor_z: 0.30}\n"
    path = scenario(folder, known, sensor="{mount: 3d, scale: free}")
    return Case(truth, Calibration.setup(load_scenario(path)).run())


def test_noise_free_camera_reaches_the_targets_through_a_scenario(target: Case) -> None:
    for solver in ("gauss_newton", "ipopt"):
        assert target.run.reports[solver].result.converged
        check_targets(target.params(solver), target.truth)
    assert target.run.data.tracker_lag_s == pytest.approx(0.010, abs=1e-3)


def test_the_closed_form_start_alone_is_within_a_degree_and_a_centimetre(target: Case) -> None:
    start = target.run.initial
    assert rotation_error_deg(start, target.truth) < 1.0
    assert all(abs(start[n] - target.truth[n]) < 0.01 for n in ("sensor_x", "sensor_y"))
    dropped = target.run.data.start_dropped
    assert dropped is not None and set(dropped) >= {"tiny_translation", "small_rotation", "axis_off_normal"}
    assert target.run.data.fit_dropped is not None


def test_gauss_newton_and_ipopt_agree(target: Case) -> None:
    gn, ip = (target.run.reports[s].result.params for s in ("gauss_newton", "ipopt"))
    assert np.max(np.abs(gn - ip) / np.maximum(np.abs(gn), 1e-3)) < 1e-6


def test_monocular_poses_give_the_scale_with_one_known_length(monocular: Case) -> None:
    params = monocular.params()
    assert abs(params["scale"] / 3.7 - 1) < 1e-3
    check_targets(params, monocular.truth)
    assert params["sensor_z"] == 0.30 and params["wheel_separation"] == 0.45


def test_a_trajectory_up_to_scale_is_scored_in_metres(target: Case, monocular: Case) -> None:
    # The same drive (seed and options) written in metres and in units of 3.7 m.
    metres, scaled = target.run.baseline.distance_m, monocular.run.baseline.distance_m
    assert scaled == pytest.approx(metres, rel=1e-3)


def test_the_outputs_hold_the_full_mount(target: Case) -> None:
    doc = result_document(target.run)
    assert doc["sensor"]["mount"] == "3d" and doc["sensor"]["held"] == {"sensor_z": 0.0}
    assert "planar driving cannot determine" in doc["sensor"]["held_why"]
    assert doc["sensor"]["start"]["sensor_roll"] == target.run.initial["sensor_roll"]
    calibration = calibration_dict(target.run)
    assert calibration is not None
    assert set(calibration["parameters"]) >= {"sensor_x", "sensor_y", "sensor_z", *ANGLES}
    joint = urdf_joint(target.run, "gauss_newton")
    p = target.params()
    assert f'rpy="{p["sensor_roll"]!r} {p["sensor_pitch"]!r} {p["sensor_yaw"]!r}"' in joint
    assert any("sensor_z is held" in w for w in target.run.warnings)
    findings = target.run.checks.findings
    assert findings is not None and findings.report.unchecked == "" and findings.report.faults == ()
    assert not any("not screened for jumps" in w for w in target.run.warnings)  # they are now


def test_a_stored_camera_run_writes_the_same_document(target: Case) -> None:
    back = CalibrationRun.from_data(target.run.to_data())
    assert back.data.start_dropped == target.run.data.start_dropped
    assert result_document(back) == result_document(target.run)


def test_the_truth_beside_the_tum_file_is_compared_in_sigma(target: Case) -> None:
    truth = target.run.checks.truth
    assert truth is not None and truth.path.endswith("cam.truth.json")
    assert "left_wheel_radius" in truth.names and np.isfinite(
        truth.truth[truth.names.index("left_wheel_radius")]
    )


@pytest.mark.parametrize(
    ("sensor", "words"),
    [
        ("6d", "sensor.mount: '6d' is not one of planar, 3d"),
        ("{mount: planar, scale: free}", "a free scale needs a 3-D sensor"),
        ("{mount: 3d, scale: loose}", "sensor.scale"),
    ],
)
def test_a_bad_sensor_is_one_line_on_load(tmp_path: Path, sensor: str, words: str) -> None:
    recording(tmp_path, duration_s=5.0)
    with pytest.raises(ScenarioError) as exc:
        load_scenario(scenario(tmp_path, sensor=sensor))
    assert "\n" not in str(exc.value) and words in str(exc.value)


def test_bad_camera_input_is_one_line_naming_the_file(tmp_path: Path) -> None:
    recording(tmp_path, duration_s=20.0)
    tum = tmp_path / "cam.tum"
    lines = tum.read_text().splitlines()
    lines[5] = " ".join(lines[5].split()[:7])
    tum.write_text("\n".join(lines) + "\n")
    with pytest.raises(NlpCalibError) as exc:
        Calibration.setup(load_scenario(scenario(tmp_path)))
    assert "\n" not in str(exc.value) and str(exc.value).startswith(f"{tum}:6: has 7 columns")


def test_too_little_rotation_to_see_the_floor_normal_is_one_line(tmp_path: Path) -> None:
    from nlp_calib.simulation.options import DriveShape

    recording(tmp_path, duration_s=20.0, drive=DriveShape(trajectory="straight", stop_fraction=0.1))
    with pytest.raises(NlpCalibError) as exc:
        Calibration.setup(load_scenario(scenario(tmp_path)))
    assert "\n" not in str(exc.value) and "too little rotation" in str(exc.value)


def test_simulate_writes_a_camera_and_the_planar_only_commands_refuse_it(tmp_path: Path) -> None:
    out = cli(
        "simulate", "--out", str(tmp_path / "cam.tum"), "--duration", "20", "--seed", "3", "--latency", "0.01"
    )
    assert out.returncode == 0, out.stderr
    assert {p.name for p in tmp_path.iterdir()} == {"cam.tum", "cam.joints.csv", "cam.truth.json"}
    assert json.loads((tmp_path / "cam.truth.json").read_text())["lag_s"] == 0.01
    refused = cli("simulate", "--out", str(tmp_path / "x.tum"), "--records", "30")
    assert refused.returncode == 2 and "does not apply to a camera simulation" in refused.stderr
    path = scenario(tmp_path)
    odometry = cli("odometry", str(path), "--out", str(tmp_path / "odo"))
    assert odometry.returncode == 2
    assert "odometry is not available for a 3-D sensor" in odometry.stderr.strip().splitlines()[-1]


@pytest.mark.slow
def test_the_shipped_camera_demo_runs_end_to_end_and_shows_the_truth(tmp_path: Path) -> None:
    out = cli("run", "scenarios/camera_demo.yaml", "--out", str(tmp_path / "demo"), "--report")
    assert out.returncode == 0, out.stderr
    # The exported tracker track is the camera's own trajectory, orientation included (for evo).
    exported = np.loadtxt(tmp_path / "demo" / "trajectories" / "tracker.tum")
    given = np.loadtxt(REPO / "scenarios" / "data" / "camera_demo.tum")
    assert exported.shape == given.shape and np.allclose(exported[:, 1:], given[:, 1:], atol=1e-9)
    assert "against the simulator's truth" in out.stdout and "closed-form start alone" in out.stdout
    doc = json.loads((tmp_path / "demo" / "result.json").read_text())
    assert max(abs(z) for z in doc["truth"]["error_in_sigma"].values() if z is not None) < 3.0
    calibration = yaml.safe_load((tmp_path / "demo" / "calibration.yaml").read_text())
    assert calibration["parameters"]["sensor_z"] == 0.30
    assert (REPO / "scenarios" / "data" / "camera_demo.truth.json").is_file()


def test_no_overlap_in_time_with_the_joints_is_one_line(tmp_path: Path) -> None:
    recording(tmp_path, duration_s=10.0)
    tum = tmp_path / "cam.tum"
    rows = [line.split() for line in tum.read_text().splitlines()]
    tum.write_text("".join(" ".join([f"{float(r[0]) + 1000.0:.9f}", *r[1:]]) + "\n" for r in rows))
    with pytest.raises(NlpCalibError) as exc:
        Calibration.setup(load_scenario(scenario(tmp_path)))
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{tmp_path / 'cam.joints.csv'}: its times")
    assert "do not overlap" in msg and "clock_offset" in msg


def test_a_tricycle_with_a_camera_calibrates_in_robot_units(tmp_path: Path) -> None:
    truth = recording(tmp_path, model="tricycle", **{**TARGET, "duration_s": 40.0})
    path = tmp_path / "tri.yaml"
    path.write_text(
        "model: tricycle\nsensor: 3d\ninitial_guess: auto\nknown: {sensor_z: 0.30}\nvalidation: {blocks: 0}\n"
        "dataset: {poses: cam.tum, joints: cam.joints.csv,\n"
        "          encoders: {steering: steering_joint, traction_wheel: traction_wheel_joint}}\n"
        "alignment: {tracker_lag: auto, search: [-0.05, 0.05], step: 0.005}\n"
    )
    run = Calibration.setup(load_scenario(path)).run()
    params = run.reports["gauss_newton"].result.param_dict()
    assert "wheel_radius" in params and "wheelbase" in params
    assert rotation_error_deg(params, truth) < 0.05
    check = run.checks.truth
    assert check is not None
    # The simulator's traction gain is metres per revolution: the run's wheel radius per radian.
    assert check.truth[check.names.index("wheel_radius")] == pytest.approx(truth["k_traction"] / (2 * np.pi))
    # The lower layer's tolerance for every model (tests/test_camera.py), here with the lag estimated;
    # the lag (a parameter of the fit, absorbing the steering read at each interval's start) within 2 ms.
    for name, true, error in zip(check.names, check.truth, check.error):
        assert abs(error) <= (2e-3 if name == "tracker_lag" else 1e-3 * max(abs(true), 1.0)), name


def noisy_demos(folder: Path, seeds: int = 10) -> Iterator[Scenario]:
    """The shipped demo's scenario on recordings of its noise (1 mm, 0.1°) from other seeds."""
    from nlp_calib.simulation.camera import CameraNoise

    demo = (REPO / "scenarios" / "camera_demo.yaml").read_text().replace("data/camera_demo", "cam")
    for seed in range(seeds):
        (folder / f"seed{seed}").mkdir()
        noise = CameraNoise(0.001, 0.0017)
        recording(folder / f"seed{seed}", duration_s=40.0, seed=seed, stamp_offset_s=0.01, noise=noise)
        (folder / f"seed{seed}" / "c.yaml").write_text(demo)
        yield load_scenario(folder / f"seed{seed}" / "c.yaml")


@pytest.mark.slow
def test_realistic_noise_truth_within_three_sigma_on_most_seeds(tmp_path: Path) -> None:
    """1 mm and 0.1° of pose noise, the shipped demo's scenario on other seeds."""
    worst = []
    for sc in noisy_demos(tmp_path):
        check = Calibration.setup(sc).run().checks.truth
        assert check is not None
        worst.append(float(np.nanmax(np.abs(check.z))))
    print("largest |estimate − truth| / σ per seed:", np.round(worst, 2))
    assert np.mean(np.array(worst) < 3.0) >= 0.9


@pytest.mark.parametrize("seed", [2, 3])
def test_forward_and_reverse_agree_on_a_noise_free_camera_with_its_lag_fitted(
    tmp_path: Path, seed: int
) -> None:
    """Issue 38: the shipped demo's scenario on a noise-free recording. The σ of the two parts'
    difference is nearly nothing, so a discretisation bias of microseconds of lag is many σ; it is
    no finding below the precision the drive needs, the one the verdict judges by."""
    demo = (REPO / "scenarios" / "camera_demo.yaml").read_text().replace("data/camera_demo", "cam")
    recording(tmp_path, duration_s=60.0, seed=seed)
    one_solver = demo.replace("solvers: [gauss_newton, ipopt]", "solvers: [gauss_newton]")
    (tmp_path / "c.yaml").write_text(one_solver)
    run = Calibration.setup(load_scenario(tmp_path / "c.yaml")).run()
    check = run.checks.direction
    assert check is not None and check.compared and check.needed is not None
    assert not check.significant, check.sentence()
    assert not any("forward" in r for r in run.verdict.reasons), run.verdict.reasons
    values = dict(zip(check.names, 0.5 * (check.forward + check.reverse)))
    needed = run.scenario.layout.needed({n: values[n] for n in run.scenario.layout.names})
    for name, amount in needed.items():
        assert check.needed[check.names.index(name)] == pytest.approx(amount, rel=1e-12), name


@pytest.mark.slow
def test_a_ros2_bags_tracker_read_as_a_3d_sensor(tmp_path: Path) -> None:
    """A bag's PoseStamped with its full orientation (a level sensor here: roll and pitch 0)."""
    import ros2_bags as rb

    rec = rb.record()
    bag = rb.write(rec, tmp_path / "drive", "sqlite3")
    path = tmp_path / "b.yaml"
    path.write_text(
        f"model: tricycle\nsensor: 3d\n{rb.dataset_block(bag, rec)}\ninitial_guess: auto\n"
        f"residual: {{horizon_s: 0.5}}\nknown: {{sensor_z: {rb.SENSOR_Z}}}\nsolvers: [gauss_newton]\n"
    )
    p = Calibration.setup(load_scenario(path)).run().reports["gauss_newton"].result.param_dict()
    t = rec.truth
    assert abs(p["sensor_roll"]) < 1e-3 and abs(p["sensor_pitch"]) < 1e-3
    assert abs(p["sensor_yaw"] - t["sensor_theta"]) < 0.005
    assert (
        abs(p["wheel_radius"] / t["wheel_radius"] - 1) < 0.005
        and abs(p["wheelbase"] / t["wheelbase"] - 1) < 0.01
    )
    assert abs(p["sensor_x"] - t["sensor_x"]) < 0.01 and abs(p["sensor_y"] - t["sensor_y"]) < 0.01


def test_a_wheel_joint_jump_is_found_against_the_camera_and_left_out(tmp_path: Path) -> None:
    data = REPO / "scenarios" / "data"
    (tmp_path / "cam.tum").write_bytes((data / "camera_demo.tum").read_bytes())
    lines = (data / "camera_demo.joints.csv").read_text().splitlines()
    for i in range(2000, len(lines)):  # the left wheel loses 0.8 rad at t ≈ 19.5 s
        t, left, right = lines[i].split(",")
        lines[i] = f"{t},{float(left) - 0.8!r},{right}"
    (tmp_path / "cam.joints.csv").write_text("\n".join(lines) + "\n")
    demo = (REPO / "scenarios" / "camera_demo.yaml").read_text().replace("data/camera_demo", "cam")
    (tmp_path / "c.yaml").write_text(demo)
    run = Calibration.setup(load_scenario(tmp_path / "c.yaml")).run()
    findings = run.checks.findings
    assert findings is not None
    assert [(f.kind, f.encoder) for f in findings.report.faults] == [("counter_jump", "left_wheel")]
    assert run.data.dropped_faulty > 0
    truth = json.loads((data / "camera_demo.truth.json").read_text())["params"]
    params = run.reports["gauss_newton"].result.param_dict()
    assert abs(params["left_wheel_radius"] / truth["k_left"] - 1) < 1e-3


def test_data_names_either_file_of_a_joint_log_pair_and_both_move(tmp_path: Path) -> None:
    data = REPO / "scenarios" / "data"
    for suffix in (".tum", ".joints.csv"):
        (tmp_path / f"run2{suffix}").write_bytes((data / f"camera_demo{suffix}").read_bytes())
    sc = load_scenario(REPO / "scenarios" / "camera_demo.yaml")
    for given in ("run2.tum", "run2.joints.csv"):
        source = sc.with_dataset(tmp_path / given).log.source
        assert (source.joints, source.poses) == (tmp_path / "run2.joints.csv", tmp_path / "run2.tum")
        assert source.encoders == sc.log.source.encoders  # the same block on another recording
    # As import-bag writes a pair (NAME.csv beside NAME.tum), and the run reads the moved pair.
    (tmp_path / "run3.csv").write_bytes((data / "camera_demo.joints.csv").read_bytes())
    lines = (data / "camera_demo.tum").read_text().splitlines(keepends=True)
    (tmp_path / "run3.tum").write_text("".join(lines[: len(lines) // 2]))
    out = cli(
        "run",
        "scenarios/camera_demo.yaml",
        "--data",
        str(tmp_path / "run3.csv"),
        "--out",
        str(tmp_path / "out"),
        "--solver",
        "gauss_newton",
    )
    assert out.returncode == 0, out.stderr
    dataset = json.loads((tmp_path / "out" / "result.json").read_text())["dataset"]
    assert dataset["path"] == str(tmp_path / "run3.csv") and dataset["records"] < len(lines) * 0.6


@pytest.mark.parametrize(
    ("files", "given", "words"),
    [
        (("run2.joints.csv",), "run2.joints.csv", "run2.joints.csv: no run2.tum beside it"),
        (("run2.tum", "run2.csv", "run2.joints.csv"), "run2.tum", "two candidate partners run2.csv or"),
        ((), "run2.tum", "run2.tum: no such file"),
    ],
)
def test_data_without_one_partner_beside_it_is_one_line(
    tmp_path: Path, files: tuple[str, ...], given: str, words: str
) -> None:
    for name in files:
        (tmp_path / name).write_text("")
    sc = load_scenario(REPO / "scenarios" / "camera_demo.yaml")
    with pytest.raises(NlpCalibError) as exc:
        sc.with_dataset(tmp_path / given)
    msg = str(exc.value)
    assert "\n" not in msg and words in msg and "dataset block" in msg


def test_the_c_examples_window_names_the_tum_file_its_lines_count(tmp_path: Path) -> None:
    """The window's line numbers are the TUM file's: the camera's motion between those two lines is
    the example's measured motion ``z``."""
    import re

    from nlp_calib.pipeline.export import write_c_export

    sc = load_scenario(REPO / "scenarios" / "camera_demo.yaml")
    _, example = write_c_export(dataclasses.replace(sc, solvers=("gauss_newton",)), tmp_path)
    match = re.search(r"\(lines (\d+)-(\d+)\) of (\S+),", example.window)
    assert match is not None and match.group(3) == "camera_demo.tum", example.window
    lines = (REPO / "scenarios" / "data" / "camera_demo.tum").read_text().splitlines()
    a, b = (np.array(lines[int(match.group(k)) - 1].split()[1:], dtype=float) for k in (1, 2))
    # u, then z, then the clock (two joints' rates at both ends, the lag read at, the log), the weight
    clock = 2 * 2 + 2
    z = example.column[-8 - clock : -1 - clock]
    z = z if z[6] * poses3d.between(a, b)[6] > 0 else np.r_[z[:3], -z[3:]]
    assert np.allclose(poses3d.between(a, b), z, atol=1e-9)


def glitched_demo(folder: Path, line: int, shift_m: np.ndarray, turn_rad: np.ndarray) -> Path:
    """The camera demo's scenario beside a copy of its recording whose TUM ``line`` is moved by
    ``shift_m`` (world frame) and turned by ``turn_rad`` (on the right: the camera's own axes)."""
    data = REPO / "scenarios" / "data"
    (folder / "cam.joints.csv").write_bytes((data / "camera_demo.joints.csv").read_bytes())
    lines = (data / "camera_demo.tum").read_text().splitlines()
    stamp, *values = lines[line - 1].split()
    p = np.array(values, dtype=float)
    q = poses3d.quat_multiply(p[3:], poses3d.rotvec_to_quat(turn_rad))
    lines[line - 1] = " ".join([stamp, *(repr(float(v)) for v in np.r_[p[:3] + shift_m, q])])
    (folder / "cam.tum").write_text("\n".join(lines) + "\n")
    demo = (REPO / "scenarios" / "camera_demo.yaml").read_text().replace("data/camera_demo", "cam")
    (folder / "c.yaml").write_text(demo)
    return folder / "c.yaml"


def test_a_camera_pose_glitch_is_found_and_its_windows_left_out(tmp_path: Path) -> None:
    """5 cm and 2° on one pose of the demo (1 mm and 0.1° of pose noise), while the robot turns."""
    shift, turn = np.array([0.03, -0.04, 0.0]), np.radians(2.0) * np.array([0.0, 0.6, 0.8])
    run = Calibration.setup(load_scenario(glitched_demo(tmp_path, 1000, shift, turn))).run()
    findings = run.checks.findings
    assert findings is not None
    assert [(f.kind, f.line) for f in findings.report.faults] == [("tracker_jump", 1000)]
    assert "by up to 0.05" in findings.report.faults[0].evidence
    assert run.data.dropped_faulty > 0
    truth = json.loads((REPO / "scenarios" / "data" / "camera_demo.truth.json").read_text())["params"]
    gn = run.reports["gauss_newton"]
    names = gn.uncertainty.names
    for name, true in (("sensor_x", truth["sensor_x"]), ("wheel_separation", truth["baseline"])):
        assert abs(gn.result.param_dict()[name] - true) < 3 * gn.uncertainty.std[names.index(name)], name


def test_the_3d_jump_screen_raises_no_alarm_on_clean_camera_poses() -> None:
    from nlp_calib.analysis.faults import tracker_faults

    sc = load_scenario(REPO / "scenarios" / "camera_demo.yaml")
    assert tracker_faults(sc.log.source.read(get_model(sc.model), strict=True), sensor_for("3d")) == []


@pytest.mark.slow
def test_the_3d_jump_screen_raises_no_alarm_on_noisy_simulations(tmp_path: Path) -> None:
    """The demo's noise on 10 seeds: every pose is clean, none is flagged."""
    from nlp_calib.analysis.faults import tracker_faults

    logs = (sc.log.source.read(get_model(sc.model), strict=True) for sc in noisy_demos(tmp_path))
    flagged = [len(tracker_faults(log, sensor_for("3d"))) for log in logs]
    print("poses flagged per seed:", flagged)
    assert flagged == [0] * 10


def test_a_clean_camera_windows_mahalanobis_norm_is_that_of_two_poses_noise_over_six_rows() -> None:
    """camera.md's advice on δ: with Ω from the pose noise a clean window's eᵀΩe is about 2·χ²(6)
    (the window's motion carries its two poses' noise), so δ = 3 leaves about half the windows of
    the demo beyond it and δ = 6 almost none."""
    from nlp_calib.pipeline.options import RobustOptions, ValidationOptions

    sc = load_scenario(REPO / "scenarios" / "camera_demo.yaml")
    inside, said = {}, {}
    for delta in (3.0, 6.0):
        options = {"robust": RobustOptions("huber", delta), "validation": ValidationOptions(blocks=0)}
        result = Calibration.setup(sc.with_options(solvers=("gauss_newton",), **options)).run()
        gn = result.reports["gauss_newton"].result
        inside[delta], n = gn.inliers / gn.n_residuals, gn.n_residuals
        said[delta] = [w for w in result.warnings if "within the robust threshold" in w]
    print("fraction of windows within δ:", inside)
    assert 0.3 < inside[3.0] < 0.6 and inside[6.0] > 0.99
    # Most windows beyond δ is said, with the count and the key to change.
    assert len(said[3.0]) == 1 and f"only {round(inside[3.0] * n)} of {n} windows" in said[3.0][0]
    assert "robust.delta = 3" in said[3.0][0] and said[6.0] == []
