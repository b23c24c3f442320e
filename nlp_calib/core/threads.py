"""How many threads this process's own work may run at once: refits and compilers.

By default what each asks for, up to the machine's cores. A batch's worker process takes one core
(:func:`one_core`): its log's refits and compiles then run one at a time, so that the workers, not
one log's threads, share the cores (two workers on two cores, not two and a half). These threads
only schedule independent work: the results are the same. A scenario's ``compute.threads`` (the
chunk maps') is left as asked: it shapes how sums are taken.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from pathlib import Path

#: Environment variables that fix a native library's threads when it loads (OpenBLAS, MKL, OpenMP):
#: a worker process gets them before it imports numpy.
NATIVE_THREADS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")

_cores: int | None = None


def one_core() -> None:
    """This process's work runs on one thread at a time from now on."""
    global _cores
    _cores = 1


def allowed(wanted: int) -> int:
    """The threads that work asking for ``wanted`` may run: at most the cores, and one on one core."""
    return max(1, min(wanted, os.cpu_count() or 1, _cores or wanted))


@contextlib.contextmanager
def native_one_thread() -> Iterator[None]:
    """Processes started inside start with one thread per native library (set in this process's
    environment, which they inherit, and restored on leaving)."""
    saved = {k: os.environ.get(k) for k in NATIVE_THREADS}
    os.environ.update(dict.fromkeys(NATIVE_THREADS, "1"))
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def native_one_thread_by_default() -> None:
    """Native libraries loaded from now on run one thread each unless the environment says
    otherwise: the command's matrices are small (a few dozen parameters), and OpenBLAS's second
    thread only spins beside the first (about 6 % of a 10^5-record run's CPU, no faster)."""
    for name in NATIVE_THREADS:
        os.environ.setdefault(name, "1")


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _cpu_times(stat: Path) -> tuple[int, int] | None:
    """Idle and total jiffies of all CPUs from ``/proc/stat``; None where it cannot be read."""
    try:
        fields = stat.read_text().split("\n", 1)[0].split()
        ticks = [int(v) for v in fields[1:]]
    except (OSError, ValueError, IndexError):
        return None
    if fields[0] != "cpu" or len(ticks) < 5:
        return None
    return ticks[3] + ticks[4], sum(ticks[:8])  # idle + iowait; guest time is counted in user


def free_cores(sample_s: float = 0.25, stat: Path = Path("/proc/stat")) -> float:
    """How many of :func:`cores` are idle now: the idle share of the machine's CPU time over
    ``sample_s`` seconds (``/proc/stat``), or, where that cannot be read, the cores less the
    one-minute load average."""
    n = cores()
    before = _cpu_times(stat)
    if before is not None:
        time.sleep(sample_s)
        after = _cpu_times(stat)
        if after is not None and after[1] > before[1]:
            idle = (after[0] - before[0]) / (after[1] - before[1])
            return min(float(n), idle * (os.cpu_count() or n))
    try:
        return max(0.0, n - os.getloadavg()[0])
    except (AttributeError, OSError):
        return float(n)
