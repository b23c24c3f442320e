"""Real vehicles' drives (issue #43), simulated: a skid-steer spinning more than π per increment,
its encoders updating at 4 Hz and slipping on pivots, against a scan matcher's increments."""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import SHARED_DATA, cli, highway_dataset, run_fitting_the_lag
from odometry_truth import sigma_over_truth

from nlp_calib.analysis.precision import HEADING_BUDGET
from nlp_calib.analysis.verdict import verdict
from nlp_calib.core.errors import DatasetError, OptionsError
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.models import MODELS
from nlp_calib.models.car_like import HIGHWAY_TRUTH
from nlp_calib.outputs.preflight import preflight_lines
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.pipeline.analyse import Wanted
from nlp_calib.pipeline.preflight import preflight
from nlp_calib.results.checks import NominalCheck
from nlp_calib.results.layout import HELD, KNOWN
from nlp_calib.results.preflight import NOT_DETERMINED, NOT_ENOUGH, WEAK_DRIVE
from nlp_calib.results.run import CAVEATS, GOOD, UNDETERMINED
from nlp_calib.simulation.vehicles import (
    EPOCH_NS,
    FINE_S,
    HighwayOptions,
    RoadOptions,
    SkidSpinOptions,
    simulate_highway,
    simulate_skid_spins,
)

JOINT_NAMES = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}
SKID = {
    "model": "skid_steer",
    "initial_guess": "auto",
    "information": {"translation": 4.0e4, "rotation": 1.0e5},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}


