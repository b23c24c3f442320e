"""A differential drive's baseline on one-record windows: the wheels' quantised counts are an input
with noise, and the turn per 40 ms interval is only a few ticks of wheel difference, so the fit
regresses the heading change on a noisy regressor and attenuates ``1/baseline`` (errors in
variables): the baseline comes out too large by about ``baseline · Var(noise)/E[signal²]`` of the
per-interval wheel difference, several σ on the default drive, while the σ (which propagates the
input noise) cannot hold a bias. Longer windows telescope the counts' errors (only the two ends
count) and shrink it; finer counts do too, which shows the simulator agrees with the model. The
fit removes it: each estimate takes the step that frees it of the inputs' expected share of the
cost (:mod:`nlp_calib.analysis.inputs_bias`)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import ros2_bags as rb
from conftest import cli, write_sim

from nlp_calib.analysis import inputs_bias
from nlp_calib.core.numeric import wrapped_difference
from nlp_calib.logs.log import JointStream
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.simulation.simulate import SimulationOptions, simulate

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


def _baseline_z(
    tmp_path: Path, seed: int, sim: dict[str, Any], residual: dict[str, Any]
) -> tuple[float, bool]:
    """(estimate − truth)/believed σ of the baseline, the lag held at its truth; and whether the
    run's warnings say that the counts' rounding biased a parameter beyond its σ (corrected)."""
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
    said = any("encoders' rounding biased" in w for w in run.warnings)
    return float(t.z[t.names.index("baseline")]), said


def _mean_z(tmp_path: Path, sim: dict[str, Any], residual: dict[str, Any]) -> tuple[float, list[bool]]:
    # Unbiased, three seeds' mean z is N(0, 1/3): 1.5 is 2.6 of its σ; the attenuation gives about 3.5.
    found = [_baseline_z(tmp_path, s, sim, residual) for s in SEEDS]
    return float(np.mean([z for z, _ in found])), [said for _, said in found]


def test_windows_of_five_records_recover_a_diff_drives_baseline_within_its_sigma(tmp_path: Path) -> None:
    assert abs(_mean_z(tmp_path, {}, {"horizon": 5})[0]) < 1.5


def test_counts_a_hundred_times_finer_recover_the_baseline_from_one_record_windows(tmp_path: Path) -> None:
    """The simulator and the model agree: only the counts' coarseness biases one-record windows
    (here too fine to need a correction worth saying)."""
    z, said = _mean_z(tmp_path, {"truth": FINE, "guess": FINE_GUESS}, {"horizon": 1})
    assert abs(z) < 1.5 and not any(said)


def test_one_record_windows_recover_a_diff_drives_baseline_within_its_sigma(tmp_path: Path) -> None:
    """Uncorrected, the baseline comes out about 3.5σ long (the counts' rounding in the inputs):
    corrected, and the correction said."""
    z, said = _mean_z(tmp_path, {}, {"horizon": 1})
    assert abs(z) < 1.5 and all(said)


def _one_record_windows(tmp_path: Path, log: Path, model: str, lag: float) -> Calibration:
    """The calibration set up on ``log`` with one-record windows and the lag given as ``lag``."""
    raw = {"model": model, "dataset": str(log), "alignment": {"tracker_lag": lag}, "residual": {"horizon": 1}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Calibration.setup(scenario_from_mapping(raw, model, tmp_path))


def _fitted(tmp_path: Path) -> tuple[Any, np.ndarray, Any]:
    """The evaluator, Gauss-Newton's optimum and the inputs' noise of one-record windows (seed 901),
    the counts as logged: each a reading of its own, the whole rounding noise of two per increment
    (re-sampled at a lag, they blend two readings, with less)."""
    log = write_sim(tmp_path, "s.txt", records=2000, seed=901, model="diff_drive", latency_s=0.0)
    c = _one_record_windows(tmp_path, log, "diff_drive", 0.0)
    fit = c.fitting
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        x = fit.solver("gauss_newton").solve(fit.problem.start.x0, None, None).x
    return fit.evaluator, x, c.stages.windows.input_noise


def test_the_bias_step_takes_every_window_where_it_matters_and_a_subset_where_it_cannot(
    tmp_path: Path, monkeypatch: Any
) -> None:
    """Where the step moves the baseline by σ, it is the one over every window; with noise a hundred
    times smaller (a step 10⁴ times smaller), the subset's estimate stands, within 0.05σ of it."""
    ev, x, (std, counted) = _fitted(tmp_path)
    assert ev.n_residuals >= inputs_bias.SCREEN_FROM
    screened = [inputs_bias.bias_step(ev, x, (s, counted)) for s in (std, std / 100)]
    monkeypatch.setattr(inputs_bias, "SCREEN_FROM", 10**9)
    full = [inputs_bias.bias_step(ev, x, (s, counted)) for s in (std, std / 100)]
    names = ev.fns.free
    assert abs(full[0].step / full[0].sigma)[names.index("baseline")] > 0.5
    np.testing.assert_array_equal(screened[0].step, full[0].step)
    small = full[1].step / full[1].sigma
    assert np.max(np.abs(small)) < 0.01 * inputs_bias.MATTERS
    assert not np.array_equal(screened[1].step, full[1].step)
    np.testing.assert_allclose(screened[1].step / full[1].sigma, small, atol=0.2 * np.max(np.abs(small)))


def test_the_noises_second_differences_are_the_errors_at_moved_inputs(tmp_path: Path) -> None:
    """One-record windows: the noise's mean in each residual is ``½ Σ_v (e(u+v) + e(u−v) − 2e(u))``,
    here against the errors of evaluators of their own at the moved inputs. It was exactly 0: the
    error at ``u`` was kept as a view of the buffer each moved evaluation overwrote."""
    ev, x, (std, counted) = _fitted(tmp_path)
    sources = inputs_bias._sources(ev, (std, counted))
    assert sources and not ev.fns.prefix
    found = inputs_bias._second_differences(ev, x, sources)
    base = ev.data.inputs.copy()

    def errors(inputs: np.ndarray) -> np.ndarray:
        ev.set_inputs(inputs)
        return np.array(ev.robust_terms(x)[0])

    here = errors(base)
    expected = 0.5 * sum(errors(base + v) + errors(base - v) - 2.0 * here for v in sources)
    ev.set_inputs(base)
    assert np.max(np.abs(expected)) > 0.0
    # The sums' order differs: rounding at the errors' own scale, far below the differences.
    scale = 1e-12 * np.max(np.abs(here))
    assert scale < 1e-3 * np.max(np.abs(expected))
    np.testing.assert_allclose(found, expected, rtol=1e-9, atol=scale)


def _recorded_z(
    tmp_path: Path, model: str, residual: str, names: tuple[str, ...], **record: Any
) -> dict[str, float]:
    """(estimate − truth)/σ of ``names`` from a ROS robot's recording (:func:`ros2_bags.record`)."""
    rec = rb.record(model, **record)
    bag = rb.write(rec, tmp_path / "bag", "mcap")
    sc = tmp_path / "robot.yaml"
    sc.write_text(
        f"name: robot\nmodel: {model}\n{rb.dataset_block(bag, rec)}\ninitial_guess: auto\n"
        f"residual: {residual}\nsolvers: [gauss_newton]\n"
    )
    proc = cli("run", str(sc), "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    estimate = json.loads((tmp_path / "out" / "result.json").read_text())["solvers"]["gauss_newton"]
    return {n: (estimate["params"][n] - rec.truth[n]) / estimate["std"][n] for n in names}


def test_a_skid_steers_turn_rate_over_one_interval_biases_no_track(tmp_path: Path) -> None:
    """A skid-steer turns by ``Δθ_w/(1 + slip·|ω_w|)`` with ``ω_w`` its wheels' rate over each
    interval: the counts' rounding in that rate (the tracker's 120 Hz records re-sample 100 Hz
    joints) makes it turn less, by ``slip·σ_ω²`` per second whatever the rate, and the fit shortens
    the track by about its share of the turn rate: -6.4σ here with a noise-free tracker
    and no correction of the noise's mean. The step removes it."""
    names = ("wheel_separation", "turn_slip")
    z = _recorded_z(
        tmp_path, "skid_steer", "{horizon_s: 0.5}", names, seconds=45.0, seed=6, tracker_noise=0.0
    )
    assert all(abs(v) <= 3.0 for v in z.values()), z


def test_a_ros_differential_drives_track_from_one_record_windows_is_within_its_sigma(tmp_path: Path) -> None:
    """Records at 120 Hz re-sample 100 Hz joints: an increment carries about 0.8 of a reading's
    rounding, not two. Taken as two, the step overshot the track to -10.9σ (seed 3; uncorrected,
    the attenuation puts it at +4.6σ)."""
    z = _recorded_z(tmp_path, "diff_drive", "{horizon: 1}", ("wheel_separation",), seconds=60.0, seed=3)
    assert abs(z["wheel_separation"]) <= 3.0, z


def test_a_resampled_joints_increments_carry_their_readings_noise_as_interpolated() -> None:
    """Records at 120 Hz between joint readings at 100 Hz: each increment's variance, in one
    reading's, as a simulation of independent readings gives it (2 on the joints' own stamps)."""
    stream = JointStream(time_s=np.arange(100) * 0.01, positions=np.zeros((100, 1)), resolution=(0.0,))
    t = 0.0037 + np.arange(100) / 120.0
    readings = np.random.default_rng(3).normal(size=(4000, 100))
    drawn = np.var(np.diff([np.interp(t, stream.time_s, r) for r in readings], axis=1), axis=0)
    np.testing.assert_allclose(stream.increment_variance(t), drawn, rtol=0.15)
    np.testing.assert_array_equal(stream.increment_variance(stream.time_s[:50]), 2.0)


def test_a_counter_that_stands_still_carries_the_rounding_its_wheel_had(tmp_path: Path) -> None:
    """A car's drive with stops: each wheel counter's increment carries, as the bias step's
    sources take it, the rounding the simulator's drive gave it, read off the same drive with
    counts a hundred times finer (the true travel to 1 % of a tick). Where the wheels roll, two
    readings' (uniform rounding); summed over the intervals whose count did not change, at least
    what the wheel travelled there and at most twice it. Two readings on each of them were 20
    times it: a reading's rounding is that of the wheel's position, the same over a stop."""
    opts: dict[str, Any] = {"model": "car_like", "seed": 4611, "records": 4000, "latency_s": 0.0}
    log = write_sim(tmp_path, "car.txt", **opts)
    k = SimulationOptions.of(**opts).truth["k_traction"]
    fine = simulate(SimulationOptions.of(**opts, truth={"k_traction": k / 100}))
    c = _one_record_windows(tmp_path, log, "car_like", 0.0)
    ev, (std, counted) = c.fitting.evaluator, c.stages.windows.input_noise
    sources = inputs_bias._sources(ev, (std, counted))
    kinds = ev.fns.model.encoder_kinds
    names = [e for e in kinds if kinds[e] == "counter"]  # the counters' inputs come first, in this order
    wheels = [row for row in range(len(counted)) if counted[row]]
    assert wheels == [0, 1] and len(names) == 2 and ev.data.offsets == (0,)
    for row in wheels:
        counts = ev.data.inputs[row]
        travel = (
            wrapped_difference(fine.ticks[:, fine.header.encoder_index(names[row])])[: counts.size] / 100.0
        )
        rounding = 12.0 * (counts - travel) ** 2  # in readings' (a tick's rounding: 1/12 tick²)
        modelled = (sum(v[row] for v in sources) / std[row]) ** 2
        still = counts == 0
        assert still.sum() > 200, still.sum()
        assert 1.0 <= modelled[still].sum() / rounding[still].sum() <= 2.0, (
            modelled[still].sum(),
            rounding[still].sum(),
        )
        assert np.mean(rounding[~still]) == pytest.approx(2.0, rel=0.1)
        np.testing.assert_allclose(modelled[~still], 2.0, rtol=1e-12)
