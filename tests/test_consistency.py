"""Checks that say what they found: logs of one robot or of two, a direction check that could not
compare, and a calibration worse than its starting point."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import parse_lines, write_sim

from nlp_calib.analysis.consistency import combined_others, compare_logs, determined
from nlp_calib.analysis.direction import compare
from nlp_calib.models import get_model
from nlp_calib.pipeline import Calibration, consistency_check, direction_check, scenario_from_mapping
from nlp_calib.results import Checks
from nlp_calib.results.checks import CONSISTENCY_SIGMAS as SIGNIFICANT
from nlp_calib.results.checks import ConsistencyCheck, CrossValidation, believed_std
from nlp_calib.results.run import NOT_USABLE
from nlp_calib.simulation import SimulationOptions, simulate

NAMES = ("a", "b")


def _unit_check(
    own: np.ndarray, std: np.ndarray, apart: float = 10.0, known: np.ndarray | None = None
) -> ConsistencyCheck:
    """Logs whose "other logs" fit is the information-weighted mean of the other logs' own."""
    w = 1.0 / std**2
    others = (np.sum(w * own, axis=0) - w * own) / (np.sum(w, axis=0) - w)
    joint = np.sum(w * own, axis=0) / np.sum(w, axis=0)
    mask = np.ones(own.shape, dtype=bool) if known is None else known
    return compare_logs(
        NAMES[: own.shape[1]],
        LOGS[: own.shape[0]],
        joint,
        (own, std),
        others,
        mask,
        np.full(own.shape[1], apart),
    )


LOGS = ("x.txt", "y.txt", "z.txt")


def test_two_logs_differ_in_the_sigma_of_their_difference() -> None:
    """Two logs: each one's own fit against the other's, in σ of their difference (independent
    computation); beyond 4σ and beyond what one robot's logs differ by, the logs are named apart."""
    own = np.array([[1.0, 5.0], [1.6, 5.1]])
    std = np.array([[0.1, 0.2], [0.1, 0.2]])
    check = _unit_check(own, std, apart=0.3)
    pair = (own[0] - own[1]) / np.sqrt(np.sum(std**2, axis=0))
    np.testing.assert_allclose(check.z[0], pair, rtol=1e-12)
    np.testing.assert_allclose(check.z[1], -pair, rtol=1e-12)
    assert abs(pair[0]) > SIGNIFICANT > abs(pair[1])
    assert check.significant and [(d.log, d.parameter) for d in check.different] == [
        ("x.txt", "a"),
        ("y.txt", "a"),
    ]
    assert "a differ in x.txt, y.txt" in consistency_check.words(check)
    assert list(check.moved) == [True, False]


def test_a_difference_within_what_one_robot_moves_by_is_a_model_limit() -> None:
    """Far beyond σ but within ``apart``: not two robots, the parameter named as moving between the
    logs; its σ to believe takes in the jackknife over the logs, the others' do not."""
    own = np.array([[1.0, 5.0], [1.6, 5.1]])
    check = _unit_check(own, np.array([[0.1, 0.2], [0.1, 0.2]]), apart=1.0)
    assert not check.significant and check.disagreements and check.moved[0]
    assert consistency_check.limits(check)[0] == f"a by {100 * 0.6 / 1.3:.2g} % (4σ, x.txt)"
    assert "model limit" in consistency_check.words(check) and "a by" in consistency_check.words(check)
    logs = CrossValidation(NAMES, (), np.array([0.3, 0.05]))
    checks = Checks(None, None, None, None, check, logs=logs)
    white = np.array([0.01, 0.01])
    np.testing.assert_allclose(believed_std(white, *checks.spreads(white)), [0.3, 0.01])


def test_a_parameter_a_log_does_not_determine_on_its_own_is_not_compared() -> None:
    own = np.array([[1.0, 5.0], [1.6, 9.0]])
    known = np.array([[True, False], [True, False]])
    check = _unit_check(own, np.array([[0.1, 0.2], [0.1, 0.2]]), apart=0.1, known=known)
    assert np.all(np.isnan(check.z[:, 1])) and {d.parameter for d in check.disagreements} == {"a"}
    none = _unit_check(own, np.ones((2, 2)), known=np.zeros((2, 2), dtype=bool))
    assert not none.compared and not none.significant and none.worst is None
    assert "could not be compared" in consistency_check.words(none)


def test_the_other_logs_sigma_is_their_information_combined() -> None:
    std = np.array([[0.1], [0.2], [np.inf]])
    np.testing.assert_allclose(combined_others(std)[:, 0], [0.2, 0.1, 1 / np.sqrt(1 / 0.01 + 1 / 0.04)])
    assert np.isnan(combined_others(np.array([[0.1], [np.nan]]))[0, 0])


