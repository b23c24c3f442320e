"""Trustworthy estimates: recovery of known truth, honest uncertainty, observability, auto start,
fixed parameters and priors (issue: trustworthy estimates)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import SCENARIOS, parse_lines

from nlp_calib.analysis import uncertainty as unc
from nlp_calib.analysis.observability import analyse
from nlp_calib.models import get_model
from nlp_calib.pipeline import Calibration
from nlp_calib.pipeline.scenario import AlignmentOptions, Prior, RobustOptions, Scenario, load_scenario
from nlp_calib.problem import ResidualOptions
from nlp_calib.results import SolverResult
from nlp_calib.results.uncertainty import Uncertainty
from nlp_calib.simulation import SimulationOptions, simulate
from nlp_calib.solvers import GaussNewtonOptions

DEFAULT_TRUTH = get_model("tricycle").drive.default_truth
TRUTH = np.array(list(DEFAULT_TRUTH.values()))
NAMES = tuple(DEFAULT_TRUTH)
# Stated tolerances: k_traction 1 %, axis_length 2 %, steer_offset 0.01 rad, sensor 2 cm / 0.01 rad.
TOLERANCE = np.array([np.inf, 0.01 * TRUTH[1], 0.02 * TRUTH[2], 0.01, 0.02, 0.02, 0.01])
TOLERANCE[0] = 0.02 * TRUTH[0]  # k_steer 2 %


def sim_calibration(scenario: Scenario, **sim: object) -> Calibration:
    ds = parse_lines(simulate(SimulationOptions.of(**sim)).text().splitlines(), "sim")  # type: ignore[arg-type]
    return Calibration(scenario, log=ds)


def scenario(**changes: object) -> Scenario:
    base = Scenario.of(
        name="sim",
        dataset=Path("sim"),
        robust=RobustOptions("none"),
        residual=ResidualOptions(horizon=10, stride=1, steering_sample="mean"),
        # The simulated logs have no latency: these tests judge the robot's and the mount's
        # parameters (the lag's own are the ones that ask for it).
        alignment=AlignmentOptions(tracker_lag=0.0),
    )
    return base.with_options(**changes)  # type: ignore[arg-type]


def _noise(calib: Calibration) -> tuple[np.ndarray, None, np.ndarray]:
    """The inputs' noise as the pipeline gives it (a counter's on its readings), no bounds."""
    std, counted = calib.stages.windows.input_noise
    return std, None, counted


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recovers_truth_with_noise_outliers_wrap_and_latency(seed: int) -> None:
    sc = scenario(robust=RobustOptions("huber", 0.02), alignment=AlignmentOptions(tracker_lag="auto"))
    calib = sim_calibration(sc, records=2000, seed=seed, outlier_fraction=0.02, latency_s=0.05)
    assert abs(calib.alignment.lag_s - 0.05) < 0.005
    assert calib.log.encoder("traction_wheel").max() > 2**32 - 30000  # the counter wrapped
    for solver in ("gauss_newton", "ipopt"):
        res = calib.solve(solver)
        assert res.converged, res.reason
        u = unc.estimate(calib.evaluator, res.x, calib.data, *_noise(calib))
        # The lag is a parameter of the problem: its fitted value is judged like the others.
        idx = [res.names.index(n) for n in (*NAMES, "tracker_lag")]
        err = res.params[idx] - np.append(TRUTH, 0.05)
        std = u.std[idx]
        assert np.all(np.abs(err) <= 3 * std), dict(zip((*NAMES, "tracker_lag"), err / std))
        assert np.all(np.abs(err[:-1]) <= TOLERANCE), dict(zip(NAMES, err))


@pytest.mark.slow
def test_uncertainty_is_consistent_over_independent_noise() -> None:
    """NEES of the 7 parameters over 100 simulated logs matches χ²(7); 2σ covers 88-99 %.

    Horizon windows overlap (H = 10, stride 1), so residuals are correlated: the covariance
    propagates the tracker and encoder noise through the shared poses and intervals.
    """
    sc = scenario()
    runs = 100
    nees = np.empty(runs)
    covered = np.zeros(7)
    for k in range(runs):
        calib = sim_calibration(sc, records=1000, seed=1000 + k)
        res = calib.solve("gauss_newton")
        assert res.converged, res.reason
        u = unc.estimate(calib.evaluator, res.x, calib.data, *_noise(calib))
        err = res.params - TRUTH
        nees[k] = err @ np.linalg.solve(u.covariance, err)
        covered += np.abs(err) <= 2 * u.std
    assert 5.0 <= nees.mean() <= 9.0, nees.mean()
    coverage = covered / runs
    assert np.all((coverage >= 0.88) & (coverage <= 0.99)), dict(zip(NAMES, coverage))


def test_estimated_noise_matches_the_simulated_tracker_noise() -> None:
    calib = sim_calibration(
        scenario(), records=1500, seed=3, tracker_noise_xy=0.003, tracker_noise_theta=0.001
    )
    res = calib.solve("gauss_newton")
    u = unc.estimate(calib.evaluator, res.x, calib.data, *_noise(calib))
    assert u.noise["tracker_xy"] == pytest.approx(0.003, rel=0.1)
    assert u.noise["tracker_theta"] == pytest.approx(0.001, rel=0.1)


def test_straight_line_log_warns_about_turning_and_is_not_converged() -> None:
    calib = sim_calibration(scenario(), records=800, seed=2, trajectory="straight")
    res = calib.solve("gauss_newton")
    assert not res.converged and "singular normal matrix" in res.reason
    obs = analyse(calib.evaluator, res.x, calib.data.log.T_world_sensor)
    text = " ".join(obs.warnings)
    assert "no turning" in text
    for name in ("axis_length", "sensor_x", "sensor_y"):
        assert name in text
    u = unc.estimate(calib.evaluator, res.x, calib.data, *_noise(calib))
    std = u.std_dict()
    assert np.isinf(std["axis_length"]) and np.isinf(std["sensor_x"])
    assert np.isfinite(std["k_traction"]) and np.isfinite(std["sensor_theta"])


@pytest.mark.parametrize("trajectory", ["s_curves", "no_reversals"])
def test_well_excited_logs_raise_no_observability_warning(trajectory: str) -> None:
    """Reversals are not needed: a forward-only log with turns determines every parameter."""
    calib = sim_calibration(scenario(), records=1500, seed=1, trajectory=trajectory)
    res = calib.solve("gauss_newton")
    assert res.converged, res.reason
    obs = analyse(calib.evaluator, res.x, calib.data.log.T_world_sensor)
    assert obs.warnings == ()
    assert obs.condition_number < 1e4
    assert max(obs.std_reference.values()) < 5.0


def test_auto_initial_guess_reaches_the_header_optimum_on_the_real_log(real_log: Path) -> None:
    sc = load_scenario(SCENARIOS / "real_tricycle.yaml").with_dataset(real_log)
    # The closed form as this test was written for it: the steering read at each interval's start
    # (the shipped scenario now reads it at the middle; the closed form then lands 8 % off in
    # k_traction, and the refinement below reaches the same optimum all the same).
    sc = sc.with_options(
        alignment=AlignmentOptions(tracker_lag=0.0),
        residual=dataclasses.replace(sc.objective.residual, steering_sample="start"),
    )
    header = Calibration(sc).solve("gauss_newton")
    auto = Calibration(sc.with_options(initial_guess="auto"))
    assert auto.start.auto is not None
    # The closed form alone lands close to the optimum in what the data determine best: the
    # traction scale, the sensor's lever arm and the turning gain k_steer / axis_length...
    g, p = auto.start.auto, header.param_dict()
    assert g["k_traction"] == pytest.approx(p["k_traction"], rel=0.05)
    assert g["sensor_x"] == pytest.approx(p["sensor_x"], abs=0.02)
    assert g["k_steer"] / g["axis_length"] == pytest.approx(p["k_steer"] / p["axis_length"], rel=0.05)
    # ...and the refinement reaches the same optimum with both solvers.
    for solver in ("gauss_newton", "ipopt"):
        res = auto.solve(solver)
        assert res.converged, res.reason
        np.testing.assert_allclose(res.params, header.params, rtol=1e-4, atol=1e-6)


def test_auto_initial_guess_on_a_simulated_log_needs_no_header() -> None:
    sc = scenario(initial_guess="auto")
    calib = sim_calibration(sc, records=1500, seed=5, guess={n: 1.0 for n in NAMES})
    res = calib.solve("gauss_newton")
    assert res.converged, res.reason
    assert np.all(np.abs(res.params - TRUTH) <= TOLERANCE)


def test_fixed_parameter_stays_bit_identical_and_solvers_agree(small_demo: Scenario) -> None:
    sc = small_demo.with_options(
        fixed=("axis_length", "sensor_y"), initial_guess={"axis_length": 1.55, "sensor_y": 0.07}
    )
    calib = Calibration(sc)
    assert calib.fns.free == (
        "k_steer",
        "k_traction",
        "steer_offset",
        "sensor_x",
        "sensor_theta",
        "tracker_lag",
    )
    gn, ip = calib.solve("gauss_newton"), calib.solve("ipopt")
    for res in (gn, ip):
        assert res.converged, res.reason
        assert res.param_dict()["axis_length"] == 1.55
        assert res.param_dict()["sensor_y"] == 0.07
    np.testing.assert_allclose(gn.params, ip.params, rtol=1e-6)
    assert gn.cost == pytest.approx(ip.cost, rel=1e-9)
    u = unc.estimate(calib.evaluator, gn.x, calib.data, *_noise(calib))
    assert u.std_dict()["axis_length"] == 0.0 and u.std_dict()["k_steer"] > 0.0


def test_tight_prior_pulls_the_estimate_to_its_mean(small_demo: Scenario) -> None:
    free = Calibration(small_demo).solve("gauss_newton").param_dict()["axis_length"]
    mean = free + 0.1
    sc = small_demo.with_options(priors={"axis_length": Prior(mean=mean, std=1e-5)})
    calib = Calibration(sc)
    gn, ip = calib.solve("gauss_newton"), calib.solve("ipopt")
    for res in (gn, ip):
        assert res.converged, res.reason
        assert res.param_dict()["axis_length"] == pytest.approx(mean, abs=1e-4)
    # A 1e-5 prior weighs 1e10: the problem is stiff, so agreement is to the usual 1e-4 criterion.
    np.testing.assert_allclose(gn.params, ip.params, rtol=1e-4)
    loose = Calibration(small_demo.with_options(priors={"axis_length": Prior(mean=mean, std=10.0)}))
    assert loose.solve("gauss_newton").param_dict()["axis_length"] == pytest.approx(free, abs=1e-3)


def test_one_uncertainty_where_both_solvers_meet_the_same_optimum(small_demo: Scenario) -> None:
    """Gauss-Newton and IPOPT at one optimum share one uncertainty, within 1e-6 of the one computed
    at IPOPT's own estimate; a result elsewhere gets its own."""
    from nlp_calib.pipeline.analyse import uncertainties

    calib = Calibration.setup(small_demo)
    fit = calib.fitting
    noise = calib.stages.windows.input_noise
    results = {name: calib.solve(name) for name in ("gauss_newton", "ipopt")}
    shared = uncertainties(fit, results, noise, None)
    assert shared["ipopt"] is shared["gauss_newton"]
    own = unc.estimate(calib.evaluator, results["ipopt"].x, calib.data, noise[0], counted=noise[1])
    np.testing.assert_allclose(shared["ipopt"].std, own.std, rtol=1e-6)
    sigma = own.std[[own.names.index(n) for n in own.free]]
    moved = dataclasses.replace(results["ipopt"], x=results["ipopt"].x + 1e-3 * sigma)
    apart = uncertainties(fit, {"gauss_newton": results["gauss_newton"], "ipopt": moved}, noise, None)
    assert apart["ipopt"] is not apart["gauss_newton"]


