"""The simulator: deterministic, in the log format, and the source of the shipped demo log."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENARIOS, assert_close, parse_lines

from nlp_calib.pipeline.simconfig import simulation_options
from nlp_calib.simulation import SimulationOptions, simulate, write_simulation
from nlp_calib.sources import load_log


def test_shipped_demo_log_is_what_the_simulator_makes() -> None:
    opts = simulation_options(SCENARIOS / "data" / "demo_tricycle.sim.yaml", {})
    fresh = parse_lines(simulate(opts).text().splitlines())
    shipped = load_log(SCENARIOS / "data" / "demo_tricycle.txt")
    np.testing.assert_array_equal(fresh.ticks, shipped.ticks)
    assert_close(fresh.T_world_sensor, shipped.T_world_sensor, rtol=0, atol=1e-8)
    assert_close(fresh.time_s, shipped.time_s, rtol=0, atol=1e-9)


def test_deterministic_for_a_seed() -> None:
    a = simulate(SimulationOptions(records=300, seed=5)).text()
    b = simulate(SimulationOptions(records=300, seed=5)).text()
    c = simulate(SimulationOptions(records=300, seed=6)).text()
    assert a == b
    assert a != c


def test_traction_counter_wraps_and_reads_back(tmp_path: Path) -> None:
    sim = simulate(SimulationOptions(records=600, seed=1))
    ds = parse_lines(sim.text().splitlines())
    raw = ds.encoder("traction_wheel")
    assert raw.max() > 2**32 - 30000 and raw.min() < 30000  # it crossed the wrap
    inc = ds.increments("traction_wheel")
    # No wrap artefact survives unwrapping: steps stay within 0.6 m/s over a slow sample.
    assert np.abs(inc).max() < 0.6 * 0.06 * 5000 / 0.0105
    assert (inc < 0).any() and (inc > 0).any()  # reversals


def test_straight_trajectory_has_constant_steering() -> None:
    sim = simulate(SimulationOptions(records=300, seed=2, trajectory="straight"))
    assert np.unique(sim.ticks[:, 0]).size == 1


def test_abrupt_reversals_change_sign_at_speed_smooth_ones_through_a_crawl() -> None:
    def flips(reversals: str) -> np.ndarray:
        """At each change of direction, the slower of the two increments, in typical increments."""
        ds = parse_lines(
            simulate(SimulationOptions(records=1500, seed=3, reversals=reversals)).text().splitlines()
        )
        inc = ds.increments("traction_wheel")
        inc = inc[inc != 0]
        at = np.flatnonzero(np.sign(inc[1:]) != np.sign(inc[:-1]))
        return np.minimum(np.abs(inc[at]), np.abs(inc[at + 1])) / np.median(np.abs(inc))

    abrupt, smooth = flips("abrupt"), flips("smooth")
    assert np.sum(abrupt > 0.5) >= 2  # straight from one direction at speed to the other
    assert np.all(smooth < 0.5)


def test_a_tracker_on_its_own_clock_is_paired_with_the_encoders_as_a_bag_import_pairs_it() -> None:
    opts = SimulationOptions(records=1000, seed=2, rate_hz=50.0, tracker_rate_hz=30.0, outlier_fraction=0.02)
    sim = simulate(opts)
    t = (sim.time_ns - sim.time_ns[0]) * 1e-9
    assert np.median(np.diff(t)) == pytest.approx(0.02, rel=0.1)  # records at the encoders' rate
    assert sim.time_ns.size < opts.records  # encoder samples outside the tracker's span are left out
    # Between outliers, the pose is the truth's, interpolated from 30 Hz samples: off by at most
    # the noise and the chord of a 33 ms arc.
    mount = np.array([opts.truth["sensor_x"], opts.truth["sensor_y"], opts.truth["sensor_theta"]])
    c, s = np.cos(sim.T_world_base_true[:, 2]), np.sin(sim.T_world_base_true[:, 2])
    truth_xy = sim.T_world_base_true[:, :2] + np.stack(
        [c * mount[0] - s * mount[1], s * mount[0] + c * mount[1]], 1
    )
    err = np.hypot(*(sim.T_world_sensor[:, :2] - truth_xy).T)
    assert np.all(err[~sim.tracker_outliers] < 0.02)
    assert np.mean(err[sim.tracker_outliers] > 0.02) > 0.5


def test_steering_glitches_are_injected_and_recorded(tmp_path: Path) -> None:
    plain = simulate(SimulationOptions(records=1200, seed=8))
    sim = simulate(SimulationOptions(records=1200, seed=8, steering_spikes=3, steering_stuck=2))
    kinds = sorted(f.kind for f in sim.faults)
    assert kinds == ["steering_spike"] * 3 + ["steering_stuck"] * 2
    changed = np.flatnonzero(np.any(sim.ticks != plain.ticks, axis=1))
    for f in sim.faults:
        assert plain.ticks[f.record, 0] == f.true_ticks and sim.ticks[f.record, 0] == f.logged_ticks
    spikes = {f.record for f in sim.faults if f.kind == "steering_spike"}
    assert spikes <= set(changed.tolist())
    _, truth = write_simulation(sim, tmp_path / "g.txt")
    assert len(json.loads(truth.read_text())["faults"]) == 5
