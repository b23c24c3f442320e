"""How an interval's steering is read from its two readings, held as a value (the held check,
``residual.steering_sample``): the estimate's move between the readings' mean and the angle the
interval's travel saw goes into the σ to believe. A precise tracker on a drive that leaves its
stops more sharply than it reaches them otherwise gave the lag beyond 3σ under GOOD."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import write_sim

from nlp_calib import Calibration, scenario_from_mapping
from nlp_calib.models import get_model, load_log
from nlp_calib.models.base import sampled_angle
from nlp_calib.results import CalibrationRun

STEERING = "residual.steering_sample"
LAG = "tracker_lag"


def _fitted(log: Path, folder: Path, sample: str) -> CalibrationRun:
    """The demo's fit (a tricycle, horizon 10) of ``log`` with its steering read as ``sample``."""
    doc = {
        "dataset": str(log),
        "model": "tricycle",
        "initial_guess": "from_file",
        "robust": {"kernel": "huber", "delta": 0.05},
        "residual": {"horizon": 10, "stride": 1, "integration": "exact", "steering_sample": sample},
        "solvers": ["gauss_newton"],
    }
    return Calibration(scenario_from_mapping(doc, f"steer_{sample}", folder)).run(["gauss_newton"])


def _record(run: CalibrationRun) -> dict[str, object]:
    held = next((c for c in run.checks.more if c.name == "held"), None)
    assert held is not None and STEERING in held.record["held"], held
    return dict(held.record["held"][STEERING])


def test_the_steering_readings_response_is_the_refit_with_the_other_reading(tmp_path: Path) -> None:
    """What the check says the other reading moves each parameter by is what a fit with the
    steering read as the travel saw it moves it by (the fit's own: the readings' mean)."""
    log = write_sim(
        tmp_path, "drive.txt", records=4000, seed=57, tracker_noise_xy=2e-4, tracker_noise_theta=2e-4
    )
    mean, travel = (_fitted(log, tmp_path, s) for s in ("mean", "travel"))
    shift = _record(mean)["shift"]
    assert isinstance(shift, dict)
    at, moved = (r.reports["gauss_newton"].result.param_dict() for r in (mean, travel))
    std = mean.std("gauss_newton")
    compared = [n for n, s in shift.items() if abs(s) > 0.2 * std[n]]
    assert LAG in compared, shift
    for name in compared:
        assert moved[name] - at[name] == pytest.approx(shift[name], rel=0.15), name


def test_a_precise_trackers_lag_lies_within_its_sigma_to_believe(tmp_path: Path) -> None:
    """The demo's drive at 0.2 mm / 0.2 mrad of tracker noise: the readings' mean steering biased
    the lag by -3.5σ of the data's σ (GOOD). Its σ to believe carries the move to the other
    reading (std_held), and the lag lies within 3σ of its truth (0)."""
    log = write_sim(
        tmp_path, "drive.txt", records=20000, seed=4243, tracker_noise_xy=2e-4, tracker_noise_theta=2e-4
    )
    run = _fitted(log, tmp_path, "mean")
    lag, std = run.reports["gauss_newton"].result.param_dict()[LAG], run.std("gauss_newton")[LAG]
    assert abs(lag) < 3.0 * std, (lag / std, run.verdict.line())
    shift = _record(run)["shift"]
    assert isinstance(shift, dict) and 0.0 < abs(shift[LAG]) <= std  # in the σ to believe


@pytest.mark.parametrize("model", ["car_like", "car_like_bicycle"])
def test_a_cars_steering_read_as_its_travel_saw_it(tmp_path: Path, model: str) -> None:
    """A car's ``travel`` reading weighs each steering angle by the rear wheels' summed travel (the
    speeds' ratio is what counts, not their unit)."""
    log = load_log(write_sim(tmp_path, "car.txt", records=300, seed=11, model=model), get_model(model))
    car = get_model(model)
    mean, travel = car.inputs(log, "mean"), car.inputs(log, "travel")
    wheels = car.wheel_rows()  # type: ignore[attr-defined]
    np.testing.assert_array_equal(mean[:wheels], travel[:wheels])
    steering = next(e for e, kind in car.encoder_kinds.items() if kind == "absolute")
    angle = 2.0 * np.pi * log.encoder(steering) / float(log.header.encoder_range(steering))
    expected = sampled_angle(angle, "travel", 0.5 * mean[:wheels].sum(axis=0), np.asarray(log.time_s))
    np.testing.assert_allclose(travel[wheels], expected, rtol=0, atol=1e-12)
    assert np.max(np.abs(travel[wheels] - mean[wheels])) > 1e-6
