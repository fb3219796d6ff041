"""Keep freed memory for reuse during a large computation (glibc only; elsewhere a no-op).

glibc's ``malloc`` gives every block above its mmap threshold (128 KiB, rising to at most
32 MiB) its own ``mmap`` and returns it to the system on ``free``; the next block of that size
page-faults all of its pages in again.  A
reconstruction of 1M points allocates and frees a few GB of such blocks (XLA's buffers,
PARDISO's work space, numpy temporaries): 1.5M page faults a call, several seconds of system
time on the 2-core development box.  Inside :func:`reuse_freed_memory` large blocks come from
the heap instead and freed ones stay there for the next allocation; on the way out the free
memory is given back (``malloc_trim``) and the two limits are set back to glibc's defaults
(setting them, in or out, also ends glibc's own raising of its mmap threshold for the rest of
the process: later blocks above the threshold in force then are mmapped, as by default).  Measured on
``benchmarks/points.py`` at 1M points: first call 25.0-25.4 s instead of 28.9-30.1 s, peak
memory unchanged (5.2-5.5 GB).  Mesh maps (1.45M faces) gained nothing measurable, so only
:func:`jaxparam.reconstruct_surface` uses it.
"""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import threading

# mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_MAX = -1, -4
_DEFAULT_TRIM_THRESHOLD, _DEFAULT_MMAP_MAX = 128 * 1024, 65536
#: Below this many elements (points, or faces) the savings are under 0.1 s: nothing is changed.
MIN_SIZE = 100_000

_lock = threading.Lock()
_depth = 0


def _glibc():
    """glibc's ``mallopt`` and ``malloc_trim``, or None on other C libraries."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt, trim = libc.mallopt, libc.malloc_trim
    except (OSError, AttributeError):
        return None
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return mallopt, trim


_LIBC = _glibc()


@contextlib.contextmanager
def reuse_freed_memory(size: int = MIN_SIZE):
    """Within the block, freed memory stays in the process for reuse, when ``size`` (the
    problem's point or face count) is at least :data:`MIN_SIZE` and the C library is glibc.
    Nested and concurrent uses share one setting; the last one out restores it."""
    global _depth
    if _LIBC is None or size < MIN_SIZE:
        yield
        return
    mallopt, trim = _LIBC
    with _lock:
        _depth += 1
        if _depth == 1:
            mallopt(_M_MMAP_MAX, 0)
            mallopt(_M_TRIM_THRESHOLD, 2**31 - 1)
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                mallopt(_M_MMAP_MAX, _DEFAULT_MMAP_MAX)
                mallopt(_M_TRIM_THRESHOLD, _DEFAULT_TRIM_THRESHOLD)
                trim(0)
