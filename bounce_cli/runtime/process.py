"""Settings of a bounce process, made before its work starts (the console script's and its
worker processes'): how glibc's allocator keeps freed memory and how long OpenBLAS's idle
threads spin. Neither changes a result: they decide where memory comes from and when an
idle thread sleeps, never what is computed. Standard library only (it runs before numpy is
imported)."""

from __future__ import annotations

import os
import sys

#: OpenBLAS's idle worker threads spin for 2^28 CPU cycles (about 0.1 s) before they sleep:
#: at numpy's import, one core's tenth of a second for each thread but the first, for
#: nothing (0.09 s of CPU on 2 cores; a 16-core machine's 15 threads 1.5 s). 2^16 cycles
#: (some 20 microseconds) still keep a burst of calls warm. Set only where neither it nor
#: its older name is set; no result depends on it (the threads' number and the work's split
#: are unchanged). bounce's worker processes inherit it.
BLAS_THREAD_TIMEOUT = {"OPENBLAS_THREAD_TIMEOUT": "16"}

#: glibc's mallopt parameters (malloc.h) and the values set: allocations up to 32 MiB (the
#: largest threshold glibc takes) come from the heap, whose free top is returned to the
#: system only beyond 1 GiB
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
TRIM_THRESHOLD_BYTES = 1024 * 1024 * 1024


def tune() -> None:
    """Both settings (:data:`BLAS_THREAD_TIMEOUT`, :func:`keep_freed_memory`); before numpy
    is imported."""
    if not {"OPENBLAS_THREAD_TIMEOUT", "GOTO_THREAD_TIMEOUT"} & set(os.environ):
        os.environ.update(BLAS_THREAD_TIMEOUT)
    keep_freed_memory()


def keep_freed_memory() -> bool:
    """glibc gives every allocation above 128 kB a mapping of its own and unmaps it when it
    is freed: each array of a few MB that a run makes and drops costs its pages zeroed by
    the kernel again at their first touch and, at its free, a flush of every core's TLB (an
    inter-processor interrupt, dear in a virtual machine). With ``M_MMAP_THRESHOLD`` at
    32 MiB and ``M_TRIM_THRESHOLD`` at 1 GiB, such arrays come from the heap and their
    memory is reused: a 1000 x 1000 basin 0.955x the wall time (median of 12 pairs). A
    process then holds the memory of its peak until it exits. glibc on Linux only (returns
    whether it was set); the user's ``MALLOC_*`` variables or ``GLIBC_TUNABLES`` for these
    two are left to rule."""
    if not sys.platform.startswith("linux"):
        return False
    if {"MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_"} & set(os.environ) or any(
            name in os.environ.get("GLIBC_TUNABLES", "")
            for name in ("malloc.mmap_threshold", "malloc.trim_threshold")):
        return False
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(
        mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
