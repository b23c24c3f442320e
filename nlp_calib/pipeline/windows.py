"""The bind stage: a log's residual windows on the tracker's clock, clear of its faults.

The records used are those the selection asks for whose re-sampled encoder readings lie inside the
log; the fitted ones end where the hold-out starts. Everything a log's figures are computed on
(its used records, the masks of its faults) is kept with its windows.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.logs import Log
from nlp_calib.models import counted_inputs
from nlp_calib.pipeline.align import Alignment
from nlp_calib.pipeline.build import Binder, Problem
from nlp_calib.pipeline.prepare import PreparedLog, split
from nlp_calib.pipeline.screen import Screening, exclude_faults, fault_masks, median_interval
from nlp_calib.problem import ResidualData
from nlp_calib.results.faults import GROUND_KINDS


@dataclass(frozen=True)
class LogWindows:
    """A log's fitted windows and what its figures need: the records ``used`` and ``fit`` of the
    aligned log, its fault masks (per interval and per record of the whole log), the binder that
    keeps its windows clear of faults, each model input's noise (1σ; a counter's, ``counted``, on
    its readings) and, per interval of the whole log, where its records do not connect (gaps in
    time, a reference's missing increments, the joints' breaks): no track runs across them."""

    aligned: Log
    used: tuple[int, int]
    fit: tuple[int, int]
    data: ResidualData
    binder: Binder
    bad_intervals: np.ndarray
    bad_records: np.ndarray
    input_noise_std: np.ndarray
    counted: np.ndarray
    breaks: np.ndarray | None = None
    #: Per interval of the whole log, where only the ground's faults (a slipped pivot) spoil it:
    #: out of the fit and the drift, stated apart (the robot's own odometry meets them).
    ground: np.ndarray | None = None

    @property
    def input_noise(self) -> tuple[np.ndarray, np.ndarray]:
        """Each model input's noise (1σ) and whether it is a counter's (noise on its readings)."""
        return self.input_noise_std, self.counted

    @property
    def selected(self) -> Log:
        """The used records of the aligned log."""
        return self.aligned.select(*self.used)

    def inputs(self, steering_sample: str) -> np.ndarray:
        """The model inputs of every interval of the used records."""
        return self.binder.fns.model.inputs(self.selected, steering_sample)

    def masks(self) -> tuple[np.ndarray, np.ndarray]:
        """The fault masks over the used intervals and records."""
        a, b = self.used
        return self.bad_intervals[a : b - 1], self.bad_records[a:b]

    def used_breaks(self) -> np.ndarray:
        """Where the used records do not connect, per used interval."""
        return self.breaks_between(*self.used)

    def breaks_between(self, a: int, b: int) -> np.ndarray:
        """Where records ``a`` to ``b`` of the log do not connect, per interval."""
        return np.zeros(max(b - a - 1, 0), dtype=bool) if self.breaks is None else self.breaks[a : b - 1]


def bind_windows(
    problem: Problem, prepared: PreparedLog, screening: Screening, alignment: Alignment
) -> LogWindows:
    """The windows of the fitted records of ``prepared``'s log, aligned and screened."""
    sc, log = prepared.scenario, prepared.log
    dt = median_interval(log)
    binder = exclude_faults(problem.binder, screening.findings, log.n_records, alignment.lag_s, dt)
    report = screening.findings.report
    # Every detected fault shapes the fair figures, whatever the handling: like with like.
    bad_intervals, bad_records = fault_masks(report, log.n_records, alignment.lag_s, dt)
    # A reference of its own motions is composed only where one-interval increments follow on, and
    # not across one left out as its own fault.
    kind = log.reference.kind
    breaks = kind.uncovered(log.n_records)
    if kind.chained:
        matches = replace(report, faults=report.reference_faults)
        n_intervals = max(log.n_records - 1, 0)
        breaks = breaks | matches.bad_intervals(n_intervals) | report.frozen_intervals(n_intervals)
    if prepared.gaps is not None:  # dead reckoning restarts after a gap, as after a fault
        breaks = breaks | prepared.gaps
    broken = alignment.log.joint_breaks()
    if broken is not None:  # where the joints are read at the lag found, their breaks too
        breaks = breaks | broken
        binder = replace(binder, gaps=broken if binder.gaps is None else binder.gaps | broken)
    bad_intervals = bad_intervals | breaks
    if report.unchecked:
        warnings.warn(f"encoder faults not checked: {report.unchecked}", NlpCalibWarning, stacklevel=3)
    start, stop = max(prepared.start, alignment.valid[0]), min(prepared.stop, alignment.valid[1])
    fit = (start, split(sc, start, stop))
    data = binder.windows(alignment.log, *fit)
    noise = problem.model.input_noise_std(alignment.log, sc.data.encoder_noise)
    counted = counted_inputs(problem.model, alignment.log)
    ground = bad_intervals & ~(
        fault_masks(report.apart(GROUND_KINDS), log.n_records, alignment.lag_s, dt)[0] | breaks
    )
    masks = (bad_intervals, bad_records, noise, counted, breaks, ground)
    return LogWindows(alignment.log, (start, stop), fit, data, binder, *masks)
