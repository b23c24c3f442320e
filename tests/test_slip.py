"""The slip check: a car whose rear axle slides out of bends never gets a wrong sensor_x with a
small σ (it is said not determined), and a car that does not slide keeps its sensor_x."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from nlp_calib.analysis.drift import between_logs_std
from nlp_calib.outputs.handoff import calibration_dict, calibration_yaml
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.pipeline.check import check
from nlp_calib.pipeline.preflight import preflight
from nlp_calib.pipeline.slip_check import (
    BINS,
    MIN_BINS,
    MIN_LATERAL,
    NAME,
    T_LIMIT,
    NotMade,
    not_made,
    slopes,
    speed_bins,
)
from nlp_calib.pipeline.stored import read_calibration
from nlp_calib.results.checks import CAVEAT, FINE, CheckResult
from nlp_calib.results.run import DOUBTFUL, LIVE, Checks
from nlp_calib.results.uncertainty import Uncertainty
from nlp_calib.simulation.vehicles import HighwayOptions, RoadOptions, simulate_highway

NAMES = {"k_traction": "traction_wheels_radius", "rear_track": "traction_track_width"}
WHEELS = ("steering", "rear_left_wheel", "rear_right_wheel")


def _drive(
    tmp_path: Path, seed: int, slip: float, duration: float
) -> tuple[dict[str, Any], dict[str, float]]:
    """The highway car on a road with bends (its rear axle sliding out of them at ``slip`` rad per
    m/s²) for ``duration`` s: its dataset entry and truth."""
    road = RoadOptions(heading_change=-2.0, bend_angle=0.03, slip_gain=slip, pose_noise_time_s=5.0)
    sim = simulate_highway(HighwayOptions(duration_s=duration, seed=seed, road=road))
    joints, poses, _ = sim.write(tmp_path / f"car{seed}")
    truth = {NAMES.get(n, n): v for n, v in sim.options.truth.items()}
    encoders = dict(zip(WHEELS, WHEELS))
    return {"joints": str(joints), "poses": str(poses), "form": "speeds", "encoders": encoders}, truth


def _run(tmp_path: Path, seed: int, slip: float, lag: Any = "auto", logs: int = 1) -> tuple[Any, Any]:
    """The car of :func:`_drive` (160 s; or ``logs`` drives of 90 s from ``seed`` on, fitted
    together), the axle distance and track given: its run and truth."""
    drives = [_drive(tmp_path, seed + i, slip, 160.0 if logs == 1 else 90.0) for i in range(logs)]
    truth = drives[0][1]
    sc = {
        "model": "car_like",
        "initial_guess": "auto",
        "solvers": ["gauss_newton"],
        **({"dataset": drives[0][0]} if logs == 1 else {"datasets": [d for d, _ in drives]}),
        "alignment": {"tracker_lag": lag},
        "known": {n: truth[n] for n in ("wheelbase", "traction_track_width")},
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(scenario_from_mapping(sc, "car", tmp_path)).run()
    return run, truth


def _slip(run: Any) -> Any:
    return next(r for r in run.checks.more if r.name == NAME)


@pytest.mark.parametrize(("lag", "logs"), [("auto", 1), (0.0, 1), ("auto", 2)])
def test_a_car_sliding_out_of_bends_never_hands_off_a_wrong_sensor_x(
    tmp_path: Path, lag: Any, logs: int
) -> None:
    """One log with the lag fitted and held, and two logs fitted together (seeds 7 and 8)."""
    run, truth = _run(tmp_path, seed=7, slip=0.006, lag=lag, logs=logs)
    estimate, std = (
        run.reports["gauss_newton"].result.param_dict()["sensor_x"],
        run.std("gauss_newton")["sensor_x"],
    )
    status, why = run.handoff_status("gauss_newton")["sensor_x"]
    # Either right within its σ, or said not determined for the slip, never handed off live.
    assert abs(estimate - truth["sensor_x"]) < std or "NOT DETERMINED" in why, (estimate, std, why)
    own = run.std("gauss_newton", slip=False)["sensor_x"]  # the estimate's σ without the slip's
    assert abs(estimate - truth["sensor_x"]) > 3.0 * own  # the slip the check is for
    assert status == DOUBTFUL and "moves with the speed" in why and "known:" in why
    assert "sensor_x" in _slip(run).record["moved"]
    assert any("NOT DETERMINED" in r and "sensor_x" in r for r in run.verdict.reasons)


def test_a_slip_the_check_does_not_tell_is_in_the_sigma_every_file_states(tmp_path: Path) -> None:
    """A car sliding out of bends too little for the slope to pass the limit (seed 11, 2 mrad per
    m/s², slope 3.7σ): sensor_x, 3.7σ wrong in the σ without the slip's, lies within 2σ of the
    truth in the σ to believe, and that σ is what the verdict, calibration.yaml and its reading
    back by ``nlp-calib check`` state."""
    run, truth = _run(tmp_path, seed=11, slip=0.002)
    estimate = run.reports["gauss_newton"].result.param_dict()["sensor_x"]
    std, own = run.std("gauss_newton")["sensor_x"], run.std("gauss_newton", slip=False)["sensor_x"]
    error = abs(estimate - truth["sensor_x"])
    found = _slip(run).record
    assert "sensor_x" not in found["moved"] and abs(found["slope_in_sigma"]["sensor_x"]) < T_LIMIT
    assert error > 3.0 * own  # the class the slope misses
    status, why = run.handoff_status("gauss_newton")["sensor_x"]
    assert error <= 2.0 * std or "NOT DETERMINED" in why, (estimate, std, why)
    # The σ to believe is the estimate's with the slip's in quadrature, everywhere it is stated.
    assert std == pytest.approx(np.hypot(own, found["std_slip"]["sensor_x"]))
    assert status == DOUBTFUL and f"±{std:.2g} m" in why
    # The mount's σ (the URDF's, calibration.yaml's mount block) too: its y, calibrated, is sensor_y.
    assert "sensor_y" in found["std_slip"] and "y" in run.reports["gauss_newton"].mount.calibrated
    assert run.reports["gauss_newton"].mount.std["y"] == pytest.approx(run.std("gauss_newton")["sensor_y"])
    doc = calibration_dict(run)
    assert doc is not None and doc["std"]["sensor_x"] == pytest.approx(std)
    (tmp_path / "calibration.yaml").write_text(calibration_yaml(doc))
    stored = read_calibration(tmp_path / "calibration.yaml")
    assert stored.std["sensor_x"] == pytest.approx(std)
    # Between logs only the part that varies along the drive is widened; the slip's is not.
    # What averages over a log: the white noise, or the residuals' own errors where they exceed it.
    u, folds = run.reports["gauss_newton"].uncertainty, doc["std_blocks_folds"]
    white = float(np.fmax(u.std, u.residual_spread())[u.names.index("sensor_x")])
    shared = np.hypot(between_logs_std(own, white, folds), found["std_slip"]["sensor_x"])
    assert stored.std_shared["sensor_x"] == pytest.approx(shared, rel=1e-6)


def test_a_car_that_does_not_slide_keeps_its_sensor_x(tmp_path: Path) -> None:
    run, truth = _run(tmp_path, seed=7, slip=0.0)
    estimate, std = (
        run.reports["gauss_newton"].result.param_dict()["sensor_x"],
        run.std("gauss_newton")["sensor_x"],
    )
    assert abs(estimate - truth["sensor_x"]) < 3.0 * std
    found = _slip(run)
    assert found.level == "fine" and found.record["moved"] == []
    assert "speed" not in run.handoff_status("gauss_newton")["sensor_x"][1]
    assert run.handoff_status("gauss_newton")["sensor_theta"][0] == LIVE


def test_the_lines_over_the_speed_squared_are_weighted_least_squares() -> None:
    rng = np.random.default_rng(3)
    squared = np.linspace(8.0, 20.0, BINS) ** 2
    variance = rng.uniform(0.01, 0.2, (BINS, 2))
    fits = np.stack([1.9 - 0.004 * squared, np.full(BINS, 0.3)], axis=1) + rng.normal(0, np.sqrt(variance))
    fits[4] = np.nan  # a piece whose fit failed is left out
    drive = np.array([1.2, 0.31])  # the whole drive's fit, off the line at the lever
    lines = slopes(fits, variance, squared, drive)
    keep = np.arange(BINS) != 4
    assert np.all(lines.dof == BINS - 3)
    for i in range(2):  # numpy's weighted polynomial fit, its covariance scaled by the residuals
        w = 1.0 / np.sqrt(variance[keep, i])
        coef, cov = np.polyfit(squared[keep], fits[keep, i], 1, w=w, cov=True)
        assert lines.slope[i] == pytest.approx(coef[0]) and lines.at_zero[i] == pytest.approx(coef[1])
        assert lines.std[i] == pytest.approx(np.sqrt(cov[0, 0]))
        assert lines.std_at_zero[i] == pytest.approx(np.sqrt(cov[1, 1]))
        # The drive's lever: where the line passes the bins' information-weighed mean fit.
        lever = np.average(squared[keep], weights=1.0 / variance[keep, i])
        assert lines.lever[i] == pytest.approx(lever)
        mean = np.average(fits[keep, i], weights=1.0 / variance[keep, i])
        assert coef[1] + coef[0] * lever == pytest.approx(mean)
        # The slip's σ: the larger of the drive's fit's and the line's distance to the value at
        # zero speed, and that value's own σ.
        distance = max(abs(drive[i] - coef[1]), abs(coef[0] * lever))
        assert lines.shift()[i] == pytest.approx(np.hypot(distance, np.sqrt(cov[1, 1])))


def test_a_drive_s_fit_off_the_bins_line_is_in_the_slip_s_sigma() -> None:
    """The steering gain of a car whose axle slides: each bin, at about one speed, finds the truth
    (the slip there is a lever arm's shift), while the whole drive's fit, mixing its speeds, is off
    every bin's line. The slip's σ covers that distance; the slope's (``lever·√(b² + σ_b²)``, flat
    bins) did not."""
    rng = np.random.default_rng(11)
    squared = np.linspace(9.0, 19.0, BINS) ** 2
    variance = np.full((BINS, 1), 0.004**2)
    fits = 1.0 + rng.normal(0.0, 0.004, (BINS, 1))
    drive = np.array([0.975])  # 0.025 under the truth, as the study's slipping cars' fits are
    lines = slopes(fits, variance, squared, drive)
    assert abs(lines.slope[0]) < 3.0 * lines.std[0]  # flat: the slope tells nothing
    slope_only = abs(lines.lever[0]) * np.hypot(lines.slope[0], lines.std[0])
    assert 2.0 * slope_only < abs(drive[0] - 1.0) <= 2.0 * lines.shift()[0]


def test_the_slip_s_sigma_joins_the_sigma_to_believe_in_quadrature() -> None:
    names = ("sensor_x", "k_steer", "sensor_theta")
    white = np.array([0.3, 0.01, 0.002])
    u = Uncertainty(names, names, np.diag(white**2), white, np.eye(3), {}, 100)
    record = {"std_slip": {"sensor_x": 0.4, "k_steer": None, "sensor_theta": 0.0015}}
    checks = Checks(None, None, None, None, more=(CheckResult(NAME, "fine", "", record=record),))
    assert checks.believed(u) == pytest.approx([0.5, 0.01, 0.0025])
    assert checks.believed(u, slip=False) == pytest.approx(white)
    assert Checks(None, None, None, None).believed(u) == pytest.approx(white)  # no slip check: as before


def test_the_bins_go_by_speed_and_need_loaded_bends_at_varied_speeds() -> None:
    n = 4000
    speed = 14.0 + 6.0 * np.sin(np.linspace(0.0, 6.0, n))
    rate = 0.15 * np.sin(np.linspace(0.0, 40.0, n))
    cut = speed_bins(speed, rate)
    assert not isinstance(cut, str)
    label, squared = cut
    assert set(label) == set(range(BINS))
    for j in range(BINS - 1):  # slowest first
        assert speed[label == j].max() <= speed[label == j + 1].min()
    first = label == 0  # weighed by the squared turn rate
    assert squared[0] == pytest.approx(
        np.sum(rate[first] ** 2 * speed[first] ** 2) / np.sum(rate[first] ** 2)
    )
    standing = speed.copy()
    standing[:10] = 0.0
    stood = speed_bins(standing, rate)
    assert not isinstance(stood, str) and np.all(stood[0][:10] == -1)
    # Why a drive is not binned, said: bends that barely load the tyres, one speed, too short.
    load = np.percentile(np.abs(speed * 0.02 * rate), 90)
    assert f"bends reach {load:.2g} m/s²" in str(speed_bins(speed, 0.02 * rate))
    assert "too alike" in str(speed_bins(np.full(n, 14.0), rate))
    assert f"{4 * BINS - 1} timed moving" in str(speed_bins(speed[: 4 * BINS - 1], rate[: 4 * BINS - 1]))
    assert MIN_BINS < BINS


def test_a_check_not_made_says_why_and_is_a_caveat_where_the_bends_load_the_tyres() -> None:
    calm = not_made(NotMade("its bends reach 0.2 m/s²", 0.2))
    assert calm.level == FINE and calm.words == "not made: its bends reach 0.2 m/s²"
    assert calm.record == {"made": False, "why": "its bends reach 0.2 m/s²", "lateral_mps2": 0.2}
    for load, said in ((2.5, "bends reaching 2.5 m/s²"), (float("nan"), "slip in its bends")):
        loaded = not_made(NotMade("too few windows", load))
        assert loaded.level == CAVEAT and said in loaded.caveat and "too few windows" in loaded.caveat
        assert "nan" not in loaded.caveat


#: A small car on a circuit (an F1/10's size): 1 to 5 m/s, braking and accelerating every 3 to 10 s,
#: bends loading its tyres to several m/s², records at 18.4 Hz and poses at 19.6 Hz.
CIRCUIT_TRUTH = {
    "wheelbase": 0.32,
    "rear_track": 0.25,
    "sensor_x": 0.2,
    "sensor_y": 0.0,
    "sensor_theta": 0.01,
    "k_traction": 0.05,
    "steer_offset": -0.006,
}


def _circuit_scenario(tmp_path: Path, seed: int, slip: float) -> Any:
    """The circuit car's 60 s drive in half-second windows (as ``init`` drafts them), the axle
    distance and track given."""
    road = RoadOptions(heading_change=12.0, bend_angle=0.15, slip_gain=slip, speed_periods_s=(3.0, 10.0))
    opts = HighwayOptions(
        duration_s=60.0,
        seed=seed,
        road=road,
        min_speed=1.0,
        max_speed=5.0,
        steer_max=0.05,
        wheel_rate_hz=18.4,
        pose_rate_hz=19.6,
        pose_noise=(0.01, 0.005),
        truth=CIRCUIT_TRUTH,
    )
    joints, poses, _ = simulate_highway(opts).write(tmp_path / f"circuit{seed}_{slip:g}")
    sc = {
        "model": "car_like",
        "initial_guess": "auto",
        "solvers": ["gauss_newton"],
        "dataset": {
            "joints": str(joints),
            "poses": str(poses),
            "form": "speeds",
            "encoders": dict(zip(WHEELS, WHEELS)),
        },
        "residual": {"horizon_s": 0.5},
        "known": {"wheelbase": 0.32, "traction_track_width": 0.25},
    }
    return scenario_from_mapping(sc, "circuit", tmp_path)


def _circuit(tmp_path: Path, seed: int, slip: float) -> tuple[Any, float]:
    """The circuit car's run and sensor_x's truth."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Calibration(_circuit_scenario(tmp_path, seed, slip)).run(), CIRCUIT_TRUTH["sensor_x"]


