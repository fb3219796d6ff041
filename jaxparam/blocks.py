"""Row blocks of a NumPy computation, run on a few threads (``jp.config.threads``).

The points stack computes per-point quantities (tangent frames, fans, gaps) in blocks of rows,
so that temporaries stay in cache.  Each block reads shared inputs and writes its own rows of
preallocated outputs, and NumPy releases the GIL inside its kernels (gathers, ``einsum``,
``matmul``, sorts and partitions), so the blocks can run on several cores at once.  Every row is
computed by the same operations either way: the results are bitwise the same for any number of
threads (tests/test_points_scans.py checks it).  Measured at 1M points on the 2-core box:
:func:`jaxparam.points.graph.robust_frames` 3.48 -> 2.00 s.
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor, wait
from typing import Callable

from .settings import config

__all__ = ["for_blocks"]

_pool: ThreadPoolExecutor | None = None
_pool_key = (0, 0)                      # (threads, process id) the pool was made for
_pool_lock = threading.Lock()


def _executor(threads: int) -> ThreadPoolExecutor:
    """The shared pool of ``threads`` workers, made again when the setting changes and in a
    forked child (which inherits the pool object but none of its threads: work sent to it
    would wait for ever)."""
    global _pool, _pool_key
    key = (threads, os.getpid())
    with _pool_lock:
        if _pool is None or _pool_key != key:
            if _pool is not None and _pool_key[1] == key[1]:
                _pool.shutdown(wait=False)
            _pool, _pool_key = ThreadPoolExecutor(threads, thread_name_prefix="jaxparam-rows"), key
        return _pool


def for_blocks(body: Callable[[int, int], None], n: int, block: int) -> None:
    """Call ``body(r0, r1)`` for the blocks ``[r0, r1)`` of ``range(n)`` of ``block`` rows.

    With ``jp.config.threads > 1`` and more than one block, the blocks run on that many
    threads (``body`` must write only its own rows of its outputs); else in order, here.  An
    exception in a block is raised here after the blocks have run."""
    starts = range(0, n, block)
    threads = config.threads
    if threads <= 1 or len(starts) < 2 or threading.current_thread().name.startswith("jaxparam-rows"):
        for r0 in starts:
            body(r0, min(r0 + block, n))
        return
    futures = [_executor(threads).submit(body, r0, min(r0 + block, n)) for r0 in starts]
    wait(futures)                          # every block done before any error is raised
    for f in futures:
        f.result()
