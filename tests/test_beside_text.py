"""A gyro beside a text log (``dataset: {text: …, gyro: …, counts_per_turn: …}``): the text log's
tracker poses and encoders, a gyro's CSV of the same drive, fitted in one objective."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import cli

from nlp_calib.core import poses3d
from nlp_calib.core.errors import ConfigError
from nlp_calib.pipeline import scenario_from_mapping
from nlp_calib.simulation.options import SimulationOptions
from nlp_calib.simulation.simulate import simulate, write_simulation

#: The wheels' counts per turn (a text log states none): a radius is k·COUNTS/2π.
COUNTS = 4096.0
#: The gyro's truth: biases, a 3° roll, its noise (rad/s a sample at 200 Hz).
BIAS, ROLL, RATE_NOISE = np.array([0.003, -0.002, 0.004]), float(np.radians(3.0)), 0.002
SCENARIO = {
    "model": "diff_drive",
    "sensor": {"mount": "planar", "beside": "gyro"},
    "initial_guess": "auto",
    "robust": {"kernel": "huber", "delta": 3.0},
    # The tracker's 2 mm and 2 mrad a pose (a difference of two: 8e-6); the gyro's angle.
    "information": {"translation": 1.25e5, "rotation": 1.25e5, "gyro": 1.0e8},
    "solvers": ["gauss_newton"],
}


def _gyro_csv(sim_time_s: np.ndarray, yaw: np.ndarray, path: Path, seed: int) -> None:
    """A gyro at 200 Hz, rolled ``ROLL``, reading the base's turn rate (each record interval's own,
    as the drive's arcs are) with ``BIAS`` and white noise."""
    t = np.arange(sim_time_s[0], sim_time_s[-1], 0.005)
    rate = np.diff(np.unwrap(yaw)) / np.diff(sim_time_s)
    turn = rate[np.clip(np.searchsorted(sim_time_s, t, side="right") - 1, 0, rate.size - 1)]
    R = np.asarray(poses3d.rpy_to_matrix(np.array([ROLL, 0.0, 0.0])))
    w = (
        turn[:, None] * R[2][None, :]
        + BIAS
        + np.random.default_rng(seed).normal(0.0, RATE_NOISE, (t.size, 3))
    )
    rows = [f"{s:.9f},{a:.12g},{b:.12g},{c:.12g}" for s, (a, b, c) in zip(t, w)]
    path.write_text("t,wx,wy,wz\n" + "\n".join(rows) + "\n")


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, float]]:
    """60 s of a simulated differential drive's text log (seed 44, never tuned on) and a gyro's CSV
    of its base's turning: the scenario and the truth in the fit's names."""
    folder = tmp_path_factory.mktemp("text_gyro")
    sim = simulate(SimulationOptions(records=1500, seed=44, model="diff_drive"))
    write_simulation(sim, folder / "run.log")
    time_s = sim.time_ns.astype(float) * 1e-9
    _gyro_csv(time_s, sim.T_world_base_true[:, 2], folder / "gyro.csv", 44)
    dataset = {
        "text": "run.log",
        "gyro": "gyro.csv",
        "counts_per_turn": {"left_wheel": COUNTS, "right_wheel": COUNTS},
    }
    scenario = folder / "text_gyro.yaml"
    scenario.write_text(yaml.safe_dump({**SCENARIO, "dataset": dataset}))
    t = sim.options.truth
    per_rad = COUNTS / (2.0 * np.pi)
    truth = {
        "left_wheel_radius": t["k_left"] * per_rad,
        "right_wheel_radius": t["k_right"] * per_rad,
        "wheel_separation": t["baseline"],
        "imu_roll": ROLL,
        **{f"gyro_bias_{a}": float(b) for a, b in zip("xyz", BIAS)},
    }
    return scenario, truth


def test_a_gyro_beside_a_text_logs_poses_fits_within_3_sigma(
    drive: tuple[Path, dict[str, float]], tmp_path: Path
) -> None:
    scenario, truth = drive
    proc = cli("run", str(scenario), "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    stored = yaml.safe_load((tmp_path / "out" / "calibration.yaml").read_text())
    est, std = stored["parameters"], stored["std"]
    for name, true in truth.items():
        assert abs(est[name] - true) < 3 * std[name], (name, est[name], true, std[name])


def test_a_text_log_beside_a_gyro_needs_its_wheels_counts_per_turn(
    drive: tuple[Path, dict[str, float]],
) -> None:
    scenario, _ = drive
    raw = yaml.safe_load(scenario.read_text())
    with pytest.raises(ConfigError, match="missing counts_per_turn"):
        scenario_from_mapping(
            {**raw, "dataset": {k: v for k, v in raw["dataset"].items() if k != "counts_per_turn"}},
            "s",
            scenario.parent,
        )
