"""``nlp-calib check``: the statistics it judges by, each verdict on a simulated robot (one drive
each), its files, exit codes and errors. How often it is right over many drives is
``benchmarks/check_study.py``'s to measure."""

from __future__ import annotations

import dataclasses
import json
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REAL_LOG, SCENARIOS, cli, write_sim

from nlp_calib.analysis.drift import FALSE_ALARM, between_logs_std, t_quantile, two_sided_tail, welch_dof
from nlp_calib.core.errors import UsageError
from nlp_calib.models import MODELS
from nlp_calib.outputs.check import check_document
from nlp_calib.outputs.handoff import write_calibration
from nlp_calib.outputs.results import result_dict
from nlp_calib.outputs.terminal import run_table
from nlp_calib.pipeline import Calibration, load_scenario
from nlp_calib.pipeline.check import check, check_scenario
from nlp_calib.pipeline.stored import read_calibration
from nlp_calib.results import CalibrationRun
from nlp_calib.results.check import CANNOT_TELL, DRIFTED, STILL_GOOD

TRUTH = MODELS["tricycle"].drive.default_truth


@pytest.mark.parametrize(
    ("p", "dof"), [(0.05, 9.0), (0.01 / 7, 9.0), (0.01 / 7, 18.0), (1e-4, 3.0), (0.05, 1.0)]
)
def test_the_t_quantile_is_scipys(p: float, dof: float) -> None:
    stats = pytest.importorskip("scipy.stats")
    assert t_quantile(p, dof) == pytest.approx(stats.t.ppf(1 - p / 2, dof), rel=1e-9)
    assert two_sided_tail(2.5, dof) == pytest.approx(2 * stats.t.sf(2.5, dof), rel=1e-9)


def test_the_normal_limit_and_welch_satterthwaite() -> None:
    assert t_quantile(0.05, math.inf) == pytest.approx(1.959963985, rel=1e-8)
    assert welch_dof((1.0, 1.0), (9.0, 9.0)) == pytest.approx(18.0)  # two equal jackknife σ
    assert welch_dof((1.0, 1.0), (9.0, math.inf)) == pytest.approx(36.0)
    assert math.isinf(welch_dof((1.0, 2.0), (math.inf, math.inf)))


