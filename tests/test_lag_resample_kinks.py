"""Readings re-sampled between records (at a lag that is no whole number of intervals) are
interpolated linearly, which reads a rate that changes inside an interval off by up to a quarter
of the change over it: held as a value (the held check), the estimate's move to the readings less
their expected error goes into the σ to believe. A tracker ten times finer than the simulator's
otherwise gave the lag beyond 3σ under GOOD."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from nlp_calib import Calibration, scenario_from_mapping
from nlp_calib.logs.resample import kink_error
from nlp_calib.simulation import SimulationOptions, simulate_to_file
from nlp_calib.simulation.options import DriveShape, TrackerSim

RESAMPLED = "readings re-sampled between records"


def _kinked(t: np.ndarray, start: float, v: float) -> np.ndarray:
    """Counts at ``t`` of a wheel at rest until ``start``, at speed ``v`` after."""
    return v * np.clip(t - start, 0.0, None)


def test_the_expected_error_is_the_mean_over_where_the_rate_changes() -> None:
    """Readings at irregular stamps of a wheel that starts from rest inside the fourth interval:
    what linear interpolation reads off, averaged over where inside that interval it starts,
    is what :func:`kink_error` expects from the readings alone (the same for any start)."""
    t = np.array([0.0, 0.01, 0.021, 0.030, 0.041, 0.050, 0.062, 0.070])
    when = t[3] + np.array([0.1, 0.25, 0.5, 0.8]) * (t[4] - t[3])
    starts = t[3] + (np.arange(2000) + 0.5) / 2000 * (t[4] - t[3])
    errors = [np.interp(when, t, _kinked(t, s, 50.0)) - _kinked(when, s, 50.0) for s in starts]
    expected = [kink_error(t, _kinked(t, s, 50.0), when, resolution=0.0) for s in starts]
    assert np.allclose(np.mean(expected, axis=0), np.mean(errors, axis=0), rtol=2e-3)
    assert np.all(np.mean(errors, axis=0) > 0)  # the chord above a start: always one side
    # On a record nothing is interpolated, and an even rate has no error.
    assert np.allclose(kink_error(t, _kinked(t, 0.033, 50.0), t, resolution=0.0), 0.0)
    assert np.allclose(kink_error(t, 7.0 * t, when, resolution=0.0), 0.0)
    # Counts rounded to whole ticks: a change within what the rounding gives (0.5 tick over an
    # interval, below the 2 its four readings' rounding could) is none; of 5 ticks, 3 are shown.
    assert np.allclose(kink_error(t, np.round(_kinked(t, 0.033, 50.0)), when), 0.0)
    coarse = np.round(_kinked(t, 0.033, 500.0))
    assert np.all(0 < kink_error(t, coarse, when))
    assert np.all(kink_error(t, coarse, when) < kink_error(t, coarse, when, resolution=0.0))


def test_a_precise_trackers_lag_lies_within_its_sigma_to_believe(tmp_path: Path) -> None:
    """A tricycle's s-curves with starts from rest, the tracker 29.9 ms late at a tenth of the
    simulator's noise (0.2 mm): the lag re-sampled between records came out 1.1 ms early, -3.4σ
    under GOOD. The held check's move is on the other side of the error, and the σ covers it."""
    lag = float(np.random.default_rng(501).uniform(0.0, 0.03))
    tracker = TrackerSim(
        latency_s=lag,
        tracker_noise_xy=0.1 * TrackerSim().tracker_noise_xy,
        tracker_noise_theta=0.1 * TrackerSim().tracker_noise_theta,
    )
    opts = SimulationOptions(
        seed=501, model="tricycle", drive=DriveShape(trajectory="s_curves"), tracker=tracker
    )
    log, _ = simulate_to_file(opts, tmp_path / "drive.txt")
    doc = {"dataset": str(log), "model": "tricycle", "initial_guess": "from_file"}
    doc |= {"solvers": ["gauss_newton"], "alignment": {"tracker_lag": "auto"}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(scenario_from_mapping(doc, "precise", tmp_path)).run(["gauss_newton"])
    error = run.reports["gauss_newton"].result.param_dict()["tracker_lag"] - lag
    std = run.std("gauss_newton")["tracker_lag"]
    shift = run.checks.recorded("held", "held")[RESAMPLED]["shift"]["tracker_lag"]
    assert error * shift < 0 and abs(shift) > 0.5 * abs(error), (error, shift)
    assert abs(error) < 2.0 * std, (error, std)
    assert run.verdict.level == "good"
