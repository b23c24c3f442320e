"""The steering an interval's travel saw (``steering_sample: travel``) against the speed-weighted
angle integrated independently."""

from __future__ import annotations

import numpy as np

from nlp_calib.models.base import sampled_angle

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
