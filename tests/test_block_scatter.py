"""Blocks of one drive that disagree beyond their σ widen it (nlp_calib.analysis.block_scatter).

A chain of windows each measuring the offset θ between consecutive poses, ``z_{u+1} − z_u = θ``
(see test_residual_floor): a block's own estimate is its mean increment. An error that shifts
each block by its own amount must fire and widen the σ until it covers the truth; white noise, of
each window's own or on the poses (cancelling along the chain), must not.
"""

from __future__ import annotations

import itertools
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import highway_dataset

from nlp_calib.analysis.block_scatter import LEVEL, block_scatter, chi2_tail
from nlp_calib.analysis.residual_floor import ScoreRows
from nlp_calib.outputs.handoff import calibration_dict
from nlp_calib.outputs.results import result_dict
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.results.run import Checks
from nlp_calib.results.uncertainty import Uncertainty
from nlp_calib.simulation.vehicles import HighwayOptions, RoadOptions, simulate_highway

W = 2000


def _chain(seed: int, own: float, pose: float, bias: float = 0.0) -> tuple[tuple[np.ndarray, ...], dict]:
    """The chain's blocks' figures (``ScoreRows.blocks`` and the noise model's meat) and what an
    independent computation needs: the increments, the blocks' edges, the fit and its σ."""
    rng = np.random.default_rng(seed)
    rows = ScoreRows(np.arange(W), np.arange(W) + 1, 1)
    edges = rows.edges
    shift = np.repeat(rng.normal(0.0, bias, edges.size - 1), np.diff(edges))
    inc = np.diff(rng.normal(0.0, pose, W + 1)) + rng.normal(0.0, own, W) + shift
    fit = inc.mean()
    rows.add(slice(0, W), -np.ones((W, 1, 1)), (inc - fit)[None, :], np.ones(1), np.ones(W))
    white = np.array([[2 * pose**2 + W * own**2]])  # the noise model's meat of the whole chain
    return (*rows.blocks(), white), {
        "inc": inc,
        "edges": edges,
        "fit": fit,
        "std": math.sqrt(white[0, 0]) / W,
    }


def test_chi2_tail_against_the_integrated_density() -> None:
    for dof in (1, 2, 3, 9, 18, 19):
        for x in (0.5, dof, 3.0 * dof + 10.0):
            t = np.linspace(x, x + 400.0, 400_001)
            pdf = np.exp((dof / 2 - 1) * np.log(t) - t / 2 - math.lgamma(dof / 2) - dof / 2 * math.log(2))
            assert abs(chi2_tail(x, dof) - np.trapezoid(pdf, t)) < 1e-6, (dof, x)


def test_blocks_shifted_each_by_its_own_error_fire_and_the_sigma_covers_the_truth() -> None:
    missed = 0
    for seed in (3101, 3102, 3103):
        rows, c = _chain(seed, own=1.0, pose=0.0, bias=0.3)
        spread, chi2, dof = block_scatter(rows, np.array([c["std"]]))
        # Independently: each block's mean increment, its σ the noise's (1/√N), their χ² without
        # the block that adds most to it.
        edges, inc = c["edges"], c["inc"]
        means = np.array([inc[a:b].mean() for a, b in itertools.pairwise(edges)])
        w = np.diff(edges).astype(float)  # 1/σ² of a block's mean with unit noise
        terms = w * (means - (w * means).sum() / w.sum()) ** 2
        keep = np.arange(means.size) != np.argmax(terms)  # the block adding most left out
        w, means = w[keep], means[keep]
        expect = float((w * (means - (w * means).sum() / w.sum()) ** 2).sum())
        assert dof[0] == edges.size - 3
        assert chi2_tail(expect, int(dof[0])) < LEVEL
        # The blocks' σ come from their residuals about the whole fit, which hold their shifts too: a
        # lower χ² than with the noise's σ known, never a higher one.
        assert 0.5 < chi2[0] / expect < 1.1, (chi2[0], expect)
        assert (
            np.isfinite(spread[0]) and abs(spread[0] / (c["std"] * math.sqrt(chi2[0] / dof[0])) - 1) < 1e-12
        )
        assert abs(c["fit"]) < 3.0 * spread[0], (c["fit"], spread[0])  # the truth is 0
        missed += int(abs(c["fit"]) > 3.0 * c["std"])
    assert missed  # the white-noise σ alone does not cover it


def test_white_noise_of_each_window_or_of_the_poses_does_not_fire() -> None:
    """40 draws each (seeds 3200-3239): of each window's own, of the poses (cancelling along the
    chain: a block's own meat sums cancelling terms to about 0), both."""
    for own, pose in ((1.0, 0.0), (0.0, 0.5), (0.1, 0.5)):
        fired = 0
        for seed in range(3200, 3240):
            rows, c = _chain(seed, own, pose)
            fired += int(np.isfinite(block_scatter(rows, np.array([c["std"]]))[0][0]))
        assert fired <= 1, (own, pose, fired)


