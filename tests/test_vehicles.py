"""Real vehicles' drives (issue #43), simulated: a skid-steer spinning more than π per increment,
its encoders updating at 4 Hz and slipping on pivots, against a scan matcher's increments."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from nlp_calib.core.errors import OptionsError
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.pipeline.analyse import Wanted
from nlp_calib.results.run import CAVEATS, GOOD, UNDETERMINED
from nlp_calib.simulation.vehicles import SkidSpinOptions, simulate_skid_spins

JOINT_NAMES = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}
SKID = {
    "model": "skid_steer",
    "initial_guess": "auto",
    "information": {"translation": 4.0e4, "rotation": 1.0e5},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}


def _skid_run(tmp_path: Path, seed: int, pivot_slip: float = 0.1) -> tuple[Any, SkidSpinOptions, Any]:
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
        run = Calibration(sc).run(wanted=Wanted(odometry="gauss_newton"))
    return run, opts, sim


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
        pytest.param(
            2,
            0.1,
            marks=pytest.mark.xfail(
                strict=True,
                reason="#43 open: slip of either sign on pivots, not flagged, pulls turn_slip beyond its "
                "σ (0.083 ± 0.004 against 0.05)",
            ),
        ),
    ],
)
def test_a_skid_steer_spinning_past_pi_ends_right_with_covariances_its_windows_show(
    tmp_path: Path, seed: int, pivot_slip: float
) -> None:
    run, opts, _ = _skid_run(tmp_path, seed, pivot_slip)
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
    assert odo is not None and 0.85 <= odo.coverage <= 1.0
    bad = np.zeros(odo.time_s.size - 1, dtype=bool)
    for f in run.checks.findings.report.faults:
        bad[f.first : f.last + 1] = True
    ref, track = odo.reference, odo.T_world_base
    error = wrap_angle(np.diff(ref[:, 2]) - np.diff(track[:, 2]))[~bad]
    grown = np.diff(odo.covariance[:, 2, 2])[~bad]
    ratio = np.sqrt(np.mean(error**2) / np.mean(grown))
    assert 0.5 < ratio < 2.0, ratio
