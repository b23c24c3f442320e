"""One standing per parameter in every hand-off file (issues 40 and 43): live, given or not
determined. A value a caveat concerns, held at its guess or given never reaches a robot as
calibrated: the files are parsed back (YAML, XML, ``nlp-calib check``'s reader) to say so."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from collections.abc import Callable
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
import yaml
from test_hostile5 import VENDOR_BLOCKS

import nlp_calib
from nlp_calib.outputs.write import output_options
from nlp_calib.pipeline.assemble import judged
from nlp_calib.pipeline.calibration import Calibration, Wanted
from nlp_calib.pipeline.scenario import load_scenario
from nlp_calib.pipeline.stored import read_calibration
from nlp_calib.results.run import CAVEATS, DOUBTFUL, GIVEN, LIVE, UNDETERMINED, CalibrationRun, Verdict
from nlp_calib.simulation.vendor import VendorSimulationOptions, write_vendor_simulation

URDF_FILES = ("sensor_mount.urdf.xml", "robot.urdf")
HANDOFF = ("calibration.yaml", *URDF_FILES, "ros2_control.yaml")
#: The user's robot: the sensor's link on base_link at a pose of theirs.
ROBOT = """<?xml version="1.0"?>
<robot name="mine">
  <link name="base_link"/>
  <link name="sensor"/>
  <joint name="my_sensor_joint" type="fixed">
    <parent link="base_link"/>
    <child link="sensor"/>
    <origin xyz="0.3 -0.2 0.5" rpy="0 0 0.25"/>
  </joint>
</robot>
"""


def _vendor_run(
    folder: Path, robot: str, declared: str, extra: str = "", series: bool = False
) -> CalibrationRun:
    odo, tum, _ = write_vendor_simulation(
        VendorSimulationOptions(model=robot, duration_s=40.0, seed=5), folder / "odom.txt"
    )
    sc = folder / "v.yaml"
    sc.write_text(
        f"name: v\nmodel: {declared}\ndataset: {{odometry: {odo.name}, poses: {tum.name}, "
        f"vendor: {VENDOR_BLOCKS[declared]}}}\nresidual: {{horizon_s: 0.5}}\nsolvers: [gauss_newton]\n{extra}"
    )
    return Calibration(load_scenario(sc)).run(wanted=Wanted(series=series))


@pytest.fixture(scope="module")
def misdeclared_run(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str, str], CalibrationRun]:
    """The vendor run of ``robot`` declared as ``declared``, with its series (a report reads them),
    fitted once for every test that reads it (a frozen run: each test writes its own folder)."""

    @functools.cache
    def run(robot: str, declared: str) -> CalibrationRun:
        return _vendor_run(tmp_path_factory.mktemp("caveat"), robot, declared, series=True)

    return run


@pytest.fixture(scope="module", params=[("diff_drive", "tricycle"), ("tricycle", "diff_drive")])
def caveated(
    request: pytest.FixtureRequest, misdeclared_run: Callable[[str, str], CalibrationRun]
) -> CalibrationRun:
    """A run whose verdict's caveat (the vendor's odometry is another model's) concerns every
    parameter, the mount's included."""
    run = misdeclared_run(*request.param)
    assert run.verdict.level == CAVEATS and {"sensor_x", "sensor_y", "sensor_theta"} <= set(
        run.verdict.concerns
    )
    return run


@pytest.fixture(scope="module")
def held_run(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], CalibrationRun]:
    """The differential drive's vendor run with a value held (``extra``: ``known:`` or ``fixed:``),
    fitted once for every test that reads it (a frozen run: each test writes its own folder)."""

    @functools.cache
    def run(extra: str) -> CalibrationRun:
        return _vendor_run(tmp_path_factory.mktemp("held"), "diff_drive", "diff_drive", extra)

    return run


def _clean(run: CalibrationRun) -> CalibrationRun:
    """``run`` as if no caveat concerned any parameter (its mounts as the fit estimated them)."""
    clean = dataclasses.replace(run, verdict=Verdict(CAVEATS, ("none",)))
    reports = {
        s: dataclasses.replace(r, mount=r.mount and _undoubted(r.mount)) for s, r in clean.reports.items()
    }
    return dataclasses.replace(clean, reports=reports)