def _skid_run(tmp_path: Path, seed: int, pivot_slip: float = 0.1) -> tuple[Any, SkidSpinOptions, Any, Any]:
    opts = SkidSpinOptions(duration_s=240.0, seed=seed, pivot_slip=pivot_slip)
    sim = simulate_skid_spins(opts)
    joints, motions, _ = sim.write(tmp_path / "skid")
    dataset = {
        "joints": str(joints),
        "motions": str(motions),
        "encoders": {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"},
    }
    sc = scenario_from_mapping({**SKID, "dataset": dataset}, "skid", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        calib = Calibration(sc)
        run = calib.run(wanted=Wanted(odometry="gauss_newton"))
    return run, opts, sim, calib


#: A skid-steer's run, its options, drive and calibration, as :func:`_skid_run` returns them.
SkidRun = tuple[Any, SkidSpinOptions, Any, Any]


@pytest.fixture(scope="module")
def skid_runs(tmp_path_factory: pytest.TempPathFactory) -> Callable[[int, float], SkidRun]:
    """:func:`_skid_run` of each (seed, pivot slip), made once for the tests that read the same
    drive's run (none changes it)."""
    made: dict[tuple[int, float], SkidRun] = {}

    def get(seed: int, pivot_slip: float) -> SkidRun:
        if (seed, pivot_slip) not in made:
            made[seed, pivot_slip] = _skid_run(tmp_path_factory.mktemp("skid"), seed, pivot_slip)
        return made[seed, pivot_slip]

    return get


def test_the_skid_steer_simulator_spins_past_pi_and_checks_its_options() -> None:
    sim = simulate_skid_spins(SkidSpinOptions(duration_s=120.0, seed=3))
    t = sim.joint_time_s
    heading = np.interp(sim.motion_stamps_s, t, np.unwrap(sim.base_poses[:, 2]))
    turned = np.abs(heading[:, 1] - heading[:, 0])
    assert np.sum(turned > np.pi) >= 5  # increments a matcher reports wrapped
    assert np.all(np.abs(sim.motions[:, 2]) <= np.pi)
    # 4 Hz updates under 20 Hz messages: each position repeats about five times.
    repeats = np.mean(np.all(np.diff(sim.joint_positions, axis=0) == 0.0, axis=1))
    assert 0.7 < repeats < 0.9
    with pytest.raises(OptionsError, match="encoder_update_hz"):
        SkidSpinOptions(encoder_update_hz=0.0)
    with pytest.raises(OptionsError, match="unknown parameter"):
        SkidSpinOptions(truth={"wheelbase": 1.0})
    with pytest.raises(OptionsError, match="turn_slip"):
        SkidSpinOptions(spin_rate=5.0, truth={"turn_slip": 0.5})


@pytest.mark.parametrize(
    ("seed", "pivot_slip"),
    [
        (1, 0.1),
        (2, 0.0),
        # Slip of either sign on pivots, one draw per pivot: the pivots the wheels agree with are
        # those of one sign (turn_slip 0.081 against 0.05), 6 of the block σ; each pivot fitted on
        # its own, the slipped ones among them, gives the σ that covers it.
        (2, 0.1),
    ],
)
def test_a_skid_steer_spinning_past_pi_ends_right_with_covariances_its_windows_show(
    skid_runs: Callable[[int, float], SkidRun], seed: int, pivot_slip: float
) -> None:
    run, opts, sim, calib = skid_runs(seed, pivot_slip)
    # The truth in the joint form's names (the counts form's k_left is a radius in m per rad here).
    truth = {JOINT_NAMES.get(n, n): v for n, v in opts.truth.items()}
    # The start survived the wrapped increments: positive radii near the truth, no mirror image.
    for n in ("left_wheel_radius", "right_wheel_radius"):
        assert run.initial[n] == pytest.approx(truth[n], rel=0.2)
    level = run.verdict.level
    assert level in (GOOD, CAVEATS, UNDETERMINED), run.verdict
    if level != UNDETERMINED:
        estimate, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
        for n, v in truth.items():
            assert abs(estimate[n] - v) < 4.0 * std[n], n
    # The slipped pivots are said as such (a slow encoder's stale pivots may be too).
    kinds = {f.kind for f in run.checks.findings.report.faults}
    assert "pivot_slip" in kinds or pivot_slip == 0.0
    # The odometry's heading variance grows per interval by what the good windows' errors show.
    odo = run.odometry
    assert odo is not None and odo.coverage is not None and 0.85 <= odo.coverage <= 1.0
    bad = np.zeros(odo.time_s.size - 1, dtype=bool)
    for f in run.checks.findings.report.faults:
        bad[f.first : f.last + 1] = True
    ref, track = odo.reference, odo.T_world_base
    error = wrap_angle(np.diff(ref[:, 2]) - np.diff(track[:, 2]))[~bad]
    grown = np.diff(odo.covariance[:, 2, 2])[~bad]
    ratio = np.sqrt(np.mean(error**2) / np.mean(grown))
    assert 0.5 < ratio < 2.0, ratio
    # Against the true base: the rates per metre and per radian grown as a filter grows them within
    # a factor 2 of the σ whose 2σ holds 95 % of the true errors over the fit's windows (x, y and θ
    # together); every covariance handed off (those rates, ros2_control.yaml's pose diagonal over a
    # metre and twist diagonal over an interval) each component (along, across, heading) never
    # under, and over only where the rates say the segments bound it (the wheels' drift under the
    # matcher's 5 mm, a 4 Hz encoder showing no noise of its own).
    # Over the metres no fault spoils, not every metre: the slipped pivots are stated apart (the
    # rates' slip_per_radian), and over a coarse arc the track here is the model's one arc per
    # 2 s interval, not the odometry a controller integrates at the joints' rate.
    found = sigma_over_truth(calib, run, (sim.joint_time_s, sim.base_poses, EPOCH_NS))
    assert {way for way, _ in found} == {"rates", "pose", "twist"}
    for way, ratios in found.items():
        print(way, ratios, odo.rates.bounded if odo.rates else None)
        assert ratios[-1] >= 0.5, (way, ratios)
        _within_two_unless_bounded(ratios, odo.rates)
    assert found[("rates", 1)][-1] <= 2.0, found
    # ros2_control.yaml's pose diagonal over the metres no fault touches holds their drift along,
    # across and together, bounded or not: not the slipped pivots' (their metres left out of its
    # average), nor a pivot's heading rate given to every arc (11.6x along on seed 2 with slip).
    pose = found[("pose", 0)]
    assert np.all(pose[[0, 1, 3]] <= 2.0), pose


def test_a_skid_steers_handed_off_diagonals_are_within_two_of_its_drift_bounded_or_not(
    tmp_path: Path,
) -> None:
    """Seed 5 (chosen before its result was seen), pivots slipping up to ±10 %: ros2_control.yaml's
    pose diagonal (x, y, θ) over the metres no fault touches and its twist diagonal (vx, wz) over
    the moving intervals are each within a factor 2 of the σ whose 2σ holds 95 % of the true
    errors, bounded components too: one diagonal for pivots and arcs is the variance holding 95 %
    of them (their mean gave seed 4405's wz 5.67x), held under the drift its spans show (a rate
    bounded under the matcher's noise gave the pose's θ 3.9x)."""
    run, _, sim, calib = _skid_run(tmp_path, 5, 0.1)
    found = sigma_over_truth(calib, run, (sim.joint_time_s, sim.base_poses, EPOCH_NS))
    pose, twist = found[("pose", 0)], found[("twist", 1)]
    stated = np.r_[pose[:3], twist[[0, 2]]]
    assert np.all((0.5 <= stated) & (stated <= 2.0)), (pose, twist)


def _reversals(sim: Any) -> int:
    """How many of the drive's 2 s records the true base drives more than twice its net motion in
    (and over 10 cm): it reverses, or swings its turn, inside one record."""
    count = 0
    for t0, t1 in sim.motion_stamps_s:
        inside = (sim.joint_time_s >= t0) & (sim.joint_time_s <= t1)
        xy = sim.base_poses[inside, :2]
        path = float(np.sum(np.hypot(*np.diff(xy, axis=0).T))) if xy.shape[0] > 1 else 0.0
        count += int(path > max(2.0 * float(np.hypot(*(xy[-1] - xy[0]))), 0.1)) if xy.size else 0
    return count


@pytest.mark.parametrize(("seed", "pivot_slip"), [(9606, 0.1), (7, 0.0)])
def test_a_skid_steer_reversing_inside_its_records_is_covered_across(
    skid_runs: Callable[[int, float], SkidRun], seed: int, pivot_slip: float
) -> None:
    """A skid-steer that reverses inside some 2 s records (seed 9606 of #43, and seed 7 without
    slip, the first tried): the model integrates one arc on each record's net wheel motion, which
    such a record is not (56 mm across in 18 cm net, at 10x the σ the rates gave it: 0.43 and 0.39
    of the across drift the fit's windows truly have). That error is the model's, known where the
    joints have samples of their own: beside the rates, nlp-calib odometry's covariance over the
    fit's windows holds their across drift within a factor 2 (over only where the rates say the
    segments bound it)."""
    run, _, sim, calib = skid_runs(seed, pivot_slip)
    assert _reversals(sim) >= 2
    found = sigma_over_truth(calib, run, (sim.joint_time_s, sim.base_poses, EPOCH_NS))
    rates = found[("rates", 1)]
    assert rates[1] >= 0.5, rates
    assert rates[1] <= 2.0 or "across" in run.odometry.rates.bounded, rates
    _within_two_unless_bounded(rates, run.odometry.rates)


def test_a_skid_steer_whose_screen_fit_runs_out_of_steps_at_its_optimum_is_still_screened(
    skid_runs: Callable[[int, float], SkidRun],
) -> None:
    """Seed 9404 of #43 (never tuned on), its pivots slipping over 57 % of the drive (one of 96 rad):
    the screen's fit needs 235 Gauss-Newton steps to the solver's 1e-14, its 200th the same cost to
    12 digits. Read as not converged, the screen judged nothing: no slipped pivot was left out of the
    fit or stated apart, and ros2_control.yaml's pose diagonal (heading 0.47) and the filter's
    covariance with the slipped pivots' rate (along 0.40, across 0.43) fell under half the drift its
    metres truly have."""
    run, _, sim, calib = skid_runs(9404, 0.1)
    report = run.checks.findings.report
    assert not report.unchecked, report.unchecked
    assert any(f.kind == "pivot_slip" for f in report.faults)
    assert run.odometry.rates.slipped > 0
    truth = (sim.joint_time_s, sim.base_poses, EPOCH_NS)
    found = sigma_over_truth(calib, run, truth, every_metre=True)
    for way in (("pose", 0), ("pivots_all", 0), ("rates", 1)):
        assert np.all(found[way] >= 0.5), (way, found[way])


def test_a_skid_steers_turn_law_takes_the_scatter_of_its_pivots_each_fitted_on_its_own(
    skid_runs: Callable[[int, float], SkidRun],
) -> None:
    """Seed 2, pivots slipping up to ±10 %: every pivot the simulator drove is one draw, the slipped
    ones the fit left out among them, and the σ of what the pivots determine is their scatter about
    the estimate (the block σ alone put turn_slip 6σ off its truth)."""
    from nlp_calib.analysis.pivots import pivots_std

    run, opts, sim, _ = skid_runs(2, 0.1)
    pivots = run.checks.pivots
    assert pivots is not None
    names = list(pivots.names)
    # The simulator's pivots, each a run of the increments its slip spoiled: all found, none merged
    # (but one whose increments all start or stop a pivot, left out as coarse arcs).
    drawn = int(np.sum(np.diff(np.concatenate([[0], sim.slipped.astype(int)])) == 1))
    assert drawn - 1 <= len(pivots.pivots) <= drawn
    # Each pivot's own turn law scatters by the slip's share, both ways about the truth.
    own = pivots.params[:, names.index("turn_slip")]
    assert own.min() < opts.truth["turn_slip"] < own.max()
    estimate = run.reports["gauss_newton"].result.param_dict()
    centre = np.array([estimate[n] for n in names])
    mean, scatter = pivots.params.mean(axis=0), pivots.params.std(axis=0, ddof=1)
    expected = np.sqrt(scatter**2 / own.size + (centre - mean) ** 2)
    assert np.allclose(pivots.std, expected, equal_nan=True)
    assert np.allclose(pivots_std(pivots.params, centre), expected, equal_nan=True)
    white = run.reports["gauss_newton"].uncertainty.std_dict()
    std = run.std("gauss_newton")
    assert std["turn_slip"] == pytest.approx(pivots.std[names.index("turn_slip")])
    assert std["turn_slip"] > 5.0 * white["turn_slip"]
    assert abs(estimate["turn_slip"] - opts.truth["turn_slip"]) < 3.0 * std["turn_slip"]
    # What the pivots hardly move keeps its own σ (the wheels' radii: the straight runs').
    assert std["left_wheel_radius"] == pytest.approx(white["left_wheel_radius"])


@pytest.mark.parametrize("mounts", ["shared", "per_log"])
def test_skid_steers_fitted_together_take_the_scatter_of_every_logs_pivots(
    tmp_path: Path, mounts: str
) -> None:
    """Two drives (seeds 91 and 92, chosen before their result was seen), pivots slipping up to
    ±10 %, fitted together: every pivot of both logs is one draw, the slipped ones the fit left out
    among them, each refit keeping both logs' windows off the pivots; the joint σ of what the
    pivots determine is their scatter about the joint estimate (a joint fit had none), and of a
    log's own parameters (its clock; its mount too, one per log) its own pivots' scatter."""
    from nlp_calib.pipeline.calibration import log_ranges

    entries, drawn = [], []
    for seed in (91, 92):
        sim = simulate_skid_spins(SkidSpinOptions(duration_s=240.0, seed=seed, pivot_slip=0.1))
        joints, motions, _ = sim.write(tmp_path / f"skid{seed}")
        encoders = {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
        entries.append({"joints": str(joints), "motions": str(motions), "encoders": encoders})
        drawn.append(int(np.sum(np.diff(np.concatenate([[0], sim.slipped.astype(int)])) == 1)))
    sc = scenario_from_mapping({**SKID, "datasets": entries, "sensor": {"mounts": mounts}}, "joint", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        calib = Calibration(sc)
        run = calib.run()
    pivots = run.checks.pivots
    assert pivots is not None
    names = list(pivots.names)
    # Each pivot lies inside one log's records (the joint numbering), and each log's are the
    # simulated pivots give or take one at their edges (a pivot whose increments all start or stop
    # it, or a stretch of turning on the spot the slip spared: seed 91 alone finds 15 of 14).
    ranges = log_ranges(calib.parts)
    found = [sum(a <= first and stop <= b for first, stop in pivots.pivots) for a, b in ranges]
    assert sum(found) == len(pivots.pivots)
    assert all(abs(f - n) <= 1 for f, n in zip(found, drawn))
    truth = SkidSpinOptions().truth["turn_slip"]
    own = pivots.params[:, names.index("turn_slip")]
    assert own.min() < truth < own.max()
    estimate = run.reports["gauss_newton"].result.param_dict()
    centre = np.array([estimate[n] for n in names])
    # What the logs share takes every pivot's scatter; a log's own parameter (its clock) its own
    # pivots' only (another log's pivot leaves it where the off-pivot windows put it).
    owner = {p.name: p.log for p in calib.fitting.fns.layout.parameters if p.log is not None}
    assert owner, "each log has its own clock"
    in_log = np.array([next(i for i, (a, b) in enumerate(ranges) if a <= f < b) for f, _ in pivots.pivots])
    for j, name in enumerate(names):
        rows = pivots.params[in_log == owner[name], j] if name in owner else pivots.params[:, j]
        expected = np.sqrt(rows.var(ddof=1) / rows.size + (centre[j] - rows.mean()) ** 2)
        assert pivots.std[j] == pytest.approx(expected, rel=1e-9), name
    white = run.reports["gauss_newton"].uncertainty.std_dict()
    std = run.std("gauss_newton")
    assert std["turn_slip"] >= pivots.std[names.index("turn_slip")]
    assert std["turn_slip"] > 3.0 * white["turn_slip"]
    assert abs(estimate["turn_slip"] - truth) < 3.0 * std["turn_slip"]


def test_a_pivot_is_a_run_of_turns_on_the_spot_and_a_window_across_two_joins_them() -> None:
    from nlp_calib.analysis.pivots import pivot_intervals, pivot_windows, pivots_std

    steps = np.array(
        [
            [0.5, 0.0, 0.1],  # an arc: 5 m per radian
            [0.01, 0.0, 0.8],  # pivots
            [0.0, 0.02, -0.9],
            [0.3, 0.0, 0.0],  # straight
            [0.1, 0.0, 0.3],  # a tight turn: 0.33 m per radian
            [0.0, 0.0, 0.0],  # standing
            [0.0, 0.0, 0.0],
            [0.02, 0.0, 1.0],
            [0.02, 0.0, 1.0],
            [1.0, 0.0, 0.1],
        ]
    )
    pivot = pivot_intervals(steps)
    assert pivot.tolist() == [False, True, True, False, True, False, False, True, True, False]
    # One window per interval: three pivots, numbered as driven.
    one = pivot_windows(pivot, np.arange(10), np.arange(10) + 1)
    assert one.tolist() == [-1, 0, 0, -1, 1, -1, -1, 2, 2, -1]
    # A window over intervals 2 to 4 shares the first two pivots' draws: they are one.
    joined = pivot_windows(pivot, np.array([0, 2, 5, 8]), np.array([2, 5, 8, 10]))
    assert joined.tolist() == [0, 0, 1, 1]
    # ... and one across the second and third then joins all three, in whatever order windows come.
    chain = pivot_windows(pivot, np.array([7, 4, 2, 0]), np.array([9, 8, 5, 1]))
    assert chain.tolist() == [0, 0, 0, -1]
    apart = pivot_windows(pivot, np.array([7, 4, 1, 0]), np.array([9, 8, 3, 1]))
    assert apart.tolist() == [1, 1, 0, -1]
    params = np.array([[1.0, 2.0], [3.0, 2.0], [2.0, 2.0], [6.0, 2.0]])
    # Their mean 3 with a variance of (4 + 0 + 1 + 9) / 3 over 4 pivots, the estimate 2 off it by
    # 1; no scatter in the second, the estimate on it.
    assert np.allclose(pivots_std(params, np.array([2.0, 2.0])), [np.sqrt(14.0 / 12.0 + 1.0), 0.0])
    assert np.all(np.isnan(pivots_std(params[:1], np.array([2.0, 2.0]))))


def _within_two_unless_bounded(ratios: np.ndarray, rates: Any) -> None:
    """Each component's σ over the one whose 2σ holds 95 % of the true errors: at least 0.5, at
    most 2 unless the rates say the segments only bound that component."""
    for c, axis in enumerate(("along", "across", "heading")):
        if np.isnan(ratios[c]):  # what the file does not state (the twist's lateral velocity)
            continue
        assert ratios[c] >= 0.5, (axis, ratios)
        assert ratios[c] <= 2.0 or axis in rates.bounded, (axis, ratios, rates)


@pytest.mark.parametrize("seed", [91, 92])
def test_a_slip_free_skid_steer_at_4_hz_is_never_said_to_slip(tmp_path: Path, seed: int) -> None:
    """No slip simulated, the encoders updating at 4 Hz under 20 Hz messages: no increment is
    called slip or a bad match (a held reading is filled in between updates; an increment is judged
    against the wheels over their own samples, beyond what their readings can move it). Those the
    model's one arc per 2 s interval cannot follow (a pivot's start) are said as such, and their
    windows and drift left out."""
    run, _, _, _ = _skid_run(tmp_path, seed, 0.0)
    report = run.checks.findings.report
    assert not report.unchecked, report.unchecked
    faults = report.faults
    assert not [f.evidence for f in faults if f.kind in ("pivot_slip", "bad_match")]
    arcs = [f for f in faults if f.kind == "coarse_arc"]
    assert arcs and all("one arc per interval" in f.evidence for f in arcs)
    assert run.odometry is not None and run.odometry.rates is not None
    assert run.odometry.rates.slipped == 0


def test_a_slow_drivers_held_readings_are_filled_in_between_its_updates() -> None:
    """A 4 Hz driver under 20 Hz messages repeats its last reading: the stream is read between its
    updates (up to 0.25 s late otherwise), and a hold of a joint that stood still is kept flat."""
    from nlp_calib.logs.bag_joints import fresh_positions

    t = np.arange(0.0, 6.0, 0.05)
    updated = np.floor(t * 4.0) / 4.0
    angle = np.where(updated < 3.0, 2.0 * updated, 6.0)  # drives 3 s at 2 rad/s, then stands still
    held = angle[:, None]
    filled, fresh = fresh_positions(t, held)
    assert fresh[:, 0].sum() == 12 + 1  # the 12 updates while driving, and the first message
    moving = t < 2.9
    # Each update's first message carries the angle at its update (here on a message's stamp): the
    # filled stream is the straight run through them, the drive itself; the staircase 0.4 rad off.
    truth = 2.0 * t
    assert np.max(np.abs(filled[moving, 0] - truth[moving])) < 1e-9
    assert np.max(np.abs(held[moving, 0] - truth[moving])) > 0.35
    # Standing still from 3 s: flat from its last update on, not a ramp to the log's end.
    assert np.all(filled[t >= 3.0, 0] == 6.0)
    # A reading of its own in most messages (a fine encoder, resting now and then): as published.
    fine = np.round(np.sin(t) / 0.01)[:, None] * 0.01
    assert np.array_equal(fresh_positions(t, fine)[0], fine)
    # A wheel with a reading of its own in every message beside a steering joint held on a circle,
    # one step of its resolution now and then (a real tricycle's): the steering's rare changes say
    # nothing of its driver, and a ramp between them would be a steering that never was.
    toggled = -0.1571 - 0.00785 * ((t >= 1.0) & (t < 1.5) | (t >= 3.0) & (t < 4.2))
    both = np.c_[2.0 * t, toggled]
    assert np.array_equal(fresh_positions(t, both)[0], both)


def test_a_skid_steer_whose_pivots_slipped_is_never_called_good(
    skid_runs: Callable[[int, float], SkidRun],
) -> None:
    """The slip too small to find biases what the pivots determine beyond its σ (the xfail above):
    the verdict says so; the slipped pivots' heading drift is stated apart from the rates."""
    run, _, _, _ = skid_runs(2, 0.1)
    rates = run.odometry.rates if run.odometry is not None else None
    assert rates is not None and rates.slipped > 0 and rates.slip_per_radian > 0
    assert "pivots the ground slipped on" in rates.words()
    assert run.verdict.level != GOOD
    said = [r for r in run.verdict.reasons if "pivots the ground slipped on were left out" in r]
    # The rule that keeps or leaves out a pivot, stated with it (the summary prints the verdict).
    assert said and "under 0.5 m of travel per radian turned" in said[0] and "5× the increments'" in said[0]


@pytest.mark.parametrize(
    ("vehicle", "flags", "options", "simulator"),
    [
        (
            "skid_spins",
            ("--seed", "3", "--duration", "20", "--noise-theta", "0.004"),
            SkidSpinOptions(duration_s=20.0, seed=3, motion_noise_theta=0.004),
            simulate_skid_spins,
        ),
        (
            "highway_car",
            ("--seed", "31", "--duration", "10"),
            HighwayOptions(duration_s=10.0, seed=31),
            simulate_highway,
        ),
    ],
)
def test_the_command_line_writes_a_vehicles_drive_as_the_simulator_does(
    tmp_path: Path, vehicle: str, flags: tuple[str, ...], options: Any, simulator: Any
) -> None:
    """``simulate --vehicle``: the joints, the reference and the truth the tests and the benchmark
    calibrate, byte for byte, and how a scenario reads them; what does not apply is refused."""
    config = tmp_path / "vehicle.yaml"
    config.write_text("pivot_slip: 0.05\n" if vehicle == "skid_spins" else "pose_noise: [0.03, 0.001]\n")
    proc = cli(
        "simulate", "--vehicle", vehicle, "--out", str(tmp_path / "drive"), "--config", str(config), *flags
    )
    assert proc.returncode == 0, proc.stderr
    given = {"pivot_slip": 0.05} if vehicle == "skid_spins" else {"pose_noise": (0.03, 0.001)}
    expected = simulator(dataclasses.replace(options, **given))
    joints, reference, truth = (
        tmp_path / f"drive{s}"
        for s in (".csv", ".motions.csv" if vehicle == "skid_spins" else ".tum", ".truth.json")
    )
    assert joints.read_text() == expected.joints_csv()
    assert reference.read_text() == (
        expected.motions_csv() if vehicle == "skid_spins" else expected.poses_tum()
    )
    assert truth.is_file() and "a scenario reads it as: dataset: {joints:" in proc.stdout
    refused = cli("simulate", "--vehicle", vehicle, "--out", str(tmp_path / "again"), "--records", "20")
    assert refused.returncode == 2 and "records: does not apply to a " + vehicle in refused.stderr


# --- a car on a highway ------------------------------------------------------------------------

#: The highway car's truth in the joint form's names (k_traction: the wheels' radius in m per rad).
CAR_NAMES = {"k_traction": "traction_wheels_radius", "rear_track": "traction_track_width"}
#: What a straight kilometre cannot determine, given as measured.
CAR_KNOWN = ("k_steer", "wheelbase", "rear_track", "sensor_x", "sensor_y")


def _car_scenario(
    tmp_path: Path,
    seed: int,
    known: tuple[str, ...] = (),
    truth: dict[str, float] | None = None,
    residual: dict[str, Any] | None = None,
) -> tuple[Any, HighwayOptions]:
    opts = HighwayOptions(seed=seed, truth=truth or {})
    joints, poses, _ = simulate_highway(opts).write(tmp_path / "car")
    truth = {CAR_NAMES.get(n, n): v for n, v in opts.truth.items()}
    wheels = ("steering", "rear_left_wheel", "rear_right_wheel")
    sc = {
        "model": "car_like",
        "initial_guess": "auto",
        "solvers": ["gauss_newton"],
        "dataset": {
            "joints": str(joints),
            "poses": str(poses),
            "form": "speeds",
            "encoders": dict(zip(wheels, wheels)),
        },
        "known": {CAR_NAMES.get(n, n): truth[CAR_NAMES.get(n, n)] for n in known},
        **({"residual": residual} if residual else {}),
    }
    return scenario_from_mapping(sc, "car", tmp_path), opts


@pytest.fixture(scope="module")
def car_known(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, HighwayOptions, Any, Any]:
    """The highway car of seed 1 given what it cannot determine (``CAR_KNOWN``), and its run: one
    calibration that several tests read."""
    sc, opts = _car_scenario(tmp_path_factory.mktemp("car_known"), 1, CAR_KNOWN)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        calib = Calibration(sc)
        run = calib.run()
    return sc, opts, run, calib


def test_the_highway_simulator_drives_a_kilometre_barely_steering_and_checks_its_options() -> None:
    sim = simulate_highway(HighwayOptions(seed=4))
    truth = sim.truth_dict()
    assert 700.0 < truth["distance_m"] < 1300.0
    speed = np.mean(sim.joint_values[:, :2], axis=1) * sim.options.truth["k_traction"]
    assert 7.5 < np.min(speed) and np.max(speed) < 20.5
    heading = np.unwrap(sim.base_poses[:, 2])
    assert abs(np.degrees(heading[-1] - heading[0]) - 1.0) < 0.2
    assert np.max(np.abs(sim.joint_values[:, -1])) < np.radians(0.35)  # the steering joint (gain 1)
    assert sim.joint_values.shape[1] == 5 and 1.0 / np.median(np.diff(sim.joint_time_s)) == pytest.approx(
        90.0
    )
    assert 1.0 / np.median(np.diff(sim.pose_time_s)) == pytest.approx(20.0)
    with pytest.raises(OptionsError, match="min_speed"):
        HighwayOptions(min_speed=25.0)
    with pytest.raises(OptionsError, match="unknown parameter"):
        HighwayOptions(truth={"turn_slip": 0.1})
    with pytest.raises(OptionsError, match="steer_max"):
        HighwayOptions(steer_max=1.0)


def test_a_highway_car_is_refused_what_a_straight_kilometre_cannot_determine(tmp_path: Path) -> None:
    sc, _ = _car_scenario(tmp_path, seed=1)
    report = preflight(sc)
    assert report.verdict == NOT_ENOUGH
    refused = set(report.named(NOT_DETERMINED))
    assert {"k_steer", "wheelbase", "sensor_x", "sensor_y"} <= refused
    assert "traction_track_width" in refused  # held: no turn is tight enough
    # Run anyway: NOT DETERMINED, and nothing handed off.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    assert run.verdict.level == UNDETERMINED
    assert run.handoff_solver() is None


@pytest.mark.parametrize("seed", [1, 2])
def test_a_highway_car_given_what_it_cannot_determine_finds_its_wheel_scale_and_yaw(
    tmp_path: Path, seed: int, request: pytest.FixtureRequest
) -> None:
    if seed == 1:
        sc, opts, run, _ = request.getfixturevalue("car_known")
    else:
        sc, opts = _car_scenario(tmp_path, seed, CAR_KNOWN)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = Calibration(sc).run()
    estimate, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    truth = {CAR_NAMES.get(n, n): v for n, v in opts.truth.items()}
    assert run.verdict.level in (GOOD, CAVEATS), run.verdict
    for name in ("traction_wheels_radius", "sensor_theta", "steer_offset"):
        assert abs(estimate[name] - truth[name]) < 3.0 * std[name], (name, estimate[name], std[name])
    # Known under known:, never calibrated.
    for name in ("k_steer", "wheelbase", "traction_track_width", "sensor_x", "sensor_y"):
        assert estimate[name] == truth[name]
        assert run.scenario.layout.param(name).status == KNOWN


def test_a_highway_cars_lag_is_fitted_where_its_cost_rounds_above_the_solvers_tolerance(
    tmp_path: Path,
) -> None:
    """The scenario ``init`` drafts for a highway car (windows of half a second, the steer angle's
    two readings' mean), given what a straight kilometre cannot determine: over 700 m its cost's
    own rounding (1e-13 of it) passes the solver's function tolerance (1e-14), so a fit started at
    the optimum found no step that lowered the cost and its decrement, 1e-13 of the cost, was called
    not converged: the lag's re-sampling stopped there, every start over the search did the same,
    and the run held the lag at 0 ms, "not fitted" (seed 9403, never tuned on)."""
    residual = {"horizon_s": 0.5, "steering_sample": "mean"}
    sc, opts = _car_scenario(tmp_path, 9403, CAR_KNOWN, residual=residual)
    run = run_fitting_the_lag(sc)
    result, std = run.reports["gauss_newton"].result, run.std("gauss_newton")
    assert result.converged
    truth = {CAR_NAMES.get(n, n): v for n, v in opts.truth.items()}
    # The simulator's lag is 0: the fitted one within its σ, and every estimate within 3σ of the truth.
    assert abs(result.param_dict()["tracker_lag"]) < 3.0 * std["tracker_lag"]
    for name in ("traction_wheels_radius", "sensor_theta", "steer_offset"):
        assert abs(result.param_dict()[name] - truth[name]) < 3.0 * std[name], (name, std[name])


def test_a_wheel_over_a_metre_is_a_robots_wheel(tmp_path: Path) -> None:
    """Wheels of 1.2 m radius (a tractor's, a haul truck's; or a car's speed in m/s read as the
    rad/s of a 1 m wheel, 0.6 % fast): within what the joints' form calls a real robot's wheel
    (up to 2 m), so calibrated, not refused as "outside what a car_like can have ([1e-07, 1])" (the
    counts form's metre per tick, a 1 m wheel per radian). Seed 4711, never tuned on."""
    radius = 1.2
    sc, _ = _car_scenario(tmp_path, 4711, CAR_KNOWN, {"k_traction": radius})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    estimate, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    assert run.verdict.level in (GOOD, CAVEATS), run.verdict
    assert abs(estimate["traction_wheels_radius"] - radius) < 3.0 * std["traction_wheels_radius"], (
        estimate["traction_wheels_radius"],
        std["traction_wheels_radius"],
    )
    assert run.handoff_solver() == "gauss_newton"
    lo, hi = MODELS["car_like"].in_radians().physical_ranges["traction_wheels_radius"]
    assert lo <= 1e-7 and hi == pytest.approx(2.0)  # the counts form's floor, the plausible top


def test_the_run_past_the_preflight_says_not_determined_for_the_preflights_reason(tmp_path: Path) -> None:
    """Past a pre-flight that refuses (--skip-preflight), a solver that wanders along the direction
    the drive leaves free ends anywhere (k_steer -1.8e4, steer_offset -1.16 rad): the run said
    "outside what a car_like can have: are the encoders right?"; it names what the pre-flight names."""
    sc, _ = _car_scenario(tmp_path, seed=0)
    sc = dataclasses.replace(sc, solvers=("gauss_newton", "ipopt"))
    refused = set(preflight(sc).named(NOT_DETERMINED))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    said = " ".join(run.verdict.reasons)
    print(run.verdict.line())
    assert run.verdict.level == UNDETERMINED and run.handoff_solver() is None
    assert "are the encoders" not in said and "not observable" in said
    held = {n for n in refused if run.scenario.layout.param(n).status == HELD}
    assert refused - held and all(n in said for n in refused - held), (refused, said)


def test_a_mount_given_under_known_is_never_called_calibrated_in_robot_urdf(
    car_known: tuple[Any, HighwayOptions, Any, Any], tmp_path: Path
) -> None:
    """The car's device position is given under ``known:`` and only its yaw calibrated:
    sensor_mount.urdf.xml said so, while robot.urdf, the same joint in a whole robot, called the
    mount calibrated and said nothing of x and y. Both now say what each number is."""
    from nlp_calib import write_run

    _, _, run, _ = car_known
    write_run(run, tmp_path)
    joint, robot = ((tmp_path / n).read_text() for n in ("sensor_mount.urdf.xml", "robot.urdf"))
    said = "Calibrated: yaw; z, roll, pitch not known (0), which planar driving cannot see; x given"
    assert said in joint
    assert said in robot, robot.splitlines()[1]


def test_the_preflight_states_the_sigma_the_run_will_state(
    car_known: tuple[Any, HighwayOptions, Any, Any],
) -> None:
    """One σ per parameter before the fit and after it: the pre-flight's was the white residuals'
    (steer_offset ±0.0032 rad where the run says ±0.00018: a pose tracker's noise telescopes
    along the drive); it is the run's computation, within the sampling of its own windows."""
    sc, _, run, _ = car_known
    assert tuple(sc.solvers) == ("gauss_newton",)
    before = {p.name: p.std for p in preflight(sc).parameters}
    after = run.std("gauss_newton")
    for name in ("steer_offset", "traction_wheels_radius", "sensor_theta"):
        print(name, before[name], after[name])
        assert 0.5 < before[name] / after[name] < 2.0, (name, before[name], after[name])


def test_a_parameter_the_run_holds_is_a_caveat_before_the_fit_as_after(tmp_path: Path) -> None:
    """The track no turn is tight enough to tell is held at its start by the run, a caveat of its
    verdict (exit 0); the pre-flight called the drive NOT ENOUGH for it (exit 4) while the gate let
    the run go on: both say it is held, neither refuses."""
    sc, _ = _car_scenario(tmp_path, 1, ("k_steer", "wheelbase", "sensor_x", "sensor_y"))
    report = preflight(sc)
    assert report.named(NOT_DETERMINED) == ("traction_track_width",) and not report.stop_words()
    assert report.verdict == WEAK_DRIVE and report.exit_code == 3
    assert "traction_track_width held at its start" in "\n".join(preflight_lines(report))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run(["gauss_newton"])
    assert run.verdict.level == CAVEATS and run.verdict.handoff
    assert any("traction_track_width held at its initial value" in r for r in run.verdict.reasons)


def test_a_cars_steering_offset_must_resolve_what_turns_its_heading_at_its_own_speed(
    car_known: tuple[Any, HighwayOptions, Any, Any],
) -> None:
    _, opts, run, _ = car_known
    layout = run.scenario.layout
    # An offset δ turns the heading by δ·v/L a second; the budget is the reference robot's 2.5 mrad/s.
    speed = run.reports["gauss_newton"].metrics.distance_m / run.log.duration_s
    wheelbase = opts.truth["wheelbase"]
    assert layout.param("steer_offset").precision == (
        "absolute",
        pytest.approx(HEADING_BUDGET * wheelbase / speed, rel=0.1),
    )
    # What errs in proportion to the drive (a wheel scale, the known values) and the mount keep theirs.
    assert layout.param("traction_wheels_radius").precision == ("relative", 0.01)
    assert layout.param("sensor_theta").precision == ("absolute", 0.005)
    # A calibration that dead-reckons farther from the tracker than the nominal robot is never GOOD.
    ours = run.reports["gauss_newton"].metrics
    better = dataclasses.replace(
        ours, segment_ate=dataclasses.replace(ours.segment_ate, mean=0.5 * ours.segment_ate.mean)
    )
    nominal = NominalCheck({"k_steer": 1.0}, "a test", np.zeros(0), better)
    behind = dataclasses.replace(run, checks=dataclasses.replace(run.checks, nominal=nominal))
    said = verdict(behind, MODELS["car_like"])
    assert said.level != GOOD and any(
        "no closer to the tracker than the nominal robot" in r for r in said.reasons
    )
    # Said once: the caveat is the gain's own words, which the verdict's line had repeated after it.
    assert said.line().count("no closer to the tracker than the nominal robot") == 1, said.line()


def test_a_track_held_at_its_start_is_never_blamed_on_the_encoders(tmp_path: Path) -> None:
    """No tight turn holds the track at its start; a start outside what a car can have is the
    start's, not a sign of wrong encoders (it was NOT DETERMINED, "are the encoders right?", exit 1)."""
    sc, opts = _car_scenario(tmp_path, 1, ("k_steer", "wheelbase", "sensor_x", "sensor_y"))
    guess = {CAR_NAMES.get(n, n): v for n, v in opts.truth.items()} | {"traction_track_width": 7.061}
    sc = dataclasses.replace(sc, parameters=dataclasses.replace(sc.parameters, initial_guess=guess))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    assert run.scenario.layout.param("traction_track_width").status == HELD
    assert not any("came out" in r for r in run.verdict.reasons), run.verdict
    assert run.verdict.level in (CAVEATS, UNDETERMINED)
    assert any("traction_track_width held at its initial value" in r for r in run.verdict.reasons)


def test_a_cars_wheel_speeds_read_as_positions_are_found_and_named(tmp_path: Path) -> None:
    sc, _ = _car_scenario(tmp_path, 3)
    entry = sc.data.logs[0]
    entry = dataclasses.replace(entry, source=dataclasses.replace(entry.source, form="positions"))
    as_positions = dataclasses.replace(sc, data=dataclasses.replace(sc.data, logs=(entry,)))
    found = [u for u in preflight(as_positions).units if u.blocking]
    assert [u.kind for u in found] == ["speeds"], found
    assert "form: speeds" in found[0].words
    assert not any(u.blocking for u in preflight(sc).units)


@pytest.mark.parametrize("noise", [1.0, 10.0])
def test_noisy_wheel_speeds_read_as_positions_are_named_speeds_not_wraps(
    tmp_path: Path, noise: float
) -> None:
    """Speed columns with 1 or 10 rad/s of noise (of 25-63) read as positions (no ``form:``): their
    values follow the tracker's speed, their changes do not. They were a wheel that wraps its angle
    (1 rad/s) or nothing at all (10 rad/s: a radian of them moved the robot a plausible distance);
    the same wheels as positions (the speeds integrated) are not speeds."""
    opts = HighwayOptions(seed=3, duration_s=30.0, wheel_noise=noise)
    sim = simulate_highway(opts)
    joints, poses, _ = sim.write(tmp_path / "car")
    wheels = ("steering", "rear_left_wheel", "rear_right_wheel")
    sc = {
        "model": "car_like",
        "dataset": {"joints": str(joints), "poses": str(poses), "encoders": dict(zip(wheels, wheels))},
    }
    found = [u for u in preflight(scenario_from_mapping(sc, "car", tmp_path)).units if u.blocking]
    assert [u.kind for u in found] == ["speeds"], found
    assert "form: speeds" in found[0].words and "follow the robot's speed" in found[0].words
    # The same drive's wheels as positions: their trapezoids summed, as a speeds column is read.
    values = np.array(sim.joint_values)
    step = 0.5 * (values[1:, :4] + values[:-1, :4]) * np.diff(sim.joint_time_s)[:, None]
    values[:, :4] = np.vstack([np.zeros((1, 4)), np.cumsum(step, axis=0)])
    joints.write_text(dataclasses.replace(sim, joint_values=values).joints_csv())
    assert not [u for u in preflight(scenario_from_mapping(sc, "car", tmp_path)).units if u.blocking]


def test_a_highway_cars_odometry_noise_is_never_under_the_drift_its_windows_truly_have(
    car_known: tuple[Any, HighwayOptions, Any, Any],
) -> None:
    """The hand-off's noise against the true base over the fit's windows: a wheel speed's noise
    (0.14 mm an interval along) and the steering's under the device's 2 cm and 2 mrad, which the
    segments can bound only from above: each component's σ at least half the one whose 2σ holds
    95 % of the true errors (a filter never trusts the wheels beyond what they drift). The rates
    per metre and per radian take the joints' own noise there (their third differences: the wheel
    speeds' and the steering angle's) and the calibration's constant errors over the fit's windows:
    within a factor 2, each component (the inputs' noise propagated, the most the segments allow,
    was 14x along on this seed)."""
    _, opts, run, calib = car_known
    sim = simulate_highway(opts)
    # Over the metres no fault spoils, not every metre: the slipped pivots are stated apart (the
    # rates' slip_per_radian), and over a coarse arc the track here is the model's one arc per
    # 2 s interval, not the odometry a controller integrates at the joints' rate.
    found = sigma_over_truth(calib, run, (sim.joint_time_s, sim.base_poses, EPOCH_NS))
    assert {way for way, _ in found} == {"rates", "pose", "twist"}
    for way, ratios in found.items():
        print(way, ratios)
        # NaN: what the file does not state (the twist's lateral velocity).
        assert np.all(ratios[~np.isnan(ratios)] >= 0.5), (way, ratios)
    rates = (
        run.odometry.rates if run.odometry is not None else run.reports["gauss_newton"].controller.noise.rates
    )
    assert rates.bounded == ()
    _within_two_unless_bounded(found[("rates", 1)], rates)


# --- a car's joints read as a car's (#43 item 5) --------------------------------------------------


@pytest.mark.parametrize(
    ("joints", "model", "read"),
    [
        # Four wheel speeds and a steering joint (the highway car's CAN): a car, not a tricycle.
        (
            ("rear_left_wheel", "rear_right_wheel", "front_left_wheel", "front_right_wheel", "steering"),
            "car_like",
            {
                "steering": "steering",
                "rear_left_wheel": "rear_left_wheel",
                "rear_right_wheel": "rear_right_wheel",
            },
        ),
        # Each front wheel's steering joint: the Ackermann pair, each read by its own side.
        (
            ("front_left_steering", "front_right_steering", "rear_left_wheel", "rear_right_wheel"),
            "car_like_ackermann",
            {
                "steering_left": "front_left_steering",
                "steering_right": "front_right_steering",
                "rear_left_wheel": "rear_left_wheel",
                "rear_right_wheel": "rear_right_wheel",
            },
        ),
        # A steering joint beside two wheels: never a differential drive's wheels.
        (
            ("left_wheel", "right_wheel", "steer_joint"),
            "car_like",
            {"steering": "steer_joint", "rear_left_wheel": "left_wheel", "rear_right_wheel": "right_wheel"},
        ),
        (("left_wheel_joint", "right_wheel_joint"), "diff_drive", None),
    ],
)
def test_init_reads_a_steering_joint_with_a_steered_model(
    joints: tuple[str, ...], model: str, read: dict[str, str] | None
) -> None:
    from nlp_calib.pipeline.draft import guess_model

    chosen, found, why = guess_model(list(joints), None)
    assert chosen == model, why
    assert read is None or found == read
    if model == "car_like_ackermann":  # the pair's steering track, held whatever the drive, said
        assert "it holds" in why and "steering_track_width" in why


@pytest.mark.parametrize(
    ("cornering", "model"),
    [(1.1, "car_like_bicycle"), (0.02, "tricycle"), (None, "tricycle")],
)
def test_a_steering_and_one_wheel_joint_are_a_cars_where_the_drive_corners_as_a_car(
    cornering: float | None, model: str
) -> None:
    """A tricycle and a bicycle car read one steering and one wheel joint alike: the drive's bends
    (their lateral acceleration) tell a car's; a slow drive, or none known, keeps the first
    registered (a tricycle), naming the car's model to give."""
    from nlp_calib.pipeline.draft import CAR_CORNERING, guess_model

    chosen, _, why = guess_model(["steering_cmd", "rear_wheels"], None, cornering)
    assert chosen == model, why
    if model == "tricycle":
        assert "--model car_like_bicycle" in why
    else:
        assert f"a car's from {CAR_CORNERING:g}" in why
    # Given, the model is the user's whatever the drive.
    assert guess_model(["steering_cmd", "rear_wheels"], "tricycle", 1.1)[0] == "tricycle"


def _bicycle_files(tmp_path: Path, fast: bool) -> tuple[Path, np.ndarray]:
    """A simulated car's steering and the mean of its rear wheels' speeds (rad/s) as one joint log,
    beside the device's poses: on bends at 8-20 m/s, or at a walking pace."""
    speeds = {"min_speed": 8.0, "max_speed": 20.0} if fast else {"min_speed": 0.3, "max_speed": 0.8}
    sim = simulate_highway(
        HighwayOptions(seed=5, duration_s=60.0, road=RoadOptions(bend_angle=0.03), **speeds)
    )
    names = list(sim.joint_names)
    rear = 0.5 * (
        sim.joint_values[:, names.index("rear_left_wheel")]
        + sim.joint_values[:, names.index("rear_right_wheel")]
    )
    values = np.column_stack([sim.joint_values[:, names.index("steering")], rear])
    joints = tmp_path / "car.csv"
    stamps = EPOCH_NS + np.round(sim.joint_time_s * 1e9).astype(np.int64)  # the poses' clock
    joints.write_text(format_joint_csv(stamps, ("steering_cmd", "rear_wheels"), values))
    (tmp_path / "car.tum").write_text(sim.poses_tum())
    # The true base's lateral acceleration, speed × turn rate, at the 90th percentile.
    step = np.diff(sim.base_poses, axis=0)
    dt = np.diff(sim.joint_time_s)
    load = np.hypot(step[:, 0], step[:, 1]) * np.abs(wrap_angle(step[:, 2])) / dt**2
    return joints, np.percentile(load, 90)


@pytest.mark.parametrize("fast", [True, False])
def test_init_drafts_a_car_and_its_wheel_speeds_from_the_data(tmp_path: Path, fast: bool) -> None:
    """``init`` on a car's steering and rear wheel speeds: the car's model where the drive corners
    as a car's, and ``form: speeds`` found by the pre-flight's own detector (the columns' values
    follow the tracker's speed), so that the draft reads them as speeds."""
    from nlp_calib.analysis.units import findings
    from nlp_calib.pipeline.draft import CAR_CORNERING, cornering, draft

    joints, load = _bicycle_files(tmp_path, fast)
    # The tracker's bends as the draft measures them are the true base's (within its noise at a walk).
    assert cornering(joints.with_suffix(".tum")) == pytest.approx(load, rel=0.1, abs=0.01)  # pose noise
    assert (load >= CAR_CORNERING) == fast
    d = draft(joints, tmp_path / "car.yaml")
    assert d.raw["model"] == ("car_like_bicycle" if fast else "tricycle")
    assert d.raw["dataset"]["form"] == "speeds"
    assert "dataset.form: speeds, because" in d.text and "look like speeds (rad/s)" in d.text
    # Read back as the run reads it, the wheel columns are speeds: the detector says nothing more.
    sc = d.scenario(tmp_path / "car.yaml")
    from nlp_calib.pipeline import prepare

    model, log = prepare.read(sc)
    track = sc.objective.sensor.sensor.floor_track(log)
    assert not [
        f for f in findings(log, model, (track[:, :2], track[:, 2]), None, False) if f.kind == "speeds"
    ]


def test_a_car_run_the_preflight_stops_writes_its_plan(tmp_path: Path) -> None:
    """A new user's car (``init`` then ``run``) whose bends cannot tell the steering gain from the
    wheelbase: the run stops at the pre-flight (exit 4, NOT DETERMINED) and, as a run left NOT
    DETERMINED does, writes plan.md and plan.png into its folder: the ranking the terminal shows
    the first four of, for the parameter it names."""
    joints, _ = _bicycle_files(tmp_path, fast=True)
    scenario, out = tmp_path / "car.yaml", tmp_path / "out"
    assert cli("init", str(joints), "--out", str(scenario)).returncode == 0
    done = cli("run", str(scenario), "--out", str(out))
    assert done.returncode == 4, done.stdout + done.stderr
    plan_line = next(line for line in done.stdout.splitlines() if line.startswith("plan: "))
    target = plan_line.split("the σ of ", 1)[1].split(" ", 1)[0]
    text = (out / "plan.md").read_text()
    assert f"**{target}** is the parameter known least well" in text
    if plan_line.startswith("plan: drive "):
        assert f"| 1 | {plan_line.removeprefix('plan: drive ').split(':', 1)[0]} |" in text
    assert (out / "plan.png").read_bytes().startswith(b"\x89PNG")
    assert f"wrote {out / 'plan.md'}" in done.stdout
    # Calibrated anyway, the run ends NOT DETERMINED and writes its own plan in its place.
    anyway = cli("run", str(scenario), "--out", str(out), "--skip-preflight")
    assert "NOT DETERMINED" in anyway.stdout and (out / "result.json").is_file()
    assert (out / "plan.md").is_file()


def test_init_keeps_a_real_tricycles_model_and_its_positions(tmp_path: Path) -> None:
    """OptiOdom's tricycle (steer_joint, traction_joint as positions) drafts a tricycle without a
    form, on its circles (steering within a car's lock) and its squares (turning on the spot)."""
    from nlp_calib.pipeline.draft import draft

    for session in ("circular/140120211440", "square/140120211430"):
        joints = SHARED_DATA / "real4/optiodom/tricyc" / session / f"{session.split('/')[1]}_run-01.csv"
        if not joints.is_file():
            pytest.skip(f"OptiOdom's runs are not at {joints}")
        d = draft(joints, tmp_path / "tricycle.yaml")
        assert d.raw["model"] == "tricycle", d.text
        assert "form" not in d.raw["dataset"]


def test_one_steering_joint_for_both_sides_of_an_ackermann_pair_is_refused(tmp_path: Path) -> None:
    """A single steering column read as both front wheels' (it was accepted silently: no Ackermann
    split, the steering track started at 0)."""
    from nlp_calib.core.errors import ConfigError

    joints, poses, _ = simulate_highway(HighwayOptions(seed=2, duration_s=20.0)).write(tmp_path / "car")
    sc = {
        "model": "car_like_ackermann",
        "dataset": {
            "joints": str(joints),
            "poses": str(poses),
            "form": "speeds",
            "encoders": {
                "steering_left": "steering",
                "steering_right": "steering",
                "rear_left_wheel": "rear_left_wheel",
                "rear_right_wheel": "rear_right_wheel",
            },
        },
    }
    with pytest.raises(
        ConfigError, match="steering_left and steering_right both read the joint 'steering'"
    ) as e:
        scenario_from_mapping(sc, "car", tmp_path)
    assert "Ackermann split" in str(e.value)


def test_the_highway_simulator_adds_bends_a_sliding_axle_and_a_wandering_device_error() -> None:
    """What a real car has at speed that the kinematic model lacks: the axle's course leaves its
    heading by slip_gain × v²κ (out of the bend), the heading itself unchanged; the device's noise
    is a Gauss-Markov process of the σ and time constant asked for; bends turn at radii of ~100 m."""
    base: dict[str, Any] = {"seed": 4801, "duration_s": 60.0}
    plain = simulate_highway(HighwayOptions(**base, road=RoadOptions(bend_angle=0.03)))
    slid = simulate_highway(HighwayOptions(**base, road=RoadOptions(bend_angle=0.03, slip_gain=0.004)))
    np.testing.assert_allclose(slid.base_poses[:, 2], plain.base_poses[:, 2])
    step = np.diff(slid.base_poses, axis=0)
    ds = np.hypot(step[:, 0], step[:, 1])
    # The poses are the fine grid's nearest to each joint stamp: their own times, not the stamps.
    dt = np.diff(np.round(slid.joint_time_s / FINE_S)) * FINE_S
    v, kappa = ds / dt, wrap_angle(step[:, 2]) / ds
    # A chord runs along the mean of its ends' headings, less the slip.
    slip = wrap_angle(slid.base_poses[:-1, 2] + 0.5 * step[:, 2] - np.arctan2(step[:, 1], step[:, 0]))
    turning = np.abs(kappa) > 2e-3
    assert turning.mean() > 0.3 and np.min(1.0 / np.abs(kappa[turning])) < 150.0
    load = (v**2 * kappa)[turning]  # the lateral acceleration, m/s²
    gain = np.sum(slip[turning] * load) / np.sum(load**2)
    assert gain == pytest.approx(0.004, rel=0.05) and np.corrcoef(slip[turning], load)[0, 1] > 0.9
    quiet = HighwayOptions(seed=4801, duration_s=400.0, pose_noise=(0.0, 0.0))
    wander = HighwayOptions(
        seed=4801, duration_s=400.0, pose_noise=(0.3, 0.002), road=RoadOptions(pose_noise_time_s=5.0)
    )
    noise = simulate_highway(wander).poses - simulate_highway(quiet).poses
    a = np.exp(-1.0 / (20.0 * 5.0))  # 20 Hz poses, 5 s
    for column, sd in zip(noise.T, (0.3, 0.3, 0.002)):
        assert np.std(column) == pytest.approx(sd, rel=0.3)
        assert np.corrcoef(column[1:], column[:-1])[0, 1] == pytest.approx(a, abs=0.01)
    with pytest.raises(OptionsError, match="road's slip_gain"):
        RoadOptions(slip_gain=1.0)


#: A car's lap with what the kinematic model lacks at speed: bends, the rear axle sliding out of
#: them and a device error wandering over two minutes (seed 4802 of the fresh range 4801-4806).
LAP = RoadOptions(heading_change=-4.7, bend_angle=0.03, slip_gain=0.004, pose_noise_time_s=120.0)


#: The lap's drive: 400 s on the LAP road, with the device's noise wandering as it does on it.
LAP_DRIVE = {"duration_s": 400.0, "seed": 4802, "road": LAP, "pose_noise": (0.3, 0.002)}


def _lap_scenario(tmp_path: Path, name: str, sim: Any, samples: dict[str, int]) -> Any:
    """The car's scenario of ``sim``'s records in ``samples``, as a scenario file states it."""
    joints, poses, _ = sim.write(tmp_path / name)
    sc = {
        "model": "car_like", "initial_guess": "auto", "solvers": ["gauss_newton"], "samples": samples,
        "dataset": highway_dataset(joints, poses), "known": {"wheelbase": 2.8, "traction_track_width": 1.6},
    }  # fmt: skip
    return scenario_from_mapping(sc, name, tmp_path)


def _second_half_drift(tmp_path: Path, cal: Any, moved: dict[str, float], half: int) -> Any:
    """``check`` of the stored first-half calibration ``cal`` on the lap's second half, the device's
    mount moved by ``moved`` there, as ``check`` does."""
    from nlp_calib.pipeline.check import check

    sim = simulate_highway(HighwayOptions(**LAP_DRIVE, truth=moved))  # type: ignore[arg-type]
    scenario = _lap_scenario(tmp_path, "car1", sim, {"start": half})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # As check_scenario starts a scenario file's fit: from the stored values, with its solver.
        second = scenario.with_options(initial_guess=cal.start(), solvers=(cal.solver,))
        return check(cal, second).checks.drift


@pytest.mark.slow
def test_a_laps_wandering_device_error_is_no_confirmed_drift_while_a_turned_device_is(tmp_path: Path) -> None:
    """The second half of an unchanged car's lap: its device's heading error, wandering over two
    minutes, is common to every 20 s block of a half, so the jackknife cannot see it; the yaw's
    change (+6.3σ of the jackknife's) is reported, not confirmed. A device turned by 1° on the
    same drive is a confirmed drift. The first half is calibrated once, as ``run`` does, and
    ``check`` reads its stored file for both second halves."""
    from nlp_calib.outputs.handoff import write_calibration
    from nlp_calib.pipeline.stored import read_calibration

    first = simulate_highway(HighwayOptions(**LAP_DRIVE, truth={}))  # type: ignore[arg-type]
    half = first.pose_time_s.size // 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(_lap_scenario(tmp_path, "car0", first, {"start": 0, "stop": half})).run()
        (path,) = write_calibration(run, tmp_path, "calibration.yaml")
        cal = read_calibration(path)
    same = _second_half_drift(tmp_path / "same", cal, {}, half)
    assert same is not None and all(not c.confirmed for c in same.drifted), same.line()
    assert all("not confirmed" in r for r in same.reasons if " moved by " in r)
    turned_theta = {"sensor_theta": HIGHWAY_TRUTH["sensor_theta"] + 0.0175}
    turned = _second_half_drift(tmp_path / "turned", cal, turned_theta, half)
    assert turned is not None and [c.name for c in turned.drifted] == ["sensor_theta"], turned.line()
    assert turned.drifted[0].confirmed and turned.drifted[0].change == pytest.approx(0.0175, abs=0.005)


def test_a_refusals_way_out_addresses_its_own_reason_and_its_plan_is_one_sentence() -> None:
    """A car whose drive already turns both ways is not told to turn both ways: what trades off is
    named, with one to measure; the plan's no-manoeuvre line says where the model was evaluated in
    parentheses (it had read "... with the model as the initial guess, fitted ..., has it")."""
    from nlp_calib.analysis.verdict import way_out
    from nlp_calib.results.preflight import Plan

    class NoClock:  # the layout's one question here: none of these is a clock offset
        def in_block(self, name: str, block: str) -> bool:
            return False

    model, names, layout = MODELS["car_like_bicycle"], ["k_steer", "sensor_x", "sensor_y"], NoClock()
    unturned = way_out(names, model, layout)  # type: ignore[arg-type]
    assert unturned == "next: drive turns in both directions (S-curves, circles each way) and fit again"
    turned = way_out(names, model, layout, turned_both_ways=True)  # type: ignore[arg-type]
    assert (
        "drive turns in both directions" not in turned
        and "leaves k_steer, sensor_x, sensor_y loose" in turned
    )
    assert "(known: {" in turned and "tighter ones, at other speeds" in turned
    # The pre-flight's way out addresses what it refuses for (not determined), not a weak lag beside.
    from types import SimpleNamespace

    from nlp_calib.pipeline.preflight import _way_out
    from nlp_calib.results.preflight import NOT_DETERMINED, WEAKLY, ParameterStatus

    class Clock(NoClock):
        def in_block(self, name: str, block: str) -> bool:
            return name == "tracker_lag"

    fns = SimpleNamespace(model=model, layout=Clock(), sensor=None)
    found = [ParameterStatus("k_steer", NOT_DETERMINED, np.inf, np.inf, 0.01, "1", ("sensor_x",), "")]
    found.append(ParameterStatus("tracker_lag", WEAKLY, 0.005, 40.0, 1e-4, "s", (), ""))
    both = SimpleNamespace(turned_left_rad=4.5, turned_right_rad=9.2, heading_span_rad=4.7)
    said = _way_out(fns, found, ["k_steer", "tracker_lag"], {}, both)  # type: ignore[arg-type]
    assert "give the lag" not in said and "(known: {k_steer: <value>})" in said, said
    assert _way_out(fns, found[1:], ["tracker_lag"], {}, both).startswith("next: give the lag")  # type: ignore[arg-type]
    # Only weakly determined, the loosest and what it trades with: the real car around Monza, drafted
    # by init, had its steering gain and wheelbase at 119× and 124×, the lag at 53×: the advice gave
    # the lag only.
    weak = [ParameterStatus("k_steer", WEAKLY, 0.28, 119.0, 0.0023, "1", ("wheelbase",), "")]
    weak.append(ParameterStatus("wheelbase", WEAKLY, 17.0, 124.0, 0.13, "m", ("k_steer",), ""))
    weak.append(ParameterStatus("tracker_lag", WEAKLY, 0.007, 53.0, 1e-4, "s", (), ""))
    said = _way_out(fns, weak, ["k_steer", "wheelbase", "tracker_lag"], {}, both)  # type: ignore[arg-type]
    assert "give the lag" not in said and "(known: {wheelbase: <value>})" in said, said
    where = "the initial guess, fitted to convergence on the windows judged"
    line = Plan("k_steer", "1", 50.0, 0.2, where, ()).line()
    assert line == f"no manoeuvre considered lowers the σ of k_steer (the model evaluated at {where})"


def test_the_preflights_windows_never_cross_a_gap_in_the_tracker_as_the_runs_do(tmp_path: Path) -> None:
    """A car's GNSS lost for 10 s: the run's windows never cross the gap; the pre-flight's did (one
    window over 250 m, whose motion inflated the fidelity floor of a free direction ~20× on a real
    car's lap with 7 gaps: k_steer, sensor_x and sensor_y "not determined" where the run found
    each ±4 %, ±0.1 m, ±0.03 m)."""
    from nlp_calib.pipeline.preflight import drive

    sc, _ = _car_scenario(tmp_path, 4813, CAR_KNOWN)
    tum = tmp_path / "car.tum"
    lines = tum.read_text().splitlines(keepends=True)
    t = np.array([float(line.split()[0]) for line in lines])
    tum.write_text("".join(line for line, ti in zip(lines, t) if not 20.0 <= ti - t[0] < 30.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d, _ = drive(sc)
    data = d.data
    times = np.concatenate([lg.time_s for lg in data.logs])
    spans = times[data.stops] - times[data.starts]
    assert data.n_residuals > 0 and np.max(spans) < 1.0, np.max(spans)


def test_init_drafts_a_joint_log_beside_its_motions_as_simulate_writes_them(tmp_path: Path) -> None:
    """``simulate --vehicle skid_spins`` writes ``NAME.csv`` beside ``NAME.motions.csv``; ``init`` on
    either drafts a scenario of the two that a run reads (before: "no NAME.tum beside it"), the
    model by the joints' names and the drive's turning; a TUM file beside the joints is still
    their reference."""
    from nlp_calib.pipeline.draft import draft
    from nlp_calib.pipeline.prepare import read

    joints, motions, _ = simulate_skid_spins(SkidSpinOptions(duration_s=60.0, seed=5)).write(
        tmp_path / "skid"
    )
    for named in (joints, motions):
        d = draft(named, tmp_path / "skid.yaml")
        assert d.raw["dataset"]["joints"] == joints.name and d.raw["dataset"]["motions"] == motions.name
        assert "poses" not in d.raw["dataset"] and d.raw["model"] in MODELS
        _, log = read(d.scenario(tmp_path / "skid.yaml"))
        assert log.n_records >= 60.0 / 2.0  # one record per stamp of the 2 s increments
    tum = tmp_path / "skid.tum"
    tum.write_text("0 0 0 0 0 0 0 1\n")
    with pytest.raises(DatasetError, match=r"skid\.tum: holds 1 pose"):  # its pair read, as before
        draft(joints, tmp_path / "both.yaml")
