"""The answer in the robot stack's terms: ros2_control parameters and the user's own URDF re-posed."""

from __future__ import annotations

import json
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
import yaml
from conftest import SCENARIOS, cli

from nlp_calib.core.errors import UsageError
from nlp_calib.outputs import urdf

ROBOT = """<?xml version="1.0"?>
<!-- my robot, hand written: this comment and every byte but the laser's origin stay -->
<robot name="trike">
  <link name="base_link"/>
  <link name="chassis"/>
  <link name="laser"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>
  <link name="front_wheel"/>
  <joint name="base_to_chassis" type="fixed">
    <parent link="base_link"/>
    <child link="chassis"/>
    <origin xyz="0.2 0 0.1" rpy="0 0 0.1"/>
  </joint>
  <joint name="chassis_to_laser" type="fixed">
    <parent link="chassis"/>   <child link="laser"/>
    <origin rpy="0.02 -0.05 0" xyz="1.2 0.05 0.4" />
  </joint>
  <joint name="steer" type="revolute">
    <parent link="base_link"/><child link="front_wheel"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>
"""


@pytest.fixture(scope="module")
def handed_off(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, Path]:
    tmp = tmp_path_factory.mktemp("ros2")
    robot = tmp / "robot_in.urdf"
    robot.write_text(ROBOT)
    out = tmp / "out"
    sc = tmp / "demo.yaml"
    sc.write_text((SCENARIOS / "demo.yaml").read_text().replace("data/", f"{SCENARIOS / 'data'}/"))
    proc = cli(
        "run",
        str(sc),
        "--out",
        str(out),
        "--solver",
        "gauss_newton",
        "--urdf",
        str(robot),
        "--sensor-link",
        "laser",
    )
    assert proc.returncode == 0, proc.stderr
    return out, json.loads((out / "result.json").read_text()), robot


def _pose(T: np.ndarray) -> tuple[float, float, float, float]:
    return float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), float(np.arctan2(T[1, 0], T[0, 0]))


def test_the_tricycle_controller_gets_its_parameters(handed_off: tuple[Path, dict, Path]) -> None:
    out, result, _ = handed_off
    p = result["solvers"]["gauss_newton"]["params"]
    doc = yaml.safe_load((out / "ros2_control.yaml").read_text())
    params = doc["tricycle_controller"]["ros__parameters"]
    # The traction encoder's range is the unit k_traction is counted in, not a wheel turn: without
    # the counts per turn no radius is written, and one line says what is needed.
    assert params["wheelbase"] == pytest.approx(p["axis_length"]) and "wheel_radius" not in params
    text = (out / "ros2_control.yaml").read_text()
    (why,) = [line for line in text.splitlines() if line.startswith("#   wheel_radius:")]
    assert "counts per wheel turn of 'traction_wheel'" in why and "counts_per_turn" in why
    assert (
        "k_steer = " in text
        and "mechanical_reduction = 1/k_steer" in text
        and "offset = steer_offset" in text
    )
    cal = yaml.safe_load((out / "calibration.yaml").read_text())
    assert [e["name"] for e in cal["encoders"]] == ["steering", "traction_wheel"]
    assert cal["verdict"]["level"] == result["verdict"]["level"]


def test_the_users_urdf_is_re_posed_and_nothing_else_changes(handed_off: tuple[Path, dict, Path]) -> None:
    import yourdfpy

    out, result, robot = handed_off
    p = result["solvers"]["gauss_newton"]["params"]
    before, after = robot.read_text().splitlines(), (out / "robot.urdf").read_text().splitlines()
    changed = [i for i, (a, b) in enumerate(zip(before, after)) if a != b]
    assert len(before) == len(after) and len(changed) == 1 and "<origin" in after[changed[0]]
    old = yourdfpy.URDF.load(str(robot)).get_transform("laser", "base_link")
    new = yourdfpy.URDF.load(str(out / "robot.urdf")).get_transform("laser", "base_link")
    x, y, z, yaw = _pose(new)
    assert (x, y, yaw) == pytest.approx((p["sensor_x"], p["sensor_y"], p["sensor_theta"]), abs=1e-12)
    assert z == pytest.approx(old[2, 3], abs=1e-12)
    # Roll and pitch of the sensor in base_link are kept: the last row of Rz(yaw)·Ry(pitch)·Rx(roll)
    # does not depend on the yaw.
    assert new[2, :3] == pytest.approx(old[2, :3], abs=1e-12)


