"""What to drive next is what the robot can drive (issues 39 item 6, 43 item 5): each model says its
base's tightest turn at its steering limit and whether it turns on the spot, and no plan asks any
model for a tighter turn, a spot turn it cannot make, or a turn at a car's road speed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import write_sim

from nlp_calib.analysis.plan import LATERAL_ACCEL, REVERSE_SPEED
from nlp_calib.core.errors import ScenarioError
from nlp_calib.models import MODELS
from nlp_calib.models.radians import default_guess
from nlp_calib.pipeline import load_scenario
from nlp_calib.pipeline.preflight import preflight

CAR_MODELS = {"car_like", "car_like_ackermann", "car_like_bicycle"}


@pytest.mark.parametrize("name", list(MODELS))
def test_every_model_says_how_tight_its_base_turns(name: str) -> None:
    for model in (MODELS[name], MODELS[name].in_radians()):
        guess = default_guess(model)
        reach = model.reach(guess)
        if name in CAR_MODELS:
            inner = 0.5 * guess.get("steering_track", guess.get("steering_track_width", 0.0))
            assert reach.min_radius_m == pytest.approx(
                guess["wheelbase"] / math.tan(math.radians(35)) + inner
            )
            assert not reach.spot_turns
            tighter = model.reach(guess, math.radians(45))
            assert tighter.min_radius_m == pytest.approx(guess["wheelbase"] + inner)
        elif name.startswith("tricycle"):
            length = guess.get("axis_length", guess.get("wheelbase"))
            assert reach.spot_turns  # its steered drive wheel turns a quarter turn
            assert model.reach(guess, math.radians(30)).min_radius_m == pytest.approx(
                length / math.tan(math.radians(30))
            )
        else:
            assert reach.spot_turns and reach.steer_max_rad is None


def _straight(tmp_path: Path, name: str, vehicle: str = "") -> Path:
    log = write_sim(tmp_path, "straight.txt", model=name, records=600, seed=3, trajectory="straight")
    path = tmp_path / "straight.yaml"
    path.write_text(
        f"name: straight\nmodel: {name}\ndataset: {log.name}\ninitial_guess: from_file\n"
        f"residual: {{horizon: 10}}\nsolvers: [gauss_newton]\n{vehicle}"
    )
    return path


@pytest.mark.parametrize("name", list(MODELS))
def test_no_plan_asks_a_model_for_a_turn_it_cannot_make(name: str, tmp_path: Path) -> None:
    """A straight drive says nothing of how far the robot steers: the model's own limit bounds the
    plan (a car was asked for turns on the spot)."""
    report = preflight(load_scenario(_straight(tmp_path, name)))
    plan = report.plan
    assert plan is not None and plan.ranked, report.way_out
    kinds = {m.kind for m in plan.ranked}
    for m in plan.ranked:
        print(name, m.words)
        if m.radius_m > 0:
            assert m.speed_mps**2 / m.radius_m <= LATERAL_ACCEL * (1 + 1e-9)
    if name in CAR_MODELS:
        assert "spot_turns" not in kinds
        tightest = plan.size_m["wheelbase"] / math.tan(math.radians(35))
        assert min(m.radius_m for m in plan.ranked if m.radius_m > 0) >= tightest
    elif name in ("diff_drive", "skid_steer"):
        assert "spot_turns" in kinds


def test_a_scenario_says_how_far_its_car_steers(tmp_path: Path) -> None:
    path = _straight(tmp_path, "car_like", "vehicle: {max_steering_deg: 10}\n")
    plan = preflight(load_scenario(path)).plan
    assert plan is not None and plan.ranked
    tightest = plan.size_m["wheelbase"] / math.tan(math.radians(10))
    radii = [m.radius_m for m in plan.ranked if m.radius_m > 0]
    assert radii and min(radii) >= tightest
    path.write_text(path.read_text().replace("10}", "120}"))
    with pytest.raises(ScenarioError, match=r"vehicle.max_steering_deg: must be a number in \(0, 90\]"):
        load_scenario(path)


def test_a_highway_cars_plan_is_driven_at_a_circles_speed_and_reversed_slowly(tmp_path: Path) -> None:
    from test_vehicles import _car_scenario

    sc, opts = _car_scenario(tmp_path, seed=1)
    plan = preflight(sc).plan
    assert plan is not None and plan.best is not None
    kinds = {m.kind: m for m in plan.ranked}
    assert "spot_turns" not in kinds
    for m in plan.ranked:
        assert m.speed_mps <= opts.max_speed
        if m.kind in ("reversals", "arcs_backwards"):
            assert m.speed_mps <= REVERSE_SPEED
        if m.radius_m > 0:
            assert m.radius_m >= opts.truth["wheelbase"] / math.tan(math.radians(35))
            assert m.speed_mps**2 / m.radius_m <= LATERAL_ACCEL * (1 + 1e-9)
    assert np.isfinite(plan.best.target_std_after)


def test_plan_md_states_the_runs_sigma_of_its_target(tmp_path: Path) -> None:
    """One σ per parameter: plan.md's σ of its target is the run's 1σ as the summary states it (it
    gave the white-noise σ of the plan's own information, 0.25 m against the summary's ±0.052 m)."""
    import warnings

    from nlp_calib.outputs.plan import plan_text
    from nlp_calib.pipeline import Calibration

    log = write_sim(tmp_path, "car.txt", model="car_like", seed=3)
    path = tmp_path / "car.yaml"
    path.write_text(f"name: car\nmodel: car_like\ndataset: {log.name}\nsolvers: [gauss_newton]\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(load_scenario(path)).run(["gauss_newton"])
    plan = run.checks.plan
    assert plan is not None and plan.best is not None
    std = run.std("gauss_newton")[plan.target]
    print(plan.target, std, plan.target_std_before, plan.best.words)
    assert plan.target_std_before == pytest.approx(std, rel=1e-12)
    assert f"σ {std:.3g} {plan.target_unit} (the run's 1σ" in plan_text(plan, "car")
    # The manoeuvre that lowers it most asks a turn the car can steer, wider than its own lock.
    assert plan.best.target_std_after < std
    wheelbase = run.reports["gauss_newton"].result.param_dict()["wheelbase"]
    assert all(m.radius_m == 0 or m.radius_m >= wheelbase / math.tan(math.radians(35)) for m in plan.ranked)
    assert "spot_turns" not in {m.kind for m in plan.ranked}
