"""Process-level tuning the command line applies (never the engine on its own).

reuse_large_buffers: glibc hands every allocation above its mmap threshold (128 KiB to start
with) fresh pages from the kernel and returns them on free, so a buffer of that size made every
step (a 150 kB MCAP message, a contact array of a large scene) pays for zeroing new pages each
time. Raising the threshold keeps such buffers in the heap and reuses them (bench/HISTORY.md has
what it saved on the 500-body pile's contacts). It changes no result, only where memory comes
from; on a C library without mallopt it does nothing.

one_blas_thread: numpy's OpenBLAS starts a thread per CPU when numpy is imported, and those
threads spin a while waiting for work that never comes: nothing ISAAC runs calls BLAS with
matrices big enough to share out (the step is numba kernels; the tools multiply 2 x 2 and
k x 2 arrays). On a 2-core machine that spinning is CPU taken from the other processes of a
recorded run, which start up at the same time (the recording rows of bench/results/latest.md).
Dask's workers get the same setting from Dask itself (its nanny's ``pre-spawn-environ``). It
changes no result.
"""

from __future__ import annotations

import ctypes
import os
import sys

M_TRIM_THRESHOLD = -1  # glibc malloc.h
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD = 32 * 1024 * 1024  # bytes: glibc's largest (DEFAULT_MMAP_THRESHOLD_MAX)
TRIM_THRESHOLD = 128 * 1024 * 1024  # bytes of free heap top kept rather than returned

_done = False


def reuse_large_buffers() -> bool:
    """Raise glibc's mmap and trim thresholds once per process; True if it took effect."""
    global _done
    if _done:
        return True
    try:
        # the C library this interpreter runs on (its own symbols); ctypes.util is imported
        # only when that has no mallopt (it imports subprocess, tempfile and shutil, on every
        # command's start-up)
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        try:
            from ctypes.util import find_library

            mallopt = ctypes.CDLL(find_library("c") or None).mallopt
        except (OSError, AttributeError):
            return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    ok = bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    )
    _done = ok
    return ok


def one_blas_thread() -> bool:
    """Ask for one OpenBLAS thread (``OPENBLAS_NUM_THREADS=1``), in this process if numpy is not
    imported yet and in every process it starts, unless the user set the variable. Returns
    whether this process's numpy will start without the pool."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    return "numpy" not in sys.modules
