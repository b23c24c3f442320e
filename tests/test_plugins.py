"""What the seams take: a check is one function and one registry line; nothing else is edited.

A toy check is registered here (no file of the package changes): it runs on every run, its result
is stored with the run and read back, its one wording reaches the terminal, the report and the
summary, and at the caveat level the verdict names it.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import pytest
from conftest import write_sim

from nlp_calib.outputs.markdown import report_markdown
from nlp_calib.outputs.results import result_dict
from nlp_calib.outputs.summary import summary_lines
from nlp_calib.outputs.terminal import run_table
from nlp_calib.pipeline import Calibration, direction_check, fault_check, scenario_from_mapping
from nlp_calib.pipeline import checks as plugin_checks
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, CheckResult
from nlp_calib.results.run import CAVEATS


def toy_check(run: CalibrationRun, context: plugin_checks.CheckContext) -> CheckResult | None:
    """Says how many windows the fit used, and makes it a caveat when they are under 10,000."""
    n = run.data.n_residuals
    return CheckResult(
        "toy",
        CAVEAT if n < 10_000 else "fine",
        f"the toy check counted {n} windows",
        (f"{n} of at least 10000 wanted",),
        {"solver": str(run.chosen_solver())},
        {"windows": {"fitted": float(n)}},
        record={"windows": n},
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> CalibrationRun:
    tmp = tmp_path_factory.mktemp("plugins")
    log = write_sim(tmp, "drive.txt", records=700, seed=61)
    sc = scenario_from_mapping(
        {"dataset": str(log), "model": "tricycle", "residual": {"horizon": 10}, "solvers": ["gauss_newton"]},
        "toy",
        tmp,
    )
    with pytest.MonkeyPatch.context() as mp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mp.setitem(plugin_checks.RUN_CHECKS, "toy", toy_check)
        return Calibration(sc).run()


def test_a_registered_check_runs_and_is_stored_with_the_run(run: CalibrationRun) -> None:
    found = run.checks.plugin("toy")
    assert found is not None and found.table["windows"]["fitted"] == run.data.n_residuals
    back = CalibrationRun.from_data(run.to_data())
    assert back.checks.plugin("toy") == found
    # The truth beside a simulated log is a plug-in check too, read as its figures.
    assert run.checks.plugin("truth") is not None and run.checks.truth is not None
    assert set(run.checks.truth.names) == set(run.reports["gauss_newton"].result.names)


def test_its_one_wording_reaches_every_output_and_the_verdict(run: CalibrationRun, tmp_path: Path) -> None:
    words = run.checks.plugin("toy").words  # type: ignore[union-attr]
    assert run.verdict.level == CAVEATS and words in run.verdict.reasons
    assert any(words in line for line in summary_lines(run))
    assert words in run_table(run)
    assert words[1:] in report_markdown(run, [])
    # Its record is what result.json holds under its name.
    assert result_dict(run)["toy"] == {"windows": run.data.n_residuals}


def test_a_fine_result_is_no_caveat(run: CalibrationRun) -> None:
    fine = dataclasses.replace(run.checks.plugin("toy"), level="fine")  # type: ignore[arg-type]
    from nlp_calib.analysis.verdict import caveats
    from nlp_calib.models import get_model

    quiet = dataclasses.replace(run, checks=dataclasses.replace(run.checks, more=(fine,)))
    assert fine.words not in caveats(quiet, "gauss_newton", get_model("tricycle"))


def test_the_direction_checks_one_wording_is_the_terminals_and_the_reports(run: CalibrationRun) -> None:
    d = run.checks.direction
    assert d is not None
    said = direction_check.sentence(d)
    assert f"forward-only ({d.windows[0]} windows) and reverse-only ({d.windows[1]})" in said
    assert said.endswith(direction_check.words(d)) and f"direction: {said}" in run_table(run)
    assert f"{said[0].upper()}{said[1:]}." in report_markdown(run, [])


def test_the_built_in_checks_are_plug_ins_with_one_wording(run: CalibrationRun) -> None:
    """Faults and direction are registered like the toy: their words reach the terminal, the
    report and the summary alike, the faults with a section of their own in the report."""
    # The slip's first: its σ is part of the σ to believe the others read.
    assert list(plugin_checks.RUN_CHECKS)[:5] == [
        "slip",
        "observability",
        "faults",
        "direction",
        "consistency",
    ]
    report, table, summary = report_markdown(run, []), run_table(run), summary_lines(run)
    for name in ("faults", "direction"):
        found = run.checks.plugin(name)
        assert found is not None
        assert (found.reason in run.verdict.reasons) == (found.level == CAVEAT)
        assert f"{name}: {found.words}" in table and f"  {name}: {found.words}" in summary
        assert found.words[1:] in report
    assert "## Encoder and tracker faults" in report
    findings, faults = run.checks.findings, run.checks.plugin("faults")
    assert findings is not None and faults is not None
    assert faults.words == fault_check.words(findings, run.data.dropped_faulty)


def test_a_plug_ins_level_concerns_and_caveat_decide_the_verdict(run: CalibrationRun) -> None:
    """The verdict reads the generic record: an unusable level makes it NOT USABLE in the check's
    words; a caveat's own words and the parameters it concerns reach the verdict and the hand-off."""
    from nlp_calib.analysis.verdict import verdict
    from nlp_calib.models import get_model
    from nlp_calib.results.checks import UNUSABLE
    from nlp_calib.results.run import DOUBTFUL, NOT_USABLE

    def judged(*more: CheckResult) -> CalibrationRun:
        changed = dataclasses.replace(run, checks=dataclasses.replace(run.checks, more=more))
        return dataclasses.replace(changed, verdict=verdict(changed, get_model("tricycle")))

    bad = judged(CheckResult("toy", UNUSABLE, "the toy says these logs are two robots"))
    assert bad.verdict.level == NOT_USABLE and "the toy says these logs are two robots" in bad.verdict.reasons
    loose = judged(
        CheckResult(
            "toy", CAVEAT, "long words", caveat="short caveat", concerns={"k_steer": "the toy doubts it"}
        )
    )
    assert loose.verdict.level == CAVEATS and "short caveat" in loose.verdict.reasons
    assert "long words" not in loose.verdict.reasons
    assert loose.handoff_status("gauss_newton")["k_steer"] == (DOUBTFUL, "the toy doubts it")


