"""The held check: a value the fit holds (a lag given as a number, a parameter under ``known:``)
moved by its plausible error, and what that moves in the free parameters against their σ."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import sinusoids_scenario, two_sinusoids, write_sim

from nlp_calib import Calibration, load_scenario, scenario_from_mapping
from nlp_calib.analysis.drift import common_held
from nlp_calib.outputs.handoff import write_calibration
from nlp_calib.pipeline.stored import read_calibration
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, FINE, CheckResult
from nlp_calib.results.run import DOUBTFUL, GOOD

LAG = "alignment.tracker_lag"
MOVED = ("left_wheel_radius", "right_wheel_radius", "sensor_y")


def _held(run: CalibrationRun) -> CheckResult:
    found = next((c for c in run.checks.more if c.name == "held"), None)
    assert found is not None
    return found


def _sinusoids(folder: Path, lag: float) -> CalibrationRun:
    """The two-sinusoid drive (a camera at 50 Hz: 20 ms between records) stamped 40 ms late,
    fitted with the lag given as ``lag``."""
    path = sinusoids_scenario(folder, f"{{tracker_lag: {lag}}}")
    return Calibration(load_scenario(path)).run(["gauss_newton"])


@pytest.fixture(scope="module")
def one_interval_off(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, float], CalibrationRun]:
    """The drive of :func:`_sinusoids` and its truth, fitted with the lag given 20 ms (one record
    interval) off: one calibration for the tests that read it."""
    folder = tmp_path_factory.mktemp("one_interval_off")
    truth = two_sinusoids(folder, stamp_offset_s=-0.04)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # as the tests that read it filter them
        return truth, _sinusoids(folder, 0.02)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_lag_given_off_names_what_it_moves_and_keeps_it_from_the_hand_off(
    tmp_path: Path, one_interval_off: tuple[dict[str, float], CalibrationRun]
) -> None:
    """The camera's stamps 40 ms late (two record intervals), the lag given as 0: on this drive a
    time shift is a mix of the two wheels, which the radii and the mount take up (4 % on a radius,
    at σ of 1e-8 m). The check names the radii and sensor_y with the lag and what to do, and keeps
    them from the hand-off. Its linear response is the refit's: the lag given one record interval
    later moves each by what it says, and twice that is the run's error against the truth."""
    truth = two_sinusoids(tmp_path, stamp_offset_s=-0.04)
    run = _sinusoids(tmp_path, 0.0)
    held = _held(run)
    assert held.level == CAVEAT and run.verdict.level != GOOD
    record = held.record["held"][LAG]
    assert record["rule"] == "one record interval" and abs(record["error"] - 0.02) < 1e-3
    for name in MOVED:
        assert name in held.concerns and name in record["moved"]
        assert LAG in held.concerns[name] and "tracker_lag: auto" in held.concerns[name]
        status, why = run.handoff_status("gauss_newton")[name]
        assert status == DOUBTFUL and LAG in why
    later = one_interval_off[1].reports["gauss_newton"].result.param_dict()  # the same drive
    fitted = run.reports["gauss_newton"].result.param_dict()
    for name in MOVED:
        shift = record["shift"][name]
        assert later[name] - fitted[name] == pytest.approx(shift, rel=0.15), name
        # The truth lies two intervals later (the stamps 40 ms late): about twice the shift away.
        assert truth[name] - fitted[name] == pytest.approx(2 * shift, rel=0.15), name


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_lag_pinned_on_the_edge_of_its_search_is_held_there_against_what_it_moves(tmp_path: Path) -> None:
    """The camera's stamps 40 ms late on a drive that determines the lag (a beat on the right wheel),
    the lag searched within ±20 ms: pinned on the edge at 20 ms, one record interval short, with no
    σ of its own. The check holds it there, moves it one record interval beyond the edge (to the
    truth), names what that moves with the search to widen, and keeps them from the hand-off. Its
    response is the refit's with the lag given at 40 ms, which recovers the truth."""
    truth = two_sinusoids(tmp_path, stamp_offset_s=-0.04, beat=1.0)
    path = sinusoids_scenario(tmp_path, "{tracker_lag: auto, search: [-0.02, 0.02]}")
    run = Calibration(load_scenario(path)).run(["gauss_newton"])
    assert run.pinned() == ("tracker_lag",)
    held = _held(run)
    assert held.level == CAVEAT and run.verdict.level != GOOD
    record = held.record["held"]["tracker_lag"]
    assert abs(record["error"] - 0.02) < 1e-3 and "pinned" in record["rule"]
    fitted = run.reports["gauss_newton"].result.param_dict()
    for name in MOVED:
        assert name in record["moved"] and "widen alignment.search" in held.concerns[name]
        assert run.handoff_status("gauss_newton")[name][0] == DOUBTFUL
    later_run = _sinusoids(tmp_path, fitted["tracker_lag"] + 0.02)
    later, std = later_run.reports["gauss_newton"].result.param_dict(), later_run.std("gauss_newton")
    for name in MOVED:
        assert later[name] - fitted[name] == pytest.approx(record["shift"][name], rel=0.15), name
        assert abs(later[name] - truth[name]) < 2.0 * std[name], name


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_lag_given_one_interval_off_is_in_the_sigma_of_what_it_moves(
    tmp_path: Path, one_interval_off: tuple[dict[str, float], CalibrationRun]
) -> None:
    """The camera's stamps 40 ms late, the lag given 20 ms (one record interval, the plausible
    error) off. The σ the data give do not cover what the held lag moves (the radii, sensor_y and
    wheel_separation, which it moves within the 1 % a calibration needs, are many of them off); with
    each parameter's ``std_held`` in quadrature every estimate lies within 1.5σ of the truth, and the
    calibration.yaml ``nlp-calib check`` reads carries it in its between-logs σ."""
    truth, run = one_interval_off
    held = _held(run)
    std_held = held.record["std_held"]
    fitted, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    data_only = run.std("gauss_newton", slip=False)
    off = {n: abs(fitted[n] - truth[n]) for n in run.reports["gauss_newton"].uncertainty.free}
    assert max(off[n] / data_only[n] for n in MOVED) > 100.0  # the σ the data give alone
    assert off["wheel_separation"] > 3.0 * data_only["wheel_separation"]
    assert off["wheel_separation"] < 0.0057  # within the precision it needs: no caveat of its own
    assert "wheel_separation" not in held.concerns
    for name, err in off.items():
        assert err < 1.5 * std[name], (name, err, std[name])
    for name, extra in std_held.items():
        assert std[name] == pytest.approx(np.hypot(data_only[name], extra), rel=1e-9), name
    (path,) = write_calibration(run, tmp_path, "calibration.yaml")
    doc = yaml.safe_load(path.read_text())
    assert doc["std_held"]["wheel_separation"] == pytest.approx(std_held["wheel_separation"], rel=1e-12)
    stored = read_calibration(path)
    shared = stored.std_shared
    assert all(shared[n] >= std_held[n] for n in std_held)
    # The value held is written beside its σ: a check's refit that holds the same one shares that
    # part of the σ (it drops out of the change); one holding another lag, or none, shares nothing.
    assert doc["held_values"] == {LAG: 0.02} and stored.spreads.held_values == {LAG: 0.02}
    parts = (stored.spreads.held, stored.spreads.held_values)
    assert common_held(run, "gauss_newton", parts)
    assert not common_held(run, "gauss_newton", (parts[0], {LAG: 0.0}))
    assert not common_held(run, "gauss_newton", (parts[0], {}))


