"""Reports (``--report``) and hand-off files: contents match result.json, images are real PNGs."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import struct
import subprocess
import sys
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import numpy as np
import pytest
import yaml
from conftest import REPO, SCENARIOS, assert_close

from nlp_calib import __version__
from nlp_calib.cli import main
from nlp_calib.outputs import registry
from nlp_calib.outputs.markdown import fmt_std, fmt_value
from nlp_calib.outputs.progress import Progress
from nlp_calib.pipeline import Calibration, Wanted
from nlp_calib.pipeline.scenario import Scenario, ValidationOptions
from nlp_calib.results import CalibrationRun, Verdict
from nlp_calib.results.run import CAVEATS, UNDETERMINED
from nlp_calib.solvers import GaussNewtonOptions

IMAGES = (
    "trajectory.png",
    "convergence.png",
    "residuals.png",
    "residuals_time.png",
    "model_check.png",
    "trust.png",
)
CALIBRATION_FILE, URDF_FILE, ROBOT_URDF_FILE = "calibration.yaml", "sensor_mount.urdf.xml", "robot.urdf"


def write_handoff(run: CalibrationRun, out: Path) -> list[Path]:
    """The hand-off files of ``run``, written as a run writes them."""
    return _write(run, out, "handoff")


def _write(run: CalibrationRun, out: Path, group: str) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    outputs = registry.selected((group,), report=True)
    return registry.write(outputs, [(run, out)], (run, out), registry.OutputOptions())


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``compare demo.yaml --report`` run once through the command line."""
    out = tmp_path_factory.mktemp("report")
    assert main(["compare", str(SCENARIOS / "demo.yaml"), "--out", str(out), "--report"]) == 0
    return out


@pytest.fixture(scope="module")
def result(report_dir: Path) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads((report_dir / "result.json").read_text())
    return doc


def png_size(path: Path) -> tuple[int, int]:
    """Width and height from the IHDR chunk, after checking the signature."""
    head = path.read_bytes()[:24]
    assert head[:8] == PNG_SIGNATURE, f"{path.name} is not a PNG"
    assert head[12:16] == b"IHDR"
    width, height = struct.unpack(">II", head[16:24])
    return width, height


def test_report_writes_every_file_as_a_sizeable_png(report_dir: Path) -> None:
    for name in (*IMAGES, "report.md", CALIBRATION_FILE, URDF_FILE, "result.json"):
        assert (report_dir / name).is_file(), name
    for name in IMAGES:
        path = report_dir / name
        width, height = png_size(path)
        assert width >= 1000 and height >= 500, (name, width, height)
        assert path.stat().st_size > 10_000, name
    assert not list(report_dir.glob(".*.tmp")), "temporary files were left behind"


