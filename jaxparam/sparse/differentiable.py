"""The differentiable solve :func:`solve`: ``jax.custom_vjp`` around a ``jax.pure_callback``
that factorizes on the host, with a small cache of recent factorizations (keyed by the
pattern's uid and a hash of the values) so that the backward pass reuses the forward's.
"""
from __future__ import annotations

import functools
import hashlib
import threading
from collections import OrderedDict

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import SolverError
from .backends import Factorization, choose_backend, factorize
from .counters import stats
from .pattern import Pattern, pattern_for_uid

#: Recent factorizations of :func:`solve`, by (pattern uid, symmetric, backend, values hash),
#: least recently used first; at most ``_CACHE_SIZE`` of them.  Hold :data:`cache_lock`
#: to read or change it.
cache: "OrderedDict[tuple, Factorization]" = OrderedDict()
_CACHE_SIZE = 4
#: The lock of :data:`cache`.
cache_lock = threading.Lock()


def _cached_factorization(pattern: Pattern, values: np.ndarray, symmetric: bool, backend: str):
    values = np.ascontiguousarray(values, np.float64)
    key = (pattern.uid, symmetric, backend,
           hashlib.blake2b(values.view(np.uint8), digest_size=16).digest())
    with cache_lock:
        fac = cache.get(key)
        if fac is not None:
            cache.move_to_end(key)
            stats["cache_hits"] += 1
            return fac
    fac = factorize(pattern, values, symmetric=symmetric, backend=backend)
    with cache_lock:
        cache[key] = fac
        while len(cache) > _CACHE_SIZE:
            cache.popitem(last=False)
    return fac


def solve(pattern: Pattern, values, rhs, *, symmetric: bool = False, backend: str = "auto"):
    """Differentiable ``x = A^{-1} rhs`` for JAX.

    **Arguments:** ``values: (nnz,) float64`` A's entries on ``pattern`` (may
    be tracers, under ``jit``, ``grad`` and ``vmap``); ``rhs: (n, k)`` or
    ``(n,)``; ``symmetric``, ``backend`` as in :func:`factorize`.

    **Returns:** ``x`` with the shape of ``rhs``.

    The factorization happens on the host (``jax.pure_callback``) and is
    cached (4 most recent matrices), so the backward pass (one solve with
    ``A^T``) does not factorize again.  The pattern travels as operands (its
    uid and index arrays), so the compiled code depends on the sizes only.
    Called with concrete arrays it runs on the host at once and raises
    :class:`SolverError` itself; under ``jit`` that error reaches the caller
    inside JAX's runtime error.

    Example::

        x = solve(pattern, values, b)            # inside jax.grad or jax.jit
    """
    if not isinstance(pattern, Pattern):
        raise TypeError(f"sparse.solve: pattern must be a sparse.Pattern, got {type(pattern).__name__}.")
    if not jax.config.jax_enable_x64:
        raise SolverError("sparse.solve: needs float64; enable it with "
                          "jax.config.update('jax_enable_x64', True) (importing jaxparam does).",
                          stage="solve")
    choose_backend(backend, bool(symmetric))
    if np.shape(values) != (pattern.nnz,):
        raise SolverError(f"sparse.solve: values must have shape ({pattern.nnz},), got "
                          f"{tuple(np.shape(values))}.", stage="solve")
    if np.ndim(rhs) not in (1, 2) or np.shape(rhs)[0] != pattern.n:
        raise SolverError(f"sparse.solve: rhs must have shape ({pattern.n},) or ({pattern.n}, k), "
                          f"got {tuple(np.shape(rhs))}.", stage="solve")
    if not any(isinstance(a, jax.core.Tracer) for a in (values, rhs)):
        fac = _cached_factorization(pattern, np.asarray(values, np.float64), bool(symmetric), backend)
        return jnp.asarray(fac.solve(np.asarray(rhs, np.float64)))
    return _solve_jit(jnp.asarray(values, jnp.float64), jnp.asarray(rhs, jnp.float64),
                      pattern.rows, pattern.indices, pattern.indptr, np.int64(pattern.uid),
                      symmetric=bool(symmetric), backend=backend)


def _host_solve(symmetric, backend, transpose, values, b, indptr, indices, uid):
    pattern = pattern_for_uid(uid, indptr, indices)
    fac = _cached_factorization(pattern, np.asarray(values), symmetric, backend)
    b = np.asarray(b, np.float64)
    return (fac.solve_transpose(b) if transpose else fac.solve(b)).reshape(b.shape)


def _callback(symmetric, backend, transpose, values, b, indptr, cols, uid):
    return jax.pure_callback(functools.partial(_host_solve, symmetric, backend, transpose),
                             jax.ShapeDtypeStruct(b.shape, jnp.float64), values, b, indptr, cols, uid,
                             vmap_method="sequential")


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1))
def _solve_core(symmetric, backend, values, rhs, rows, cols, indptr, uid):
    return _callback(symmetric, backend, False, values, rhs, indptr, cols, uid)


def _solve_fwd(symmetric, backend, values, rhs, rows, cols, indptr, uid):
    x = _callback(symmetric, backend, False, values, rhs, indptr, cols, uid)
    return x, (values, x, rows, cols, indptr, uid)


def _solve_bwd(symmetric, backend, res, g):
    values, x, rows, cols, indptr, uid = res
    lam = _callback(symmetric, backend, not symmetric, values, g, indptr, cols, uid)   # A^T lam = g
    prod = lam[rows] * x[cols]
    dvals = -(prod if x.ndim == 1 else jnp.sum(prod, axis=1))
    return dvals, lam, None, None, None, None


_solve_core.defvjp(_solve_fwd, _solve_bwd)


@functools.partial(jax.jit, static_argnames=("symmetric", "backend"))
def _solve_jit(values, rhs, rows, cols, indptr, uid, *, symmetric, backend):
    return _solve_core(symmetric, backend, values, rhs, rows, cols, indptr, uid)
