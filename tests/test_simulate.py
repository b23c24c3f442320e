"""The simulator: deterministic, in the log format, and the source of the shipped demo log."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, SCENARIOS, assert_close, parse_lines

from nlp_calib.pipeline.simconfig import simulation_options
from nlp_calib.simulation import SimulationOptions, simulate, simulate_to_file, write_simulation
from nlp_calib.sources import load_log


def test_shipped_demo_log_is_what_the_simulator_makes() -> None:
    opts = simulation_options(SCENARIOS / "data" / "demo_tricycle.sim.yaml", {})
    fresh = parse_lines(simulate(opts).text().splitlines())
    shipped = load_log(SCENARIOS / "data" / "demo_tricycle.txt")
    np.testing.assert_array_equal(fresh.ticks, shipped.ticks)
    assert_close(fresh.T_world_sensor, shipped.T_world_sensor, rtol=0, atol=1e-8)
    assert_close(fresh.time_s, shipped.time_s, rtol=0, atol=1e-9)


def test_deterministic_for_a_seed() -> None:
    a = simulate(SimulationOptions.of(records=300, seed=5)).text()
    b = simulate(SimulationOptions.of(records=300, seed=5)).text()
    c = simulate(SimulationOptions.of(records=300, seed=6)).text()
    assert a == b
    assert a != c


def test_traction_counter_wraps_and_reads_back(tmp_path: Path) -> None:
    sim = simulate(SimulationOptions.of(records=600, seed=1))
    ds = parse_lines(sim.text().splitlines())
    raw = ds.encoder("traction_wheel")
    assert raw.max() > 2**32 - 30000 and raw.min() < 30000  # it crossed the wrap
    inc = ds.increments("traction_wheel")
    # No wrap artefact survives unwrapping: steps stay within 0.6 m/s over a slow sample.
    assert np.abs(inc).max() < 0.6 * 0.06 * 5000 / 0.0105
    assert (inc < 0).any() and (inc > 0).any()  # reversals


def test_straight_trajectory_has_constant_steering() -> None:
    sim = simulate(SimulationOptions.of(records=300, seed=2, trajectory="straight"))
    assert np.unique(sim.ticks[:, 0]).size == 1


def test_abrupt_reversals_change_sign_at_speed_smooth_ones_through_a_crawl() -> None:
    def flips(reversals: str) -> np.ndarray:
        """At each change of direction, the slower of the two increments, in typical increments."""
        ds = parse_lines(
            simulate(SimulationOptions.of(records=1500, seed=3, reversals=reversals)).text().splitlines()
        )
        inc = ds.increments("traction_wheel")
        inc = inc[inc != 0]
        at = np.flatnonzero(np.sign(inc[1:]) != np.sign(inc[:-1]))
        return np.minimum(np.abs(inc[at]), np.abs(inc[at + 1])) / np.median(np.abs(inc))

    abrupt, smooth = flips("abrupt"), flips("smooth")
    assert np.sum(abrupt > 0.5) >= 2  # straight from one direction at speed to the other
    assert np.all(smooth < 0.5)


def test_a_tracker_on_its_own_clock_is_paired_with_the_encoders_as_a_bag_import_pairs_it() -> None:
    opts = SimulationOptions.of(
        records=1000, seed=2, rate_hz=50.0, tracker_rate_hz=30.0, outlier_fraction=0.02
    )
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
    plain = simulate(SimulationOptions.of(records=1200, seed=8))
    sim = simulate(SimulationOptions.of(records=1200, seed=8, steering_spikes=3, steering_stuck=2))
    kinds = sorted(f.kind for f in sim.faults)
    assert kinds == ["steering_spike"] * 3 + ["steering_stuck"] * 2
    changed = np.flatnonzero(np.any(sim.ticks != plain.ticks, axis=1))
    for f in sim.faults:
        assert plain.ticks[f.record, 0] == f.true_ticks and sim.ticks[f.record, 0] == f.logged_ticks
    spikes = {f.record for f in sim.faults if f.kind == "steering_spike"}
    assert spikes <= set(changed.tolist())
    _, truth = write_simulation(sim, tmp_path / "g.txt")
    assert len(json.loads(truth.read_text())["faults"]) == 5


#: Options that touch every piece a block carries to the next: latency (the fine grid kept for
#: the tracker), outliers (their own error streams), counter faults (placed on the whole log),
#: each model's drive and vendor odometry, more sub-steps than records per block.
BLOCKED_CASES = [
    {"records": 400, "seed": 4, "latency_s": 0.37, "outlier_fraction": 0.05},
    {"records": 300, "seed": 5, "model": "diff_drive", "counter_faults": 2, "latency_s": 0.05},
    {
        "records": 300,
        "seed": 6,
        "model": "tricycle_reverse",
        "substeps": 3,
        "rate_hz": 1000.0,
        "latency_s": 1.0,
    },
    {"records": 200, "seed": 7, "trajectory": "straight", "jitter_s": 0.0},
    {"records": 300, "seed": 8, "reversals": "abrupt", "steering_spikes": 2, "steering_stuck": 1},
    {"records": 300, "seed": 9, "rate_hz": 50.0, "tracker_rate_hz": 30.0, "outlier_fraction": 0.05},
]


@pytest.mark.parametrize("case", BLOCKED_CASES)
def test_a_log_made_in_blocks_is_the_log_made_at_once(case: dict[str, object], tmp_path: Path) -> None:
    """Each block continues the sums, the random draws and the fine grid of the one before, so the
    block size changes no byte, in memory or written block by block."""
    opts = SimulationOptions.of(**case)  # type: ignore[arg-type]
    whole = simulate(opts, block=opts.records).text()
    for block in (1, 2, 7, 64):
        assert simulate(opts, block=block).text() == whole, block
        path, truth = simulate_to_file(opts, tmp_path / f"b{block}.txt", block=block)
        assert path.read_text() == whole, block
        assert json.loads(truth.read_text()) == json.loads(json.dumps(simulate(opts).truth_dict()))


@pytest.mark.parametrize("name", ["demo_tricycle", "diff_drive_demo"])
def test_the_command_line_still_writes_the_shipped_demo_logs(name: str, tmp_path: Path) -> None:
    """``simulate --config`` (written block by block) makes the shipped logs, which the simulator
    made in one piece before it wrote in blocks."""
    out = tmp_path / f"{name}.txt"
    proc = subprocess.run(
        [sys.executable, "-m", "nlp_calib", "simulate", "--config",
         str(SCENARIOS / "data" / f"{name}.sim.yaml"), "--out", str(out)],
        capture_output=True, text=True, cwd=REPO, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    opts = simulation_options(SCENARIOS / "data" / f"{name}.sim.yaml", {})
    assert out.read_text() == simulate(opts).text()
    model = opts.model
    fresh = parse_lines(out.read_text().splitlines(), model=model)
    shipped = parse_lines((SCENARIOS / "data" / f"{name}.txt").read_text().splitlines(), model=model)
    np.testing.assert_array_equal(fresh.ticks, shipped.ticks)
    assert_close(fresh.T_world_sensor, shipped.T_world_sensor, rtol=0, atol=1e-8)


def test_a_log_beyond_the_old_limit_is_written_in_bounded_memory(tmp_path: Path) -> None:
    """60,000 records (over the 50,000 the command line allowed when it simulated in one piece):
    the blocks' sizes bound what is held, and the log reads back whole."""
    opts = SimulationOptions.of(records=60_000, seed=3)
    path, _ = simulate_to_file(opts, tmp_path / "long.txt")
    log = parse_lines(path.read_text().splitlines())
    assert log.n_records == 60_000
    assert np.all(np.diff(log.time_s) > 0)


