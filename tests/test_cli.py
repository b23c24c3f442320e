"""The command line end to end: result.json contract, exit codes, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from conftest import SCENARIOS, cli

DEMO_LOG = SCENARIOS / "data" / "demo_tricycle.txt"
PARAMS = {
    "k_steer",
    "k_traction",
    "axis_length",
    "steer_offset",
    "sensor_x",
    "sensor_y",
    "sensor_theta",
}


def test_run_demo_writes_result_matching_contract(tmp_path: Path) -> None:
    proc = cli("run", str(SCENARIOS / "demo.yaml"), "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "result.json").read_text())
    assert doc["scenario"] == "demo"
    assert doc["dataset"]["records"] == 1500
    # The records whose encoders can be read at their time less the fitted lag (t − lag inside the log).
    t = np.array([float(ln.split()[1]) for ln in DEMO_LOG.read_text().splitlines() if ln.startswith("time:")])
    lag = doc["alignment"]["tracker_lag_s"]
    inside = np.flatnonzero((t - lag >= t[0]) & (t - lag <= t[-1]))
    assert doc["dataset"]["used"] == [int(inside[0]), int(inside[-1]) + 1]
    assert Path(doc["dataset"]["path"]).name == "demo_tricycle.txt"
    assert set(doc["solvers"]) == {"gauss_newton", "ipopt"}
    for res in doc["solvers"].values():
        assert set(res["params"]) == {*PARAMS, "tracker_lag"}  # the time offset fitted by default
        assert set(res["std"]) == {*PARAMS, "tracker_lag"}
        assert all(v > 0 for v in res["std"].values())
        for key, typ in [
            ("cost", float),
            ("chi2", float),
            ("inliers", int),
            ("iterations", int),
            ("converged", bool),
            ("time_s", float),
        ]:
            assert isinstance(res[key], typ), key
        assert res["converged"] is True
        assert {"ate_mean", "ate_max", "ate_final"} <= set(res["metrics"])
    truth = json.loads((SCENARIOS / "data" / "demo_tricycle.truth.json").read_text())["params"]
    gn = doc["solvers"]["gauss_newton"]
    for name in PARAMS:
        assert abs(gn["params"][name] - truth[name]) <= 4 * gn["std"][name] + 1e-6, name
    assert abs(gn["params"]["tracker_lag"]) <= 4 * gn["std"]["tracker_lag"]  # simulated without latency
    assert "gauss_newton" in proc.stdout and "ATE mean" in proc.stdout


def test_misspelt_key_exits_2_with_one_line_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text((SCENARIOS / "demo.yaml").read_text().replace("residual:", "residuals:"))
    (tmp_path / "data").symlink_to(SCENARIOS / "data")
    proc = cli("run", str(bad), "--out", str(tmp_path / "out"))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: ") and "residuals" in lines[0] and "unknown key" in lines[0]
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "out" / "result.json").exists()


def test_missing_dataset_is_a_usage_error(tmp_path: Path) -> None:
    proc = cli(
        "run",
        str(SCENARIOS / "demo.yaml"),
        "--data",
        str(tmp_path / "nope.txt"),
        "--out",
        str(tmp_path),
    )
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: ") and "nope.txt" in proc.stderr and "no such file" in proc.stderr


def test_bad_subcommand_is_one_line(tmp_path: Path) -> None:
    proc = cli("calibrate", "x.yaml")
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and proc.stderr.startswith("error: ")


def test_simulate_writes_log_and_truth(tmp_path: Path) -> None:
    out = tmp_path / "sim.txt"
    proc = cli("simulate", "--out", str(out), "--records", "200", "--seed", "4")
    assert proc.returncode == 0, proc.stderr
    assert out.is_file() and out.with_suffix(".truth.json").is_file()
    assert len([ln for ln in out.read_text().splitlines() if ln.startswith("time:")]) == 200
