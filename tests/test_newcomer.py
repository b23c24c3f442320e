"""What a newcomer reads: the closing verdict, evo-style figures, help, --data, odometry, plots."""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENARIOS, assert_close, cli, write_sim

from nlp_calib.analysis.metrics import path_distance, trajectory_metrics
from nlp_calib.cli.parser import build_parser
from nlp_calib.models import get_model
from nlp_calib.outputs.plots.residuals import BINS, _calibrated_range
from nlp_calib.outputs.summary import summary_lines
from nlp_calib.pipeline import Calibration, Scenario, Wanted, scenario_from_mapping
from nlp_calib.pipeline.scenario import FaultOptions, ValidationOptions
from nlp_calib.problem import ProblemSpec, build
from nlp_calib.results import CalibrationRun
from nlp_calib.results.run import CAVEATS, GOOD, UNDETERMINED, Verdict

SUBCOMMANDS = ("run", "compare", "validate", "odometry", "codegen", "simulate", "import-bag")


def _scenario(tmp_path: Path, log: Path, extra: str = "") -> Path:
    path = tmp_path / "sc.yaml"
    path.write_text(f"name: sc\ndataset: {log}\nvalidation: {{blocks: 0}}\n{extra}")
    return path


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict, Path]:
    out = tmp_path_factory.mktemp("demo") / "out"
    proc = cli("compare", str(SCENARIOS / "demo.yaml"), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return proc.stdout, json.loads((out / "result.json").read_text()), out


def test_the_closing_summary_names_the_verdict_the_distance_and_the_files(
    demo_run: tuple[str, dict, Path],
) -> None:
    stdout, doc, out = demo_run
    summary = stdout[stdout.index("summary of demo") :]
    distance = doc["solvers"]["gauss_newton"]["metrics"]["distance_m"]
    assert f"the sensor travelled {distance:.1f} m" in summary
    assert "verdict: GOOD:" in summary
    assert "gauss_newton: converged" in summary and "the result written" in summary
    for name in ("calibration.yaml", "sensor_mount.urdf.xml"):
        assert re.search(rf"next: .*{name}|\n\s+{name}", summary), name
        assert (out / name).is_file()
    assert "nlp-calib codegen" in summary
    # The figures the summary quotes are result.json's.
    seg = doc["solvers"]["gauss_newton"]["metrics"]["segment_ate"]["mean"]
    assert f"segment ATE {seg:.3g} m" in summary


def test_no_output_prints_a_raw_python_structure(demo_run: tuple[str, dict, Path], tmp_path: Path) -> None:
    odo = cli("odometry", str(SCENARIOS / "demo.yaml"), "--out", str(tmp_path / "odo"))
    assert odo.returncode == 0, odo.stderr
    for text in (demo_run[0], odo.stdout):
        assert not re.search(r"\{'|\['|np\.float", text), text


def test_the_distance_is_the_tracker_path_without_its_bad_poses(demo_run: tuple[str, dict, Path]) -> None:
    _, doc, _ = demo_run
    from nlp_calib.sources import load_log

    log = load_log(SCENARIOS / "data" / "demo_tricycle.txt", get_model("tricycle"))
    bad = {f["record"] for f in doc["faults"]["found"] if f["kind"] == "tracker_jump"}
    first, stop = doc["dataset"]["used"]  # the records the fitted lag leaves inside the log
    keep = np.array([first <= i < stop and i not in bad for i in range(log.n_records)])
    expected = float(path_distance(log.T_world_sensor[keep])[-1])
    assert doc["solvers"]["gauss_newton"]["metrics"]["distance_m"] == pytest.approx(expected, rel=1e-12)


def test_full_run_figures_leave_out_a_bad_tracker_pose() -> None:
    fns = build(get_model("tricycle"), ProblemSpec(horizon=1))
    p = np.array([0.5, 0.01, 1.5, 0.0, 1.0, 0.0, 0.0])
    n = 60
    inputs = np.vstack([np.full(n - 1, 1.0), np.full(n - 1, 0.1)])
    from nlp_calib.analysis.metrics import integrate

    ref = integrate(fns, p, inputs, np.zeros(3))
    clean = trajectory_metrics(fns, p, inputs, ref)
    ref_bad = ref.copy()
    ref_bad[30, :2] += 5.0  # a gross tracker outlier
    bad = np.zeros(n, dtype=bool)
    bad[30] = True
    flagged = trajectory_metrics(fns, p, inputs, ref_bad, bad_records=bad)
    assert clean.ate.max == pytest.approx(0.0, abs=1e-12)
    assert flagged.ate.max == pytest.approx(0.0, abs=1e-12) and flagged.ate.n == n - 1
    assert flagged.distance_m == pytest.approx(float(path_distance(ref[~bad])[-1]), rel=1e-12)
    assert trajectory_metrics(fns, p, inputs, ref_bad).ate.max == pytest.approx(np.hypot(5.0, 5.0), rel=1e-9)


def test_verdicts_good_with_caveats_and_not_determined(tmp_path: Path, demo: Scenario) -> None:
    run = Calibration(demo.with_options(validation=ValidationOptions(blocks=0))).run(("gauss_newton",))
    assert run.verdict.level == GOOD, run.verdict

    short = write_sim(tmp_path, "short.txt", records=700, seed=4)
    v = Calibration.setup(_load(_scenario(tmp_path, short))).run(("gauss_newton",)).verdict
    assert v.level == CAVEATS and any("weakly observable" in r for r in v.reasons), v

    faulty = write_sim(tmp_path, "faulty.txt", records=900, seed=5, counter_faults=3)
    sc = _load(_scenario(tmp_path, faulty)).with_options(faults=FaultOptions(handling="keep"))
    v = Calibration.setup(sc).run(("gauss_newton",)).verdict
    assert v.level == CAVEATS and any("kept in the fit" in r for r in v.reasons), v

    straight = write_sim(tmp_path, "straight.txt", records=300, seed=5, trajectory="straight")
    v = Calibration.setup(_load(_scenario(tmp_path, straight))).run(("gauss_newton",)).verdict
    assert v.level == UNDETERMINED and any("not observable" in r for r in v.reasons), v


def test_the_runs_advice_reads_its_own_drive(tmp_path: Path) -> None:
    """A run left undetermined in its turning parameters is told to turn both ways only where its
    drive does not: the run reads its fitted records' excitation as the pre-flight does. It had never
    been given it, so a drive already turning both ways was told to turn both ways."""
    from dataclasses import replace

    from nlp_calib.analysis.excitation import turns_both_ways
    from nlp_calib.analysis.verdict import verdict
    from nlp_calib.pipeline.preflight import preflight

    straight = write_sim(tmp_path, "straight.txt", records=300, seed=5, trajectory="straight")
    sc = _load(_scenario(tmp_path, straight, "alignment: {tracker_lag: 0}\n"))  # not the clock's advice
    run = Calibration.setup(sc).run(("gauss_newton",))
    ex = run.data.excitation
    assert ex is not None and ex == preflight(sc).excitation[0]  # one reading of the same records
    assert run.verdict.level == UNDETERMINED and not turns_both_ways(ex), run.verdict
    assert any("drive turns in both directions" in r for r in run.verdict.reasons), run.verdict
    both = replace(ex, heading_span_rad=6.0, turned_left_rad=5.0, turned_right_rad=5.0)
    again = verdict(replace(run, data=replace(run.data, excitation=both)), get_model(sc.model))
    said = " ".join(again.reasons)
    assert again.level == UNDETERMINED and "drive turns in both directions" not in said, said
    assert "the drive turns both ways, yet it leaves" in said, said


def _load(path: Path) -> Scenario:
    from nlp_calib.pipeline import load_scenario

    return load_scenario(path)


def test_data_with_scenarios_on_different_logs_is_refused(tmp_path: Path) -> None:
    proc = cli(
        "run",
        str(SCENARIOS / "demo.yaml"),
        str(SCENARIOS / "diff_drive_demo.yaml"),
        "--data",
        str(tmp_path / "x.txt"),
        "--out",
        str(tmp_path / "o"),
    )
    assert proc.returncode == 2
    assert "would replace different logs" in proc.stderr and "NAME=PATH" in proc.stderr
    assert not (tmp_path / "o").exists()


def test_data_name_equals_path_replaces_one_scenarios_log(tmp_path: Path) -> None:
    other = write_sim(tmp_path, "other.txt", records=400, seed=8)
    a = tmp_path / "a.yaml"
    a.write_text(f"name: a\ndataset: {SCENARIOS / 'data' / 'demo_tricycle.txt'}\nvalidation: {{blocks: 0}}\n")
    b = tmp_path / "b.yaml"
    b.write_text(f"name: b\ndataset: {SCENARIOS / 'data' / 'demo_tricycle.txt'}\nvalidation: {{blocks: 0}}\n")
    out = tmp_path / "o"
    proc = cli("run", str(a), str(b), "--data", f"b={other}", "--out", str(out), "--solver", "gauss_newton")
    assert proc.returncode == 0, proc.stderr
    used = {n: json.loads((out / n / "result.json").read_text())["dataset"]["path"] for n in ("a", "b")}
    assert used["a"].endswith("demo_tricycle.txt") and used["b"] == str(other)


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_every_help_has_an_example_the_exit_codes_and_text_for_each_option(command: str) -> None:
    text = cli(command, "--help").stdout
    assert "example" in text and f"nlp-calib {command}" in text
    assert "exit codes: 0 success" in text
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    undocumented = [a.dest for a in sub.choices[command]._actions if not a.help]
    assert undocumented == [], undocumented


def test_odometry_writes_what_run_writes_with_units(tmp_path: Path) -> None:
    out = tmp_path / "odo"
    proc = cli("odometry", str(SCENARIOS / "demo.yaml"), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    for name in ("result.json", "calibration.yaml", "sensor_mount.urdf.xml", "odometry.csv"):
        assert (out / name).is_file(), name
    assert re.search(r"k_traction .* m per t_max ticks", proc.stdout)
    assert "steering_angle" in proc.stdout and " rad" in proc.stdout and "verdict:" in proc.stdout


def test_histograms_resolve_the_calibrated_spread(small_demo: Scenario) -> None:
    run = Calibration(small_demo).run(("gauss_newton",), Wanted(series=True))
    series = run.require_series().residuals
    for i in range(3):
        after = series.after["gauss_newton"][i]
        width = 2 * _calibrated_range([after], float(series.thresholds[i])) / (BINS - 1)
        assert np.std(after) / width > 8  # the calibrated peak spans many bins, not five


def test_residuals_over_time_mark_the_faults(tmp_path: Path) -> None:
    log = write_sim(tmp_path, "faults.txt", records=1200, seed=6, counter_faults=3)
    sc = _load(_scenario(tmp_path, log)).with_options(validation=ValidationOptions(blocks=0))
    calib = Calibration(sc)
    run = calib.run(("gauss_newton",), Wanted(series=True))
    series = run.require_series()
    errors, time_s = series.residuals.after["gauss_newton"], series.residuals.time_s
    assert errors.shape == (3, calib.data.n_residuals) == (3, time_s.size)
    assert np.all(np.diff(time_s) > 0)
    found = run.checks.findings.report.faults  # type: ignore[union-attr]
    assert len(series.fault_spans) == len(found) >= 3
    for span, f in zip(series.fault_spans, found):
        t0, t1 = span.first_s, span.last_s
        assert span.kind == f.kind and t0 <= f.time_s <= t1 + 1e-9
        # No window crosses a fault left out of the fit.
        assert not np.any((time_s > t0) & (time_s < t1))


@pytest.mark.slow
def test_codegen_example_evaluates_the_calibrated_parameters(tmp_path: Path, demo: Scenario) -> None:
    out = tmp_path / "c"
    proc = cli("codegen", str(SCENARIOS / "demo.yaml"), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "calibrated by gauss_newton" in proc.stdout and "records " in proc.stdout
    src = (out / "example.c").read_text()
    m = re.search(r"params\[\d+\] = \{([^}]*)\}", src)
    assert m
    params = np.array([float(v) for v in m.group(1).split(",")])
    expected = Calibration(demo).solve(demo.solvers[0]).params
    assert_close(params, expected, rtol=1e-12)
    assert re.search(r"window: records \d+-\d+ \(lines \d+-\d+\) of demo_tricycle.txt", src)


@pytest.mark.parametrize("start", ["auto", "from_file"])
def test_a_not_determined_summary_gives_the_verdicts_next_step_and_no_other(
    tmp_path: Path, start: str
) -> None:
    """The summary's next step is the one the verdict names; without one, the data-driven start is
    advised only to a run that did not start from it."""
    log = write_sim(tmp_path, "drive.txt", records=500, seed=71)
    sc = scenario_from_mapping(
        {
            "dataset": str(log),
            "initial_guess": start,
            "validation": {"blocks": 0},
            "solvers": ["gauss_newton"],
        },
        "sc",
        tmp_path,
    )
    run = Calibration(sc).run()
    assert run.scenario.initial_guess == start
    named = "the drive leaves k_steer loose; next: hold k_steer at a measured value (known: {k_steer: <v>})"
    told = _next_steps(dataclasses.replace(run, verdict=Verdict(UNDETERMINED, (named,))))
    assert "hold k_steer at a measured value (known: {k_steer: <v>})" in told
    assert not any("initial guess" in step or "check the log" in step for step in told), told
    bare = _next_steps(
        dataclasses.replace(run, verdict=Verdict(UNDETERMINED, ("the drive leaves k_steer loose",)))
    )
    (again,) = [step for step in bare if "run again" in step]
    assert ("initial_guess: auto" in again) == (start != "auto"), again


def _next_steps(run: CalibrationRun) -> list[str]:
    """The summary's next steps: the line after 'next: ' and the lines indented below it."""
    lines = summary_lines(run)
    first = next(i for i, line in enumerate(lines) if line.startswith("  next: "))
    return [lines[first][len("  next: ") :], *(line.strip() for line in lines[first + 1 :])]
