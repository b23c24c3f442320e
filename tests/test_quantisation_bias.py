"""A differential drive's baseline on one-record windows: the wheels' quantised counts are an input
with noise, and the turn per 40 ms interval is only a few ticks of wheel difference, so the fit
regresses the heading change on a noisy regressor and attenuates ``1/baseline`` (errors in
variables): the baseline comes out too large by about ``baseline · Var(noise)/E[signal²]`` of the
per-interval wheel difference, several σ on the default drive, while the σ (which propagates the
input noise) cannot hold a bias. Longer windows telescope the counts' errors (only the two ends
count) and remove it; finer counts do too, which shows the simulator agrees with the model."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import write_sim

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


@pytest.mark.xfail(
    strict=True,
    reason="issue 38j open: quantised counts attenuate 1/baseline on one-record windows "
    "(errors in variables), baseline +4 to +6 mm, 3.4-3.7σ, verdict GOOD",
)
def test_one_record_windows_recover_a_diff_drives_baseline_within_its_sigma(tmp_path: Path) -> None:
    assert abs(_mean_z(tmp_path, {}, {"horizon": 1})) < 1.5
