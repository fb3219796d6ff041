"""Whether this thread is running a solver inside a JAX host callback, where a compiled
kernel must not use XLA's blocking parallel LAPACK calls.

:func:`jaxparam.minimize` under ``jax.jit``, ``jax.vmap`` or ``jax.grad`` runs its solver in a
``jax.pure_callback`` (:mod:`~jaxparam.optimize.implicit`), that is, on one of the XLA CPU
client's pool threads (one per core), while the outer computation waits for it.  The solver's
own kernels run on the same pool.  A batched ``jnp.linalg.eigh`` (LAPACK ``syevd``) splits its
batch over the pool and blocks until every part is done: with two cores, one thread blocked
in the callback and the other in ``eigh``, the parts never run (session 20: ``jax.jit`` of an
ARAP ``minimize`` on a 360-face disk hung in 3 of 4 runs on the 2-core box, from the first
release of this code on).  Inside the callback :mod:`~jaxparam.optimize.newton` therefore
projects its Hessians with Jacobi rotations written in plain XLA operations instead.
"""
from __future__ import annotations

import contextlib
import threading

__all__ = ["host_callback", "inside_host_callback"]

_state = threading.local()


@contextlib.contextmanager
def host_callback():
    """Mark this thread as inside a host callback for the ``with`` block (nests)."""
    _state.depth = getattr(_state, "depth", 0) + 1
    try:
        yield
    finally:
        _state.depth -= 1


def inside_host_callback() -> bool:
    """Whether this thread is inside a :func:`host_callback` block."""
    return getattr(_state, "depth", 0) > 0