def test_a_block_that_leaves_a_parameter_free_is_left_out_of_its_chi2() -> None:
    """Two parameters, the second seen only by the first half of the windows."""
    rng = np.random.default_rng(3300)
    rows = ScoreRows(np.arange(W), np.arange(W) + 1, 2)
    J = np.ones((W, 1, 2))
    J[:, 0, 1] = rng.normal(size=W)
    J[W // 2 :, 0, 1] = 0.0
    rows.add(slice(0, W), J, rng.normal(size=(1, W)), np.ones(1), np.ones(W))
    _, chi2, dof = block_scatter((*rows.blocks(), np.eye(2) * W), np.ones(2))
    blocks = rows.edges.size - 1
    half = int(np.sum(rows.edges[1:] <= W // 2))
    assert dof[0] == blocks - 2 and dof[1] == half - 2 and blocks > half  # the worst block left out
    assert np.all(np.isfinite(chi2))


def test_the_sigma_to_believe_takes_the_block_scatter_in_where_it_is_the_largest() -> None:
    names = ("a", "b", "c")
    u = Uncertainty(
        names=names,
        free=names,
        covariance=np.diag([1.0, 4.0, 9.0]) * 1e-4,
        std=np.array([0.01, 0.02, 0.03]),
        correlation=np.eye(3),
        noise={},
        dof=100,
        std_residuals=np.array([0.015, np.nan, np.nan]),
        std_block_scatter=np.array([0.012, 0.05, np.nan]),
    )
    believed = Checks(observability=None, crossval=None, direction=None, findings=None).believed(u)
    np.testing.assert_array_equal(believed, [0.015, 0.05, 0.03])


def _highway(tmp_path: Path, seed: int, pose_noise_time_s: float) -> tuple[Any, dict[str, float]]:
    """A car on a highway with bends (160 s), its device's noise white or correlated over
    ``pose_noise_time_s``: the run (axle distance and track given) and the truth."""
    road = RoadOptions(heading_change=-2.0, bend_angle=0.03, pose_noise_time_s=pose_noise_time_s)
    sim = simulate_highway(HighwayOptions(duration_s=160.0, seed=seed, road=road))
    joints, poses, _ = sim.write(tmp_path / f"car{seed}")
    names = {"k_traction": "traction_wheels_radius", "rear_track": "traction_track_width"}
    truth = {names.get(n, n): v for n, v in sim.options.truth.items()}
    sc = {
        "model": "car_like",
        "initial_guess": "auto",
        "solvers": ["gauss_newton"],
        "dataset": highway_dataset(joints, poses),
        "known": {n: truth[n] for n in ("wheelbase", "traction_track_width")},
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Calibration(scenario_from_mapping(sc, "car", tmp_path)).run(), truth


def test_a_device_noise_correlated_along_the_drive_fires_and_reaches_the_handoff(tmp_path: Path) -> None:
    """Seed 44: noise correlated over 5 s shifts each block its own way (the white-noise σ of
    sensor_x misses the truth by tens of σ); the blocks disagree, the spread is carried to
    result.json and calibration.yaml, and the σ to believe covers the truth."""
    run, truth = _highway(tmp_path, 44, 5.0)
    u = run.reports["gauss_newton"].uncertainty
    assert u.block_chi2 is not None
    i = u.names.index("sensor_x")
    chi2, dof = u.block_chi2[:, i]
    assert chi2_tail(float(chi2), int(dof)) < LEVEL
    base = max(u.std[i], np.nan_to_num(u.residual_spread()[i]))
    assert u.block_spread()[i] == pytest.approx(base * math.sqrt(chi2 / dof), rel=1e-12)
    std, err = (
        run.std("gauss_newton"),
        run.reports["gauss_newton"].result.param_dict()["sensor_x"] - truth["sensor_x"],
    )
    assert (
        abs(err) > 5.0 * u.std[i]
        and abs(err) < 3.0 * std["sensor_x"]
        and std["sensor_x"] >= u.block_spread()[i]
    )
    spread = result_dict(run)["solvers"]["gauss_newton"]["std_block_scatter"]["sensor_x"]
    assert (
        spread == pytest.approx(u.block_spread()[i])
        and calibration_dict(run)["std_block_scatter"]["sensor_x"] == spread
    )


def test_white_device_noise_on_a_highway_does_not_fire(tmp_path: Path) -> None:
    """Seed 44 with white noise: no parameter's blocks disagree."""
    run, _ = _highway(tmp_path, 44, 0.0)
    u = run.reports["gauss_newton"].uncertainty
    assert u.block_chi2 is not None and (u.block_chi2[1] > 0).sum() >= 5
    assert not np.isfinite(u.block_spread()).any(), u.block_chi2
