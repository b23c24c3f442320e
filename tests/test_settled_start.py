"""The solvers start where the lag stage's fit settled (nearly the fit's optimum on nearly the same
windows), not at the initial guess again, and never at a point that explains the windows worse."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import SCENARIOS, write_sim

from nlp_calib import Calibration, load_scenario
from nlp_calib.pipeline.align import white_std
from nlp_calib.pipeline.build import at_lags
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.stages import align_stage
from nlp_calib.solvers import ProblemEvaluator

#: The two starts' optima agree within this share of each parameter's white-noise σ.
SAME_OPTIMUM_SIGMAS = 0.05


@contextmanager
def passes(ev: ProblemEvaluator | None = None) -> Iterator[dict[str, int]]:
    """Full passes over their windows (normal equations, costs) of ``ev`` (None: every evaluator)
    while the block runs; a point evaluated before is kept by the evaluator and costs no pass."""
    counted = {"normal_equations": 0, "cost": 0}
    owner = ProblemEvaluator if ev is None else ev
    call = owner._call

    def counting(*args):  # type: ignore[no-untyped-def]
        name = args[-2]
        if name in counted:
            counted[name] += 1
        return call(*args)

    owner._call = counting  # type: ignore[method-assign]
    try:
        yield counted
    finally:
        if ev is None:
            ProblemEvaluator._call = call  # type: ignore[method-assign]
        else:
            del ev._call


def _white_sigma(fit: Fit, x: np.ndarray) -> np.ndarray:
    """Each free parameter's white-noise σ at ``x`` on ``fit``'s windows."""
    ne = fit.evaluator.normal_equations(x)
    dof = fit.fns.error_rows * fit.evaluator.n_residuals - fit.fns.n_free
    sigma = np.array([white_std(ne.H, ne.cost / dof, i) for i in range(fit.fns.n_free)])
    assert np.all(sigma > 0)
    return sigma


def _from_guess(fit: Fit) -> Fit:
    """``fit``'s problem on the same windows, without a settled start: the solvers from the guess."""
    start = dataclasses.replace(fit.problem.start, settled=None)
    return Fit(dataclasses.replace(fit.problem, start=start), fit.data, ("gauss_newton",), fit.noise)


@pytest.fixture(scope="module")
def calibration(tmp_path_factory: pytest.TempPathFactory) -> Calibration:
    # Seed 71: never tuned on; the lag fitted (the demo's default), 45 ms simulated.
    log = write_sim(tmp_path_factory.mktemp("settled"), records=3000, seed=71, latency_s=0.045)
    return Calibration(load_scenario(SCENARIOS / "demo.yaml").with_options(dataset=log))


def test_the_fit_from_the_settled_start_ends_at_the_same_optimum_in_fewer_passes(
    calibration: Calibration,
) -> None:
    fit = calibration.fitting
    start = fit.problem.start
    assert start.settled is not None and calibration.alignment.estimate is not None
    # The settled lag is the one the encoders were re-sampled at.
    lag = fit.fns.free.index("tracker_lag")
    assert start.settled[lag] == calibration.alignment.lag_s
    # The initial guess stays what every figure is judged against.
    assert np.array_equal(start.x0, [start.initial[n] for n in fit.fns.free])
    assert not np.allclose(start.settled, start.x0)
    with passes(fit.evaluator) as settled:
        near = fit.solve("gauss_newton")
    guess = _from_guess(fit)
    with passes(guess.evaluator) as initial:
        far = guess.solve("gauss_newton")
    assert near.converged and far.converged
    assert np.array_equal(fit.solvers_start(), start.settled)
    assert np.array_equal(guess.solvers_start(), start.x0)
    sigma = _white_sigma(fit, far.x)
    assert np.all(np.abs(near.x - far.x) <= SAME_OPTIMUM_SIGMAS * sigma), (near.x - far.x) / sigma
    # The guess's own cost is the one pass the choice of start adds.
    assert settled["cost"] == initial["cost"] + 1
    assert settled["normal_equations"] <= initial["normal_equations"] - 2, (settled, initial)


