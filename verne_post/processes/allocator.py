"""The C allocator's settings for verne-post's own processes: freed memory is kept for reuse.

numpy allocates every large array with malloc. By default glibc serves blocks above a moving
threshold (128 KiB at first) with mmap and returns them to the kernel on free, and trims the
top of the heap whenever 128 KiB lie free there. A toolpath is worked in parts of the same
shapes, one after another, so each part's arrays would get fresh pages from the kernel, which
zeroes every page on its first touch. Keeping freed memory in the heap (glibc's mallopt,
``M_MMAP_THRESHOLD`` and ``M_TRIM_THRESHOLD``, see the mallopt(3) manual page) lets the next
part reuse those pages: on the 105k-point job in one process, 39,000 page faults instead of
239,000 and 0.25 s of system time instead of 1.1 s. The peak resident memory stays that of
the largest part (benchmarks/memory.py: 121, 130, 483 MiB at 30k, 300k, 3M points).

The command line and batch's own workers (local processes, and the workers of the local Dask
cluster it starts) call this; a library user's process keeps its own allocator settings, and a
Dask cluster of one's own can preload this module (:func:`dask_setup`). Elsewhere than glibc
(musl, macOS, Windows) it does nothing.
"""

from __future__ import annotations

import ctypes
import sys

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: glibc's largest mmap threshold on 64-bit systems (DEFAULT_MMAP_THRESHOLD_MAX, 32 MiB):
#: blocks above it (whole-program arrays of millions of points) are still mapped and unmapped.
_MMAP_THRESHOLD = 32 << 20
#: Free memory at the top of the heap is given back beyond 1 GiB only.
_TRIM_THRESHOLD = 1 << 30


#: Whether this process's malloc keeps freed memory (set by :func:`keep_freed_memory`).
kept = False


def keep_freed_memory() -> bool:
    """Ask glibc's malloc to keep freed memory for reuse; True if it took both settings."""
    global kept
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc: no mallopt
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    # Either setting alone fixes the thresholds and stops glibc's own adjustment, which made
    # things worse in measurement (2.3 and 5 times the page faults of neither): both or neither.
    kept = bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))
    return kept


def dask_setup(service: object) -> None:
    """Dask's preload hook (docs.dask.org, "Customize Initialization": a ``--preload`` module's
    ``dask_setup`` is called as the worker starts): ``dask worker ADDRESS --preload
    verne_post.processes.allocator`` makes a worker that posts CL files keep freed memory too.

    It matters more there: a Dask worker runs its tasks in a thread, whose malloc arena gives
    memory back even more eagerly. A 3,000-point job took 3.0-3.8 s in a worker (380,000 page
    faults) against 1.5-1.8 s with this (7,000-34,000), as in a local process.
    """
    keep_freed_memory()
