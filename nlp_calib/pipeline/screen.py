"""The screen stage: encoder and tracker faults found in a log, and how the fit is kept clear of them.

Faults are screened once, on the records as logged (re-sampling would smear a bad reading into its
neighbours), before the lag search, which they are kept out of; each mismatch is put down to the
stream that explains it (:mod:`nlp_calib.analysis.faults`), the counters judged with a fit of the
log's windows by the internal solver.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.analysis.faults import repair
from nlp_calib.analysis.faults import screen as screen_log
from nlp_calib.logs import Log
from nlp_calib.pipeline.build import Binder
from nlp_calib.results.faults import MATCH_KINDS, FaultReport, Findings


def find_faults(binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray) -> FaultReport:
    """Faults in records ``start:stop`` of ``log`` as logged (nothing re-sampled), the counters
    judged with a fit to the windows the binder keeps and the streams' own glitches spoil not, at
    the scenario's tracker lag (or, when it is estimated, the screen's own estimate in its range)."""

    def judge(bad_intervals: np.ndarray, bad_records: np.ndarray) -> np.ndarray | None:
        masks = np.zeros(log.n_records - 1, dtype=bool), np.zeros(log.n_records, dtype=bool)
        masks[0][start : stop - 1], masks[1][start:stop] = bad_intervals, bad_records
        masked = replace(binder.lag_held(x0), bad_intervals=masks[0], bad_records=masks[1])
        _, ev = masked.bind(log, start, stop)
        # A fit out of iterations at its optimum but for the last digits goes on to REFIT_SIGMAS
        # of its σ (Binder.fit): a skid-steer whose pivots mostly slipped, 235 steps to the
        # solver's 1e-14, its 200th estimate the same to 12 digits, had been left unjudged.
        _, x, converged = masked.fit(ev, x0)
        return ev.params(x) if converged and np.all(np.isfinite(x)) else None

    sc = binder.scenario
    al = sc.log.alignment
    lag = al.search if al.tracker_lag == "auto" else float(al.tracker_lag)
    sample = sc.objective.residual.steering_sample
    report = screen_log(binder.fns, log.select(start, stop), sample, lag, judge)
    return report.shifted(start, log.line_numbers)


def handle_faults(log: Log, report: FaultReport, handling: str) -> tuple[Log, Findings]:
    """The log to fit (repaired when ``handling`` asks for it) and what was found and done."""
    if handling == "repair" and report.encoder_faults:
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
    encoders = replace(report, faults=report.encoder_faults)
    # A bad match is the reference's: re-sampling the encoders spreads nothing of it.
    matches = replace(report, faults=tuple(f for f in report.faults if f.kind in MATCH_KINDS))
    intervals = dilate(encoders.bad_intervals(n_records - 1), reach) | matches.bad_intervals(n_records - 1)
    return intervals, report.bad_records(n_records)


def exclude_faults(binder: Binder, findings: Findings, n_records: int, lag_s: float, dt_s: float) -> Binder:
    """A binder that skips the windows the findings spoil on a log re-sampled by ``lag_s``.

    Re-sampling the encoders by a lag spreads a faulty reading over the records within the lag,
    so a fault's stretch is widened by that many records (plus one) on each side.
    """
    if findings.handling == "keep" or not findings.report.faults:
        return binder
    faults = findings.report.faults
    if findings.handling == "repair":
        faults = findings.report.unrepaired
    bad_intervals, bad_records = fault_masks(replace(findings.report, faults=faults), n_records, lag_s, dt_s)
    return replace(binder, bad_intervals=bad_intervals, bad_records=bad_records)


@dataclass(frozen=True)
class Screening:
    """What the screen found in a log, and the log to fit (repaired when the scenario asks)."""

    findings: Findings
    fitted_log: Log


def screen(binder: Binder, log: Log, records: tuple[int, int], x0: np.ndarray) -> Screening:
    """Screen records ``[start, stop)`` of ``log`` for faults."""
    report = find_faults(binder, log, *records, x0)
    fitted, findings = handle_faults(log, report, binder.scenario.data.faults.handling)
    return Screening(findings, fitted)


def median_interval(log: Log) -> float:
    """The median time between records (s)."""
    return float(np.median(np.diff(log.time_s))) if log.n_records > 1 else 1.0
