"""Checks that say what they found: logs of one robot or of two, a direction check that could not
compare, and a calibration worse than its starting point."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import parse_lines, write_sim

from nlp_calib.analysis.consistency import compare_logs
from nlp_calib.analysis.direction import compare
from nlp_calib.pipeline import Calibration, JointCalibration, scenario_from_mapping
from nlp_calib.results.checks import CONSISTENCY_SIGMAS as SIGNIFICANT
from nlp_calib.results.checks import ConsistencyCheck
from nlp_calib.results.run import NOT_USABLE
from nlp_calib.simulation import SimulationOptions, simulate

NAMES = ("a", "b")


def test_against_the_joint_fit_two_logs_differ_as_they_differ_from_each_other() -> None:
    """For estimates combined by their information, each log's difference to the joint fit in σ
    of that difference is the two logs' difference in σ of theirs (independent computation; logs
    of equal information, where the floor on that σ does not bind)."""
    own = np.array([[1.0, 5.0], [1.6, 5.1]])
    std = np.array([[0.1, 0.2], [0.1, 0.2]])
    w = 1.0 / std**2
    joint = np.sum(w * own, axis=0) / np.sum(w, axis=0)
    std_joint = 1.0 / np.sqrt(np.sum(w, axis=0))
    check = compare_logs(NAMES, ("x.txt", "y.txt"), joint, std_joint, own, std)
    pair = (own[0] - own[1]) / np.sqrt(np.sum(std**2, axis=0))
    np.testing.assert_allclose(check.z[0], pair, rtol=1e-12)
    np.testing.assert_allclose(check.z[1], -pair, rtol=1e-12)
    assert abs(pair[0]) > SIGNIFICANT > abs(pair[1])
    assert check.significant and [(d.log, d.parameter) for d in check.disagreements] == [
        ("x.txt", "a"),
        ("y.txt", "a"),
    ]
    assert "a differ in x.txt, y.txt" in check.words()


def test_a_log_holding_most_of_the_information_is_compared_conservatively() -> None:
    """Where the joint σ comes close to a log's own, the σ of their difference is at least the
    log's share of its own variance: never a division by a vanishing difference of variances."""
    own, std = np.array([[1.0], [1.3]]), np.array([[0.1], [1.0]])
    w = 1.0 / std**2
    joint = np.sum(w * own, axis=0) / np.sum(w, axis=0)
    check = compare_logs(("a",), ("x.txt", "y.txt"), joint, 1.0 / np.sqrt(np.sum(w, axis=0)), own, std)
    assert abs(check.z[0, 0]) == pytest.approx(abs(own[0, 0] - joint[0]) / (0.1 / np.sqrt(2.0)), rel=1e-12)
    assert abs(check.z[0, 0]) < abs(own[0, 0] - own[1, 0]) / np.sqrt(np.sum(std**2))


def test_held_parameters_are_not_compared_and_nothing_to_compare_is_said() -> None:
    check = compare_logs(
        NAMES, ("x.txt",), np.zeros(2), np.ones(2), np.ones((1, 2)), np.full((1, 2), 2.0), [{"a", "b"}]
    )
    assert not check.compared and not check.significant and check.worst is None
    assert "could not be compared" in check.words()


def _pair(tmp_path: Path, seed: int, other: dict[str, float]) -> tuple[Path, Path]:
    a = write_sim(tmp_path, f"a{seed}.txt", records=1200, seed=seed, latency_s=0.05)
    b = write_sim(tmp_path, f"b{seed}.txt", records=1200, seed=seed + 50, latency_s=0.05, truth=other)
    return a, b


RAW = {
    "model": "tricycle",
    "solvers": ["gauss_newton"],
    "residual": {"horizon": 25, "steering_sample": "mean"},
    "alignment": {"tracker_lag": "auto"},
}


def _check(a: Path, b: Path, folder: Path) -> ConsistencyCheck:
    """The joint run's own check: each log fitted alone against the two fitted together."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        joint = JointCalibration(
            scenario_from_mapping({**RAW, "datasets": [str(a), str(b)]}, "j", folder)
        ).run()
    assert joint.checks.consistency is not None
    return joint.checks.consistency


def test_two_logs_of_one_robot_agree(tmp_path: Path) -> None:
    check = _check(*_pair(tmp_path, 1, {}), tmp_path)
    assert check.compared and not check.significant, check.words()


def test_two_logs_of_different_robots_are_told_apart_naming_parameter_and_logs(tmp_path: Path) -> None:
    a, b = _pair(tmp_path, 2, {"k_traction": 0.0105 * 1.03, "axis_length": 1.6})
    check = _check(a, b, tmp_path)
    assert check.significant
    named = {d.parameter for d in check.disagreements}
    assert "k_traction" in named and {d.log for d in check.disagreements} == {str(a), str(b)}
    assert "k_traction" in check.words() and a.name in check.words()


def test_the_direction_check_says_when_it_could_not_compare() -> None:
    nan = np.full(2, np.nan)
    check = compare(NAMES, np.ones(2), np.ones(2), (100, 30), np.ones(2), nan, set())
    assert not check.compared and not check.significant
    assert "could not be compared" in check.words() and "nan" not in check.words()
    ok = compare(NAMES, np.ones(2), np.array([1.1, 1.0]), (100, 90), np.ones(2), np.ones(2), set())
    assert ok.words() == "agree within 0.1σ (a)"


def test_a_calibration_worse_than_its_initial_guess_is_not_usable(tmp_path: Path) -> None:
    """Started at the truth, with a prior that holds the traction gain 5 % off it: the fit ends
    farther from the tracker than where it started, whatever else holds."""
    sim = simulate(SimulationOptions.of(records=1000, seed=3))
    log = parse_lines(sim.text().splitlines(), "sim.txt")
    truth = dict(sim.options.truth)
    raw = {
        "dataset": "sim.txt",
        "model": "tricycle",
        "solvers": ["gauss_newton"],
        "validation": {"blocks": 0},
        "initial_guess": truth,
    }
    pulled = {**raw, "priors": {"k_traction": {"mean": truth["k_traction"] * 1.05, "std": 1e-7}}}
    worse = Calibration(scenario_from_mapping(pulled, "w", tmp_path), log=log).run()
    fine = Calibration(scenario_from_mapping(raw, "b", tmp_path), log=log).run()
    assert worse.reports["gauss_newton"].metrics.segment_ate.mean > worse.baseline.segment_ate.mean
    v = worse.verdict
    assert v.level == NOT_USABLE and "worse than the initial guess" in v.reasons[0], v
    assert fine.verdict.level != NOT_USABLE
    # The same fit judged against a start computed from the data (initial_guess: auto): that start
    # is itself a fit, so doing no better than it is a caveat, not a reason to discard the answer.
    from dataclasses import replace

    from nlp_calib.analysis.verdict import verdict
    from nlp_calib.models import get_model
    from nlp_calib.results.run import CAVEATS

    fitted_start = replace(worse, scenario=replace(worse.scenario, initial_guess="auto"))
    v = verdict(fitted_start, get_model("tricycle"))
    assert v.level == CAVEATS and any("no better than the data-driven start" in r for r in v.reasons), v