def test_a_check_on_a_drive_whose_slip_leaves_parameters_open_says_to_drive_bends_slowly(
    tmp_path: Path,
) -> None:
    """The circuit car calibrated on a drive without slip, checked on one whose tyres slide (8 mrad
    per m/s²): what the check cannot test is what the slip leaves open, and its advice is slow bends,
    not more turning (the drive turns plenty)."""
    calm, _ = _circuit(tmp_path, 24, 0.0)
    doc = calibration_dict(calm)
    assert doc is not None
    (tmp_path / "calibration.yaml").write_text(calibration_yaml(doc))
    stored = read_calibration(tmp_path / "calibration.yaml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        checked = check(stored, _circuit_scenario(tmp_path / "slid", 25, 0.008))
    drift = checked.checks.drift
    assert drift is not None and drift.verdict == "cannot tell", drift.reasons
    assert "drive bends slowly" in drift.hint and "sensor_x" in drift.hint, drift.hint
    assert "more turning" not in drift.hint


def test_the_pre_flight_says_its_sigma_hold_for_tyres_that_do_not_slide(tmp_path: Path) -> None:
    """Where the bends load the tyres (the circuit car), the pre-flight names the slip the run will
    judge, with the lateral acceleration the run's check would state; on the highway car's
    straight road (bends under 1 m/s²) it says nothing of it."""
    circuit = preflight(_circuit_scenario(tmp_path, 23, 0.0))
    said = circuit.check(NAME)
    assert said is not None and said.level == CAVEAT and "σ below hold for tyres that do not" in said.words
    assert said.record["lateral_mps2"] >= MIN_LATERAL and circuit.verdict != "check data"
    road = RoadOptions(heading_change=-2.0)
    joints, poses, _ = simulate_highway(HighwayOptions(duration_s=60.0, seed=23, road=road)).write(
        tmp_path / "hw"
    )
    encoders = dict(zip(WHEELS, WHEELS))
    sc = {
        "model": "car_like",
        "dataset": {"joints": str(joints), "poses": str(poses), "form": "speeds", "encoders": encoders},
        "known": {"wheelbase": 2.8, "traction_track_width": 1.6},
    }
    assert preflight(scenario_from_mapping(sc, "highway", tmp_path)).check(NAME) is None


@pytest.mark.parametrize("seed", [21, 22])
def test_windows_of_several_records_are_binned_by_their_own_speed(tmp_path: Path, seed: int) -> None:
    """Half-second windows on a car whose speed keeps changing lie in no one bin of speed record by
    record: binned by their own mean speed, the check is made. Sliding out of its bends (8 mrad per
    m/s²), the car's sensor_x, many of its own σ wrong, is said NOT DETERMINED and never handed off
    live; the same drive without the slide keeps sensor_x, right within its σ."""
    run, truth = _circuit(tmp_path, seed, 0.008)
    found = _slip(run)
    estimate = run.reports["gauss_newton"].result.param_dict()["sensor_x"]
    assert found.record["made"] and "sensor_x" in found.record["moved"], found.words
    assert abs(estimate - truth) > 3.0 * run.std("gauss_newton", slip=False)["sensor_x"]
    status, why = run.handoff_status("gauss_newton")["sensor_x"]
    assert status == DOUBTFUL and "moves with the speed" in why
    calm, truth = _circuit(tmp_path, seed, 0.0)
    estimate = calm.reports["gauss_newton"].result.param_dict()["sensor_x"]
    assert _slip(calm).level == FINE and _slip(calm).record["moved"] == []
    assert abs(estimate - truth) < 3.0 * calm.std("gauss_newton")["sensor_x"]
    assert calm.handoff_status("gauss_newton")["sensor_x"][0] == LIVE
