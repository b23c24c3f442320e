"""From a :class:`Dataset` to the data matrix the problem Functions are mapped over.

Each column is one horizon window ``[u_0 … u_{H-1}, z, w]`` (see :mod:`nlp_calib.symbolic.builder`):
the model inputs of ``H`` consecutive intervals starting at record ``k``, the tracker's motion
``z = t2v(T(p_k)⁻¹·T(p_{k+H}))`` over the same records and the residual's weight.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.errors import ScenarioError
from nlp_calib.io.logfile import COUNTER_MODULUS, Dataset, is_absolute_encoder, wrapped_difference
from nlp_calib.symbolic.builder import ProblemFunctions


@dataclass(frozen=True)
class ResidualOptions:
    """How residuals are formed (scenario key ``residual``)."""

    horizon: int = 1
    stride: int = 1
    integration: str = "exact"
    steering_sample: str = "start"


@dataclass(frozen=True)
class ResidualData:
    """The data matrix of one fit, and where its windows sit in the dataset.

    ``columns`` is ``(data_rows, n_residuals)``; ``starts`` the first record of each window,
    relative to ``dataset``; ``inputs`` the per-interval inputs of every interval of ``dataset``.
    """

    dataset: Dataset
    inputs: np.ndarray
    columns: np.ndarray
    starts: np.ndarray
    horizon: int
    dropped_stationary: int

    @property
    def n_residuals(self) -> int:
        return int(self.columns.shape[1])


def tracker_motions(
    fns: ProblemFunctions, T_world_sensor: np.ndarray, starts: np.ndarray, horizon: int
) -> np.ndarray:
    """``t2v(T(p_k)⁻¹·T(p_{k+H}))`` for each ``k`` in ``starts``, ``(3, len(starts))``."""
    if starts.size == 0:
        return np.zeros((3, 0))
    a = T_world_sensor[starts].T
    b = T_world_sensor[starts + horizon].T
    return np.asarray(fns.between.map(starts.size)(a, b))


def window_starts(n_intervals: int, horizon: int, stride: int) -> np.ndarray:
    """First interval of every full window of ``horizon`` intervals, ``stride`` apart."""
    if n_intervals < horizon:
        return np.zeros(0, dtype=np.int64)
    return np.arange(0, n_intervals - horizon + 1, stride, dtype=np.int64)


def build_residual_data(
    fns: ProblemFunctions,
    dataset: Dataset,
    options: ResidualOptions,
    *,
    drop_stationary: bool = False,
) -> ResidualData:
    """Stack the windows of ``dataset`` into the data matrix of ``fns``."""
    if options.horizon != fns.spec.horizon:
        raise ValueError(
            f"data horizon {options.horizon} does not match the built problem's {fns.spec.horizon}"
        )
    model = fns.model
    inputs = model.inputs(dataset, options.steering_sample)
    n_intervals = inputs.shape[1]
    H = options.horizon
    starts = window_starts(n_intervals, H, options.stride)
    offsets = np.arange(H)
    dropped = 0
    if drop_stationary and starts.size:
        moving = model.moving(inputs)
        keep = moving[starts[:, None] + offsets[None, :]].any(axis=1)
        dropped = int((~keep).sum())
        starts = starts[keep]
    n_in = inputs.shape[0]
    columns = np.empty((fns.data_rows, starts.size), order="F")
    # Window inputs, interval-major: rows j*n_in:(j+1)*n_in hold interval starts+j.
    for j in range(H):
        columns[j * n_in : (j + 1) * n_in, :] = inputs[:, starts + j]
    columns[n_in * H : n_in * H + 3, :] = tracker_motions(fns, dataset.T_world_sensor, starts, H)
    columns[-1, :] = 1.0
    return ResidualData(
        dataset=dataset,
        inputs=inputs,
        columns=columns,
        starts=starts,
        horizon=H,
        dropped_stationary=dropped,
    )


def shift_encoders(dataset: Dataset, lag_s: float) -> tuple[Dataset, tuple[int, int]]:
    """Encoder readings re-sampled at ``t - lag_s``: the tracker reports ``lag_s`` after the encoders.

    Shifting the inputs rather than the tracker keeps the measurements, and so the cost, comparable
    across lags. Counters are interpolated on their unwrapped cumulative count, absolute encoders on
    their unwrapped angle. Returns the dataset and the record range ``[first, stop)`` whose shifted
    times lie inside the log (outside it the readings are clamped and must not be used).
    """
    if lag_s == 0.0:
        return dataset, (0, dataset.n_records)
    t = dataset.time_s
    tq = t - lag_s
    columns = []
    for j, (name, vmax) in enumerate(zip(dataset.header.encoder_names, dataset.header.encoder_max)):
        raw = dataset.ticks[:, j]
        if is_absolute_encoder(name):
            turns = np.unwrap(2.0 * np.pi * raw / vmax) / (2.0 * np.pi)
            columns.append(np.mod(np.round(np.interp(tq, t, turns) * vmax), vmax))
        else:
            count = np.concatenate([[0], np.cumsum(wrapped_difference(raw))]).astype(float)
            columns.append(np.mod(np.round(np.interp(tq, t, count)) + raw[0], COUNTER_MODULUS))
    ticks = np.stack(columns, axis=1).astype(np.int64)
    ticks.flags.writeable = False
    valid = np.flatnonzero((tq >= t[0]) & (tq <= t[-1]))
    if valid.size < 2:
        raise ScenarioError(
            f"alignment.tracker_lag: a lag of {lag_s:g} s leaves fewer than 2 records of the "
            f"{t[-1] - t[0]:.1f} s log; use a lag well below the log's duration"
        )
    return replace(dataset, ticks=ticks), (int(valid[0]), int(valid[-1]) + 1)
