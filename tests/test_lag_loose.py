"""A tracker lag the drive does not determine is named so, never given a σ it does not have.

On circles at constant speed, turning one way and then the other (the simulator's ``circles``),
the wheels' speeds change only at the start and at the turn's reversal. The problem's clock
correction reads the rates at each window's ends from the rounded readings, whose differences are
then rounding alone: the fitted lag followed the lag the encoders were re-sampled at, settled
where that noise crossed zero, and its white-noise σ was the noise's (3000 records, seed 9901:
−90 ms ± 13 ms under GOOD, the truth 0, −7.2σ). The alignment now re-samples the encoders several
σ off the settled lag and fits there (``_LagFits.returned``): a lag those fits do not return to is
not determined."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import RETURNS, LagEstimate
from nlp_calib.simulation import SimulationOptions, simulate
from nlp_calib.simulation.simulate import write_simulation

LAG = "tracker_lag"


def _run(tmp_path: Path, trajectory: str, seed: int, records: int) -> CalibrationRun:
    sim = SimulationOptions.of(model="diff_drive", records=records, seed=seed, trajectory=trajectory)
    log, _ = write_simulation(simulate(sim), tmp_path / "log.txt")
    raw = {"dataset": str(log), "model": "diff_drive", "initial_guess": "from_file"}
    raw["solvers"] = ["gauss_newton"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Calibration(scenario_from_mapping(raw, trajectory, tmp_path)).run()


def _lag_z(run: CalibrationRun) -> tuple[float, float]:
    """The fitted lag's σ to believe and its error in it against the simulator's truth."""
    truth = run.checks.truth
    assert truth is not None and LAG in truth.names
    return run.std("gauss_newton")[LAG], float(truth.z[truth.names.index(LAG)])


@pytest.mark.parametrize("seed", [9901, 3])
def test_the_lag_of_constant_circles_each_way_is_within_3_sigma_or_named_not_determined(
    tmp_path: Path, seed: int
) -> None:
    """Both seeds' lags came out GOOD beyond 7σ of the truth (−7.2σ, −7.6σ): now either within
    3σ of it, or held with no σ and the verdict naming the lag not determined."""
    run = _run(tmp_path, "circles", seed, 3000)
    std, z = _lag_z(run)
    if np.isfinite(std):
        assert abs(z) <= 3.0, (z, std)
    else:
        est = run.data.lag_estimate
        assert est is not None and est.loose and run.pinned() == (LAG,)
        assert "the tracker lag is not determined by this drive" in run.verdict.line()


def test_a_lag_the_drive_determines_returns_and_keeps_its_sigma(tmp_path: Path) -> None:
    """The control: turns, stops and reversals determine the lag; the fits re-sampled off it take
    the whole offset back, and the lag keeps its σ, within 3σ of the truth."""
    run = _run(tmp_path, "s_curves", 9901, 1200)
    est = run.data.lag_estimate
    assert est is not None and est.returned is not None
    assert est.returned > 0.8 > RETURNS and not est.loose and run.pinned() == ()
    std, z = _lag_z(run)
    assert np.isfinite(std) and abs(z) <= 3.0


@pytest.mark.parametrize(
    ("share", "std"), [(1.0, None), (0.9, None), (0.5, 0.004), (0.3, 0.002 / 0.3), (0.2, None)]
)
def test_a_lag_its_fits_return_to_in_part_has_its_white_sigma_over_the_share(
    share: float, std: float | None
) -> None:
    """Taken back within the noise of a full return (above SHORT, 0.85) the white σ stands; a part
    beyond it, the white σ over the share (a skid steer's circles, seed 3: 0.37, its lag 61.5 ±
    29 ms, +2.1σ of the truth, +2.8σ before); below RETURNS the lag has none: not determined."""
    est = LagEstimate(0.01, (0.0,), (1.0,), returned=share)
    got = est.returned_std(0.002)
    assert np.isnan(got) if std is None else got == pytest.approx(std), got
    assert est.loose == (share < RETURNS) and est.pinned == est.loose