def _row(md: str, name: str) -> list[str]:
    line = next(ln for ln in md.splitlines() if ln.startswith(f"| `{name}` |"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_report_md_references_images_and_both_solvers_values(report_dir: Path, result: dict) -> None:
    md = (report_dir / "report.md").read_text()
    for name in IMAGES:
        assert f"]({name})" in md, name
    solvers = result["solvers"]
    assert list(solvers) == ["gauss_newton", "ipopt"]
    for name in solvers["gauss_newton"]["params"]:
        cells = _row(md, name)
        # parameter | unit | initial | GN | ±σ | IPOPT | ±σ | difference
        assert cells[2] == fmt_value(result["initial"][name])
        assert cells[3] == fmt_value(solvers["gauss_newton"]["params"][name])
        assert cells[4] == fmt_std(solvers["gauss_newton"]["std"][name])
        assert cells[5] == fmt_value(solvers["ipopt"]["params"][name])
        assert cells[6] == fmt_std(solvers["ipopt"]["std"][name])
    metrics = solvers["gauss_newton"]["metrics"]
    for label, value in (
        ("segment ATE mean [m]", metrics["segment_ate"]["mean"]),
        ("RPE over 1 m [m]", metrics["rpe_1m"]["mean"]),
        ("full-run ATE mean [m]", metrics["ate_mean"]),
    ):
        assert any(ln.startswith(f"| {label} |") and f"{value:.4f}" in ln for ln in md.splitlines()), label
    assert "calibration.yaml" in md and "Gauss-Newton's estimate" in md


def test_calibration_yaml_loads_back_to_result_json(report_dir: Path, result: dict) -> None:
    cal = yaml.safe_load((report_dir / CALIBRATION_FILE).read_text())
    assert cal["solver"] == "gauss_newton"  # first converged in the scenario's order
    gn = result["solvers"]["gauss_newton"]
    assert cal["parameters"] == gn["params"]  # exact float equality: repr precision both ways
    assert cal["std"] == gn["std"]
    assert cal["correlation"] == gn["correlation"]
    assert all(isinstance(v, float) for v in cal["std"].values())
    for name, res in result["solvers"].items():
        entry = cal["solvers"][name]
        assert entry["parameters"] == res["params"]
        assert entry["std"] == res["std"]
        for key in ("cost", "chi2", "converged", "inliers"):
            assert entry[key] == res[key], (name, key)
    assert cal["tool"]["version"] == __version__ == result["tool"]["version"]
    assert cal["scenario"]["name"] == "demo" and cal["scenario"]["path"].endswith("demo.yaml")
    assert cal["dataset"]["path"] == result["dataset"]["path"]
    assert cal["dataset"]["used"] == result["dataset"]["used"]
    assert cal["frames"] == {"parent": "base_link", "sensor": "laser"}
    assert "&" not in (report_dir / CALIBRATION_FILE).read_text()  # no YAML anchors


def test_urdf_joint_parses_and_carries_the_sensor_pose(report_dir: Path, result: dict) -> None:
    root = ET.parse(report_dir / URDF_FILE).getroot()
    assert root.tag == "joint" and root.get("type") == "fixed"
    assert root.get("name") == "base_link_to_laser"
    assert root.find("parent").get("link") == "base_link"  # type: ignore[union-attr]
    assert root.find("child").get("link") == "laser"  # type: ignore[union-attr]
    origin = root.find("origin")
    assert origin is not None
    x, y, z = (float(v) for v in origin.get("xyz", "").split())
    roll, pitch, yaw = (float(v) for v in origin.get("rpy", "").split())
    p = result["solvers"]["gauss_newton"]["params"]
    assert (x, y, z) == (p["sensor_x"], p["sensor_y"], 0.0)
    assert (roll, pitch, yaw) == (0.0, 0.0, p["sensor_theta"])
    assert f"nlp_calib {__version__}" in (report_dir / URDF_FILE).read_text()


def test_robot_urdf_loads_in_yourdfpy_and_urdf_parser_py_with_result_json_numbers(
    report_dir: Path, result: dict
) -> None:
    yourdfpy = pytest.importorskip("yourdfpy")
    urdf = pytest.importorskip("urdf_parser_py.urdf")
    p = result["solvers"]["gauss_newton"]["params"]
    path = report_dir / ROBOT_URDF_FILE
    robot = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=True)
    assert [j.name for j in robot.robot.joints] == ["base_link_to_laser"]
    assert {link.name for link in robot.robot.links} == {"base_link", "laser"}
    c, s = np.cos(p["sensor_theta"]), np.sin(p["sensor_theta"])
    expected = np.array([[c, -s, 0, p["sensor_x"]], [s, c, 0, p["sensor_y"]], [0, 0, 1, 0], [0, 0, 0, 1]])
    assert_close(robot.get_transform("laser", "base_link"), expected, rtol=0, atol=1e-15)
    parsed = urdf.URDF.from_xml_string(path.read_text())
    (joint,) = parsed.joints
    assert (joint.parent, joint.child, joint.type) == ("base_link", "laser", "fixed")
    assert joint.origin.xyz == [p["sensor_x"], p["sensor_y"], 0.0]
    assert joint.origin.rpy == [0.0, 0.0, p["sensor_theta"]]


def _calibration(small_demo: Scenario, **changes: Any) -> Calibration:
    return Calibration(small_demo.with_options(**changes))


def test_handoff_files_are_deterministic(tmp_path: Path, small_demo: Scenario) -> None:
    texts = []
    for i in range(2):
        out = tmp_path / str(i)
        paths = write_handoff(_calibration(small_demo, solvers=("gauss_newton",)).run(), out)
        assert [p.name for p in paths] == [CALIBRATION_FILE, URDF_FILE, ROBOT_URDF_FILE, "ros2_control.yaml"]
        texts.append([p.read_bytes() for p in paths])
    assert texts[0] == texts[1]


def test_no_converged_solver_writes_no_handoff_and_removes_stale_files(
    tmp_path: Path, small_demo: Scenario
) -> None:
    calib = _calibration(
        small_demo,
        solvers=("gauss_newton",),
        solver_options={"gauss_newton": GaussNewtonOptions(max_iterations=1)},
    )
    run = calib.run()
    assert not run.reports["gauss_newton"].result.converged
    for name in (CALIBRATION_FILE, URDF_FILE, ROBOT_URDF_FILE):
        (tmp_path / name).write_text("stale")
    assert write_handoff(run, tmp_path) == []
    assert not any((tmp_path / n).exists() for n in (CALIBRATION_FILE, URDF_FILE, ROBOT_URDF_FILE))


def test_a_converged_fit_the_verdict_calls_not_determined_hands_nothing_off(
    tmp_path: Path, small_demo: Scenario
) -> None:
    """NOT DETERMINED with a converged solver (a parameter the drive leaves loose): no hand-off file
    carries a value, and stale ones are removed; the same run under caveats writes them all."""
    run = _calibration(small_demo, solvers=("gauss_newton",)).run()
    assert run.reports["gauss_newton"].result.converged
    loose = dataclasses.replace(
        run, verdict=Verdict(UNDETERMINED, ("axis_length not determined by this drive",))
    )
    files = (CALIBRATION_FILE, URDF_FILE, ROBOT_URDF_FILE, "ros2_control.yaml")
    for name in files:
        (tmp_path / name).write_text("stale")
    assert write_handoff(loose, tmp_path) == []
    assert not any((tmp_path / n).exists() for n in files)
    usable = dataclasses.replace(run, verdict=Verdict(CAVEATS, ("a caveat",)))
    assert [p.name for p in write_handoff(usable, tmp_path)] == list(files)


def test_single_solver_report_with_holdout(tmp_path: Path, small_demo: Scenario) -> None:
    calib = _calibration(
        small_demo, solvers=("gauss_newton",), validation=ValidationOptions(holdout_fraction=0.3)
    )
    run = calib.run(wanted=Wanted(series=True))
    paths = _write(run, tmp_path, "figures")
    images = [*IMAGES, "lag.png"]  # the time offset fitted by default: its profile drawn
    assert [p.name for p in paths[:8]] == [*images, "report.md"]
    tracks = {p.relative_to(tmp_path).as_posix() for p in paths[8:]}
    assert {"trajectories/tracker.tum", "trajectories/gauss_newton.tum", "trajectories/README.md"} <= tracks
    for name in images:
        png_size(tmp_path / name)
    md = (tmp_path / "report.md").read_text()
    holdout = f"{run.reports['gauss_newton'].holdout.segment_ate.mean:.4f}"  # type: ignore[union-attr]
    assert any(ln.startswith("| hold-out segment ATE mean [m] |") and holdout in ln for ln in md.splitlines())
    assert "IPOPT" not in md.split("## Hand-off files")[0]


def test_plain_run_does_not_import_matplotlib(tmp_path: Path) -> None:
    script = (
        "import sys\n"
        "from nlp_calib.cli import main\n"
        f"rc = main(['run', {str(SCENARIOS / 'demo.yaml')!r}, '--out', {str(tmp_path)!r}, "
        "'--solver', 'gauss_newton'])\n"
        "print('RC', rc, 'MPL', any(m == 'matplotlib' or m.startswith('matplotlib.') for m in sys.modules))\n"
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=REPO, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    assert "RC 0 MPL False" in proc.stdout, proc.stdout[-500:]
    assert (tmp_path / "result.json").is_file() and (tmp_path / CALIBRATION_FILE).is_file()
    assert not (tmp_path / "report.md").exists() and not list(tmp_path.glob("*.png"))


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_is_silent_unless_the_stream_is_a_terminal() -> None:
    piped = io.StringIO()
    with Progress(3, piped, label="scenarios") as progress:
        progress.update(1, "demo: solving")
    assert piped.getvalue() == ""
    tty = _Terminal()
    with Progress(3, tty, label="scenarios") as progress:
        progress.update(1, "demo: solving")
        assert "[1/3] scenarios: demo: solving" in tty.getvalue()
    assert tty.getvalue().endswith("\r\x1b[K")  # the status line is erased on exit


def test_the_summary_names_odometry_csvs_covariance_only_where_one_was_written() -> None:
    """Where the drift is no noise a filter can use, odometry.csv holds the poses and empty
    covariance columns: the closing summary says so and why (main named its covariance anyway)."""
    from types import SimpleNamespace

    why = "the drift against the reference calibrates a noise per interval as large as the inputs' own values"
    for undetermined in (why, ""):
        run: Any = SimpleNamespace(odometry=SimpleNamespace(undetermined=undetermined))
        (line,) = registry.next_steps(["odometry.csv"], run)
        assert ("with its covariance" in line) == (not undetermined), line
        assert (f"with no covariance: {why}" in line) == bool(undetermined), line
