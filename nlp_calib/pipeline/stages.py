"""One log through the stages before the fit: prepared, its problem built, screened, aligned and
its windows bound (:func:`setup_log`), for a calibration and for a check that fits another model."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

from nlp_calib.core.said import each_once, kept
from nlp_calib.logs import Log
from nlp_calib.pipeline.align import Alignment, align
from nlp_calib.pipeline.build import Problem, at_lags, build_stage, lags_held, restarted
from nlp_calib.pipeline.prepare import PreparedLog, prepare
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.pipeline.screen import Screening, exclude_faults, median_interval, screen
from nlp_calib.pipeline.windows import LogWindows, bind_windows


@dataclass(frozen=True)
class LogSetup:
    """One log through the stages before the fit."""

    prepared: PreparedLog
    problem: Problem
    screening: Screening
    alignment: Alignment
    windows: LogWindows
    #: What reading the log and these stages warned of (each warning's text): its run states it.
    said: tuple[str, ...] = ()

    @property
    def used(self) -> tuple[int, int]:
        return self.windows.used

    @property
    def fit(self) -> tuple[int, int]:
        return self.windows.fit

    @property
    def aligned(self) -> Log:
        return self.windows.aligned


def align_stage(problem: Problem, prepared: PreparedLog, screening: Screening) -> Alignment:
    """The tracker lag, searched with the windows that could cross a fault within the search's
    reach left out, applied to the encoders of the log to fit."""
    al = prepared.scenario.log.alignment
    search = al.search if al.tracker_lag == "auto" else (0.0, 0.0)
    reach = max(abs(search[0]), abs(search[1]))
    log = prepared.log
    binder = exclude_faults(problem.binder, screening.findings, log.n_records, reach, median_interval(log))
    return align(binder, screening.fitted_log, prepared.start, prepared.stop, problem.start.x0)


@dataclass(frozen=True)
class Aligned:
    """One log prepared, its problem built, screened and its lag found: the stages before its
    windows are bound (what the pre-flight inside a run judges at: the run's own lag)."""

    prepared: PreparedLog
    problem: Problem
    screening: Screening
    alignment: Alignment
    #: What these stages warned of as they ran (each warning's text): the run's result states it.
    said: tuple[str, ...] = ()


def setup_log(
    sc: Scenario,
    log: Log | None,
    solvers: Sequence[str],
    aligned: Aligned | None = None,
    start: Mapping[str, float] | None = None,
) -> LogSetup:
    """Prepare, build, screen, align and bind one log (``log``: already read, or None;
    ``aligned``: the stages before binding, done already; ``start``: the values the fit starts
    from instead of the scenario's, see :func:`started`)."""
    a = aligned if aligned is not None else align_log(sc, log, solvers)
    a = a if start is None else started(a, start)
    prepared, problem, screening, alignment = a.prepared, a.problem, a.screening, a.alignment
    problem = at_lags(problem, [alignment.lag_s], [alignment.log.clock.beside_lag_s])
    if alignment.estimate is not None and not alignment.estimate.converged:
        # A lag no fit converged at is held where the encoders are read (a caveat, not a value).
        problem = lags_held(problem)
    with kept() as said:
        windows = bind_windows(problem, prepared, screening, alignment)
    told = each_once(prepared.log.header.said, a.said, said)
    return LogSetup(prepared, problem, screening, alignment, windows, told)


def align_log(sc: Scenario, log: Log | None, solvers: Sequence[str]) -> Aligned:
    """Prepare, build, screen and align one log (``log``: already read, or None), with what
    they warned of."""
    with kept() as said:
        a = _align_log(sc, log, solvers)
    return replace(a, said=tuple(said))


def _align_log(sc: Scenario, log: Log | None, solvers: Sequence[str]) -> Aligned:
    prepared = prepare(sc, log)
    read = prepared.log
    records = (prepared.start, prepared.stop)
    start_from = (read, prepared.start, prepared.split)
    problem = build_stage(
        prepared.scenario,
        prepared.model,
        tuple(prepared.held),
        start_from,
        solvers,
        records[1] - records[0],
        gaps=prepared.gaps,
    )
    screening = screen(problem.binder, read, records, problem.start.x0)
    return Aligned(prepared, problem, screening, align_stage(problem, prepared, screening))


def started(a: Aligned, start: Mapping[str, float]) -> Aligned:
    """``a`` whose fit starts from ``start`` (a stored calibration's values, for a check): its
    screen, lag and windows stay those a run of its scenario finds from the scenario's own start.
    From other values a lag settles elsewhere within its tolerance, and a record at the log's
    edge the run fitted can fall outside the encoders' reach: the check would then not test what
    the run determined."""
    prepared = a.prepared
    # What ``start`` has no value for (a log's own mount or bias) starts where the run's start put it.
    sc = prepared.scenario.with_options(initial_guess={**a.problem.start.initial, **start})
    problem = restarted(a.problem, sc, (prepared.log, prepared.start, prepared.split))
    return Aligned(replace(prepared, scenario=sc), problem, a.screening, a.alignment)