def test_a_steering_joint_reads_the_angle_at_its_instant() -> None:
    # The base's turn over the two fine steps around an instant, over its travel there, is the
    # curvature tan φ / L of that instant's steering angle (to second order): the channel the
    # joint is read from must hold it, not the angle half a step before (0.3 mrad off at the
    # drive's steering rates). The text logs' simulator reads the same channel (profiles_on).
    from nlp_calib.models.joints import joint_map
    from nlp_calib.simulation.camera import base_motion
    from nlp_calib.simulation.lidar import LIDAR_DRIVE

    truth = joint_map("tricycle").default_truth
    t = np.arange(0.0, 30.0, 1e-3)
    planar, channels = base_motion("tricycle", truth, LIDAR_DRIVE, np.random.default_rng(3), t)
    theta = np.unwrap(planar[:, 2])
    i = np.arange(1, t.size - 1)
    travel = np.hypot(np.diff(planar[:, 0]), np.diff(planar[:, 1]))
    arcs = (travel[i - 1] + travel[i]) * np.sign(channels["front"][i + 1] - channels["front"][i - 1])
    moving = np.abs(arcs) > 1e-4
    seen = np.arctan(truth["axis_length"] * (theta[i + 1] - theta[i - 1])[moving] / arcs[moving])
    error = np.abs(channels["phi"][i][moving] - seen)
    assert moving.mean() > 0.5
    assert np.quantile(error, 0.99) < 1e-5, np.quantile(error, 0.99)
