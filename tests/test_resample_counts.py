"""Counters re-sampled at a lag keep fractional counts (``nlp_calib.logs.resample``): a lag of a
fraction of a tick per interval moves the wheels' inputs as much as the lag says, where counts
rounded back to whole ticks gave the logged readings back under a shifted label."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from conftest import SCENARIOS, write_sim

from nlp_calib import Calibration, scenario_from_mapping
from nlp_calib.core.numeric import wrapped_difference
from nlp_calib.logs import resample_encoders
from nlp_calib.models import get_model, load_log


def test_a_counter_re_sampled_a_fraction_of_a_tick_away_moves_by_rate_times_lag() -> None:
    """At 0.2 ms the wheels move a fraction of a tick between the logged stamps and the re-sampled
    ones: each re-sampled count is the logged counts' linear interpolation there (computed here
    from the logged increments), its level ``rate × lag`` below the logged one, and the model's
    inputs (the increments) are those of the interpolation."""
    model = get_model("diff_drive")
    log = load_log(SCENARIOS / "data" / "diff_drive_demo.txt", model)
    lag = 2e-4
    shifted, (a, b) = resample_encoders(log, lag, model.encoder_kinds)
    t = log.time_s
    for name in (n for n, kind in model.encoder_kinds.items() if kind == "counter"):
        logged = np.concatenate([[0.0], np.cumsum(wrapped_difference(log.encoder(name)))])
        wanted = np.interp(t - lag, t, logged)[a:b]
        level = np.concatenate([[0.0], np.cumsum(shifted.increments(name))])[a:b]
        assert np.max(np.abs(level - level[0] - (wanted - wanted[0]))) < 1e-6, name
        assert np.allclose(np.diff(level), np.diff(wanted), atol=1e-6), name
        rate = np.gradient(logged, t)[a:b]
        moved = level - level[0] + logged[a] - logged[a:b]  # re-sampled less logged level
        moving = np.abs(rate * lag) > 0.05
        assert moving.sum() > 100, name
        # rate × lag to within the counts' curvature over an interval (they are read 10 ms apart)
        assert np.median(np.abs(moved[moving] + rate[moving] * lag)) < 0.02, name
        assert np.median(np.abs(moved[moving])) > 0.05, name


def test_a_re_sampled_counts_noise_is_its_two_readings_blend() -> None:
    """Each re-sampled count is a linear blend of logged readings: an increment's variance, in one
    reading's (their noises independent), is the sum of its weights' squares, computed here by
    re-sampling each reading alone. Half an interval late it is about ½ (two records' difference
    halved), 2 as logged: what :meth:`Log.increment_variance` gives the noise model."""
    model = get_model("diff_drive")
    log = load_log(SCENARIOS / "data" / "diff_drive_demo.txt", model)
    t, lag = log.time_s, 0.5 * float(np.median(np.diff(log.time_s)))
    shifted, (a, _) = resample_encoders(log, lag, model.encoder_kinds)
    assert np.all(log.increment_variance() == 2.0)
    rows = slice(a + 100, a + 300)
    weights = np.stack([np.interp(t[rows] - lag, t, np.eye(1, t.size, k)[0]) for k in range(t.size)])
    wanted = np.sum(np.diff(weights, axis=1) ** 2, axis=0)
    got = shifted.increment_variance()[rows][:-1]
    assert np.allclose(got, wanted), np.max(np.abs(got - wanted))
    assert 0.4 < np.median(got) < 0.6


def test_a_fractional_counts_step_across_the_wrap_keeps_its_fraction() -> None:
    """A counter re-sampled just below the uint32 wrap and just above it steps by the fraction."""
    m = 2.0**32
    step = wrapped_difference(np.array([m - 0.75, 0.5, 2.25]))
    assert np.allclose(step, [1.25, 1.75])
    assert np.array_equal(wrapped_difference(np.array([2**32 - 1, 1], dtype=np.int64)), [2])


def test_a_cars_lag_on_a_precise_tracker_stays_within_its_sigma(tmp_path: Path) -> None:
    """A car's log (20000 records, tracker at 0.2 mm and 0.2 mrad, true lag 0): its lag walked
    −155, −307, −455 µs, one step per re-sampling, to −4.0σ, the re-sampled counts rounded back
    to the logged readings; the fractional counts stop it at the second re-sampling, within 3σ."""
    log = write_sim(
        tmp_path, "car.txt", records=20000, seed=4601, model="car_like",
        tracker_noise_xy=0.0002, tracker_noise_theta=0.0002,
    )  # fmt: skip
    raw = {"dataset": str(log), "model": "car_like", "initial_guess": "from_file"}
    sc = scenario_from_mapping({**raw, "alignment": {"tracker_lag": "auto"}}, "car", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run(["gauss_newton"])
    lag, std = run.reports["gauss_newton"].result.param_dict()["tracker_lag"], run.std("gauss_newton")
    assert abs(lag) < 3.0 * std["tracker_lag"], (lag, std["tracker_lag"])
    assert run.data.lag_estimate is not None and len(run.data.lag_estimate.path_s) <= 3
