"""The per-log task of a batch: one job in, its result folder written, one summary row out.

:func:`run_job` is a plain top-level function of a picklable :class:`~nlp_calib.fleet.jobs.Job`
returning a picklable :class:`~nlp_calib.results.batch.BatchRow`, so any engine that maps a
function over arguments in other processes or machines can run a batch (``concurrent.futures``,
Dask, Ray, a cluster scheduler's array job). A log that fails gives a row with its one-line error;
only a signal (an :class:`~nlp_calib.core.interrupts.Interrupted`) leaves it by an exception.
"""

from __future__ import annotations

import time
import traceback
import warnings
from pathlib import Path

from nlp_calib.core.errors import NlpCalibError
from nlp_calib.fleet.jobs import Job
from nlp_calib.outputs import registry
from nlp_calib.pipeline import Calibration, Scenario, Wanted, load_scenario
from nlp_calib.pipeline.check import check, check_scenario
from nlp_calib.pipeline.prepare import read_all
from nlp_calib.pipeline.stored import read_calibration
from nlp_calib.results import CalibrationRun
from nlp_calib.results.batch import BatchRow


def job_scenario(job: Job) -> Scenario:
    """The scenario of ``job``'s log: its own scenario file, the batch's ``--scenario`` on it, or its
    model's defaults."""
    opts = job.options
    if job.is_scenario:
        sc = load_scenario(job.path)
    elif opts.scenario is not None:
        sc = load_scenario(opts.scenario).with_dataset(job.path)
    else:
        sc = Scenario.of(job.name, job.path, **({"model": opts.model} if opts.model else {}))
    return sc.with_options(solvers=(opts.solver,)) if opts.solver else sc


def _calibrate(job: Job) -> CalibrationRun:
    opts = job.options
    if opts.check is None:
        scenario = job_scenario(job)
        return Calibration(scenario, read_all(scenario)).run(None, Wanted(series=opts.report))
    stored = read_calibration(opts.check)
    if opts.scenario is not None and not job.is_scenario:
        scenario = check_scenario(stored, opts.scenario).with_dataset(job.path)
    else:
        scenario = check_scenario(stored, job.path)
    return check(stored, scenario, read_all(scenario))


def _options(job: Job) -> registry.OutputOptions:
    """The outputs' options: the controller's name in ``ros2_control.yaml`` as the scenario gives it."""
    if job.options.check is not None:
        return registry.OutputOptions()
    return registry.OutputOptions(controller_name=job_scenario(job).handoff.controller_name)


def job_outputs(job: Job) -> tuple[registry.Output, ...]:
    """The files each log's folder gets: the check's, or a run's (with ``--report``, its figures)."""
    if job.options.check is not None:
        return registry.selected(("check", "result"), report=False)
    groups = ("result", "handoff", "figures") if job.options.report else ("result", "handoff")
    return registry.selected(groups, job.options.report)


def _failure_text(exc: BaseException) -> str:
    if isinstance(exc, NlpCalibError):
        return str(exc)
    if isinstance(exc, OSError):
        return f"{exc.filename + ': ' if exc.filename else ''}{exc.strerror or exc}"
    if isinstance(exc, MemoryError):
        return "out of memory; select fewer records or a shorter horizon"
    last = traceback.extract_tb(exc.__traceback__)[-1:] or None
    where = f" at {Path(last[0].filename).name}:{last[0].lineno}" if last else ""
    return f"internal error: {type(exc).__name__}: {exc}{where}"


def run_job(job: Job) -> BatchRow:
    """Calibrate (or check) one log, write its folder, and return its summary row."""
    where = (job.name, str(job.path), str(job.folder))
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            run = _calibrate(job)
            group = "check" if job.options.check is not None else "run"
            registry.write_staged(job.folder, job_outputs(job), run, _options(job), group,
                                  force=job.options.force)  # fmt: skip
        except Exception as exc:  # one log's failure is its row, never the batch's
            notes = tuple(str(w.message) for w in caught)
            return BatchRow.failure(where, _failure_text(exc), time.perf_counter() - t0, notes)
    notes = tuple(dict.fromkeys(str(w.message) for w in caught))
    return BatchRow.of_run(run, where, time.perf_counter() - t0, notes)
