"""A batch's jobs on this machine: in this process (one job at a time) or on worker processes.

Workers are fresh interpreters (the ``spawn`` start method: nothing of this process, no thread or
lock, is inherited). While a worker runs a log, a signal unwinds it like the command line (its
log's staged files are discarded) and the log's row says it was interrupted; an idle worker just
exits. When this process is interrupted it cancels the logs not started and ends its workers;
the folders of the logs that finished stay. A worker that dies (a crash in native code, the
out-of-memory killer) breaks its pool: the logs it left unfinished are run again, each in a pool
of its own, and a log that breaks that pool too is reported as failed.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from types import FrameType

from nlp_calib.core import interrupts, threads
from nlp_calib.fleet.jobs import Job
from nlp_calib.fleet.task import run_job
from nlp_calib.results.batch import BatchRow

#: Called with each job's index and row as it finishes.
Done = Callable[[int, BatchRow], None]
#: The per-log task (:func:`~nlp_calib.fleet.task.run_job`, or a wrapper of it: a top-level
#: function, so that worker processes can import it).
Task = Callable[[Job], BatchRow]
#: How long the ended workers have, together, to unwind before they are killed: well inside the
#: command line's grace after a signal (:data:`~nlp_calib.core.interrupts.GRACE_S`), so that the
#: batch never ends before its workers do.
STOP_WAIT_S = 1.5


def _quit(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(128 + signum)  # an idle worker holds nothing to clean up


def _init_worker(shared: bool) -> None:
    for s in interrupts.SIGNALS:
        signal.signal(s, _quit)
    if shared:  # the other workers have the other cores: this one's refits run one at a time
        threads.one_core()


def _work(task: Task, job: Job) -> BatchRow:
    """``task`` of ``job`` in a worker, signals turned into an interrupted row while it runs."""
    t0 = time.perf_counter()
    try:
        with interrupts.handled():
            return task(job)
    except interrupts.Interrupted as exc:
        where = (job.name, str(job.path), str(job.folder))
        return BatchRow.failure(where, f"interrupted ({exc.name})", time.perf_counter() - t0)


def _stop(pool: ProcessPoolExecutor) -> None:
    """Cancel the jobs not started and end the workers (each unwinds and discards its staged files)."""
    workers = list((getattr(pool, "_processes", None) or {}).values())  # no public handle on them
    pool.shutdown(wait=False, cancel_futures=True)
    for p in workers:
        if p.is_alive():
            p.terminate()
    deadline = time.monotonic() + STOP_WAIT_S
    for p in workers:
        p.join(max(deadline - time.monotonic(), 0.0))
    for p in workers:
        if p.is_alive():
            p.kill()
            p.join()


def _pass(jobs: Sequence[Job], indices: Sequence[int], workers: int, done: Done, task: Task) -> list[int]:
    """``jobs[indices]`` on a pool of ``workers``; returns those left unfinished by a worker's death.
    Several workers each take one core: one thread per native library, one refit at a time."""
    n = min(workers, len(indices))
    spawn = multiprocessing.get_context("spawn")
    with threads.native_one_thread() if n > 1 else contextlib.nullcontext():
        pool = ProcessPoolExecutor(n, mp_context=spawn, initializer=_init_worker, initargs=(n > 1,))
        return _drain(pool, jobs, indices, done, task)


def _drain(
    pool: ProcessPoolExecutor, jobs: Sequence[Job], indices: Sequence[int], done: Done, task: Task
) -> list[int]:
    """``jobs[indices]`` on ``pool``, which it shuts down; returns those a worker's death left."""
    broken: list[int] = []
    finished = False
    try:
        futures: dict[Future[BatchRow], int] = {pool.submit(_work, task, jobs[i]): i for i in indices}
        for fut in as_completed(futures):
            try:
                row = fut.result()
            except BrokenProcessPool:
                broken.append(futures[fut])
                continue
            done(futures[fut], row)
        finished = True
    finally:
        if finished:
            pool.shutdown(wait=True)
        else:
            _stop(pool)
    return broken


def local_workers(asked: int | None, n_jobs: int, free: float) -> int:
    """How many logs to run at once on this machine: as many as asked (default: its cores), at most
    one per job and one per core free now (``free``: rounded; at least one). A worker on a busy core
    only slows the others: a log run alone already keeps more than one core busy (its refits run
    two at a time), so workers past the free cores make a batch slower than one at a time."""
    limit = asked if asked is not None else threads.cores()
    return max(1, min(limit, n_jobs, round(free)))


def run_jobs(jobs: Sequence[Job], workers: int, done: Done, task: Task = run_job) -> None:
    """Every job, ``workers`` at a time (1: in this process), ``done`` called as each finishes."""
    if workers <= 1 or len(jobs) <= 1:
        for i, job in enumerate(jobs):
            done(i, task(job))
        return
    for i in _pass(jobs, range(len(jobs)), workers, done, task):
        if _pass(jobs, [i], 1, done, task):
            job = jobs[i]
            where = (job.name, str(job.path), str(job.folder))
            done(i, BatchRow.failure(where, "its worker process died (a crash, or out of memory)", 0.0))