def test_faults_not_checked_are_the_fault_checks_caveat(run: CalibrationRun) -> None:
    findings = run.checks.findings
    assert findings is not None
    unchecked = dataclasses.replace(
        findings, report=dataclasses.replace(findings.report, unchecked="no counters")
    )
    found = fault_check.check(
        dataclasses.replace(run, checks=dataclasses.replace(run.checks, findings=unchecked))
    )
    assert found is not None and found.level == CAVEAT
    assert (
        found.words == "not checked: no counters"
        and found.reason == "encoder faults not checked (no counters)"
    )


def test_determinacy_is_a_plug_in_whose_caveats_and_concerns_the_verdict_reads(run: CalibrationRun) -> None:
    """What the drive determines is the first plug-in: its record is result.json's observability,
    its words the summary's; a weak direction is its caveat on each parameter in it, and a
    parameter known beyond WEAK× the precision it needs is another, in its own words."""
    from nlp_calib.pipeline import determinacy_check
    from nlp_calib.results.checks import WEAK, WeakDirection

    obs, found = run.checks.observability, run.checks.plugin("observability")
    assert obs is not None and found is not None and found.level == "fine"
    # ... with the combinations loose only in the σ to believe (none on the demo).
    none = {"loose_in_believed": [], "only_together": []}
    assert result_dict(run)["observability"] == {**obs.as_dict(), **none}
    assert f"  observability: {found.words}" in summary_lines(run)
    weak = WeakDirection(7.0, {"k_steer": 0.8, "steer_offset": -0.6})
    # A σ to believe beyond WEAK× the needed precision: the white-noise σ of axis_length widened.
    report = run.reports["gauss_newton"]
    needed = run.scenario.layout.needed(report.result.param_dict())
    wide = report.uncertainty.std.copy()
    wide[list(report.uncertainty.names).index("axis_length")] = 1.5 * WEAK * needed["axis_length"]
    widened = dataclasses.replace(report, uncertainty=dataclasses.replace(report.uncertainty, std=wide))
    loose = dataclasses.replace(
        run,
        reports={**run.reports, "gauss_newton": widened},
        checks=dataclasses.replace(run.checks, observability=dataclasses.replace(obs, weak=(weak,))),
    )
    said = determinacy_check.check(loose)
    assert said is not None and said.level == CAVEAT
    assert (
        said.reasons[0]
        == "k_steer, steer_offset are only weakly observable apart (one combination of them is loose)"
    )
    assert said.reasons[1].startswith("axis_length is known only to ±")
    assert said.concerns["k_steer"] == said.concerns["steer_offset"] == said.reasons[0]
    assert said.concerns["axis_length"] == said.reasons[1] and len(said.reasons) == 2
    # The verdict names both, the plug-in's caveats first.
    from nlp_calib.analysis.verdict import caveats
    from nlp_calib.models import get_model

    judged = dataclasses.replace(loose, checks=dataclasses.replace(loose.checks, more=(said,)))
    assert caveats(judged, "gauss_newton", get_model("tricycle"))[:2] == list(said.reasons)


def test_a_pre_flight_check_is_one_registry_line_and_an_unusable_one_stops_the_run(tmp_path: Path) -> None:
    """A toy pre-flight check registered here alone: its words reach the pre-flight's report, and at
    the unusable level the verdict is CHECK THE DATA in its reasons; the units check beside it is
    one too, its findings read back from its record."""
    from nlp_calib.outputs.preflight import preflight_lines
    from nlp_calib.pipeline import preflight as pf
    from nlp_calib.results.checks import UNUSABLE
    from nlp_calib.results.preflight import CHECK_DATA, EXIT_CODES

    log = write_sim(tmp_path, "drive.txt", records=400, seed=62)
    sc = scenario_from_mapping(
        {"dataset": str(log), "model": "tricycle", "solvers": ["gauss_newton"]}, "pre", tmp_path
    )

    def toy(assessed: pf.Assessment) -> CheckResult:
        n = len(assessed.drive.parts)
        return CheckResult("toy", UNUSABLE, f"the toy saw {n} log", caveat=f"the toy refuses {n} log")

    with pytest.MonkeyPatch.context() as mp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mp.setitem(pf.PREFLIGHT_CHECKS, "toy", toy)
        report = pf.preflight(sc)
    assert "units" in pf.PREFLIGHT_CHECKS and report.check("units") is not None
    assert report.units == () and report.check("units").words == "nothing suspicious in units and signs"  # type: ignore[union-attr]
    assert report.verdict == CHECK_DATA and report.exit_code == EXIT_CODES[CHECK_DATA]
    assert report.stop_words() == "the toy refuses 1 log"
    lines = preflight_lines(report)
    assert "toy: the toy saw 1 log" in lines and "verdict: CHECK THE DATA: the toy refuses 1 log" in lines
