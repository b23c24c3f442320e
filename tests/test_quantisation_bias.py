"""A differential drive's baseline on one-record windows: the wheels' quantised counts are an input
with noise, and the turn per 40 ms interval is only a few ticks of wheel difference, so the fit
regresses the heading change on a noisy regressor and attenuates ``1/baseline`` (errors in
variables): the baseline comes out too large by about ``baseline · Var(noise)/E[signal²]`` of the
per-interval wheel difference, several σ on the default drive, while the σ (which propagates the
input noise) cannot hold a bias. Longer windows telescope the counts' errors (only the two ends
count) and shrink it; finer counts do too, which shows the simulator agrees with the model. The
fit removes it: each estimate takes the step that frees it of the inputs' expected share of the
cost (:mod:`nlp_calib.analysis.inputs_bias`)."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
from conftest import write_sim

from nlp_calib.analysis import inputs_bias
from nlp_calib.pipeline import Calibration, scenario_from_mapping

SEEDS = (901, 903, 905)
FINE = {
    "k_left": 4.9e-6,
    "k_right": 5.1e-6,
    "baseline": 0.55,
    "sensor_x": 0.3,
    "sensor_y": -0.05,
    "sensor_theta": 0.08,
}
FINE_GUESS = {
    "k_left": 5e-6,
    "k_right": 5e-6,
    "baseline": 0.5,
    "sensor_x": 0.25,
    "sensor_y": 0.0,
    "sensor_theta": 0.0,
}


def _baseline_z(tmp_path: Path, seed: int, sim: dict[str, Any], residual: dict[str, Any]) -> float:
    """(estimate − truth)/believed σ of the baseline, the lag held at its truth."""
    log = write_sim(
        tmp_path, f"s{seed}.txt", records=2000, seed=seed, model="diff_drive", latency_s=0.02, **sim
    )
    raw = {
        "model": "diff_drive",
        "dataset": str(log),
        "solvers": ["gauss_newton"],
        "alignment": {"tracker_lag": 0.02},
        "residual": residual,
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(scenario_from_mapping(raw, f"s{seed}", tmp_path)).run(("gauss_newton",))
    t = run.checks.truth
    assert t is not None
    return float(t.z[t.names.index("baseline")])


def _mean_z(tmp_path: Path, sim: dict[str, Any], residual: dict[str, Any]) -> float:
    # Unbiased, three seeds' mean z is N(0, 1/3): 1.5 is 2.6 of its σ; the attenuation gives about 3.5.
    return float(np.mean([_baseline_z(tmp_path, s, sim, residual) for s in SEEDS]))


def test_windows_of_five_records_recover_a_diff_drives_baseline_within_its_sigma(tmp_path: Path) -> None:
    assert abs(_mean_z(tmp_path, {}, {"horizon": 5})) < 1.5


def test_counts_a_hundred_times_finer_recover_the_baseline_from_one_record_windows(tmp_path: Path) -> None:
    """The simulator and the model agree: only the counts' coarseness biases one-record windows."""
    assert abs(_mean_z(tmp_path, {"truth": FINE, "guess": FINE_GUESS}, {"horizon": 1})) < 1.5


def test_one_record_windows_recover_a_diff_drives_baseline_within_its_sigma(tmp_path: Path) -> None:
    assert abs(_mean_z(tmp_path, {}, {"horizon": 1})) < 1.5


def _fitted(tmp_path: Path) -> tuple[Any, np.ndarray, Any]:
    """The evaluator, Gauss-Newton's optimum and the inputs' noise of one-record windows (seed 901)."""
    log = write_sim(tmp_path, "s.txt", records=2000, seed=901, model="diff_drive", latency_s=0.02)
    raw = {
        "model": "diff_drive",
        "dataset": str(log),
        "alignment": {"tracker_lag": 0.02},
        "residual": {"horizon": 1},
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = Calibration.setup(scenario_from_mapping(raw, "s", tmp_path))
        fit = c.fitting
        x = fit.solver("gauss_newton").solve(fit.problem.start.x0, None, None).x
    return fit.evaluator, x, c.stages.windows.input_noise


def test_the_bias_step_takes_every_window_where_it_matters_and_a_subset_where_it_cannot(
    tmp_path: Path, monkeypatch: Any
) -> None:
    """Where the step moves the baseline by σ, it is the one over every window; with noise a hundred
    times smaller (a step 10⁴ times smaller), the subset's estimate stands, within 0.05σ of it."""
    ev, x, (std, counted) = _fitted(tmp_path)
    assert ev.n_residuals >= inputs_bias.SCREEN_FROM
    screened = [inputs_bias.bias_step(ev, x, (s, counted)) for s in (std, std / 100)]
    monkeypatch.setattr(inputs_bias, "SCREEN_FROM", 10**9)
    full = [inputs_bias.bias_step(ev, x, (s, counted)) for s in (std, std / 100)]
    names = ev.fns.free
    assert abs(full[0].step / full[0].sigma)[names.index("baseline")] > 0.5
    np.testing.assert_array_equal(screened[0].step, full[0].step)
    small = full[1].step / full[1].sigma
    assert np.max(np.abs(small)) < 0.01 * inputs_bias.MATTERS
    assert not np.array_equal(screened[1].step, full[1].step)
    np.testing.assert_allclose(screened[1].step / full[1].sigma, small, atol=0.2 * np.max(np.abs(small)))
