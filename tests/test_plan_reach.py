"""What to drive next is what the robot can drive (issues 39 item 6, 43 item 5): each model says its
base's tightest turn at its steering limit and whether it turns on the spot, and no plan asks any
model for a tighter turn, a spot turn it cannot make, or a turn at a car's road speed."""

from __future__ import annotations

import dataclasses
import math
import re
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


def test_a_plan_names_what_no_manoeuvre_it_offers_determines(tmp_path: Path) -> None:
    """A highway car's steering gain and wheelbase trade off at every radius it can drive (the
    curvature is their ratio at small steer angles): the plan's manoeuvres lower the mount's σ, but
    it had said nothing of the two it leaves as loose as they were, so a driver who followed it got
    NOT DETERMINED again. It names them and the way out (known:), in the line and in plan.md; a
    tricycle's straight drive, which turns determine, names nothing."""
    from test_vehicles import _car_scenario

    from nlp_calib.outputs.plan import plan_text

    sc, _ = _car_scenario(tmp_path, seed=1)
    report = preflight(sc)
    plan = report.plan
    assert plan is not None and plan.best is not None
    assert set(plan.beyond) == {"k_steer", "wheelbase"}, plan.beyond
    # Each named one is not determined on the drive and stays so whichever manoeuvre is appended.
    loose = {p.name for p in report.parameters if p.status == "not"}
    assert set(plan.beyond) <= loose, loose
    said = "no manoeuvre considered determines k_steer, wheelbase: give what you know of them under known:"
    assert said in plan.line(), plan.line()
    assert said[1:] in plan_text(plan, "car")
    # Said too where no manoeuvre lowers the target's σ (a car's converter scenario: k_steer's).
    assert said in dataclasses.replace(plan, ranked=()).line()
    straight = preflight(load_scenario(_straight(tmp_path, "tricycle"))).plan
    assert straight is not None and straight.beyond == (), straight.beyond
    assert "no manoeuvre considered" not in straight.line()


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


def _urdf(folder: Path, steer: str, limit: str = 'lower="-0.15" upper="0.1745"') -> Path:
    """A user's URDF: the sensor on a fixed joint, the steered wheel on the joint ``steer``."""
    path = folder / "robot.urdf"
    path.write_text(
        '<?xml version="1.0"?>\n<robot name="car">\n  <link name="base_link"/>\n  <link name="my_lidar"/>\n'
        '  <link name="wheel"/>\n  <joint name="lidar_mount" type="fixed">\n    <parent link="base_link"/>'
        '<child link="my_lidar"/>\n    <origin xyz="0.5 0 0.3" rpy="0 0 0"/>\n  </joint>\n'
        f'  <joint name="{steer}" type="revolute">\n    <parent link="base_link"/><child link="wheel"/>\n'
        f'    <axis xyz="0 0 1"/>\n    <limit {limit} effort="1" velocity="1"/>\n  </joint>\n</robot>\n'
    )
    return path


@pytest.fixture(scope="module")
def car_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    import ros2_bags as rb

    pytest.importorskip("rosbags")
    folder = tmp_path_factory.mktemp("car_bag")
    rec = rb.record("car_like", seconds=30.0, seed=3)
    bag = rb.write(rec, folder / "drive", "sqlite3")
    sc = folder / "car.yaml"
    sc.write_text(
        f"name: car\nmodel: car_like\n{rb.dataset_block(bag, rec)}\ninitial_guess: auto\n"
        "residual: {horizon_s: 0.5}\nsolvers: [gauss_newton]\nvalidation: {blocks: 0}\n"
    )
    return sc, rec.joint_names[0]


def test_the_urdfs_steering_limit_bounds_the_plan_as_the_scenarios_would(
    car_bag: tuple[Path, str], tmp_path: Path
) -> None:
    """--urdf: the <limit> of the joint the steering encoder reads is the plan's reach, the plan the
    same as with vehicle.max_steering_deg at that angle (the larger end of the limit, either way)."""
    from nlp_calib.outputs import urdf
    from nlp_calib.pipeline.scenario import with_joint_limits

    path, steer = car_bag
    limits = urdf.joint_limits(urdf.load(_urdf(tmp_path, steer), "my_lidar"))
    assert limits == {steer: 0.1745}
    sc, said = with_joint_limits(load_scenario(path), limits)
    assert sc.parameters.vehicle.max_steering_deg == pytest.approx(math.degrees(0.1745))
    assert said is not None and f"joint {steer!r}" in said and "±10°" in said
    asked = load_scenario(path).with_options(vehicle=sc.parameters.vehicle)
    plans = [preflight(s).plan for s in (sc, asked)]
    assert plans[0] is not None and plans[1] is not None and plans[0].ranked
    assert [m.words for m in plans[0].ranked] == [m.words for m in plans[1].ranked]
    tightest = plans[0].size_m["wheelbase"] / math.tan(0.1745)
    assert min(m.radius_m for m in plans[0].ranked if m.radius_m > 0) >= tightest * (1 - 1e-9)
    # The scenario's own angle wins; a joint the scenario does not read, or a continuous one, says nothing.
    own = load_scenario(path).with_options(
        vehicle=dataclasses.replace(sc.parameters.vehicle, max_steering_deg=20.0)
    )
    assert with_joint_limits(own, limits) == (own, None)
    assert with_joint_limits(load_scenario(path), {"another_joint": 0.1}) == (load_scenario(path), None)


@pytest.mark.parametrize(
    ("limit", "error"),
    [
        ('lower="-0.5" upper="nan"', "<limit upper='nan'> is not a finite number of radians"),
        ('lower="left" upper="0.5"', "<limit lower='left'> is not a finite number of radians"),
        ('lower="0" upper="0"', "the steered wheel's joint 'front_steer_joint''s <limit> in the URDF is 0"),
    ],
)
def test_a_steering_limit_that_cannot_be_right_is_refused(
    limit: str, error: str, car_bag: tuple[Path, str], tmp_path: Path
) -> None:
    from nlp_calib.core.errors import UsageError
    from nlp_calib.outputs import urdf
    from nlp_calib.pipeline.scenario import with_joint_limits

    path, steer = car_bag
    with pytest.raises(UsageError, match=re.escape(error)):
        with_joint_limits(
            load_scenario(path), urdf.joint_limits(urdf.load(_urdf(tmp_path, steer, limit), "my_lidar"))
        )


def test_run_with_a_urdf_says_the_limit_it_plans_within_and_keeps_it(
    car_bag: tuple[Path, str], tmp_path: Path
) -> None:
    """The command line reads the limit from --urdf and says so; robot.urdf keeps the joint's
    <limit> as the user wrote it, read back by yourdfpy and urdf_parser_py."""
    from conftest import cli

    path, steer = car_bag
    robot = _urdf(tmp_path, steer)
    out = tmp_path / "out"
    proc = cli("run", str(path), "--out", str(out), "--urdf", str(robot), "--sensor-link", "my_lidar")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"car: the plan steers within ±10°, the URDF's <limit> of joint {steer!r}" in proc.stdout
    written = out / "robot.urdf"
    yourdfpy = pytest.importorskip("yourdfpy")
    joint = yourdfpy.URDF.load(str(written)).joint_map[steer]
    assert (joint.limit.lower, joint.limit.upper) == (-0.15, 0.1745)
    urdf_parser = pytest.importorskip("urdf_parser_py.urdf")
    (parsed,) = [j for j in urdf_parser.URDF.from_xml_string(written.read_bytes()).joints if j.name == steer]
    assert parsed.limit.upper == 0.1745