def test_what_a_log_determines_on_its_own() -> None:
    model = get_model("tricycle")
    names = ("k_traction", "axis_length", "sensor_x")
    values = np.array([0.01, 1.5, 1.6])
    # 5 % of a gain or length, 5 cm of a position: within, beyond, not finite.
    std = np.array([0.0004, 1.5 * 0.06, np.inf])
    assert list(determined(model, names, values, std)) == [True, False, False]


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
        joint = Calibration(scenario_from_mapping({**RAW, "datasets": [str(a), str(b)]}, "j", folder)).run()
    assert joint.checks.consistency is not None
    return joint.checks.consistency


def test_two_logs_of_one_robot_agree(tmp_path: Path) -> None:
    check = _check(*_pair(tmp_path, 1, {}), tmp_path)
    assert check.compared and not check.significant, consistency_check.words(check)


def test_two_logs_of_different_robots_are_told_apart_naming_parameter_and_logs(tmp_path: Path) -> None:
    a, b = _pair(tmp_path, 2, {"k_traction": 0.0105 * 1.03, "axis_length": 1.6})
    check = _check(a, b, tmp_path)
    assert check.significant
    named = {d.parameter for d in check.disagreements}
    assert "k_traction" in named and {d.log for d in check.disagreements} == {str(a), str(b)}
    assert "k_traction" in consistency_check.words(check) and a.name in consistency_check.words(check)


def test_forward_and_reverse_that_disagree_widen_the_sigma_to_cover_both() -> None:
    check = compare(
        NAMES,
        np.array([1.0, 2.0]),
        np.array([1.4, 2.01]),
        (100, 90),
        np.full(2, 0.05),
        np.full(2, 0.05),
        set(),
    )
    assert check.significant and abs(check.z[0]) > 4 > abs(check.z[1])
    noise = 0.4 / abs(check.z[0])
    np.testing.assert_allclose(check.spread(), [0.5 * np.sqrt(0.4**2 - noise**2), np.nan])


def test_a_direction_finding_needs_many_sigma_and_a_difference_beyond_the_precision_needed() -> None:
    """Three parameters each 10σ apart: one by 0.4 of its needed precision (noise-free data, where
    σ is nearly nothing), one by 4 times it; a third by 4 times it but within its noise (1σ)."""
    forward, needed = np.array([1.0, 2.0, 3.0]), np.full(3, 0.01)
    reverse = forward + np.array([0.004, 0.04, 0.04])
    std = np.array([0.0004, 0.004, 0.04]) / np.sqrt(2)  # σ of the difference: 1/10, 1/10, 1
    names = ("a", "b", "c")
    check = compare(names, forward, reverse, (100, 90), std, std, set(), None, needed)
    np.testing.assert_allclose(np.abs(check.z), [10.0, 10.0, 1.0])
    assert check.flagged.tolist() == [False, True, False]
    assert check.significant and check.worst == ("b", pytest.approx(-10.0))
    assert direction_check.words(check) == "DISAGREE: b by 10.0σ"
    one = forward + np.array([0.004, 0.0, 0.0])
    small = compare(names, forward, one, (100, 90), std, std, set(), None, needed)
    assert not small.significant and not small.flagged.any()
    assert direction_check.words(small) == (
        "agree within the precision needed (a differs by 10.0σ, only 0.4× the precision it needs)"
    )
    # Without a needed precision, any difference beyond 3σ is a finding (as before).
    bare = compare(names, forward, one, (100, 90), std, std, set())
    assert bare.significant and bare.worst[0] == "a"


def test_the_direction_check_says_when_it_could_not_compare() -> None:
    nan = np.full(2, np.nan)
    check = compare(NAMES, np.ones(2), np.ones(2), (100, 30), np.ones(2), nan, set())
    assert not check.compared and not check.significant
    assert "could not be compared" in direction_check.words(check) and "nan" not in direction_check.words(
        check
    )
    ok = compare(NAMES, np.ones(2), np.array([1.1, 1.0]), (100, 90), np.ones(2), np.ones(2), set())
    assert direction_check.words(ok) == "agree within 0.1σ (a)"


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

    # A data-driven start and no nominal values known (the guess given here was both).
    fitted_start = replace(
        worse,
        scenario=replace(worse.scenario, initial_guess="auto"),
        checks=replace(worse.checks, nominal=None),
    )
    v = verdict(fitted_start, get_model("tricycle"))
    assert v.level == CAVEATS and any("no better than the data-driven start" in r for r in v.reasons), v
    # The given guess is the robot's nominal values too: worse than them is not usable either way.
    v = verdict(replace(fitted_start, checks=worse.checks), get_model("tricycle"))
    assert v.level == NOT_USABLE and v.reasons == (
        "worse than the nominal robot (data cost 0.02409 against 0.02388)",
    ), v