def _stale(out: Path, run: CalibrationRun) -> None:
    """Older hand-off files a robot stack could pick up (an earlier run's, every one written):
    a run must remove what it does not write."""
    nlp_calib.write_run(_clean(run), out)
    assert all((out / name).exists() for name in HANDOFF)


def _live(out: Path) -> dict[str, float]:
    """The values ros2_control.yaml hands the controller (comments are not loaded)."""
    doc = yaml.safe_load((out / "ros2_control.yaml").read_text())
    (params,) = [v["ros__parameters"] for v in doc.values()]
    return {k: v for k, v in params.items() if not k.endswith("covariance_diagonal")}


def test_a_caveated_mount_is_stated_as_not_determined_and_no_urdf_carries_it(
    caveated: CalibrationRun, tmp_path: Path
) -> None:
    solver = caveated.handoff_solver()
    assert solver is not None
    status = caveated.handoff_status(solver)
    assert {n for n, (s, _) in status.items() if s == DOUBTFUL} == set(caveated.verdict.concerns)
    out = tmp_path / "out"
    _stale(out, caveated)
    nlp_calib.write_run(caveated, out, force=True)
    assert not any((out / name).exists() for name in URDF_FILES)
    cal = yaml.safe_load((out / "calibration.yaml").read_text())
    mount = cal["mount"]
    assert mount["calibrated"] == [] and mount["std"] == {}
    assert set(mount["undetermined"]) == {"x", "y", "yaw"}
    assert set(cal["not_determined"]) == set(caveated.verdict.concerns)
    controller = caveated.reports[solver].controller
    assert controller is not None  # every value the calibration gives rests on a doubted parameter
    assert set(_live(out)) <= set(controller.settings)
    text = (out / "ros2_control.yaml").read_text()
    assert "# The sensor's mount: no URDF file, x, y, yaw not determined well enough to use" in text
    stored = read_calibration(out / "calibration.yaml")  # what `nlp-calib check` reads
    assert stored.parameters == pytest.approx(cal["parameters"])


def test_the_report_names_no_urdf_file_the_run_left_out(
    misdeclared_run: Callable[[str, str], CalibrationRun], tmp_path: Path
) -> None:
    run = misdeclared_run("diff_drive", "tricycle")
    assert run.verdict.level == CAVEATS and "sensor_x" in run.verdict.concerns
    out = tmp_path / "out"
    written = {p.name for p in nlp_calib.write_run(run, out, report=True)}
    assert "report.md" in written and not written & set(URDF_FILES)
    text = (out / "report.md").read_text()
    assert "calibration.yaml" in text
    assert not any(name in text for name in URDF_FILES), [n for n in URDF_FILES if n in text]


def test_with_the_users_urdf_a_doubted_component_keeps_the_users_value(
    caveated: CalibrationRun, tmp_path: Path
) -> None:
    robot = tmp_path / "mine.urdf"
    robot.write_text(ROBOT)
    out = tmp_path / "out"
    nlp_calib.write_run(caveated, out, options=output_options(robot_urdf=robot, sensor_link="sensor"))
    for name in URDF_FILES:
        joint = next(
            j for j in ET.parse(out / name).getroot().iter("joint") if j.get("name") == "my_sensor_joint"
        )
        origin = joint.find("origin")
        assert origin is not None
        assert [float(v) for v in origin.get("xyz", "").split()] == pytest.approx([0.3, -0.2, 0.5])
        assert [float(v) for v in origin.get("rpy", "").split()] == pytest.approx([0.0, 0.0, 0.25])
    mount = yaml.safe_load((out / "calibration.yaml").read_text())["mount"]
    assert mount["calibrated"] == [] and "undetermined" not in mount
    assert mount["nominal"]["x"].startswith(
        "kept from mine.urdf (--urdf) (not determined well enough to use: "
    )
    comment = (out / "sensor_mount.urdf.xml").read_text().split("-->")[0]
    assert "Calibrated: none" in comment and "--urdf" not in comment.split("<!--", 1)[1]


