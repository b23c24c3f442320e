"""What a verdict rests on: the robot's nominal values as the baseline, a start judged by what the
reference measures well, and a joint fit judged as one fit over every log."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import shared_scenario

from nlp_calib.analysis.verdict import verdict
from nlp_calib.models import get_model
from nlp_calib.outputs.summary import summary_lines
from nlp_calib.pipeline import Calibration, consistency_check, scenario_from_mapping
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CostComparison
from nlp_calib.results.run import NOT_USABLE
from nlp_calib.simulation import SimulationOptions, simulate, write_simulation

BASE: dict[str, Any] = {"model": "tricycle", "solvers": ["gauss_newton"], "residual": {"horizon": 10}}


def test_a_cost_comparison_is_decided_held_out_in_standard_errors() -> None:
    """Per fold: the other set's and the fold's held-out cost; beyond 2 standard errors of the mean
    saving either way the fit is better or worse, within them no better; no folds: in sample."""
    rng = np.random.default_rng(0)
    fit = 10 + rng.normal(0, 1, 10)
    noise = rng.normal(0, 0.1, 10)
    better = CostComparison("the initial guess", np.stack([fit + 1 + noise, fit], axis=1), (2.0, 1.0))
    same = CostComparison("the initial guess", np.stack([fit + noise, fit], axis=1), (2.0, 1.0))
    worse = CostComparison("the initial guess", np.stack([fit - 1 + noise, fit], axis=1), (2.0, 1.0))
    d = noise
    t = np.mean(d) / (np.std(d, ddof=1) / np.sqrt(d.size))  # independent computation of `same`
    assert same.gain_sigmas == pytest.approx(t)
    assert [c.outcome for c in (better, same, worse)] == [
        "better",
        "same" if abs(t) <= 2 else same.outcome,
        "worse",
    ]
    assert worse.words().startswith(
        "worse than the initial guess on held-out data (its residual cost higher by"
    )
    insample = CostComparison("the initial guess", np.zeros((0, 2)), (1.0, 1.5))
    assert (
        insample.outcome == "worse"
        and insample.words() == "worse than the initial guess (data cost 1.5 against 1)"
    )


def _sim(folder: Path, name: str, **options: Any) -> Path:
    path = folder / name
    write_simulation(simulate(SimulationOptions.of(**options)), path)
    return path


def test_the_nominal_robot_is_the_baseline_beside_a_data_driven_start(tmp_path: Path) -> None:
    """A text log's header is its robot's nominal values: with ``initial_guess: auto`` the verdict
    states the gain over them (not over the data-driven start), with the same figure the run
    scores for them; without any, it says none is known."""
    path = _sim(tmp_path, "drive.txt", records=600, seed=5)
    sc = scenario_from_mapping({**BASE, "dataset": str(path), "initial_guess": "auto"}, "s", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    nominal = run.checks.nominal
    assert nominal is not None and nominal.source == "the log's header"
    assert set(nominal.values) == {n for n in run.initial if n in nominal.values}
    ours, theirs = run.reports["gauss_newton"].metrics.segment_ate.mean, nominal.metrics.segment_ate.mean
    assert f"{theirs / ours:.2g}× closer to the tracker than the nominal robot" in run.verdict.gain
    assert "the log's header" in run.verdict.gain and run.verdict.gain in run.verdict.line()
    unknown = dataclasses.replace(run, checks=dataclasses.replace(run.checks, nominal=None))
    assert verdict(unknown, get_model("tricycle")).gain.startswith("no nominal robot known")


def test_a_joint_fit_is_judged_on_every_log_not_on_its_first(tmp_path: Path) -> None:
    """The first log a short straight line its nominal values (the truth) already track: judged
    alone, calibrating cannot beat them there. The joint fit's verdict is the joint fit's, its
    figures are over both logs, the summary names it as the joint fit, and each log keeps its own
    figures and verdict."""
    guess = {"k_steer": 0.55, "k_traction": 0.0105, "axis_length": 1.5, "steer_offset": -0.05}
    line = _sim(tmp_path, "line.txt", records=150, seed=7, trajectory="straight", guess=guess)
    curves = _sim(tmp_path, "curves.txt", records=800, seed=8, guess=guess)
    raw = {**BASE, "datasets": [str(line), str(curves)], "initial_guess": "from_file"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        joint = Calibration(scenario_from_mapping(raw, "j", tmp_path)).run()
    whole = joint
    assert whole.data.used == (0, sum(p.data.fit[1] - p.data.fit[0] for p in joint.logs))
    assert whole.verdict.level != NOT_USABLE, whole.verdict.line()
    assert summary_lines(whole)[0].startswith("summary of the joint fit of 2 logs (j):")
    figures = {p.log.path: p.reports["gauss_newton"].metrics.segment_ate.mean for p in joint.logs}
    ate = whole.reports["gauss_newton"].metrics.segment_ate.mean
    assert min(figures.values()) <= ate <= max(figures.values())
    assert [p.log.path for p in joint.logs] == [str(line), str(curves)]
    # One σ for the joint fit and each log's view of it, NaN alike where a lag is held without one
    # (the straight line's: no valley to fit it in); NaN compared as a value, not as an object.
    stds = [joint.std("gauss_newton"), whole.std("gauss_newton"), joint.logs[1].std("gauss_newton")]
    assert all(list(s) == list(stds[0]) for s in stds)
    for s in stds[1:]:
        np.testing.assert_array_equal(list(s.values()), list(stds[0].values()))


def _shipped(name: str) -> CalibrationRun:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Calibration(shared_scenario(name)).run(("gauss_newton",))


def test_optiodom_tricycle_squares_one_robot_whose_mount_moves_with_the_turning() -> None:
    """Two runs of one tricycle on a square (clockwise, anticlockwise): their own fits put the
    tracked point 11 mm apart sideways, 16σ of their own, but within what one robot's logs differ
    by. Usable, the parameter named as a model limit and its σ covering the spread."""
    joint = _shipped("optiodom_tricycle_square")
    check = joint.checks.consistency
    assert check is not None and not check.significant and joint.verdict.level != NOT_USABLE
    moved = [n for n, m in zip(check.names, check.moved) if m]
    assert moved == ["sensor_y"], consistency_check.words(check)
    j = check.names.index("sensor_y")
    spread = abs(check.own[0, j] - check.own[1, j])
    assert joint.std("gauss_newton")["sensor_y"] >= 0.45 * spread
    assert any("sensor_y by" in r and "model limit" in r for r in joint.verdict.reasons)
    assert "closer to the tracker than the nominal robot" in joint.verdict.gain


def test_optiodom_tricycle_circles_usable_with_the_gain_over_the_nominal_robot() -> None:
    joint = _shipped("optiodom_tricycle_circular")
    assert joint.verdict.level != NOT_USABLE, joint.verdict.line()
    nominal = joint.checks.nominal
    assert nominal is not None and nominal.source == "ROBOT.yaml"
    assert set(nominal.values) == {
        "wheel_radius",
        "wheelbase",
        "steer_offset",
        "sensor_x",
        "sensor_y",
        "sensor_theta",
    }
    assert nominal.cost is not None and nominal.cost.outcome == "better"


@pytest.mark.slow
def test_optiodom_diff_drive_six_circles_agree() -> None:
    joint = _shipped("optiodom_diff_circular")
    assert joint.verdict.level != NOT_USABLE, joint.verdict.line()
    assert [p.verdict.level != NOT_USABLE for p in joint.logs] == [True] * 6
    logs = joint.checks.logs
    assert logs is not None and np.all(np.isfinite(logs.std)) and len(logs.folds) == 6
