"""The lag's fits and profile re-bind one evaluator to each re-sampling: the same windows, data and
cost as binding the re-sampled log anew."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import SCENARIOS

from nlp_calib import Calibration, load_scenario
from nlp_calib.logs import resample_encoders
from nlp_calib.pipeline.align import PROFILE_RECORDS, _LagFits, lag_column


def _same_data(a: object, b: object) -> None:
    for field in ("inputs", "T_world_sensor", "starts", "stops", "z"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    ca, cb = a.clock, b.clock  # type: ignore[attr-defined]
    assert (ca is None) == (cb is None)
    if ca is not None:
        assert (ca.lags, ca.beside) == (cb.lags, cb.beside)
        np.testing.assert_array_equal(ca.rates, cb.rates)
    assert [lg.encoder_lag_s for lg in a.logs] == [lg.encoder_lag_s for lg in b.logs]  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("name", "drop_stationary"), [("demo.yaml", False), ("demo.yaml", True), ("camera_demo.yaml", False)]
)
def test_an_evaluator_rebound_to_each_resampling_is_a_new_binds(name: str, drop_stationary: bool) -> None:
    """At each lag (the first bound anew, the rest re-bound in turn) the windows' data, cost and
    normal equations are those of an evaluator bound anew to the log re-sampled there."""
    sc = load_scenario(SCENARIOS / name)
    samples = dataclasses.replace(sc.log.samples, drop_stationary=drop_stationary)
    calib = Calibration(sc.with_options(samples=samples))
    fns, log, binder = calib.fns, calib.log, calib.stages.problem.binder
    x = np.array(calib.x0, dtype=float)
    column = lag_column(binder)
    assert column is not None
    rebound = None
    for lag in (0.0, 0.013, -0.031, 0.002):
        shifted, _ = resample_encoders(log, lag, fns.model.encoder_kinds)
        fresh = binder.bind(shifted, *calib.fit)[1]
        rebound = (
            binder.bind(shifted, *calib.fit)[1]
            if rebound is None
            else binder.rebind(rebound, shifted, *calib.fit)
        )
        _same_data(rebound.data, fresh.data)
        x[column] = lag
        assert rebound.cost(x) == fresh.cost(x)
        np.testing.assert_array_equal(rebound.normal_equations(x).H, fresh.normal_equations(x).H)


def test_the_profile_is_the_cost_bound_anew_at_each_lag() -> None:
    """The profile's costs (its evaluator the fits', re-bound lag by lag) are, lag by lag, those of
    an evaluator bound anew to the log re-sampled there."""
    calib = Calibration(load_scenario(SCENARIOS / "demo.yaml"))
    fns, log, binder = calib.fns, calib.log, calib.stages.problem.binder
    column = lag_column(binder)
    assert column is not None
    assert calib.fit[1] - calib.fit[0] <= PROFILE_RECORDS  # the fits' records are the profile's
    fits = _LagFits(binder, log, calib.fit, column)
    x = np.array(calib.x0, dtype=float)
    fits.fit(x)  # the evaluator the profile then re-binds
    grid, costs = fits.profile(x)
    for lag, cost in zip(grid[::8], costs[::8]):
        shifted, _ = resample_encoders(log, float(lag), fns.model.encoder_kinds)
        at = x.copy()
        at[column] = lag
        assert cost == binder.bind(shifted, *calib.fit)[1].cost(at)


def test_the_coordinates_a_scan_reads_are_found_once_per_step(monkeypatch: pytest.MonkeyPatch) -> None:
    """CasADi's dependency analysis of a prefix scan's step (milliseconds: it walks the step's
    graph) runs once per step Function, not at every evaluator bound; what it finds is the step's."""
    import casadi as ca

    from nlp_calib.solvers import motion

    motion.reads.cache_clear()
    analysed: list[int] = []
    real = ca.Function.which_depends

    def counted(self: ca.Function, *args: object) -> object:
        analysed.append(hash(self))
        return real(self, *args)

    monkeypatch.setattr(ca.Function, "which_depends", counted)
    calib = Calibration(load_scenario(SCENARIOS / "demo.yaml"))
    binder, x = calib.stages.problem.binder, np.array(calib.x0, dtype=float)
    for _ in range(3):
        binder.bind(calib.log, *calib.fit)[1].normal_equations(x)
    assert analysed and len(analysed) == len(set(analysed))
    step = calib.fns.step(1)
    expected = np.flatnonzero(real(step, "x", [step.name_out(0)], 1, False))
    np.testing.assert_array_equal(motion.reads(step), expected)


def test_windows_the_sensors_start_chooses_are_built_once_per_rebound_evaluator(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Issue 41: where the sensor's start chooses the windows by the inputs (a camera's), a rebound
    evaluator's windows before the choice are built at its first rebind alone (they do not depend
    on the encoders); each re-sampling chooses among them again: a new bind's windows."""
    from nlp_calib.pipeline import build

    calib = Calibration(load_scenario(SCENARIOS / "camera_demo.yaml"))
    fns, log, binder = calib.fns, calib.log, calib.stages.problem.binder
    assert binder.start is not None and binder.start.selection is not None
    built: list[int] = []
    own = build.build_residual_data
    monkeypatch.setattr(build, "build_residual_data", lambda *a, **k: built.append(1) or own(*a, **k))
    rebound = binder.bind(log, *calib.fit)[1]
    for lag in (0.013, -0.031, 0.002, 0.021):
        shifted, _ = resample_encoders(log, lag, fns.model.encoder_kinds)
        rebound = binder.rebind(rebound, shifted, *calib.fit)
        chosen = rebound.data
        fresh = binder.bind(shifted, *calib.fit)[1].data
        _same_data(chosen, fresh)
        assert chosen.dropped_selection == fresh.dropped_selection
    # One bind, its first rebind and the four fresh binds built windows; the other rebinds none.
    assert len(built) == 1 + 1 + 4