def test_every_solver_starts_from_one_point(calibration: Calibration) -> None:
    fit = calibration.fitting
    results = {name: fit.solve(name) for name in ("gauss_newton", "ipopt")}
    assert all(r.converged for r in results.values())
    gn, ip = results["gauss_newton"], results["ipopt"]
    sigma = _white_sigma(fit, gn.x)
    assert np.all(np.abs(gn.x - ip.x) <= SAME_OPTIMUM_SIGMAS * sigma)


def test_the_lag_stage_starts_from_the_screens_judging_fit(tmp_path: Path) -> None:
    """The lag's fits from where the screen's judging fit converged (its lag held at the guess's)
    settle where they do from the guess, in fewer passes (a lag the guess has already: one fit
    settles it, and that fit starts at its optimum but for the lag; seed 73, never tuned on)."""
    log = write_sim(tmp_path, records=3000, seed=73, latency_s=0.0)
    calibration = Calibration(load_scenario(SCENARIOS / "demo.yaml").with_options(dataset=log))
    setup, fit = calibration.stages, calibration.fitting
    judged, estimate = setup.screening.judged, setup.alignment.estimate
    assert judged is not None and estimate is not None
    lag = fit.fns.free.index("tracker_lag")
    assert judged[lag] == estimate.path_s[0]  # the lag re-sampled at first: the guess's
    # The problem as the lag stage had it: its lag at the guess's, not yet at the one it found.
    problem = at_lags(setup.problem, [estimate.path_s[0]])
    with passes() as near:
        again = align_stage(problem, setup.prepared, setup.screening)
    unjudged = dataclasses.replace(setup.screening, judged=None)
    with passes() as far:
        guess = align_stage(problem, setup.prepared, unjudged)
    assert again.settled is not None and guess.settled is not None
    assert np.array_equal(again.settled, fit.problem.start.settled)
    sigma = _white_sigma(fit, again.settled)
    assert np.all(np.abs(again.settled - guess.settled) <= SAME_OPTIMUM_SIGMAS * sigma)
    assert abs(again.lag_s - guess.lag_s) <= SAME_OPTIMUM_SIGMAS * sigma[lag]
    assert near["normal_equations"] < far["normal_equations"], (near, far)


def test_a_start_worse_than_the_initial_guess_is_refused(calibration: Calibration) -> None:
    fit = calibration.fitting
    start = fit.problem.start
    assert start.settled is not None
    # The settled point pushed a long way along the gains: it explains the windows worse.
    worse = start.settled.copy()
    for name in ("k_steer", "k_traction"):
        worse[fit.fns.free.index(name)] *= 1.5
    problem = dataclasses.replace(fit.problem, start=dataclasses.replace(start, settled=worse))
    refused = Fit(problem, fit.data, ("gauss_newton",), fit.noise)
    assert refused.evaluator.cost(worse) > refused.evaluator.cost(start.x0)
    assert np.array_equal(refused.solvers_start(), start.x0)
    # Within the bounds: a settled point outside them is clipped onto them first.
    if start.lower is not None and start.upper is not None:
        assert np.all(refused.solvers_start() >= start.lower)


def test_several_logs_fitted_together_start_from_the_guess(tmp_path: Path) -> None:
    """A joint fit's problem is not a lag stage's (a lag per log): its solvers start from the
    guess; each log's own fit from its lag stage's settled fit."""
    logs = [write_sim(tmp_path, f"l{i}.txt", records=600, seed=72 + i) for i in range(2)]
    path = tmp_path / "joint.yaml"
    given = {"name": "joint", "model": "tricycle", "datasets": [str(p) for p in logs]}
    path.write_text(yaml.safe_dump({**given, "initial_guess": "from_file", "solvers": ["gauss_newton"]}))
    joint = Calibration(load_scenario(path), solvers=("gauss_newton",))
    assert joint.fitting.problem.start.settled is None
    assert np.array_equal(joint.fitting.solvers_start(), joint.fitting.problem.start.x0)
    assert all(part.problem.start.settled is not None for part in joint.parts)
