"""The C allocator's settings for the command line: freed memory is kept for reuse.

numpy allocates every large array with malloc. By default glibc serves blocks above a moving
threshold (128 KiB at first) with mmap and returns them to the kernel on free, and trims the
top of the heap whenever 128 KiB lie free there. A toolpath is worked in parts of the same
shapes, one after another, so each part's arrays would get fresh pages from the kernel, which
zeroes every page on its first touch. Keeping freed memory in the heap (glibc's mallopt,
``M_MMAP_THRESHOLD`` and ``M_TRIM_THRESHOLD``, see the mallopt(3) manual page) lets the next
part reuse those pages: on the 105k-point job in one process, 39,000 page faults instead of
239,000 and 0.25 s of system time instead of 1.1 s. The peak resident memory stays that of
the largest part (benchmarks/memory.py: 121, 130, 483 MiB at 30k, 300k, 3M points).

Only the command line calls this: a library user's process keeps its own allocator settings.
Elsewhere than glibc (musl, macOS, Windows) it does nothing.
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


def keep_freed_memory() -> bool:
    """Ask glibc's malloc to keep freed memory for reuse; True if it took both settings."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc: no mallopt
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    # Either setting alone fixes the thresholds and stops glibc's own adjustment, which made
    # things worse in measurement (twice the page faults): both or neither.
    return bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))