@pytest.fixture(scope="module")
def stored(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A calibration of one simulated drive with the demo scenario's formulation, as run writes it."""
    tmp = tmp_path_factory.mktemp("check")
    log = write_sim(tmp, "calibration_drive.txt", records=1500, seed=11, outlier_fraction=0.01)
    sc = dataclasses.replace(load_scenario(SCENARIOS / "demo.yaml").with_dataset(log), path=None)
    run = Calibration.setup(sc, solvers=("gauss_newton",)).run(("gauss_newton",))
    (tmp / "cal").mkdir()
    (path,) = write_calibration(run, tmp / "cal", "calibration.yaml")
    return path


def fresh(tmp_path: Path, seed: int, **options: object) -> Path:
    return write_sim(tmp_path, f"fresh_{seed}.txt", records=1500, seed=seed, outlier_fraction=0.01, **options)


def test_an_unchanged_robot_is_still_good(stored: Path, tmp_path: Path) -> None:
    log = fresh(tmp_path, 21)
    proc = cli("check", str(stored), str(log), "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    doc = json.loads((tmp_path / "out" / "check.json").read_text())
    assert doc["verdict"] == STILL_GOOD and doc["exit_code"] == 0
    assert "STILL GOOD" in proc.stdout
    # Every parameter tested, each within its threshold, and the threshold is the statistics':
    # Bonferroni over the 7 parameters at FALSE_ALARM, Student-t at the Welch degrees of freedom.
    for name, p in doc["parameters"].items():
        assert p["untested"] is None and abs(p["z"]) <= p["threshold"], name
        level = FALSE_ALARM / len(doc["parameters"])
        expected = t_quantile(level, p["dof"]) if p["dof"] is not None else t_quantile(level, math.inf)
        assert p["threshold"] == pytest.approx(expected)
    assert set(doc["figures"]["stored"]) == {"segment ATE mean [m]", "RPE over 1 m [m]", "RPE over 5 m [m]"}
    assert (tmp_path / "out" / "result.json").is_file()


def test_a_worn_tyre_is_a_drift_naming_k_traction(stored: Path, tmp_path: Path) -> None:
    log = fresh(tmp_path, 22, truth={"k_traction": TRUTH["k_traction"] * 1.01})
    proc = cli("check", str(stored), str(log), "--out", str(tmp_path / "out"))
    assert proc.returncode == 3, proc.stdout + proc.stderr
    doc = json.loads((tmp_path / "out" / "check.json").read_text())
    assert doc["verdict"] == DRIFTED
    assert [n for n, p in doc["parameters"].items() if p["drifted"]] == ["k_traction"]
    k = doc["parameters"]["k_traction"]
    assert k["change"] / k["stored"] == pytest.approx(0.01, abs=0.002)  # the 1 % it moved
    assert "k_traction moved by +" in proc.stdout and "DRIFTED: recalibrate" in proc.stdout


def test_a_straight_drive_cannot_tell_and_says_to_turn(stored: Path, tmp_path: Path) -> None:
    log = fresh(tmp_path, 23, trajectory="straight")
    proc = cli("check", str(stored), str(log), "--out", str(tmp_path / "out"))
    assert proc.returncode == 4, proc.stdout + proc.stderr
    doc = json.loads((tmp_path / "out" / "check.json").read_text())
    assert doc["verdict"] == CANNOT_TELL
    assert "S-curves or circles" in doc["hint"]
    assert doc["parameters"]["axis_length"]["untested"]


def test_the_check_reads_back_from_the_stored_result(stored: Path, tmp_path: Path) -> None:
    """The check lives in the run's checks: a run stored and read back writes the same check.json."""
    cal = read_calibration(stored)
    run = check(cal, check_scenario(cal, fresh(tmp_path, 24)))
    again = CalibrationRun.from_data(json.loads(json.dumps(run.to_data())))
    assert check_document(again) == check_document(run)
    # The drift is a plug-in check: its one wording is the check's verdict line, its record
    # result.json's ``drift``, and it judges the stored calibration, not the refit's verdict.
    drift, found = run.checks.drift, run.checks.plugin("drift")
    assert drift is not None and found is not None and found.level == "fine"
    assert found.words == drift.line() and f"drift: {drift.line()}" in run_table(run)
    assert result_dict(run)["drift"]["verdict"] == drift.verdict == check_document(run)["verdict"]
    assert [c["name"] for c in result_dict(run)["drift"]["changes"]] == [c.name for c in drift.changes]


def test_a_stored_block_scatter_averages_over_a_log_as_the_residuals_own_sigma_does(
    stored: Path, tmp_path: Path
) -> None:
    """A calibration.yaml whose blocks disagreed on axis_length: its between-logs σ widens only the
    part of the σ beyond the blocks' scatter (it averages over a log, like white noise)."""
    doc = yaml.safe_load(stored.read_text())
    std, white, folds = (
        doc["std"]["axis_length"],
        doc["std_white_noise"]["axis_length"],
        doc["std_blocks_folds"],
    )
    doc["std"]["axis_length"] = scatter = 3.0 * std  # as the σ to believe takes the scatter in
    doc["std_block_scatter"] = {n: (scatter if n == "axis_length" else None) for n in doc["std"]}
    doc.pop("std_slip", None)
    with_scatter = tmp_path / "with.yaml"
    with_scatter.write_text(yaml.safe_dump(doc))
    doc.pop("std_block_scatter")
    without = tmp_path / "without.yaml"
    without.write_text(yaml.safe_dump(doc))
    own = (doc.get("std_residuals") or {}).get("axis_length") or math.nan
    averaged = max(v for v in (scatter, own, white) if math.isfinite(v))
    assert read_calibration(with_scatter).std_shared["axis_length"] == pytest.approx(
        between_logs_std(scatter, averaged, folds), rel=1e-12
    )
    assert read_calibration(with_scatter).std_shared["axis_length"] == pytest.approx(scatter, rel=1e-12)
    assert read_calibration(without).std_shared["axis_length"] > 1.5 * scatter  # widened as shared


def test_a_scenario_with_another_formulation_is_warned_about(stored: Path, tmp_path: Path) -> None:
    sc = tmp_path / "other.yaml"
    sc.write_text(f"dataset: {fresh(tmp_path, 25)}\nmodel: tricycle\nresidual: {{horizon: 1}}\n")
    with pytest.warns(UserWarning, match="formulation"):
        scenario = check_scenario(read_calibration(stored), sc)
    assert scenario.solvers == ("gauss_newton",)
    stored_values = dict(read_calibration(stored).parameters)
    # The stages before the fit start as a run of the scenario does; check() starts the fit from the
    # stored values. The stored time offset was the old recording's: the new log's is fitted from
    # the scenario's start.
    assert scenario.parameters.initial_guess == load_scenario(sc).parameters.initial_guess
    assert np.isfinite(stored_values.pop("tracker_lag"))
    assert read_calibration(stored).start() == stored_values


def test_windows_in_seconds_are_the_same_formulation_whatever_horizon_they_resolve_to(tmp_path: Path) -> None:
    """A calibration made with ``residual.horizon_s`` records the horizon in records its log's rate
    gave; its own scenario file says only the seconds: checking with that file is no other
    formulation, and other seconds are."""
    log = write_sim(tmp_path, "drive.txt", records=600, seed=31)
    own = tmp_path / "own.yaml"
    own.write_text(
        f"dataset: {log}\nmodel: tricycle\nresidual: {{horizon_s: 0.5}}\nsolvers: [gauss_newton]\n"
    )
    run = Calibration.setup(load_scenario(own)).run(("gauss_newton",))
    (tmp_path / "cal").mkdir()
    (path,) = write_calibration(run, tmp_path / "cal", "calibration.yaml")
    calibration = read_calibration(path)
    recorded = calibration.objective["residual"]  # type: ignore[index]
    assert recorded["horizon_s"] == 0.5 and recorded["horizon"] > 1  # resolved on the log's rate
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_scenario(calibration, own)
    other = tmp_path / "other.yaml"
    other.write_text(own.read_text().replace("horizon_s: 0.5", "horizon_s: 1.0"))
    with pytest.warns(UserWarning, match="formulation alone"):
        check_scenario(calibration, other)


def test_bad_inputs_are_one_line_errors(stored: Path, tmp_path: Path) -> None:
    not_ours = tmp_path / "calibration.yaml"
    not_ours.write_text("parameters: {k_traction: 1}\n")
    with pytest.raises(UsageError, match=re.escape("not a calibration.yaml that nlp_calib wrote")):
        read_calibration(not_ours)
    broken = tmp_path / "broken.yaml"
    broken.write_text(stored.read_text().replace("  k_traction: ", "  k_traction: .nan #", 1))
    with pytest.raises(UsageError, match=re.escape("parameters.k_traction: expected a finite number")):
        read_calibration(broken)
    proc = cli("check", str(stored), str(tmp_path / "missing.txt"), "--out", str(tmp_path / "o"))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "missing.txt" in proc.stderr
    proc = cli(
        "check", str(stored), str(SCENARIOS / "data" / "demo_tricycle.txt"), "--out", str(stored.parent)
    )
    assert proc.returncode == 2 and "holds the calibration being checked" in proc.stderr
    other = tmp_path / "dd.yaml"
    other.write_text(f"dataset: {SCENARIOS / 'data' / 'diff_drive_demo.txt'}\nmodel: diff_drive\n")
    proc = cli("check", str(stored), str(other), "--out", str(tmp_path / "o"))
    assert proc.returncode == 2 and "the calibration's" in proc.stderr and "tricycle" in proc.stderr


def test_the_simulators_default_drive_with_the_models_defaults_is_still_good(tmp_path: Path) -> None:
    """The default drive determines every parameter to the precision a check needs (each σ within
    WEAK × the needed precision): a weakly observable combination alone leaves nothing untested, so
    an unchanged robot is STILL GOOD (it said "cannot tell", exit 4, every night)."""
    first = write_sim(tmp_path, "drive.txt", records=1500, seed=11)
    proc = cli("batch", str(first), "--out", str(tmp_path / "cal"), "--jobs", "1")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    stored = tmp_path / "cal" / "drive" / "calibration.yaml"
    again = write_sim(tmp_path, "again.txt", records=1500, seed=12)
    proc = cli("check", str(stored), str(again), "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    doc = json.loads((tmp_path / "out" / "check.json").read_text())
    assert doc["verdict"] == STILL_GOOD
    assert all(p["untested"] is None for p in doc["parameters"].values())
    worn = write_sim(
        tmp_path, "worn.txt", records=1500, seed=13, truth={"k_traction": TRUTH["k_traction"] * 1.01}
    )
    proc = cli("check", str(stored), str(worn), "--out", str(tmp_path / "worn"))
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "k_traction moved by +" in proc.stdout


def test_what_the_stored_calibration_held_is_not_judged_and_does_not_stop_the_check(tmp_path: Path) -> None:
    """The real log's first 60 % holds k_steer_reverse (too little reversing): checked on its own
    data the calibration is STILL GOOD, the held parameter named as not judged, not CANNOT TELL."""
    if not REAL_LOG.is_file():
        pytest.skip(f"no real log at {REAL_LOG}")
    lines = REAL_LOG.read_text().splitlines(keepends=True)
    head = [ln for ln in lines if ln.startswith("#")]
    part = tmp_path / "first60.txt"
    part.write_text("".join(head + [ln for ln in lines if not ln.startswith("#")][:1461]))
    sc = dataclasses.replace(load_scenario(SCENARIOS / "real_tricycle.yaml").with_dataset(part), path=None)
    run = Calibration.setup(sc, solvers=("gauss_newton",)).run(("gauss_newton",))
    assert run.scenario.layout.param("k_steer_reverse").status == "held"
    (path,) = write_calibration(run, tmp_path, "calibration.yaml")
    cal = read_calibration(path)
    assert cal.uncalibrated() == ("k_steer_reverse",)
    drift = check(cal, check_scenario(cal, part)).checks.drift
    assert drift is not None and drift.verdict == STILL_GOOD, drift.reasons
    assert "k_steer_reverse" not in {c.name for c in drift.changes}
    assert any("not judged: k_steer_reverse" in r for r in drift.reasons)


def test_a_change_beyond_the_jackknife_alone_is_reported_but_not_confirmed(
    stored: Path, tmp_path: Path
) -> None:
    """The jackknife takes a log's blocks as independent; judged again as if the part of its σ
    beyond white noise were shared by all of a log's blocks (that part at one block's spread,
    √folds × the jackknife's), a change within the threshold there is named "not confirmed"."""
    import yaml

    from nlp_calib.analysis.drift import between_logs_std, moved_words
    from nlp_calib.results.check import ParameterChange
    from nlp_calib.results.checks import noise_factor

    # χ²(9)'s 95 % point is 16.919: ten blocks of white noise reach 1.371 × its σ.
    assert noise_factor(10) == pytest.approx(math.sqrt(16.919 / 9), rel=2e-3)
    shared = 0.25 - (noise_factor(10) * 0.1) ** 2
    assert between_logs_std(0.5, 0.1, 10) == pytest.approx(math.sqrt(0.25 + 9 * shared))
    assert between_logs_std(0.13, 0.1, 10) == 0.13  # within white noise's reach: as believed
    assert between_logs_std(0.5, 0.1, 0) == 0.5  # no blocks: nothing to widen by
    doc = yaml.safe_load(stored.read_text())
    doc["std_white_noise"]["sensor_theta"], doc["std_blocks"]["sensor_theta"] = 0.001, 0.004
    doc["std"]["sensor_theta"], doc["std_blocks_folds"] = 0.004, 10
    path = tmp_path / "calibration.yaml"
    path.write_text(yaml.safe_dump(doc))
    cal = read_calibration(path)
    assert cal.std_shared["sensor_theta"] == pytest.approx(between_logs_std(0.004, 0.001, 10))
    assert cal.std_shared["sensor_theta"] > 2.5 * cal.std["sensor_theta"] == pytest.approx(0.01)
    args = ("sensor_theta", "rad", 0.01, 0.04, 0.004, 0.004, 18.0, 5.3, 3.6)
    plain, unconfirmed = ParameterChange(*args, z_shared=4.0), ParameterChange(*args, z_shared=1.7)
    assert plain.drifted and plain.confirmed and "not confirmed" not in moved_words(plain)
    assert unconfirmed.drifted and not unconfirmed.confirmed
    assert "+5.3σ), but only +1.7σ if the errors" in moved_words(unconfirmed)


def test_a_log_that_determines_a_parameter_much_better_says_so_beside_still_good() -> None:
    """A calibration from a short drive (a radius ±3 %) checked on a long one that pins it to
    ±0.01 %: the change is well within the stored σ (STILL GOOD, exit 0), but the stored value lies
    hundreds of the new log's σ from its refit; the check says which parameters a calibration on
    this log would tighten, and names none the log knows no better or puts near the stored value."""
    from nlp_calib.analysis.drift import TIGHTER, decide
    from nlp_calib.results.check import ParameterChange

    loose = ParameterChange("left_wheel_radius", "m", 0.099, 0.1, 0.003, 1e-5, math.inf, 0.33, 3.0)
    near = ParameterChange("right_wheel_radius", "m", 0.1, 0.1000001, 0.003, 1e-5, math.inf, 3e-5, 3.0)
    same = ParameterChange("sensor_x", "m", 0.36, 0.361, 0.002, 0.0019, math.inf, 0.36, 3.0)
    edge = ParameterChange("sensor_y", "m", 0.06, 0.0601, 0.003, 0.003 / TIGHTER, math.inf, 0.03, 3.0)
    verdict, reasons, hint = decide((loose, near, same, edge), "", "")
    assert verdict == STILL_GOOD and not hint and reasons[0].startswith("no parameter moved")
    (said,) = reasons[1:]
    words = "left_wheel_radius to ±1e-05 m (the calibration: ±0.003; its value 100σ of this log's away)"
    assert words in said
    assert all(n not in said for n in ("right_wheel_radius", "sensor_x", "sensor_y")), said
    assert decide((near, same, edge), "", "")[1][1:] == ()
