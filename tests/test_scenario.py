"""Scenario validation: every mistake is reported with its place and the valid choices."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import SCENARIOS

from nlp_calib.core.errors import ScenarioError
from nlp_calib.pipeline import Calibration
from nlp_calib.pipeline.scenario import load_scenario


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.yaml"
    p.write_text(f"dataset: {SCENARIOS / 'data' / 'demo_tricycle.txt'}\n" + text)
    return p


def test_shipped_scenarios_load() -> None:
    for p in SCENARIOS.glob("*.yaml"):
        sc = load_scenario(p)
        assert sc.name == p.stem


def test_unknown_top_level_key_names_it_and_lists_valid_ones(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError) as exc:
        load_scenario(write(tmp_path, "solver: [ipopt]\n"))
    msg = str(exc.value)
    assert "solver" in msg and "unknown key" in msg
    assert "solvers" in msg and "residual" in msg and "robust" in msg


def test_unknown_nested_key(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"residual\.horizn: unknown key; valid keys are horizon, stride"):
        load_scenario(write(tmp_path, "residual: {horizn: 5}\n"))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("residual: {horizon: ten}\n", "residual.horizon: expected an integer"),
        ("residual: {horizon: 0}\n", "residual.horizon: must be a whole number in [1, 200], got 0"),
        ("robust: {kernel: tukey}\n", "'tukey' is not one of"),
        ("robust: {delta: -1}\n", "robust.delta: must be a number in (0, 1e+06], got -1"),
        ("solvers: [gauss_newton, lbfgs]\n", "'lbfgs' is not one of gauss_newton, ipopt"),
        ("bounds: {axis_length: [2.0, 1.0]}\n", "bounds.axis_length: needs lo < hi"),
        ("bounds: {axle: [1.0, 2.0]}\n", "'axle' is not one of k_steer"),
        ("bounds: {axis_length: [1.0]}\n", "expected a list of 2 values"),
        ("initial_guess: best\n", "'best' is not one of from_file, auto"),
        ("validation: {holdout_fraction: 1.5}\n", "must lie in (0, 1)"),
        (
            "fixed: [k_steer, k_traction, axis_length, steer_offset, sensor_x, sensor_y, sensor_theta]\n",
            "nothing is left",
        ),
        ("priors: {axis_length: {mean: 1.5, std: 0}}\n", "priors.axis_length.std: must be a number in"),
        ("ipopt: {huber_formulation: slack}\n", "huber_formulation must be one of"),
        ("gauss_newton: {max_iterations: 0}\n", "max_iterations must be >= 1"),
        ("strict: maybe\n", "expected true or false"),
    ],
)
def test_bad_values(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ScenarioError) as exc:
        load_scenario(write(tmp_path, text))
    assert message in str(exc.value)


def test_invalid_yaml_reports_line(tmp_path: Path) -> None:
    p = tmp_path / "bad.yaml"
    p.write_text("dataset: x.txt\nresidual: {horizon: 1\n")
    with pytest.raises(ScenarioError, match=r"bad\.yaml:\d+: not valid YAML"):
        load_scenario(p)


def test_initial_guess_outside_bounds_is_rejected(tmp_path: Path) -> None:
    sc = load_scenario(write(tmp_path, "bounds: {axis_length: [2.0, 3.0]}\n"))
    with pytest.raises(
        ScenarioError, match=r"bounds\.axis_length: the initial guess 1\.4 lies outside \[2, 3\]"
    ):
        Calibration.setup(sc)


def test_dataset_path_is_relative_to_the_yaml() -> None:
    sc = load_scenario(SCENARIOS / "demo.yaml")
    assert sc.dataset == SCENARIOS / "data" / "demo_tricycle.txt"