def test_every_handoff_file_states_the_users_joint_to_the_last_digit(
    handed_off: tuple[Path, dict, Path],
) -> None:
    """With --urdf, sensor_mount.urdf.xml is the user's own joint of the sensor's link, re-posed
    exactly as in robot.urdf (same link names, same origin strings), and calibration.yaml's mount
    the same numbers with the user's height, roll and pitch said to be kept."""
    out, _, robot = handed_off
    joint = ET.parse(out / "sensor_mount.urdf.xml").getroot()
    theirs = {j.get("name"): j for j in ET.parse(out / "robot.urdf").getroot().iter("joint")}
    assert joint.get("name") == "chassis_to_laser"
    mine = theirs["chassis_to_laser"]
    for tag in ("parent", "child"):
        assert joint.find(tag).get("link") == mine.find(tag).get("link")  # type: ignore[union-attr]
    assert joint.find("child").get("link") == "laser"  # type: ignore[union-attr]
    assert joint.find("origin").attrib == mine.find("origin").attrib  # type: ignore[union-attr]
    mount = yaml.safe_load((out / "calibration.yaml").read_text())["mount"]
    origin = joint.find("origin").attrib  # type: ignore[union-attr]
    assert " ".join(map(repr, mount["xyz"])) == origin["xyz"]
    assert " ".join(map(repr, mount["rpy"])) == origin["rpy"]
    assert (mount["joint"], mount["parent"], mount["child"]) == ("chassis_to_laser", "chassis", "laser")
    assert mount["calibrated"] == ["x", "y", "yaw"]
    assert mount["nominal"] == dict.fromkeys(("z", "roll", "pitch"), f"kept from {robot.name} (--urdf)")
    # The height, roll and pitch in base_link are the user's (their joints composed).
    import yourdfpy

    old = yourdfpy.URDF.load(str(robot)).get_transform("laser", "base_link")
    pose = mount["pose_in_base_link"]
    assert pose["z"] == pytest.approx(old[2, 3], abs=1e-12)
    assert pose["pitch"] == pytest.approx(float(np.arcsin(-old[2, 0])), abs=1e-12)
    assert pose["roll"] == pytest.approx(float(np.arctan2(old[2, 1], old[2, 2])), abs=1e-12)


def test_without_urdf_the_mount_is_on_base_link_with_its_nominal_sources(tmp_path: Path) -> None:
    out = tmp_path / "plain"
    proc = cli("run", str(SCENARIOS / "demo.yaml"), "--out", str(out), "--solver", "gauss_newton")
    assert proc.returncode == 0, proc.stderr
    joint = ET.parse(out / "sensor_mount.urdf.xml").getroot()
    robot = {j.get("name"): j for j in ET.parse(out / "robot.urdf").getroot().iter("joint")}
    assert joint.find("origin").attrib == robot[joint.get("name")].find("origin").attrib  # type: ignore[union-attr]
    mount = yaml.safe_load((out / "calibration.yaml").read_text())["mount"]
    assert mount["parent"] == "base_link" and set(mount["nominal"]) == {"z", "roll", "pitch"}
    assert all(v.startswith("not known (0)") for v in mount["nominal"].values())
    assert set(mount["std"]) == {"x", "y", "yaw"} and all(v > 0 for v in mount["std"].values())


def test_the_re_posed_urdf_loads_in_urdf_parser_py(handed_off: tuple[Path, dict, Path]) -> None:
    from urdf_parser_py.urdf import URDF

    out, _, _ = handed_off
    model = URDF.from_xml_string((out / "robot.urdf").read_bytes())
    assert {j.name for j in model.joints} == {"base_to_chassis", "chassis_to_laser", "steer"}


@pytest.mark.parametrize(
    ("link", "message"),
    [
        ("lidar", r"no joint has the child link 'lidar' \(--sensor-link\); links with a joint: chassis"),
        ("front_wheel_child", r"no joint has the child link"),
    ],
)
def test_a_link_without_a_joint_is_refused_naming_the_links(tmp_path: Path, link: str, message: str) -> None:
    (tmp_path / "r.urdf").write_text(ROBOT)
    with pytest.raises(UsageError, match=message):
        urdf.load(tmp_path / "r.urdf", link)