def test_a_lag_held_at_its_truth_on_a_drive_that_determines_everything_moves_nothing_beyond_its_sigma(
    tmp_path: Path,
) -> None:
    """A simulated differential drive (turns, stops, reversals; 100 Hz) whose tracker is 20 ms (two
    records) late, the lag given at its truth: a lag one record interval off would move no
    parameter by its σ: no caveat, and the record says so. (At 25 Hz one interval is 40 ms, which
    moves sensor_y by up to 2σ on such a drive, beyond the 1 cm it needs on one seed of five: the
    rule's caveat, even at the truth.)"""
    log = write_sim(
        tmp_path, "sim.txt", records=1500, seed=216, model="diff_drive", latency_s=0.02, rate_hz=100.0
    )
    doc = {
        "dataset": str(log),
        "model": "diff_drive",
        "initial_guess": "from_file",
        "alignment": {"tracker_lag": 0.02},
    }
    sc = scenario_from_mapping({**doc, "solvers": ["gauss_newton"]}, "held_truth", tmp_path)
    run = Calibration(sc).run(["gauss_newton"])
    held = _held(run)
    assert held.level == FINE and not held.concerns, held.words
    record = held.record["held"][LAG]
    assert record["moved"] == [] and abs(record["error"] - 0.01) < 1e-3
    assert all(abs(z) < 1.0 for z in record["shift_in_sigma"].values())


