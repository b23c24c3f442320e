"""The precision a calibration needs, from the vehicle's own drive: a clock offset's from how fast
the sensor moves and turns."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from nlp_calib.analysis.excitation import STEP_S, taken
from nlp_calib.analysis.precision import lag_precision, tightest
from nlp_calib.models.clock import LAG_REFERENCE
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.results.layout import CLOCK, HELD, MODEL, BlockSpec, Layout
from nlp_calib.simulation import SimulationOptions, simulate, write_simulation

REFERENCE = LAG_REFERENCE["tracker_lag"][1]
BASE_RUN = {
    "model": "diff_drive",
    "initial_guess": "auto",
    "residual": {"horizon": 10},
    "solvers": ["gauss_newton"],
}


def _layout(n_logs: int) -> Layout:
    model = BlockSpec(MODEL, ("wheelbase",), precision={"wheelbase": ("relative", 0.01)})
    clock = BlockSpec(CLOCK, ("tracker_lag",), per_log=n_logs > 1, precision=dict(LAG_REFERENCE))
    return Layout.of((model, clock), n_logs)


def _track(
    speed: float, rate: float, seconds: float = 20.0, hz: float = 50.0
) -> tuple[np.ndarray, np.ndarray]:
    """A sensor on a circle at ``speed`` (m/s) turning at ``rate`` (rad/s)."""
    t = np.arange(0.0, seconds, 1.0 / hz)
    heading = rate * t
    r = speed / rate
    return np.column_stack([r * np.sin(heading), r * (1 - np.cos(heading)), heading]), t


@pytest.mark.parametrize(
    ("speed", "rate", "needed"),
    [
        (1.0, 0.5, REFERENCE),
        (0.25, 0.1, REFERENCE / 0.25),
        (20.0, 0.05, REFERENCE / 20.0),
        (0.3, 2.0, REFERENCE / 2.0),
    ],
)
def test_a_clock_offset_needs_what_keeps_the_sensors_motion_to_the_reference_robots(
    speed: float, rate: float, needed: float
) -> None:
    """2 ms at a metre and a radian a second: the faster of the two sets it."""
    track, t = _track(speed, rate)
    out = lag_precision(_layout(1), track, t, 0, metric=True)
    # The track's steps (a quarter second, past its noise) are chords of the arc: the speed they
    # give is the chord's, within a thousandth of the arc's.
    assert out.param("tracker_lag").precision == (
        "absolute",
        pytest.approx(_chords(speed, rate, t), rel=1e-9),
    )
    assert out.param("tracker_lag").precision[1] == pytest.approx(needed, rel=1e-3)
    assert out.param("wheelbase").precision == ("relative", 0.01)


def _chords(speed: float, rate: float, t: np.ndarray) -> float:
    """What a circle at ``speed`` turning at ``rate`` needs, from its chords over the quarter-second
    steps :func:`~nlp_calib.analysis.excitation.taken` takes at ``t``: ``2R·sin(rate·Δt/2)/Δt``."""
    dt = np.diff(t[taken(t, STEP_S)])
    chord = 2 * (speed / rate) * np.sin(rate * dt / 2) / dt
    return REFERENCE / max(float(np.quantile(chord, 0.9)), rate)


def test_the_tracker_noise_is_no_speed() -> None:
    """A slow sensor (0.1 m/s) tracked at 100 Hz with 3 mm of noise: it needs 20 ms of its lag,
    within a quarter (the noise over a quarter second's steps only asks more), where the records'
    own steps had made its noise a speed of 0.4 m/s and asked 5 ms."""
    track, t = _track(0.1, 0.02, seconds=60.0, hz=100.0)
    noisy = track + np.random.default_rng(3).normal(0.0, 0.003, track.shape) * np.array([1.0, 1.0, 0.0])
    out = lag_precision(_layout(1), noisy, t, 0, metric=True)
    assert 0.75 * REFERENCE / 0.1 <= out.param("tracker_lag").precision[1] <= REFERENCE / 0.1


def test_a_track_in_its_own_units_counts_its_turn_rate_only_and_other_logs_keep_theirs() -> None:
    track, t = _track(5.0, 0.5)
    out = lag_precision(_layout(2), track, t, 1, metric=False)
    assert out.param("tracker_lag_2").precision == ("absolute", pytest.approx(REFERENCE / 0.5))
    assert out.param("tracker_lag_1").precision == LAG_REFERENCE["tracker_lag"]


def test_a_held_offset_or_a_still_sensor_keeps_the_reference() -> None:
    track, t = _track(0.2, 0.1)
    held = _layout(1).with_status({"tracker_lag": HELD})
    assert lag_precision(held, track, t, 0, metric=True) == held
    still = np.zeros((100, 3))
    assert lag_precision(_layout(1), still, np.arange(100) * 0.02, 0, metric=True) == _layout(1)


def test_several_logs_need_the_tightest_of_a_shared_parameter_and_each_its_own_offset() -> None:
    joint = _layout(2)
    fast, slow = _track(2.0, 0.2), _track(0.25, 0.1)
    logs = [lag_precision(joint, *fast, 0, metric=True), lag_precision(joint, *slow, 1, metric=True)]
    out = tightest(joint, logs)
    assert out.param("tracker_lag_1").precision[1] == pytest.approx(_chords(2.0, 0.2, fast[1]), rel=1e-9)
    assert out.param("tracker_lag_2").precision[1] == pytest.approx(_chords(0.25, 0.1, slow[1]), rel=1e-9)
    assert out.param("wheelbase").precision == ("relative", 0.01)


def test_a_slow_noisy_drive_reads_its_lag_by_what_the_drive_needs(tmp_path: Path) -> None:
    """A slow differential drive (0.15 m/s at most) tracked at 25 Hz with 6 mm of noise: the lag's
    needed precision is what the sensor's true path asks (within a fifth; the records' own steps
    had taken the noise for speed and asked a quarter of it), and a lag known within 5 times that
    is no "only weakly observable" caveat (it was, in the reference robot's 2 ms)."""
    opts = SimulationOptions.of(
        records=300,
        seed=7,
        model="diff_drive",
        max_speed=0.15,
        tracker_noise_xy=0.006,
        tracker_noise_theta=0.006,
    )
    sim = simulate(opts)
    path = write_simulation(sim, tmp_path / "slow.txt")[0]
    raw = {**BASE_RUN, "dataset": str(path), "alignment": {"tracker_lag": "auto"}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(scenario_from_mapping(raw, "slow", tmp_path)).run()
    t = np.asarray(sim.time_ns, dtype=float) * 1e-9
    truth = sim.truth_dict()["params"]
    base = np.asarray(sim.T_world_base_true, dtype=float)
    c, s = np.cos(base[:, 2]), np.sin(base[:, 2])
    x, y = truth["sensor_x"], truth["sensor_y"]
    sensor = np.column_stack([base[:, 0] + c * x - s * y, base[:, 1] + s * x + c * y, base[:, 2]])
    k = taken(t, STEP_S)
    step, dt = np.diff(sensor[k], axis=0), np.diff(t[k])
    fast = max(
        np.quantile(np.hypot(step[:, 0], step[:, 1]) / dt, 0.9), np.quantile(np.abs(step[:, 2]) / dt, 0.9)
    )
    needed = run.scenario.layout.param("tracker_lag").needed(0.0)
    assert needed == pytest.approx(REFERENCE / fast, rel=0.2)
    std = run.std("gauss_newton")["tracker_lag"]
    weak = [w.words() for w in run.checks.observability.weak]
    assert std <= 5 * needed and "tracker_lag is only weakly observable" not in weak, (std, needed, weak)
