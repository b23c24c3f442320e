"""A check on the very data a run calibrated agrees with the run: a calibration of several logs is
checked on all of them fitted jointly (as the run fitted them), and every stage before the fit
(the screen, the lag, the windows) is done as the run did it, so the check fits the records the
run fitted (issue #43)."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import cli

from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.results.check import CANNOT_TELL, STILL_GOOD
from nlp_calib.simulation import SimulationOptions, simulate, write_simulation

FORMULATION: dict[str, Any] = {
    "model": "tricycle",
    "initial_guess": "auto",
    "residual": {"horizon": 10},
    "solvers": ["gauss_newton"],
}


def scenario(folder: Path, name: str, logs: list[Path]) -> Path:
    """A scenario file of ``logs`` (one: ``dataset``; several: ``datasets``) in ``folder``."""
    data = {"dataset": str(logs[0])} if len(logs) == 1 else {"datasets": [str(p) for p in logs]}
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"name": name, **FORMULATION, **data}))
    return path


def drive(folder: Path, name: str, records: int, seed: int) -> Path:
    path = folder / f"{name}.txt"
    write_simulation(simulate(SimulationOptions.of(records=records, seed=seed)), path)
    return path


def check_json(out: Path) -> dict[str, Any]:
    return dict(json.loads((out / "check.json").read_text()))


def test_a_joint_calibration_is_checked_on_all_its_logs_as_the_run_fitted_them(tmp_path: Path) -> None:
    # A short drive and a long one: jointly every parameter is determined; the short one alone
    # determines too little to test them.
    short, long = drive(tmp_path, "short", 150, 40), drive(tmp_path, "long", 1500, 41)
    pair = scenario(tmp_path, "pair", [short, long])
    ran = cli("run", str(pair), "--out", str(tmp_path / "run"))
    assert ran.returncode == 0, ran.stdout + ran.stderr
    result = json.loads((tmp_path / "run" / "result.json").read_text())
    assert result["verdict"]["level"] == "good", result["verdict"]
    calibration = str(tmp_path / "run" / "calibration.yaml")

    # The short log alone (what the check refitted before: the scenario's first log) cannot tell.
    alone = cli("check", calibration, str(scenario(tmp_path, "alone", [short])), "--out", str(tmp_path / "a"))
    assert alone.returncode == 4, alone.stdout + alone.stderr
    assert check_json(tmp_path / "a")["verdict"] == CANNOT_TELL

    # The scenario itself: both logs fitted jointly, the same windows from the stored values.
    both = cli("check", calibration, str(pair), "--out", str(tmp_path / "b"))
    assert both.returncode == 0, both.stdout + both.stderr
    doc = check_json(tmp_path / "b")
    assert doc["verdict"] == STILL_GOOD
    assert "2 logs" in doc["dataset"] and "fair figures on these logs" in both.stdout
    stored = result["solvers"]["gauss_newton"]
    fitted = {n for n, sd in stored["std"].items() if sd is not None and "lag" not in n}
    assert set(doc["parameters"]) == fitted
    for name, p in doc["parameters"].items():
        # The run's own minimum and σ, found again: the check tests what the run determined.
        assert p["untested"] is None, name
        assert p["refit"] == pytest.approx(stored["params"][name], rel=1e-7, abs=1e-9), name
        assert p["std_refit"] == pytest.approx(stored["std"][name], rel=1e-5), name
        assert abs(p["z"]) < 1e-3, name
    for log in ("short", "long"):
        assert (tmp_path / "b" / log / "result.json").is_file()


def test_a_check_fits_the_records_and_lag_the_run_fitted(tmp_path: Path) -> None:
    # The lag fitted (the default): from the stored values it would settle elsewhere within its
    # tolerance, and the records the encoders reach at it, the windows, move with it.
    log = drive(tmp_path, "one", 900, 7)
    sc = scenario(tmp_path, "one", [log])
    ran = cli("run", str(sc), "--out", str(tmp_path / "run"))
    assert ran.returncode == 0, ran.stdout + ran.stderr
    checked = cli("check", str(tmp_path / "run" / "calibration.yaml"), str(sc), "--out", str(tmp_path / "c"))
    assert checked.returncode == 0, checked.stdout + checked.stderr
    run, check = (json.loads((tmp_path / d / "result.json").read_text()) for d in ("run", "c"))
    assert run["alignment"]["estimate"] is not None
    assert check["alignment"]["tracker_lag_s"] == run["alignment"]["tracker_lag_s"]
    for key in ("used", "fit", "residuals", "dropped_records"):
        assert check["dataset"][key] == run["dataset"][key], key
    # ...and from there the run's minimum: every change far inside its σ.
    assert all(abs(p["z"]) < 1e-3 for p in check_json(tmp_path / "c")["parameters"].values())


@pytest.mark.parametrize(("lags", "held"), [((0.0, 0.0), {"alignment.tracker_lag": 0.0}), ((0.0, 0.02), {})])
def test_a_joint_fit_records_the_lag_every_log_holds(
    tmp_path: Path, lags: tuple[float, float], held: Any
) -> None:
    # A check takes the held values' part out of both σ only where the refit holds what the stored
    # calibration held (drift.common_held): a joint fit must say the lag it holds, as one log's does.
    logs = [drive(tmp_path, f"d{i}", 400, 50 + i) for i in range(2)]
    entries = [{"path": str(p), "alignment": {"tracker_lag": lag}} for p, lag in zip(logs, lags)]
    sc = scenario_from_mapping({"name": "held", **FORMULATION, "datasets": entries}, "s", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    found = run.checks.plugin("held")
    assert found is not None and found.record is not None
    # A steered model also holds how each interval's steer angle is read (held_check.STEERING).
    assert run.checks.held_values() == {**held, "residual.steering_sample": 0.0}
    value = found.record["held"]["alignment.tracker_lag"]["value"]
    assert value == held["alignment.tracker_lag"] if held else math.isnan(value)  # lags that differ: none


def test_a_joint_fit_holds_each_logs_lag_pinned_on_its_search_edge(tmp_path: Path) -> None:
    # Two logs 50 ms late, each searched within ±20 ms: every log's lag is pinned at 20 ms. The
    # joint fit's held check holds both there, as one log's does (it saw none: the joint run knew
    # its logs' pinned lags only once its logs were attached, after its checks).
    from nlp_calib.pipeline.held_check import PINNED

    logs = []
    for i in range(2):
        path = tmp_path / f"late{i}.txt"
        write_simulation(simulate(SimulationOptions.of(records=900, seed=60 + i, latency_s=0.05)), path)
        logs.append(path)
    entries = [{"path": str(p), "alignment": {"tracker_lag": "auto", "search": [-0.02, 0.02]}} for p in logs]
    sc = scenario_from_mapping({"name": "pinned", **FORMULATION, "datasets": entries}, "s", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    assert run.pinned() == ("tracker_lag_1", "tracker_lag_2")
    found = run.checks.plugin("held")
    assert found is not None and found.record is not None
    held = found.record["held"]
    assert set(held) == {"tracker_lag_1", "tracker_lag_2", "residual.steering_sample"}
    for record in (held["tracker_lag_1"], held["tracker_lag_2"]):
        assert record["rule"] == PINNED and record["value"] == pytest.approx(0.02, abs=1e-6)


def test_a_check_judges_only_what_the_calibration_determined(tmp_path: Path) -> None:
    """A car whose drive leaves its rear track, wheelbase and steering gain loose together: the run
    hands them off as not determined and the rest as calibrated. Its check on the same log judged
    those three too and could not tell ("rear_track is known only to ±0.048 m from this drive");
    it judges what the calibration vouches for and names the rest as not judged."""
    log = tmp_path / "car.txt"
    write_simulation(simulate(SimulationOptions.of(model="car_like", records=3000, seed=8801)), log)
    sc = tmp_path / "car.yaml"
    sc.write_text(yaml.safe_dump({"model": "car_like", "dataset": str(log), "initial_guess": "from_file",
                                  "solvers": ["gauss_newton"]}))  # fmt: skip
    ran = cli("run", str(sc), "--out", str(tmp_path / "run"))
    assert ran.returncode == 0, ran.stdout + ran.stderr
    stored = yaml.safe_load((tmp_path / "run" / "calibration.yaml").read_text())
    doubted = set(stored.get("not_determined") or {})
    assert "rear_track" in doubted, stored.get("verdict")
    checked = cli("check", str(tmp_path / "run" / "calibration.yaml"), str(sc), "--out", str(tmp_path / "c"))
    assert checked.returncode == 0, checked.stdout + checked.stderr
    doc = check_json(tmp_path / "c")
    assert doc["verdict"] == STILL_GOOD
    assert doubted.isdisjoint(doc["parameters"]) and doc["parameters"]
    assert f"not judged: {', '.join(n for n in stored['parameters'] if n in doubted)}" in checked.stdout
