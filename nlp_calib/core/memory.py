"""Address-space limits (``ulimit -v``), checked before native code that cannot fail cleanly.

The OpenBLAS inside CasADi's IPOPT (through MUMPS) reserves a 128 MiB work buffer the first time
a thread calls it, and when that reservation fails it retries forever, at full CPU, in native
code. So before such code runs, :func:`require_address_space` reserves (and at once releases)
as much address space as it will take: no pages are touched, so the probe costs nothing, and a
limit too tight to hold it is a one-line error instead of a hang. Under such a limit,
:func:`fit_to_limit` also keeps OpenBLAS to one thread and stops glibc from reserving 64 MiB of
address space per thread for its malloc arenas, which otherwise takes a third of a run's.
"""

from __future__ import annotations

import contextlib
import mmap
import os

from nlp_calib.core.errors import ResourceError

#: The message of an allocation that failed in Python or in native code (``std::bad_alloc``).
OUT_OF_MEMORY = (
    "out of memory; select fewer records or a shorter horizon (or raise the limit if the shell set "
    "one: ulimit -v)"
)
#: The message of a thread that could not be started (address space or process limits).
NO_THREAD = (
    "could not start a thread: the address space (ulimit -v) or the number of processes (ulimit -u) "
    "is limited too tightly; raise the limit"
)
_MIB = 1 << 20


def address_space_limit() -> int | None:
    """The soft limit on the process's address space in bytes (``ulimit -v``), or None."""
    try:
        import resource
    except ImportError:  # not a Unix
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    return None if soft == resource.RLIM_INFINITY else int(soft)


def fit_to_limit() -> None:
    """Under an address-space limit, before the libraries load: one BLAS thread (each OpenBLAS
    thread reserves its own work buffer at start, spins when it cannot, and then keeps the
    process from exiting) and one malloc arena for all threads (glibc)."""
    if address_space_limit() is None:
        return
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    with contextlib.suppress(Exception):  # not glibc, or no ctypes: nothing to save
        import ctypes

        m_arena_max = -8  # glibc's malloc.h
        ctypes.CDLL(None).mallopt(m_arena_max, 1)


def give_back() -> None:
    """Return the heap's free pages to the system (glibc's ``malloc_trim``; elsewhere nothing).

    Buffers freed by other threads (the refits') go back to those threads' malloc arenas, and
    freed blocks below glibc's grown mmap threshold to the heap: the process would keep their
    pages resident to its end."""
    with contextlib.suppress(Exception):  # not glibc, or no ctypes: nothing to give back
        import ctypes

        ctypes.CDLL(None).malloc_trim(0)


def available_memory() -> int | None:
    """Bytes of memory the system can give without swapping (Linux ``MemAvailable``), or the
    address-space limit when lower; None when neither is known."""
    free = None
    with contextlib.suppress(OSError, ValueError, IndexError), open("/proc/meminfo", "rb") as fh:
        for line in fh:
            if line.startswith(b"MemAvailable:"):
                free = int(line.split()[1]) * 1024
    limit = address_space_limit()
    known = [v for v in (free, limit) if v is not None]
    return min(known) if known else None


def address_space_used() -> int | None:
    """Bytes of address space the process holds (Linux), or None."""
    with contextlib.suppress(OSError, ValueError, IndexError), open("/proc/self/statm", "rb") as fh:
        return int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    return None


def require_address_space(nbytes: int, what: str, fix: str) -> None:
    """Raise :class:`ResourceError` naming ``what`` and ``fix`` when the address-space limit leaves
    less than ``nbytes`` free (nothing to check when there is no limit)."""
    limit = address_space_limit()
    if limit is None:
        return
    try:
        probe = mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS, prot=mmap.PROT_READ)
    except (OSError, ValueError, OverflowError):
        used = address_space_used()
        need = f", at least ulimit -v {(used + nbytes) // 1024 + 1}" if used is not None else ""
        raise ResourceError(
            f"the address space is limited to {limit // _MIB} MiB (ulimit -v {limit // 1024}), which "
            f"leaves less than the {-(-nbytes // _MIB)} MiB {what} needs; raise the limit (ulimit -v "
            f"unlimited{need}) or {fix}"
        ) from None
    probe.close()
