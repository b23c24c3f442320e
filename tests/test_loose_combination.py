"""A combination of parameters loose in the σ to believe though not in the white-noise σ: the
verdict names it, with what would determine it, and keeps its parameters from the hand-off; the
pre-flight, from its own fit, reads the same rule."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import sinusoids_scenario, two_sinusoids, write_sim

from nlp_calib import Calibration, load_scenario, scenario_from_mapping
from nlp_calib.outputs.ros2_control import write_ros2_control
from nlp_calib.pipeline.preflight import preflight
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, WEAK, CheckResult
from nlp_calib.results.preflight import WEAK_DRIVE, WEAKLY, Preflight
from nlp_calib.results.run import DOUBTFUL, LIVE

RADII = ("left_wheel_radius", "right_wheel_radius")
LAG = "tracker_lag"


def _observability(run: CalibrationRun) -> CheckResult:
    found = next((c for c in run.checks.more if c.name == "observability"), None)
    assert found is not None
    return found


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_ridge_loose_only_in_the_sigma_to_believe_is_named_and_kept_from_handoff(tmp_path: Path) -> None:
    """The two-sinusoid drive with a small beat on one wheel (a time shift is nearly a mix of the
    wheels) and rolling radii that vary 1 % along the drive, fitted as a user would (defaults, the
    lag fitted). The white noise determines every direction; the blocks' σ widen each parameter
    many times, the radii each still within 5× the 1 % they need, but they move with the lag: the
    combination's σ (from the run's own σ to believe and correlations) is beyond 5×, and the
    difference of the radii is off by more than the 1 % a calibration needs of it."""
    truth = two_sinusoids(tmp_path, beat=0.1, wobble=0.01)
    scenario = load_scenario(sinusoids_scenario(tmp_path, alignment="", formulation=""))
    run = Calibration(scenario).run(["gauss_newton"])
    obs, found = run.checks.observability, _observability(run)
    assert obs is not None and not obs.weak, obs.weak  # the white noise names nothing
    u = run.reports["gauss_newton"].uncertainty
    std, params = run.std("gauss_newton"), run.reports["gauss_newton"].result.param_dict()
    needed = run.scenario.layout.needed(params)
    for name in RADII:  # each passes alone
        assert std[name] <= WEAK * needed[name], (name, std[name])
    off = (params[RADII[1]] - params[RADII[0]]) - (truth[RADII[1]] - truth[RADII[0]])
    assert abs(off) > needed[RADII[0]]  # what the hand-off would carry
    loose = found.record["loose_in_believed"]
    assert len(loose) == 1 and {*RADII, LAG} <= set(loose[0]["components"]), loose
    # Its σ, from the σ to believe and the white-noise correlations, computed here on their own.
    names = list(loose[0]["components"])
    v = np.array([loose[0]["components"][n] for n in names])
    idx = [u.names.index(n) for n in names]
    z = np.array([std[n] / needed[n] for n in names])
    sigma = float(np.sqrt(v @ (u.correlation[np.ix_(idx, idx)] * np.outer(z, z)) @ v / (v @ v)))
    assert sigma > WEAK and loose[0]["std_in_reference_units"] == pytest.approx(sigma, rel=0.05)
    said = [r for r in run.verdict.reasons if "move together" in r]
    assert len(said) == 1 and all(n in said[0] for n in (*RADII, LAG)), run.verdict.reasons
    assert "give the lag (alignment.tracker_lag" in said[0]
    assert "move together" in found.words
    status = run.handoff_status("gauss_newton")
    for name in RADII:
        assert status[name][0] == DOUBTFUL and "move together" in status[name][1], status[name]
    assert status["wheel_separation"][0] == LIVE
    # What the loose combination leaves determined is handed off: the mean radius (the controller's
    # wheel_radius) is known to its precision, and right; the radii's ratio (the multipliers) is not.
    controller = run.reports["gauss_newton"].controller
    waived = run.waived("gauss_newton")
    assert set(waived) == {"wheel_radius"}, waived
    mean = 0.5 * (truth[RADII[0]] + truth[RADII[1]])
    assert abs(controller.parameters["wheel_radius"] - mean) <= 2 * controller.std["wheel_radius"]
    assert controller.std["wheel_radius"] <= needed[RADII[0]]
    # A caveat on every parameter (a wrong model's) leaves nothing waived.
    wrong = CheckResult("model", CAVEAT, "the model does not fit", about={"concerns": "all"})
    every = dataclasses.replace(run.checks, more=(*run.checks.more, wrong))
    assert dataclasses.replace(run, checks=every).waived("gauss_newton") == {}
    (path,) = write_ros2_control(run, tmp_path, "ros2_control.yaml", "jazzy")
    live = yaml.safe_load(path.read_text())["diff_drive_controller"]["ros__parameters"]
    assert "wheel_radius" in live and "left_wheel_radius_multiplier" not in live, live
    # The pre-flight reads the same rule from its own fit: the combination's parameters are weakly
    # determined, each passing alone, with the run's advice; it does not refuse (nor does the run).
    report = preflight(scenario)
    _agrees_with_the_run(report, {*RADII, LAG}, "give the lag (alignment.tracker_lag")


def _agrees_with_the_run(report: Preflight, loose: set[str], advice: str) -> None:
    status = {p.name: p for p in report.parameters}
    for name in loose:
        p = status[name]
        assert p.status == WEAKLY and all(n in p.because for n in loose - {name}), p
    for name in RADII:  # each passes alone: the combination is why
        p = status[name]
        assert p.std_reference <= WEAK and "one combination of them is known only to" in p.because, p
    assert report.verdict == WEAK_DRIVE and not report.stop_words()
    assert advice in report.way_out, report.way_out


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_drive_that_determines_everything_gets_no_loose_combination(tmp_path: Path) -> None:
    """A simulated differential drive with turns (seed 4301, never tuned on), fitted with the
    defaults: no combination is loose in its σ to believe, and the verdict names none."""
    log = write_sim(tmp_path, "sim.txt", records=600, seed=4301, model="diff_drive")
    doc = {"dataset": str(log), "model": "diff_drive", "initial_guess": "from_file"}
    doc["solvers"] = ["gauss_newton"]
    run = Calibration(scenario_from_mapping(doc, "turns", tmp_path)).run(["gauss_newton"])
    found = _observability(run)
    assert found.record["loose_in_believed"] == []
    assert not any("move together" in r for r in run.verdict.reasons), run.verdict.reasons
    report = preflight(scenario_from_mapping(doc, "turns", tmp_path))
    assert not any("one combination of them" in p.because for p in report.parameters), report.parameters