@pytest.mark.parametrize("doubted", ["sensor_x", "sensor_y", "sensor_theta"])
def test_one_doubted_mount_parameter_takes_its_component_alone_out(
    caveated: CalibrationRun, doubted: str, tmp_path: Path
) -> None:
    """A caveat on one mount parameter: that component alone leaves ``calibrated``, its σ with it."""
    components = {"x": "sensor_x", "y": "sensor_y", "yaw": "sensor_theta"}
    component = next(c for c, n in components.items() if n == doubted)
    verdict = Verdict(CAVEATS, ("a caveat",), concerns={doubted: "a caveat on it"})
    run = judged(_clean(caveated), verdict, components)
    solver = run.handoff_solver()
    assert solver is not None
    assert run.doubts(solver) == {doubted: "a caveat on it"}
    out = tmp_path / "out"
    nlp_calib.write_run(run, out)
    mount = yaml.safe_load((out / "calibration.yaml").read_text())["mount"]
    assert mount["undetermined"] == {component: "a caveat on it"}
    assert set(mount["calibrated"]) == {"x", "y", "yaw"} - {component} == set(mount["std"])
    assert not any((out / name).exists() for name in URDF_FILES)


def _undoubted(mount):  # type: ignore[no-untyped-def]
    """The mount as the fit estimated it, before any doubt (the fixture's run is caveated)."""
    std = {c: 0.01 if c in mount.undetermined else s for c, s in mount.std.items()}
    return dataclasses.replace(
        mount, calibrated=(*mount.calibrated, *mount.undetermined), std=std, undetermined={}
    )


def test_not_determined_writes_no_handoff_file_and_removes_older_ones(
    caveated: CalibrationRun, tmp_path: Path
) -> None:
    run = dataclasses.replace(caveated, verdict=Verdict(UNDETERMINED, ("the drive leaves sensor_y loose",)))
    out = tmp_path / "out"
    _stale(out, caveated)
    nlp_calib.write_run(run, out, force=True)
    assert not any((out / name).exists() for name in HANDOFF)


def test_given_values_are_written_as_given_with_no_sigma(
    held_run: Callable[[str], CalibrationRun], tmp_path: Path
) -> None:
    """known: values are given, not calibrated: null σ (never 0) in every σ block of
    calibration.yaml, which `nlp-calib check` reads back and leaves unjudged."""
    run = held_run("known: {sensor_theta: 0.05}\n")
    solver = run.handoff_solver()
    assert solver is not None
    status = run.handoff_status(solver)
    assert status["sensor_theta"][0] == GIVEN and status["sensor_x"] == (LIVE, "")
    out = tmp_path / "out"
    nlp_calib.write_run(run, out)
    cal = yaml.safe_load((out / "calibration.yaml").read_text())
    for block in (cal["std"], cal["std_white_noise"], cal["solvers"][solver]["std"]):
        assert block["sensor_theta"] is None and block["sensor_x"] > 0
    assert cal["mount"]["calibrated"] == ["x", "y"] and cal["mount"]["nominal"]["yaw"].startswith("given")
    stored = read_calibration(out / "calibration.yaml")
    assert math.isnan(stored.std["sensor_theta"]) and "sensor_theta" in stored.uncalibrated()
    joint = ET.parse(out / "robot.urdf").getroot().find("joint")
    assert joint is not None and joint.find("origin") is not None
    assert float(joint.find("origin").get("rpy", "").split()[2]) == 0.05  # type: ignore[union-attr]


@pytest.mark.parametrize("extra", ["known: {sensor_theta: 0.05}\n", "fixed: [sensor_theta]\n"])
def test_result_json_writes_no_sigma_for_a_value_the_fit_held(
    extra: str, held_run: Callable[[str], CalibrationRun], tmp_path: Path
) -> None:
    """result.json and validation.json, like calibration.yaml: null σ (never 0) for a value held
    (given under known: or fixed:), in every σ block; an estimated value keeps its σ."""
    run = held_run(extra)
    out = tmp_path / "out"
    nlp_calib.write_run(run, out)
    doc = json.loads((out / "result.json").read_text())
    blocks = [b for s in doc["solvers"].values() for b in (s["std"], s["std_white_noise"])]
    if doc["crossvalidation"] is not None:
        blocks.append(doc["crossvalidation"]["std_blocks"])
    for block in blocks:
        assert block["sensor_theta"] is None and block["sensor_x"] > 0
    for solver in run.reports:  # the run itself still holds the σ its fit computed
        assert run.reports[solver].uncertainty.std_dict()["sensor_theta"] == 0.0
