"""The screen stage: encoder and tracker faults found in a log, and how the fit is kept clear of them.

Faults are judged on the encoder readings as logged (re-sampling them would smear a faulty one),
with a fit of the log's windows by the internal solver.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.analysis.faults import check_log, repair
from nlp_calib.logs import Log, resample_encoders, resample_tracker
from nlp_calib.pipeline.build import Binder
from nlp_calib.results.faults import FaultReport, Findings


def find_faults(
    binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray, lag_s: float = 0.0
) -> FaultReport:
    """Faults in records ``start:stop`` of ``log``, judged with a fit to its windows (those the
    binder keeps) and, with a tracker ``lag_s``, against the tracker re-sampled onto the encoders'
    clock: the encoder readings stay as logged, so a jump stays on its record."""
    _, ev = binder.bind(resample_encoders(log, lag_s, binder.fns.model.encoder_kinds)[0], start, stop)
    _, x, converged = binder.fit(ev, x0)
    if not converged or not np.all(np.isfinite(x)):
        # Judged by a wrong model every interval looks faulty; the solvers will say why.
        why = "the fit that judges the encoders did not converge from the initial guess"
        return FaultReport((), {}, {}, unchecked=why)
    sel = resample_tracker(log, lag_s).select(start, stop)
    model = binder.fns.model
    inputs = model.inputs(sel, binder.scenario.objective.residual.steering_sample)
    report = check_log(binder.fns, ev.params(x), sel, inputs, model.counter_rows(sel))
    return report.shifted(start, log.line_numbers)


def handle_faults(log: Log, report: FaultReport, handling: str) -> tuple[Log, Findings]:
    """The log to fit (repaired when ``handling`` asks for it) and what was found and done."""
    if handling == "repair" and report.counter_faults:
        log, repairs = repair(log, report)
        return log, Findings(report, handling, repairs)
    return log, Findings(report, handling)


def dilate(mask: np.ndarray, reach: int) -> np.ndarray:
    """``mask`` widened by ``reach`` elements on each side of every true run."""
    if reach <= 0 or not mask.any():
        return mask
    idx = np.flatnonzero(mask)
    out = np.zeros_like(mask)
    for i in idx:
        out[max(i - reach, 0) : i + reach + 1] = True
    return out


def fault_masks(
    report: FaultReport, n_records: int, lag_s: float, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """The intervals (widened by the records a lag re-samples across) and the tracker records the
    findings mark as bad, per interval and per record of the whole log."""
    reach = int(np.ceil(abs(lag_s) / dt_s)) + 1 if lag_s else 0
    return dilate(report.bad_intervals(n_records - 1), reach), report.bad_records(n_records)


def exclude_faults(binder: Binder, findings: Findings, n_records: int, lag_s: float, dt_s: float) -> Binder:
    """A binder that skips the windows the findings spoil on a log re-sampled by ``lag_s``.

    Re-sampling the encoders by a lag spreads a faulty reading over the records within the lag,
    so a fault's stretch is widened by that many records (plus one) on each side.
    """
    if findings.handling == "keep" or not findings.report.faults:
        return binder
    faults = findings.report.faults
    if findings.handling == "repair":
        faults = tuple(f for f in faults if f.kind == "tracker_jump")
    bad_intervals, bad_records = fault_masks(replace(findings.report, faults=faults), n_records, lag_s, dt_s)
    return replace(binder, bad_intervals=bad_intervals, bad_records=bad_records)


@dataclass(frozen=True)
class Screening:
    """What the screen found in a log at a given tracker lag, the log to fit (repaired when the
    scenario asks) and the masks of what every fair figure leaves out."""

    lag_s: float
    findings: Findings
    fitted_log: Log
    bad_intervals: np.ndarray
    bad_records: np.ndarray


def screen(
    binder: Binder, log: Log, records: tuple[int, int], x0: np.ndarray, lag_s: float = 0.0
) -> Screening:
    """Screen records ``[start, stop)`` of ``log`` for faults with the tracker ``lag_s`` applied."""
    report = find_faults(binder, log, *records, x0, lag_s)
    fitted, findings = handle_faults(log, report, binder.scenario.data.faults.handling)
    masks = fault_masks(report, log.n_records, lag_s, median_interval(log))
    return Screening(lag_s, findings, fitted, *masks)


def median_interval(log: Log) -> float:
    """The median time between records (s)."""
    return float(np.median(np.diff(log.time_s))) if log.n_records > 1 else 1.0