def test_a_movable_joint_above_the_sensor_is_refused(tmp_path: Path) -> None:
    mount = '<joint name="cam_mount" type="fixed"><parent link="front_wheel"/><child link="cam"/></joint>'
    text = ROBOT.replace("</robot>", f'<link name="cam"/>{mount}\n</robot>')
    (tmp_path / "r.urdf").write_text(text)
    with pytest.raises(UsageError, match=r"revolute joint 'steer'.*below fixed joints"):
        urdf.load(tmp_path / "r.urdf", "cam")


def test_urdf_without_sensor_link_is_a_usage_error_before_any_work(tmp_path: Path) -> None:
    (tmp_path / "r.urdf").write_text(ROBOT)
    proc = cli(
        "run", str(SCENARIOS / "demo.yaml"), "--out", str(tmp_path / "o"), "--urdf", str(tmp_path / "r.urdf")
    )
    assert proc.returncode == 2 and "give --urdf and --sensor-link together" in proc.stderr
    assert not (tmp_path / "o").exists()


def test_the_diff_drive_controller_gets_radii_from_the_counts_per_turn(tmp_path: Path) -> None:
    out = tmp_path / "dd"
    proc = cli("run", str(SCENARIOS / "diff_drive_demo.yaml"), "--out", str(out), "--solver", "gauss_newton")
    assert proc.returncode == 0, proc.stderr
    p = json.loads((out / "result.json").read_text())["solvers"]["gauss_newton"]["params"]
    ticks = [e["counts_per_turn"] for e in yaml.safe_load((out / "calibration.yaml").read_text())["encoders"]]
    assert ticks == [4096, 4096]  # the scenario's counts_per_turn
    left, right = (k * n / (2 * np.pi) for k, n in zip((p["k_left"], p["k_right"]), ticks))
    params = yaml.safe_load((out / "ros2_control.yaml").read_text())["diff_drive_controller"][
        "ros__parameters"
    ]
    r = params["wheel_radius"]
    assert r * params["left_wheel_radius_multiplier"] == pytest.approx(left, rel=1e-12)
    assert r * params["right_wheel_radius_multiplier"] == pytest.approx(right, rel=1e-12)
    assert params["wheel_separation"] * params["wheel_separation_multiplier"] == pytest.approx(p["baseline"])


@pytest.mark.slow
def test_the_odometry_covariance_covers_the_drift_on_simulated_truth() -> None:
    """The input noise calibrated on a log's drift against its tracker: the propagated 2σ covers at
    least 90 % of the odometry's drift from the true base poses (mean over six fresh drives), where
    the encoders' quantisation alone (each reading's rounding) covers a small share."""
    from nlp_calib.analysis.metrics import segments
    from nlp_calib.analysis.odometry import drift_coverage, segment_drift
    from nlp_calib.logs.reader import parse_log
    from nlp_calib.models import get_model
    from nlp_calib.pipeline import Calibration, Scenario, Wanted
    from nlp_calib.pipeline.options import ValidationOptions
    from nlp_calib.simulation import SimulationOptions, simulate

    model = get_model("tricycle")
    calibrated, quantisation = [], []
    for seed in range(11, 17):
        sim = simulate(SimulationOptions.of(model="tricycle", records=2000, seed=seed))
        log = parse_log(sim.text().splitlines(), model.encoder_kinds, "sim")
        sc = Scenario.of("s", "sim.txt", solvers=("gauss_newton",), validation=ValidationOptions(blocks=0))
        calib = Calibration(sc, log=log)
        run = calib.run(wanted=Wanted(odometry="gauss_newton"))
        assert run.odometry is not None
        w = calib.stages.windows
        truth = sim.T_world_base_true[w.used[0] : w.used[1]]
        inputs = w.inputs(sc.objective.residual.steering_sample)
        params = run.reports["gauss_newton"].result.params
        drift = segment_drift(
            calib.fns, params, inputs, truth, segments(len(truth), w.masks()[0]), np.ones(len(truth), bool)
        )
        # The random walk calibrated beside the readings' rounding, and that rounding alone.
        floor = np.array(list(run.odometry.quantisation.values()))
        walk = np.array(list(run.odometry.input_noise.values()))
        calibrated.append(drift_coverage(drift, walk, floor, np.zeros(2)))
        quantisation.append(drift_coverage(drift, np.zeros_like(floor), floor, np.zeros(2)))
    assert np.mean(calibrated) >= 0.9, calibrated
    assert np.mean(quantisation) < 0.5, quantisation


