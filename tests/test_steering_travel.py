"""The steering an interval's travel saw (``steering_sample: travel``) against the speed-weighted
angle integrated independently."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import steering_step

from nlp_calib.models.base import sampled_angle
from nlp_calib.simulation.simulate import SimulationOptions, simulate, write_simulation

LAG = "tracker_lag"

DT = 0.04


def _drive(speed: np.poly1d, angle: np.poly1d, records: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Record times, each interval's travel and the angle read at each record."""
    t = DT * np.arange(records)
    travel = np.diff(np.polyint(speed)(t))
    return t, travel, angle(t)


def _seen(speed: np.poly1d, angle: np.poly1d, t: np.ndarray) -> np.ndarray:
    """Per interval, ``∫ v φ dt / ∫ v dt`` (exact polynomial integrals)."""
    num, den = np.polyint(speed * angle), np.polyint(speed)
    return np.diff(num(t)) / np.diff(den(t))


def test_travel_is_the_angle_the_travel_saw_while_speeding_up_and_steering() -> None:
    speed, angle = np.poly1d([1.5, 0.2]), np.poly1d([0.8, 0.1])  # v = 0.2 + 1.5 t, φ = 0.1 + 0.8 t
    t, travel, phi = _drive(speed, angle, 8)
    truth = _seen(speed, angle, t)
    # Inner intervals: both records' speeds come from two intervals (exact for a linear speed).
    inner = slice(1, -1)
    weighted = sampled_angle(phi, "travel", travel, t)[inner]
    mean = sampled_angle(phi, "mean")[inner]
    np.testing.assert_allclose(weighted, truth[inner], rtol=0, atol=1e-12)
    assert np.min(np.abs(mean - truth[inner])) > 1e-5  # the readings' mean is off, this far


def test_travel_falls_back_to_the_mean_where_the_direction_changes() -> None:
    speed, angle = np.poly1d([-3.0, 0.09]), np.poly1d([0.5, -0.2])  # reverses at t = 30 ms
    t, travel, phi = _drive(speed, angle, 4)
    assert travel[0] * travel[1] < 0
    np.testing.assert_array_equal(sampled_angle(phi, "travel", travel, t)[:2], sampled_angle(phi, "mean")[:2])


def _lag_step(log_path: Path, truth: dict[str, float], sample: str) -> float:
    """The lag's Gauss-Newton step (ms) from the truth, lag 0, on a noise-free log: the bias the
    model's error gives the fitted lag (the demo's residual options)."""
    return steering_step(log_path, truth, sample)[LAG] * 1e3


@pytest.mark.parametrize("stops", [0.15, 0.0])
def test_travel_halves_the_lags_bias_from_starting_off_stops(tmp_path: Path, stops: float) -> None:
    """The simulated drive holds a stop, then leaves it over a shorter stretch than it took to stop:
    steering while speeding up, more sharply than while slowing down. The readings' mean steering
    biases the lag fitted on a noise-free log (truth: 0) by -0.045 ms here (-0.035 ms on 10^5
    records before the curvature correction, whatever the tracker noise: 2.5σ of the first fit at
    10^6); the travel-weighted one by under half as much (-0.020 ms). Without stops, neither biases it."""
    opts = SimulationOptions.of(
        records=20000, seed=38, tracker_noise_xy=0.0, tracker_noise_theta=0.0, stop_fraction=stops
    )
    log_path, _ = write_simulation(simulate(opts), tmp_path / "drive.txt")
    mean, travel = (_lag_step(log_path, dict(opts.truth), s) for s in ("mean", "travel"))
    if stops:
        assert mean < -0.04
        assert abs(travel) < 0.55 * abs(mean)
    else:
        assert abs(mean) < 0.005 and abs(travel) < 0.005
