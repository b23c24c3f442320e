"""A batch's jobs on a Dask cluster (``nlp-calib batch --dask ADDRESS``; the ``fleet`` extra).

Each job is :func:`~nlp_calib.fleet.task.run_job` on a worker: the job and its row are pickled
across, and the log's folder is written by the worker, so every worker must see ``--out`` (a
shared file system). Each worker takes one core (its log's refits one at a time: Dask runs one
worker per core). A worker that dies is replaced by Dask and its log run again; a log that kills
its workers again and again is reported as failed, like a crash on this machine.
"""

from __future__ import annotations

import socket
from collections.abc import Sequence
from typing import Any
from urllib.parse import urlsplit

from nlp_calib.core import threads
from nlp_calib.core.errors import UsageError
from nlp_calib.fleet.jobs import Job
from nlp_calib.fleet.pool import Done, Task
from nlp_calib.fleet.task import run_job
from nlp_calib.results.batch import BatchRow

INSTALL = "pip install 'nlp_calib[fleet]'"


def _distributed() -> Any:
    try:
        import dask.distributed
    except ImportError:
        raise UsageError(f"--dask needs Dask's distributed scheduler, not installed: {INSTALL}") from None
    return dask.distributed


def _refused(address: str) -> OSError | None:
    """A plain TCP scheduler address that refuses connections outright (a typo, a scheduler not
    started): said at once, not after Dask's retries until its timeout."""
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    try:
        port = parts.port
    except ValueError:
        return None
    if parts.scheme != "tcp" or parts.hostname is None or port is None:
        return None
    try:
        socket.create_connection((parts.hostname, port), timeout=5.0).close()
    except (ConnectionRefusedError, socket.gaierror) as exc:
        return exc
    except OSError:  # slow or filtered: Dask's own timeout decides
        return None
    return None


def _transport(address: str) -> None:
    """Refuse an address whose transport this Dask cannot use (ucx:// without its package): Dask
    would fail inside its connector instead of naming it."""
    scheme = address.partition("://")[0].lower() if "://" in address else "tcp"
    try:
        from distributed.comm.registry import get_backend

        get_backend(scheme).get_connector()
    except Exception as exc:  # any failure to build the connector: the transport is not usable here
        raise UsageError(
            f"--dask {address}: this Dask cannot connect over {scheme}:// ({type(exc).__name__}); install "
            "its transport (for ucx://: pip install distributed-ucxx) or give a tcp:// address"
        ) from None


def _worker_takes_one_core() -> None:
    threads.one_core()


def run_on_dask(jobs: Sequence[Job], address: str, done: Done, task: Task = run_job) -> None:
    """Every job on the Dask cluster whose scheduler is at ``address``, ``done`` called as each
    finishes."""
    distributed = _distributed()
    _transport(address)
    if (refused := _refused(address)) is not None:
        raise UsageError(f"--dask {address}: cannot reach a Dask scheduler there ({refused})")
    try:
        client = distributed.Client(address, timeout="20s")
    except (OSError, TimeoutError) as exc:
        raise UsageError(f"--dask {address}: cannot reach a Dask scheduler there ({exc})") from None
    with client:
        client.run(_worker_takes_one_core)
        futures = client.map(task, list(jobs), pure=False)
        index = {future.key: i for i, future in enumerate(futures)}
        for future in distributed.as_completed(futures):
            i = index[future.key]
            try:
                row = future.result()
            except Exception as exc:  # the task never raises for a log: its workers died
                job = jobs[i]
                where = (job.name, str(job.path), str(job.folder))
                why = f"its Dask workers died ({type(exc).__name__}: a crash, or out of memory)"
                row = BatchRow.failure(where, why, 0.0)
            done(i, row)
