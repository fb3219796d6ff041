"""Keep freed memory for reuse (glibc only; elsewhere a no-op).

glibc's ``malloc`` gives every block above its mmap threshold (128 KiB, rising to at most
32 MiB) its own ``mmap`` and returns it to the system on ``free``; the next block of that size
page-faults all of its pages in again.  Two settings keep freed blocks for the next allocation:

- Process-wide, from the moment JAX loads (:func:`keep_freed`, ``jp.config.keep_freed_mb``,
  default 512 MiB): blocks up to that size come from the heap, and up to that much freed memory
  at the heap's top stays in the process.  XLA allocates one block for a compiled call's
  temporaries and frees it after the call; above 32 MiB every call page-faulted it in again.
  On camelhead's 126k point-fan entries the meshless map's gradient has 35 MB of temporaries:
  49.7 -> 26.5-28.2 ms a call on one core, 40 % of it page faults (issue 12,
  benchmarks/README.md).  The cost: up to that much freed memory is kept by the process.
- Around a large computation (:func:`reuse_freed_memory`): no block is mmapped and no freed
  memory is returned, then ``malloc_trim`` on the way out and the process-wide setting back.
  A reconstruction of 1M points allocates and frees a few GB of such blocks (XLA's buffers,
  PARDISO's work space, numpy temporaries): 1.5M page faults a call, several seconds of system
  time on the 2-core development box.  Measured on ``benchmarks/points.py`` at 1M points: first
  call 25.0-25.4 s instead of 28.9-30.1 s, peak memory unchanged (5.2-5.5 GB).  Mesh maps
  (1.45M faces) gained nothing measurable, so only :func:`jaxparam.reconstruct_surface` uses it.

Setting either limit ends glibc's own raising of its mmap threshold for the rest of the
process: blocks above the threshold in force are then mmapped, as by default.
"""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import threading

# mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD, _M_MMAP_MAX = -1, -3, -4
_DEFAULT_TRIM_THRESHOLD, _DEFAULT_MMAP_THRESHOLD, _DEFAULT_MMAP_MAX = 128 * 1024, 128 * 1024, 65536
#: The largest mmap threshold glibc's dynamic raising reaches (64-bit).
_DYNAMIC_MMAP_MAX = 32 << 20
#: The largest value :func:`keep_freed` takes (mallopt's argument is a C int).
MAX_KEEP_MB = (2**31 - 1) >> 20
#: Below this many elements (points, or faces) the savings are under 0.1 s: nothing is changed.
MIN_SIZE = 100_000

_lock = threading.Lock()
_depth = 0
#: The trim threshold in force outside :func:`reuse_freed_memory` (set by :func:`keep_freed`).
_baseline_trim = _DEFAULT_TRIM_THRESHOLD
#: Whether :func:`keep_freed` has set glibc's limits in this process.
_set = False


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


def keep_freed(mb: int) -> bool:
    """Process-wide: blocks of up to ``mb`` MiB come from the heap, and up to ``mb`` MiB of
    freed memory at the heap's top stays in the process for the next allocation.  ``mb = 0``
    leaves glibc's own (dynamic) limits alone; after an earlier call it sets the limits glibc's
    dynamic ones reach at most, 32 MiB (blocks) and 64 MiB (freed memory kept).  ``import
    jaxparam`` calls it with ``jp.config.keep_freed_mb`` when JAX loads.  Returns whether it
    changed anything (False where the C library is not glibc).  Raises ``ValueError`` outside
    ``[0, MAX_KEEP_MB]``."""
    global _baseline_trim, _set
    mb = int(mb)
    if not 0 <= mb <= MAX_KEEP_MB:
        raise ValueError(f"keep_freed_mb must be in [0, {MAX_KEEP_MB}] MiB, got {mb}.")
    if _LIBC is None or (mb == 0 and not _set):
        return False
    mallopt, _ = _LIBC
    limit, trim = (mb << 20, mb << 20) if mb else (_DYNAMIC_MMAP_MAX, 2 * _DYNAMIC_MMAP_MAX)
    with _lock:
        _set, _baseline_trim = True, trim
        mallopt(_M_MMAP_THRESHOLD, limit)
        if _depth == 0:              # inside reuse_freed_memory its own trim limit stays
            mallopt(_M_TRIM_THRESHOLD, trim)
    return True


@contextlib.contextmanager
def reuse_freed_memory(size: int = MIN_SIZE):
    """Within the block, freed memory stays in the process for reuse, when ``size`` (the
    problem's point or face count) is at least :data:`MIN_SIZE` and the C library is glibc.
    Nested and concurrent uses share one setting; the last one out gives the free memory back
    (``malloc_trim``) and restores the process-wide setting of :func:`keep_freed`."""
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
                mallopt(_M_TRIM_THRESHOLD, _baseline_trim)
                trim(0)