def _moved(calib: Calibration, result: SolverResult, i: int, spread: float) -> SolverResult:
    """``result`` moved along the direction that moves free parameter ``i`` most for its length in
    the metric of H, to ``‖δ‖²_H = spread`` (tangent step; first order: δ is at rounding)."""
    ne = calib.evaluator.normal_equations(result.x)
    d = np.linalg.solve(ne.H, np.eye(ne.H.shape[0])[i])
    d *= np.sqrt(spread / (d @ ne.H @ d))
    return dataclasses.replace(result, x=result.x + np.asarray(calib.evaluator.tangent_map(result.x)) @ d)


@pytest.mark.parametrize(("tolerance", "share", "computed"), [(1e-8, 3.0, 1), (1e-14, 5.0, 2)])
def test_one_uncertainty_exactly_where_gauss_newtons_stopping_test_cannot_tell_two_estimates_apart(
    small_demo: Scenario, monkeypatch: pytest.MonkeyPatch, tolerance: float, share: float, computed: int
) -> None:
    """Two estimates each within Gauss-Newton's stopping test of one optimum (‖δ‖²_H ≤
    tolerance·cost) are at most 4·tolerance·cost apart: within that they share an uncertainty
    (though apart by more than 1e-4 of σ where the tolerance is loose), beyond it they do not
    (though within 1e-4 of σ where the tolerance is tight). Counted: the uncertainties computed."""
    from nlp_calib.pipeline.analyse import uncertainties

    scenario = small_demo.with_solver_options(
        "gauss_newton", GaussNewtonOptions(function_tolerance=tolerance)
    )
    calib = Calibration.setup(scenario)
    noise = calib.stages.windows.input_noise
    ip = calib.solve("ipopt")
    assert ip.converged, ip.reason
    own = unc.estimate(calib.evaluator, ip.x, calib.data, noise[0], counted=noise[1])
    sigma = own.std[[own.names.index(n) for n in own.free]]
    cost = calib.evaluator.normal_equations(ip.x).cost
    moved = _moved(calib, ip, 0, share * tolerance * cost)
    seen = np.max(np.abs(moved.x - ip.x) / sigma)
    # The fixed share of σ judged these the other way round.
    assert (seen > 1e-4) if computed == 1 else (seen < 1e-4), seen
    estimate = unc.estimate
    calls: list[int] = []

    def counted(*args: Any, **kwargs: Any) -> Uncertainty:
        calls.append(1)
        return estimate(*args, **kwargs)

    monkeypatch.setattr(unc, "estimate", counted)
    out = uncertainties(calib.fitting, {"ipopt": ip, "moved": moved}, noise, None)
    assert len(calls) == computed
    assert (out["moved"] is out["ipopt"]) == (computed == 1)
