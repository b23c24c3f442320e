"""What a run says beside a simulated log's truth, and cross-validated figures beside in-sample
ones over the same blocks."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import write_sim

from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.pipeline.truth import read_truth
from nlp_calib.results import CalibrationRun


def _run(tmp_path: Path, log: Path, blocks: int = 0) -> CalibrationRun:
    raw = {"dataset": str(log), "solvers": ["gauss_newton"], "validation": {"blocks": blocks}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Calibration(scenario_from_mapping(raw, "t", tmp_path)).run()


def test_the_estimate_is_put_against_the_truth_file_beside_the_log(tmp_path: Path) -> None:
    log = write_sim(tmp_path, records=900, seed=21)
    run = _run(tmp_path, log)
    t = run.checks.truth
    assert t is not None and t.solver == "gauss_newton"
    truth = read_truth(log)  # the simulator's values and its latency: the fitted time offset's truth
    assert truth is not None and "tracker_lag" in truth
    result, std = run.reports["gauss_newton"].result, run.std("gauss_newton")
    for i, name in enumerate(result.names):
        assert t.error[i] == pytest.approx(result.params[i] - truth[name], abs=1e-15)
        assert t.z[i] == pytest.approx((result.params[i] - truth[name]) / std[name], rel=1e-12)
    assert t.words().startswith("estimate − truth")


def test_no_truth_file_no_comparison_and_a_foreign_one_is_said(tmp_path: Path) -> None:
    log = write_sim(tmp_path, records=600, seed=22)
    log.with_suffix(".truth.json").unlink()
    assert _run(tmp_path, log).checks.truth is None
    log.with_suffix(".truth.json").write_text('{"something": "else"}')
    with pytest.warns(NlpCalibWarning, match="not a truth file nlp-calib simulate wrote"):
        raw = {"dataset": str(log), "solvers": ["gauss_newton"], "validation": {"blocks": 0}}
        run = Calibration(scenario_from_mapping(raw, "t", tmp_path)).run()
    assert run.checks.truth is None


def test_held_out_and_in_sample_figures_score_the_same_blocks(tmp_path: Path) -> None:
    """Each block is scored twice, by the fit without it and by the full fit: same records, same
    figure; the full fit's own blocks fit it at least about as well on average."""
    run = _run(tmp_path, write_sim(tmp_path, records=1500, seed=23), blocks=5)
    cv = run.checks.crossval
    assert cv is not None and cv.available
    for f in cv.converged:
        assert f.heldout is not None and f.insample is not None
        assert f.heldout.records == f.insample.records
    label = "segment ATE mean [m]"
    held, inside = cv.heldout_mean(label), cv.insample_mean(label)
    assert np.isfinite(held) and np.isfinite(inside) and inside <= 1.2 * held
