"""An interval's steering angle corrected for the angle's curvature over it
(:func:`~nlp_calib.models.base.curvature_correction`) against the angle's mean integrated
independently, and the steering gain's bias it removes on a noise-free simulated drive."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import steering_step

from nlp_calib.models.base import sampled_angle
from nlp_calib.simulation.simulate import SimulationOptions, simulate, write_simulation


def _jittered_times(records: int) -> np.ndarray:
    rng = np.random.default_rng(5)
    return np.concatenate([[0.0], np.cumsum(0.04 + rng.uniform(-0.004, 0.004, records - 1))])


def test_mean_is_the_angles_mean_over_the_interval_for_a_curving_angle() -> None:
    angle = np.poly1d([-2.0, 1.2, 0.3])  # peaks at 0.3 s, mid-log
    t = _jittered_times(16)
    inner = slice(1, -1)  # the log's ends have no reading beyond them
    exact = np.diff(np.polyint(angle)(t)) / np.diff(t)
    readings_mean = 0.5 * (angle(t)[:-1] + angle(t)[1:])
    np.testing.assert_allclose(
        sampled_angle(angle(t), "mean", time_s=t)[inner], exact[inner], rtol=0, atol=1e-12
    )
    assert np.min(np.abs(readings_mean - exact)[inner]) > 2e-4  # the readings' mean reads it short


def test_travel_is_the_angle_the_travel_saw_for_a_curving_angle() -> None:
    speed, angle = np.poly1d([1.5, 0.2]), np.poly1d([-2.0, 1.2, 0.3])
    t = 0.04 * np.arange(16)  # equal intervals: the speeds read at the records are exact
    travel = np.diff(np.polyint(speed)(t))
    seen = np.diff(np.polyint(speed * angle)(t)) / travel
    inner = slice(1, -1)  # the speeds at the ends come from one interval
    np.testing.assert_allclose(
        sampled_angle(angle(t), "travel", travel, t)[inner], seen[inner], rtol=0, atol=1e-12
    )


def test_a_one_record_spike_moves_only_the_two_intervals_that_read_it() -> None:
    t = _jittered_times(12)
    line = 0.2 + 0.7 * t
    spiked = line.copy()
    spiked[6] += 0.8
    moved = np.flatnonzero(
        np.abs(sampled_angle(spiked, "mean", time_s=t) - sampled_angle(line, "mean", time_s=t)) > 0
    )
    np.testing.assert_array_equal(moved, [5, 6])


def _k_steer_step(log_path: Path, truth: dict[str, float], sample: str) -> float:
    """k_steer's Gauss-Newton step from the truth (lag 0) on a noise-free log: the bias the
    interval model's error gives it (the demo's residual options)."""
    return steering_step(log_path, truth, sample)["k_steer"]


@pytest.mark.parametrize("sample", ["mean", "travel"])
def test_k_steer_unbiased_on_a_drive_steering_between_its_readings(tmp_path: Path, sample: str) -> None:
    """The simulated drive steers linearly between knots 1-2.5 s apart, peaking at each: the two
    readings' mean under-reads every peak that falls between them, which biased k_steer by
    +9·10⁻⁵ on this drive (25 Hz, no stops; 2σ at 0.2 mm tracker noise, 2·10⁴ records); corrected
    for the angle's curvature, by 3·10⁻⁶ (either sample)."""
    opts = SimulationOptions.of(
        records=20000, seed=4243, tracker_noise_xy=0.0, tracker_noise_theta=0.0, stop_fraction=0.0
    )
    log_path, _ = write_simulation(simulate(opts), tmp_path / "drive.txt")
    assert abs(_k_steer_step(log_path, dict(opts.truth), sample)) < 9e-6
