"""Horizon residuals, trajectory metrics and the real-log accuracy targets (issue: accuracy)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENARIOS, assert_close, mat, parse_lines, vec

from nlp_calib.analysis.metrics import trajectory_metrics
from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.logs import format_log, resample_encoders
from nlp_calib.models import get_model
from nlp_calib.pipeline import Calibration
from nlp_calib.pipeline.scenario import (
    AlignmentOptions,
    SampleSelection,
    ValidationOptions,
    load_scenario,
)
from nlp_calib.problem import ProblemSpec, ResidualOptions, build, build_residual_data
from nlp_calib.results import CalibrationRun
from nlp_calib.simulation import SimulationOptions, simulate
from nlp_calib.sources import load_log

MODEL = get_model("tricycle")
TRUTH = np.array([0.55, 0.0105, 1.5, -0.05, 1.6, 0.1, 0.05])


def base_increment(p: np.ndarray, revs: float, angle: float, exact: bool = True) -> np.ndarray:
    """The bicycle increment written out in numpy, independently of the CasADi model."""
    phi = p[0] * angle + p[3]
    d = p[1] * revs
    v, w = d * np.cos(phi), d * np.sin(phi) / p[2]
    if not exact:
        return mat(np.array([v, 0.0, w]))
    if abs(w) < 1e-12:
        return mat(np.array([v, 0.0, 0.0]))
    return mat(np.array([v * np.sin(w) / w, v * (1 - np.cos(w)) / w, w]))


def sensor_motion(p: np.ndarray, revs: float, angle: float, exact: bool = True) -> np.ndarray:
    S = mat(p[4:7])
    return np.linalg.inv(S) @ base_increment(p, revs, angle, exact) @ S


@pytest.mark.parametrize("exact", [True, False])
@pytest.mark.parametrize("H", [1, 2, 7])
def test_horizon_residual_equals_numpy_composition(H: int, exact: bool) -> None:
    fns = build(MODEL, ProblemSpec(horizon=H, integration="exact" if exact else "euler"))
    rng = np.random.default_rng(H)
    for _ in range(10):
        revs = rng.uniform(-2, 2, H)
        angles = rng.uniform(-2, 2, H)
        z = rng.normal(0, 0.3, 3)
        p = TRUTH + rng.normal(0, 0.05, 7)
        h = np.eye(3)
        for j in range(H):
            h = h @ sensor_motion(p, revs[j], angles[j], exact)
        expected = vec(np.linalg.inv(mat(z)) @ h)
        data = np.concatenate([np.column_stack([revs, angles]).ravel(), z, [1.0]])
        got = np.asarray(fns.residual(p, [], data)).ravel()
        assert_close(got, expected, rtol=1e-10, atol=1e-12)


def test_horizon_one_is_the_single_step_residual() -> None:
    """H = 1 windows are exactly the per-interval residuals of consecutive records."""
    sim = parse_lines(simulate(SimulationOptions.of(records=60, seed=2)).text().splitlines())
    fns = build(MODEL, ProblemSpec(horizon=1))
    options = ResidualOptions(horizon=1)
    rd = build_residual_data(fns, sim, options)
    e = np.asarray(fns.residual.map(rd.n_residuals)(TRUTH, [], rd.columns))
    P, u = sim.T_world_sensor, MODEL.inputs(sim, options.steering_sample)
    for k in range(rd.n_residuals):
        Z = np.linalg.inv(mat(P[k])) @ mat(P[k + 1])
        expected = vec(np.linalg.inv(Z) @ sensor_motion(TRUTH, u[0, k], u[1, k]))
        assert_close(e[:, k], expected, rtol=1e-10, atol=1e-12)


def model_consistent_log(tmp_path: Path, records: int = 800) -> Path:
    """A log whose tracker poses are the truth model integrated (numpy) on its own encoder ticks."""
    sim = simulate(SimulationOptions.of(records=records, seed=9))
    ds = parse_lines(sim.text().splitlines())
    u = MODEL.inputs(ds, "start")
    T = mat(np.array([0.3, -0.2, 0.4]))
    S = mat(TRUTH[4:7])
    poses = [vec(T @ S)]
    for k in range(u.shape[1]):
        T = T @ base_increment(TRUTH, u[0, k], u[1, k])
        poses.append(vec(T @ S))
    text = format_log(sim.header, sim.time_ns, sim.ticks, sim.model_pose, np.array(poses), digits=17)
    p = tmp_path / "consistent.txt"
    p.write_text(text)
    return p


def test_ate_of_truth_on_noiseless_log_is_zero(tmp_path: Path) -> None:
    ds = load_log(model_consistent_log(tmp_path))
    fns = build(MODEL, ProblemSpec())
    m = trajectory_metrics(fns, TRUTH, MODEL.inputs(ds, "start"), ds.T_world_sensor)
    assert m.ate_max <= 1e-9, m
    assert m.rpe_trans <= 1e-9 and m.rpe_rot <= 1e-9
    wrong = TRUTH * np.array([1, 1.01, 1, 1, 1, 1, 1])
    assert trajectory_metrics(fns, wrong, MODEL.inputs(ds, "start"), ds.T_world_sensor).ate_mean > 1e-3


def test_ate_does_not_depend_on_where_the_record_range_starts(tmp_path: Path) -> None:
    """Scoring records 300: of a log equals scoring a log that starts at record 300."""
    log = SCENARIOS / "data" / "demo_tricycle.txt"
    lines = log.read_text().splitlines()
    header = [ln for ln in lines if ln.startswith("#")]
    records = [ln for ln in lines if not ln.startswith("#")]
    cut = tmp_path / "cut.txt"
    cut.write_text("\n".join(header + records[300:]) + "\n")
    # The clock held: a fitted lag re-samples the encoders, which the cut log cannot do before its
    # first record (the record range then starts one later), the metric's question aside.
    sc = load_scenario(SCENARIOS / "demo.yaml").with_options(alignment=AlignmentOptions(tracker_lag=0.0))
    later = Calibration(sc.with_options(samples=dataclasses.replace(sc.log.samples, start=300)))
    fresh = Calibration(sc.with_options(dataset=cut))
    p = np.array([later.initial[n] for n in later.fns.names]) * 1.01
    a, _ = later.score(p)
    b, _ = fresh.score(p)
    assert a.records == b.records == 1200
    assert_close([a.ate_mean, a.ate_max, a.ate_final], [b.ate_mean, b.ate_max, b.ate_final], rtol=1e-12)


def test_stationary_windows_are_dropped_and_counted() -> None:
    sc = load_scenario(SCENARIOS / "demo.yaml")
    keep = Calibration(sc)
    drop = Calibration(sc.with_options(samples=dataclasses.replace(sc.log.samples, drop_stationary=True)))
    assert drop.data.dropped_stationary > 0
    assert drop.data.n_residuals + drop.data.dropped_stationary == keep.data.n_residuals


def test_encoder_shift_by_whole_samples_reproduces_the_readings() -> None:
    ds = load_log(SCENARIOS / "data" / "demo_tricycle.txt")
    t = ds.time_s
    lag = float(t[5] - t[4])  # not a whole sample everywhere: jitter; check the one record it is
    shifted, valid = resample_encoders(ds, lag, MODEL.encoder_kinds)
    assert valid[0] >= 1
    np.testing.assert_array_equal(shifted.ticks[5], ds.ticks[4])
    assert resample_encoders(ds, 0.0, MODEL.encoder_kinds)[0] is ds


@pytest.mark.slow
def test_tracker_lag_is_recovered_from_a_simulated_log(tmp_path: Path) -> None:
    from nlp_calib.simulation import write_simulation

    log, _ = write_simulation(
        simulate(SimulationOptions.of(records=1500, seed=4, latency_s=0.06, tracker_noise_xy=0.001)),
        tmp_path / "lag.txt",
    )
    sc = load_scenario(SCENARIOS / "demo.yaml").with_options(
        dataset=log,
        alignment=dataclasses.replace(
            load_scenario(SCENARIOS / "demo.yaml").log.alignment, tracker_lag="auto"
        ),
    )
    calib = Calibration(sc)
    assert calib.alignment.estimate is not None
    assert calib.alignment.lag_s == pytest.approx(0.06, abs=0.012)


@pytest.fixture(scope="module")
def recommended(real_log: Path) -> CalibrationRun:
    """The recommended scenario on the real log, both solvers, as shipped."""
    return Calibration(load_scenario(SCENARIOS / "real_tricycle.yaml").with_dataset(real_log)).run()


@pytest.mark.slow
def test_recommended_real_scenario_meets_the_fault_robust_targets(recommended: CalibrationRun) -> None:
    """Segment ATE <= 0.07 m and RPE over 5 m <= 0.06 m for both solvers, which agree to 1e-4."""
    for name, rep in recommended.reports.items():
        assert rep.result.converged, rep.result.reason
        assert rep.metrics.segment_ate.mean <= 0.07, name
        assert rep.metrics.rpe_distance[5.0].mean <= 0.06, name
        # ... where the uncalibrated robot is off by metres on both figures.
        assert recommended.baseline.segment_ate.mean > 1.0
        assert recommended.baseline.rpe_distance[5.0].mean > 1.0
    gn, ip = (rep.result for rep in recommended.reports.values())
    assert_close(ip.params, gn.params, rtol=1e-4)


@pytest.fixture(scope="module")
def k_traction_of_parts(recommended: CalibrationRun, real_log: Path) -> list[float]:
    """k_traction fitted on the first 60 %, the last 60 %, the middle half and after the faults."""
    sc = load_scenario(SCENARIOS / "real_tricycle.yaml").with_dataset(real_log)
    sc = sc.with_options(solvers=("gauss_newton",))
    values = []
    for a, b in ((0, 1460), (974, 2434), (608, 1825), (1220, 2434)):
        part = sc.with_options(
            samples=SampleSelection(start=a, stop=b),
            validation=dataclasses.replace(sc.validation, blocks=0),
            alignment=dataclasses.replace(sc.log.alignment, tracker_lag=recommended.data.tracker_lag_s),
        )
        res = Calibration(part).solve("gauss_newton")
        assert res.converged, res.reason
        values.append(res.param_dict()["k_traction"])
    return values


@pytest.mark.slow
def test_white_noise_sigma_alone_would_not_cover_the_parts(
    recommended: CalibrationRun, k_traction_of_parts: list[float]
) -> None:
    """The parts disagree by far more than 3 white-noise σ; the block σ is several times larger."""
    spread = max(k_traction_of_parts) - min(k_traction_of_parts)
    honest = recommended.std("gauss_newton")["k_traction"]
    white = recommended.reports["gauss_newton"].uncertainty.std_dict()["k_traction"]
    assert spread / white > 10.0
    assert honest > 3.0 * white


@pytest.mark.xfail(
    strict=True,
    reason="not reached: the spread is about 4 block σ; the parts that reverse much (up to 66 % of "
    "intervals) give a lower traction gain, also with a gain per direction, so the gain changes slowly "
    "along the drive and neighbouring blocks are not independent (docs/accuracy.md, section 5)",
)
@pytest.mark.slow
def test_honest_sigma_covers_the_spread_of_fits_on_parts_of_the_log(
    recommended: CalibrationRun, k_traction_of_parts: list[float]
) -> None:
    """The spread of the part fits is within 3 honest σ of the whole fit."""
    spread = max(k_traction_of_parts) - min(k_traction_of_parts)
    assert spread / recommended.std("gauss_newton")["k_traction"] <= 3.0


@pytest.mark.xfail(
    strict=True,
    reason="not reached: the leading 60 % of the real log holds 5 intervals of reversing, so the reverse "
    "steering gain is held at 0 there and the last 40 %, mostly reversing, scores 0.12 m (docs/accuracy.md)",
)
@pytest.mark.slow
def test_recommended_real_scenario_holdout_target(real_log: Path) -> None:
    sc = load_scenario(SCENARIOS / "real_tricycle.yaml").with_dataset(real_log)
    sc = sc.with_options(validation=ValidationOptions(holdout_fraction=0.4, blocks=0))
    for rep in Calibration(sc).run().reports.values():
        assert rep.holdout is not None
        assert rep.holdout.segment_ate.mean <= 0.09


@pytest.mark.slow
def test_seed_formulation_and_uncalibrated_robot_are_far_off(
    recommended: CalibrationRun, real_log: Path
) -> None:
    """The seed formulation's error is an order of magnitude larger; the uncalibrated robot's ~14 m."""
    seed = Calibration(load_scenario(SCENARIOS / "real_tricycle_seed.yaml").with_dataset(real_log))
    res = seed.solve("gauss_newton")
    ours = recommended.reports["gauss_newton"].metrics.segment_ate.mean
    assert seed.score(res.params)[0].segment_ate.mean > 10 * ours
    p0 = np.array([seed.initial[n] for n in seed.fns.names])
    assert 13.0 < seed.score(p0)[0].ate_mean < 15.0


def test_lag_at_the_edge_of_its_search_range_is_named() -> None:
    sim = simulate(SimulationOptions.of(records=600, seed=4, latency_s=0.25, tracker_noise_xy=0.001))
    sc = load_scenario(SCENARIOS / "demo.yaml").with_options(
        solvers=("gauss_newton",),
        alignment=AlignmentOptions(tracker_lag="auto", search=(-0.1, 0.1), step=0.01),
    )
    with pytest.warns(
        NlpCalibWarning, match=r"alignment.tracker_lag: the fitted lag 100.0 ms lies at the edge"
    ):
        calib = Calibration(sc, log=parse_lines(sim.text().splitlines()))
    assert calib.alignment.estimate is not None and calib.alignment.estimate.at_edge
    assert any("lies at the edge" in w for w in calib.run().warnings)