def test_a_known_parameters_response_is_the_refit_with_it_moved(tmp_path: Path) -> None:
    """The wheels' separation given under known: at its truth, its plausible error the precision a
    calibration needs of it (1 % of it). What the check says that error moves each free parameter
    by is what a fit with the separation given that much larger moves it by."""
    log = write_sim(tmp_path, "sim.txt", records=600, seed=217, model="diff_drive")
    doc = {
        "dataset": str(log),
        "model": "diff_drive",
        "initial_guess": "from_file",
        "solvers": ["gauss_newton"],
        "alignment": {"tracker_lag": 0.0},  # at its truth (a fitted lag settles only to its tolerance)
    }

    def fitted(baseline: float) -> CalibrationRun:
        sc = scenario_from_mapping({**doc, "known": {"baseline": baseline}}, "known", tmp_path)
        return Calibration(sc).run(["gauss_newton"])

    run = fitted(0.55)
    record = _held(run).record["held"]["baseline"]
    assert record["rule"] == "the precision a calibration needs of it"
    assert record["error"] == pytest.approx(0.0055, rel=1e-9)
    moved = fitted(0.55 + record["error"]).reports["gauss_newton"].result.param_dict()
    at = run.reports["gauss_newton"].result.param_dict()
    std = run.std("gauss_newton")
    compared = [n for n, s in record["shift"].items() if abs(s) > 0.2 * std[n]]
    assert compared, record
    for name in compared:
        assert moved[name] - at[name] == pytest.approx(record["shift"][name], rel=0.1), name


def test_a_lag_given_to_logs_fitted_together_is_moved_in_every_log(tmp_path: Path) -> None:
    """Two logs of the two-sinusoid drive fitted together, their camera's stamps 40 and 20 ms late
    and the lag given as 0 to both: the check moves both logs' lag by one record interval, names
    what that moves beyond its σ, and what it says each parameter moves by is what the joint fit
    with both lags given that much later moves it by."""
    entries = []
    for name, late in (("a", -0.04), ("b", -0.02)):
        (tmp_path / name).mkdir()
        two_sinusoids(tmp_path / name, stamp_offset_s=late)
        entries.append(
            {
                "poses": str(tmp_path / name / "cam.tum"),
                "joints": str(tmp_path / name / "cam.joints.csv"),
                "encoders": {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"},
            }
        )
    doc = {
        "model": "diff_drive",
        "sensor": "3d",
        "initial_guess": "auto",
        "known": {"sensor_z": 0.10},
        "datasets": entries,
        "residual": {"horizon_s": 0.25},
        "information": {"translation": 1.0e6, "rotation": 3.0e5},
        "robust": {"kernel": "huber", "delta": 10.0},
        "solvers": ["gauss_newton"],
    }

    def fitted(lag: float) -> CalibrationRun:
        sc = scenario_from_mapping({**doc, "alignment": {"tracker_lag": lag}}, "joint", tmp_path)
        return Calibration(sc).run(["gauss_newton"])

    run = fitted(0.0)
    held = _held(run)
    record = held.record["held"][LAG]
    assert held.level == CAVEAT and abs(record["error"] - 0.02) < 1e-3
    assert {"left_wheel_radius", "right_wheel_radius"} <= set(held.concerns)
    later = fitted(0.02).reports["gauss_newton"].result.param_dict()
    at = run.reports["gauss_newton"].result.param_dict()
    for name in MOVED:
        assert later[name] - at[name] == pytest.approx(record["shift"][name], rel=0.15), name


def test_a_value_declared_under_known_is_taken_as_exact_and_what_it_moves_said(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A steering gain given under known: whose plausible error would move the wheelbase beyond its
    σ and the precision it needs: the user's value is taken as exact (fine, no concern), and the
    words say what it would move; a time offset's same shift stays a caveat concerning it."""
    from nlp_calib.pipeline import held_check

    log = write_sim(tmp_path, "sim.txt", records=300, seed=218)
    doc = {"dataset": str(log), "model": "tricycle", "known": {"k_steer": 1.0}, "solvers": ["gauss_newton"]}
    run = Calibration(scenario_from_mapping(doc, "k", tmp_path)).run(["gauss_newton"])
    needed, shift = {"axis_length": 0.0015}, {"axis_length": 0.0016}
    gain = held_check.Response(
        "k_steer", 1.0, 0.01, held_check.NEEDED, "", shift, {"axis_length": 3.05}, needed
    )
    lag = held_check.Response(
        "tracker_lag", 0.0, 0.02, held_check.RECORD_INTERVAL, "s", shift, {"axis_length": 3.05}, needed
    )
    assert held_check.declared(gain, run) and not held_check.declared(lag, run)
    monkeypatch.setattr(held_check, "responses", lambda run, fit: [gain])
    said = held_check.check(run, object())  # type: ignore[arg-type]
    assert said is not None and said.level == FINE and not said.concerns, said
    assert "axis_length rests on k_steer given as 1 and taken as exact" in said.words, said.words
    assert "+0.0016" in said.words and "(+3.0σ)" in said.words, said.words
    monkeypatch.setattr(held_check, "responses", lambda run, fit: [gain, lag])
    said = held_check.check(run, object())  # type: ignore[arg-type]
    assert said is not None and said.level == CAVEAT and set(said.concerns) == {"axis_length"}, said
    assert "tracker_lag" in said.concerns["axis_length"] and "k_steer" not in said.concerns["axis_length"]
    assert "rests on k_steer" in said.words, said.words
