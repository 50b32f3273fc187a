"""glibc's allocator settings for the kernel's temporaries (issue 13).

A kernel step allocates hundreds of numpy temporaries of 0.1-2 MB (a few float64 values per path of
a 16 384-path batch). glibc serves blocks above its mmap threshold (128 KiB at start, adjusted
upward only as such blocks are freed) with fresh `mmap` pages and returns freed heap tops above its
trim threshold to the system, so the same memory is faulted in again step after step: measured on
the clear room (benchmarks/path_cost.py), 27 000 minor page faults and 0.06-0.1 s of system time per
262 144 paths, and a 5-term row-wise dot product of 40 000 rows took 350 us instead of 60 us.

`tune_allocator` fixes the mmap threshold at 8 MiB (blocks below come from the heap and are reused)
and keeps up to 32 MiB of freed heap (trim threshold; top pad 8 MiB) instead of returning it: page
faults drop to ~1 500 for the same run, and the process keeps at most ~40 MiB more than it uses. It
calls `mallopt` (glibc only: elsewhere, or when the MALLOC_* environment variables already set
these, it does nothing) once per process; the kernel calls it before its first batch, so worker
processes get it too.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

#: mallopt parameters (glibc's malloc.h)
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3
#: bytes: blocks below come from the heap; freed heap kept up to the trim threshold; extra heap per growth
MMAP_THRESHOLD = 8 << 20
TRIM_THRESHOLD = 32 << 20
TOP_PAD = 8 << 20

_done = False


def tune_allocator() -> bool:
    """Apply the settings above once per process; True when glibc accepted them."""
    global _done
    if _done:
        return False
    _done = True
    if not sys.platform.startswith("linux") or any(k.startswith("MALLOC_") for k in os.environ):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (e.g. musl has no mallopt)
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    ok = mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
    ok &= mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
    ok &= mallopt(M_TOP_PAD, TOP_PAD) == 1
    return bool(ok)
