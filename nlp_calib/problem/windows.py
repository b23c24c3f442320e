"""From a :class:`~nlp_calib.logs.Log` to the data matrix the problem Functions are mapped over.

Each column is one horizon window ``[u_0 … u_{H-1}, z, w]`` (see :mod:`nlp_calib.problem.functions`):
the model inputs of ``H`` consecutive intervals starting at record ``k``, the tracker's motion
``z = t2v(T(p_k)⁻¹·T(p_{k+H}))`` over the same records and the residual's weight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlp_calib.core.errors import ProblemError
from nlp_calib.logs import Log
from nlp_calib.problem.functions import ProblemFunctions


@dataclass(frozen=True)
class ResidualOptions:
    """How residuals are formed (scenario key ``residual``)."""

    horizon: int = 1
    stride: int = 1
    integration: str = "exact"
    steering_sample: str = "start"


@dataclass(frozen=True)
class ResidualData:
    """The data matrix of one fit, and where its windows sit in the log.

    ``columns`` is ``(data_rows, n_residuals)``; ``starts`` the first record of each window,
    relative to ``log``; ``inputs`` the per-interval inputs of every interval of ``log``.
    """

    log: Log
    inputs: np.ndarray
    columns: np.ndarray
    starts: np.ndarray
    horizon: int
    dropped_stationary: int
    dropped_faulty: int = 0

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
    log: Log,
    options: ResidualOptions,
    *,
    drop_stationary: bool = False,
    bad_intervals: np.ndarray | None = None,
    bad_records: np.ndarray | None = None,
) -> ResidualData:
    """Stack the windows of ``log`` into the data matrix of ``fns``.

    Windows without encoder motion are dropped when ``drop_stationary``; windows that cross an
    interval of ``bad_intervals`` (per interval of ``log``) or start or end at a record of
    ``bad_records`` (per record) are always dropped.
    """
    if options.horizon != fns.spec.horizon:
        raise ProblemError(
            f"data horizon {options.horizon} does not match the built problem's {fns.spec.horizon}"
        )
    model = fns.model
    inputs = model.inputs(log, options.steering_sample)
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
    faulty = np.zeros(starts.size, dtype=bool)
    if bad_intervals is not None and np.any(bad_intervals):
        bad = np.concatenate([[0], np.cumsum(np.asarray(bad_intervals, dtype=np.int64))])
        faulty |= bad[starts + H] - bad[starts] > 0
    if bad_records is not None and np.any(bad_records):
        faulty |= np.asarray(bad_records)[starts] | np.asarray(bad_records)[starts + H]
    starts = starts[~faulty]
    n_in = inputs.shape[0]
    columns = np.empty((fns.data_rows, starts.size), order="F")
    # Window inputs, interval-major: rows j*n_in:(j+1)*n_in hold interval starts+j.
    for j in range(H):
        columns[j * n_in : (j + 1) * n_in, :] = inputs[:, starts + j]
    columns[n_in * H : n_in * H + 3, :] = tracker_motions(fns, log.T_world_sensor, starts, H)
    columns[-1, :] = 1.0
    return ResidualData(
        log=log,
        inputs=inputs,
        columns=columns,
        starts=starts,
        horizon=H,
        dropped_stationary=dropped,
        dropped_faulty=int(faulty.sum()),
    )
