"""Time alignment as pipeline steps: the tracker lag, given or estimated, applied to the encoders.

The estimate reuses one evaluator for every lag it tries (the windows and the tracker's motions
stay; only the encoder inputs are re-sampled): :func:`nlp_calib.analysis.alignment.estimate_lag`
decides which lags to fit.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from nlp_calib.analysis.alignment import LagEstimate, estimate_lag
from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.logs import Log, resample_encoders
from nlp_calib.pipeline.build import Binder
from nlp_calib.pipeline.keys import scenario_key
from nlp_calib.pipeline.prepare import split
from nlp_calib.pipeline.scenario import Scenario

#: A lag's fit (from the previous lag's estimate) stops once the next Gauss-Newton step would lower
#: the cost by less than this fraction: its cost is then the optimum's to half of that, far below
#: the cost differences between lags a parabola is fitted through (about 1e-2 on the real log).
LAG_FIT_TOLERANCE = 1e-8


@dataclass(frozen=True)
class Alignment:
    """The tracker lag used, how it was found, and the log with encoders on the tracker's clock.

    ``valid`` is the record range whose shifted times lie inside the log.
    """

    lag_s: float
    estimate: LagEstimate | None
    log: Log
    valid: tuple[int, int]


def estimate_tracker_lag(binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray) -> LagEstimate:
    """The tracker lag that minimises the internal solver's fit cost on a common record range.

    One evaluator serves every lag: the windows and the tracker's motions stay, only the encoder
    inputs are re-sampled (and, when stationary windows are dropped, the windows re-selected).
    """
    sc = binder.scenario
    al = sc.log.alignment
    kinds = binder.fns.model.encoder_kinds
    reach = max(abs(al.search[0]), abs(al.search[1]))
    t = log.time_s
    first = max(start, int(np.searchsorted(t, t[0] + reach, side="left")))
    last = min(stop, int(np.searchsorted(t, t[-1] - reach, side="right")))
    fit_stop = split(sc, first, last)
    _, ev = binder.bind(log, first, fit_stop)
    x_start = x0

    def fit_cost(lag: float) -> float:
        nonlocal x_start
        shifted, _ = resample_encoders(log, lag, kinds)
        if sc.log.samples.drop_stationary:
            binder.bind(shifted, first, fit_stop, evaluator=ev)
        else:
            ev.set_inputs(binder.inputs(shifted, first, fit_stop))
        cost, x, converged = binder.fit(ev, x_start, LAG_FIT_TOLERANCE)
        if not converged:
            return float("nan")
        x_start = x
        return cost

    return estimate_lag(fit_cost, al.search, al.step)


def align(binder: Binder, log: Log, start: int, stop: int, x0: np.ndarray) -> Alignment:
    """The scenario's tracker lag (given, or estimated when ``auto``) applied to the encoders."""
    sc = binder.scenario
    lag = sc.log.alignment.tracker_lag
    estimate = None
    if lag == "auto":
        with scenario_key(sc, "alignment.search"):
            estimate = estimate_tracker_lag(binder, log, start, stop, x0)
        lag = estimate.lag_s
        if estimate.at_edge:
            warnings.warn(lag_at_edge(sc, estimate.lag_s), NlpCalibWarning, stacklevel=2)
    with scenario_key(sc, "alignment.tracker_lag"):
        aligned, valid = resample_encoders(log, float(lag), binder.fns.model.encoder_kinds)
    return Alignment(lag_s=float(lag), estimate=estimate, log=aligned, valid=valid)


def lag_at_edge(sc: Scenario, lag_s: float) -> str:
    """The warning for a tracker lag estimated at an end of the searched range."""
    lo, hi = sc.log.alignment.search
    return (
        f"{sc.path or sc.name}: alignment.tracker_lag: the estimated lag {1e3 * lag_s:.1f} ms lies at the "
        f"edge of the searched range [{lo:g}, {hi:g}] s, so the best lag may lie beyond it: widen "
        "alignment.search, or check the log's timestamps (a gap or a jump in time misleads the estimate)"
    )