#: A user's description whose sensor link is named like no default (not the log's 'laser', not
#: 'sensor'), below an intermediate link.
MARKER_ROBOT = """<?xml version="1.0"?>
<robot name="cart">
  <link name="base_link"/>
  <link name="roof_rack"/>
  <link name="mocap_marker_0"/>
  <joint name="base_to_rack" type="fixed">
    <parent link="base_link"/><child link="roof_rack"/>
    <origin xyz="0.3 0 0.8" rpy="0 0 0"/>
  </joint>
  <joint name="rack_to_marker" type="fixed">
    <parent link="roof_rack"/><child link="mocap_marker_0"/>
    <origin xyz="1.0 0.0 0.1" rpy="0 0 0"/>
  </joint>
</robot>
"""


def test_the_snippet_pasted_into_a_users_urdf_loads_in_both_urdf_tools(tmp_path: Path) -> None:
    """Done as the snippet's comment says (the user's joint replaced by it), the robot loads in
    yourdfpy and in urdf_parser_py, the sensor where robot.urdf has it; every file names the user's
    link; ros2_control.yaml's top key is the name given."""
    import yourdfpy
    from urdf_parser_py.urdf import URDF

    robot = tmp_path / "cart.urdf"
    robot.write_text(MARKER_ROBOT)
    out = tmp_path / "out"
    args = (
        "--urdf",
        str(robot),
        "--sensor-link",
        "mocap_marker_0",
        "--controller-name",
        "cart_base_controller",
    )
    proc = cli("run", str(SCENARIOS / "demo.yaml"), "--out", str(out), "--solver", "gauss_newton", *args)
    assert proc.returncode == 0, proc.stderr
    snippet = (out / "sensor_mount.urdf.xml").read_text()
    joint = snippet[snippet.index("<joint") :]
    start, end = MARKER_ROBOT.index('<joint name="rack_to_marker"'), MARKER_ROBOT.rindex("</joint>") + 8
    pasted = tmp_path / "pasted.urdf"
    pasted.write_text(MARKER_ROBOT[:start] + joint + MARKER_ROBOT[end:])
    T = yourdfpy.URDF.load(str(pasted), load_meshes=False).get_transform("mocap_marker_0", "base_link")
    T_robot = yourdfpy.URDF.load(str(out / "robot.urdf"), load_meshes=False).get_transform(
        "mocap_marker_0", "base_link"
    )
    assert T == pytest.approx(T_robot, abs=1e-12)
    model = URDF.from_xml_string(pasted.read_bytes())
    (mine,) = [j for j in model.joints if j.name == "rack_to_marker"]
    assert (mine.parent, mine.child) == ("roof_rack", "mocap_marker_0")
    cal = yaml.safe_load((out / "calibration.yaml").read_text())
    assert cal["mount"]["child"] == cal["frames"]["sensor"] == "mocap_marker_0"
    assert list(yaml.safe_load((out / "ros2_control.yaml").read_text())) == ["cart_base_controller"]


def test_values_given_under_known_are_handed_off_as_given_never_as_calibrated(tmp_path: Path) -> None:
    """The wheelbase and the sensor's yaw given under known: the controller file writes the
    wheelbase as the user's value (no σ), the mount lists yaw with where it comes from, not among
    the calibrated components, and calibration.yaml lists both as held; without --controller-name
    the file's first line says to rename its key."""
    sc = tmp_path / "known.yaml"
    text = (SCENARIOS / "demo.yaml").read_text().replace("data/", f"{SCENARIOS / 'data'}/")
    sc.write_text(text + "\nknown: {axis_length: 1.5, sensor_theta: 0.05}\n")
    out = tmp_path / "out"
    proc = cli("run", str(sc), "--out", str(out), "--solver", "gauss_newton")
    assert proc.returncode == 0, proc.stderr
    lines = (out / "ros2_control.yaml").read_text().splitlines()
    assert lines[0].startswith("# Rename the top key 'tricycle_controller' to your controller's name")
    i = lines.index("    wheelbase: 1.5")
    assert "not calibrated: given under known: (1.5)" in lines[i - 1]
    cal = yaml.safe_load((out / "calibration.yaml").read_text())
    assert set(cal["held"]) == {"axis_length", "sensor_theta"}
    assert cal["mount"]["calibrated"] == ["x", "y"] and set(cal["mount"]["std"]) == {"x", "y"}
    assert cal["mount"]["nominal"]["yaw"] == "given under known: (0.05)"
    assert "Calibrated: x, y; " in (out / "sensor_mount.urdf.xml").read_text()
