"""The per-window data an evaluator binds is written into its buffer a block of windows at a time,
and a re-binding to the same windows writes the clock rows alone: the same bits as the matrix
stacked row block by row block and padded (the former path), with no stacked copy made."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SCENARIOS

from nlp_calib import Calibration, load_scenario
from nlp_calib.logs import resample_encoders
from nlp_calib.problem import windows
from nlp_calib.problem.windows import ResidualData
from nlp_calib.solvers.backends import pad_columns


def _stacked(data: ResidualData) -> np.ndarray:
    """``[z, clock, w]`` as the rows stacked over every window at once (the former path)."""
    n = data.n_residuals
    rows = [data.z]
    if data.clock is not None:
        which = np.searchsorted(np.asarray(data.offsets), data.starts, side="right") - 1
        select = np.zeros((len(data.logs), n))
        select[which, np.arange(n)] = 1.0
        if data.clock.lags:
            rates = data.clock.rates
            rows += [rates[:, data.starts], rates[:, data.stops], data.clock.resampled(which, data.z)[None]]
        rows.append(select)
    return np.asfortranarray(np.vstack([*rows, np.ones((1, n))]))


@pytest.mark.parametrize("name", ["demo.yaml", "camera_demo.yaml", "diff_drive_demo.yaml"])
def test_rebound_buffers_hold_the_stacked_padded_data(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """At each lag (the first bound anew, the rest re-bound in turn) the evaluator's window buffer is,
    to the bit, the stacked matrix padded, in blocks that split the windows unevenly; the buffer is
    never filled from a whole-matrix copy (``data()``)."""
    monkeypatch.setattr(windows, "WRITE_BLOCK", 1000)
    calib = Calibration(load_scenario(SCENARIOS / name))
    fns, log, binder = calib.fns, calib.log, calib.stages.problem.binder
    x = np.array(calib.x0, dtype=float)

    def no_copy(self: ResidualData) -> np.ndarray:
        raise AssertionError("the evaluator's buffer filled from a copy of the whole matrix")

    rebound = None
    for lag in (0.0, 0.013, -0.031):
        shifted, _ = resample_encoders(log, lag, fns.model.encoder_kinds)
        with monkeypatch.context() as m:
            m.setattr(ResidualData, "data", no_copy)
            ev = (
                binder.bind(shifted, *calib.fit)[1]
                if rebound is None
                else binder.rebind(rebound, shifted, *calib.fit)
            )
            ev.cost(x)
        rebound = ev
        data = ev.data
        assert data.n_residuals > 1000
        buffer = ev._on.window_data
        expected = pad_columns(_stacked(data), buffer.shape[1])
        assert buffer.shape == expected.shape and buffer.tobytes(order="F") == expected.tobytes(order="F")
        assert data.data().tobytes(order="F") == _stacked(data).tobytes(order="F")
        np.testing.assert_array_equal(data.clock_rows(), _stacked(data)[fns.sensor.z_rows : -1])
