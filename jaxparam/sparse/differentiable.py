"""The differentiable solve :func:`solve`: ``jax.lax.custom_linear_solve`` around a
``jax.pure_callback`` that factorizes on the host, with a small cache of recent factorizations
(found by the pattern's uid and the exact values) so that the derivative solves reuse the
forward's factorization.
"""
from __future__ import annotations

import functools
import threading
from collections import OrderedDict

import numpy as np

from ..lazy_jax import jax, jnp  # JAX loads on first use (issue 17)
from ..errors import SolverError
from .backends import Factorization, choose_backend, factorize
from .counters import stats
from .pattern import Pattern, pattern_for_uid

#: Recent factorizations of :func:`solve`, by (pattern uid, symmetric, backend, a fingerprint
#: of the values), least recently used first; at most ``_CACHE_SIZE`` of them.  A hit is
#: confirmed by comparing all the values with the factorized ones (exactly), so two matrices
#: that share a fingerprint never share a factorization (the newer one takes the slot).  Hold
#: :data:`cache_lock` to read or change it.
cache: "OrderedDict[tuple, Factorization]" = OrderedDict()
_CACHE_SIZE = 4
#: The lock of :data:`cache`.
cache_lock = threading.Lock()
#: How many evenly spaced values make the fingerprint.
_FINGERPRINT = 64


def _fingerprint(values: np.ndarray) -> bytes:
    """A cheap key for ``values (nnz,)``: the bytes of ``_FINGERPRINT`` evenly spaced entries
    and of the last one.  Not a hash: a hit is confirmed by an exact comparison (30 us for
    80k values, where hashing them all took 1.2-1.4 ms per solve; issue 12)."""
    step = max(1, values.size // _FINGERPRINT)
    return values[::step].tobytes() + values[-1:].tobytes()


def cached_factorization(pattern: Pattern, values: np.ndarray, symmetric: bool, backend: str):
    """The factorization of ``values (nnz,)`` on ``pattern`` from the cache of the most recent
    ones (:func:`solve`'s), factorized and cached on a miss.  A host computation that will be
    differentiated takes its factor from here, so that the adjoint solves find it, already
    checked, instead of factorizing again."""
    values = np.ascontiguousarray(values, np.float64)
    key = (pattern.uid, symmetric, backend, values.size, _fingerprint(values))
    with cache_lock:
        fac = cache.get(key)
        if fac is not None and np.array_equal(fac.values, values):
            cache.move_to_end(key)
            stats["cache_hits"] += 1
            return fac
    fac = factorize(pattern, values, symmetric=symmetric, backend=backend)
    with cache_lock:
        cache[key] = fac
        cache.move_to_end(key)
        while len(cache) > _CACHE_SIZE:
            cache.popitem(last=False)
    return fac


def solve(pattern: Pattern, values, rhs, *, symmetric: bool = False, backend: str = "auto"):
    """Differentiable ``x = A^{-1} rhs`` for JAX, in forward and reverse mode and under ``vmap``.

    **Arguments:** ``values: (nnz,) float64`` A's entries on ``pattern`` (may
    be tracers, under ``jit``, ``grad``, ``jvp`` and ``vmap``); ``rhs: (n, k)`` or
    ``(n,)``; ``symmetric``, ``backend`` as in :func:`factorize`.

    **Returns:** ``x`` with the shape of ``rhs``.

    The factorization happens on the host (``jax.pure_callback``) and is
    cached (4 most recent matrices), so the derivative solves do not factorize
    again.  The pattern travels as operands (its uid and index arrays), so the
    compiled code depends on the sizes only.  Called with concrete arrays it
    runs on the host at once and raises :class:`SolverError` itself; under
    ``jit`` that error reaches the caller inside JAX's runtime error.

    **Transformations.**  One definition gives both modes: the solve is a
    ``jax.lax.custom_linear_solve`` whose ``matvec`` is the sparse product
    ``(A y)_i = sum_j A_ij y_j`` on the traced values and whose ``solve`` and
    ``transpose_solve`` are the host callback (``A`` and ``A^T``, both from the
    one cached factorization: PARDISO and SuperLU solve transposed with it;
    for ``symmetric=True`` the transpose is ``A``).

    - Forward (``jax.jvp``, ``jax.jacfwd``): ``dx = A^{-1} (db - dA x)``, one
      more solve with ``A``, where ``dA x`` is the product of the tangent values
      on the pattern (``jacfwd``'s tangents go as the columns of one block).
    - Reverse (``jax.grad``, ``jax.vjp``, ``jax.jacrev``): JAX transposes that
      linear map: one solve ``A^T lam = g``, then ``d rhs = lam`` and
      ``d A_ij = -lam_i . x_j`` on the pattern (one factorization, two solves
      per gradient, as before).  The adjoint solve skips the residual check
      when the factor has passed it already (on the forward solve; see
      ``Factorization._solve`` for why that is sound), and checks only that
      ``lam`` is finite; a factor that has not been checked yet is checked.
    - Higher order and mixed (``jax.hessian``, grad of grad, ``jacfwd`` of
      ``grad``): the derivative solves are again linear solves of the same
      kind, so they differentiate the same way (each order adds solves with
      ``A`` or ``A^T``, never another factorization of the same values).
    - ``jax.vmap``: the callback is batched with ``vmap_method="expand_dims"``:
      one host call per batched solve, which factorizes (or takes from the
      cache) each distinct matrix once and solves all the right-hand sides
      that share it as the columns of one block.  Over ``rhs`` that is one
      factorization for the batch; over ``values`` every member is its own
      matrix (its own factorization; more than 4 distinct matrices in a batch
      overflow the cache, so their derivative solves factorize again).  The
      batched result equals a Python loop of solves to rounding (bitwise
      while a shared matrix's block has at most 8 columns; PARDISO's blocked
      multi-column solve above that differs in the last bits, and so does
      its transposed LU solve, the adjoint of reverse mode, which is always
      blocked).  All
      members of a batch must share the pattern.

    The derivatives are those of ``A^{-1} rhs`` as a function of every stored
    entry on its own, at every order (``transpose_solve`` solves with ``A^T`` and
    JAX transposes the product, so a tangent on entry ``(i, j)`` alone is taken as
    it comes; cotangents are not symmetrized).  ``symmetric=True`` promises
    ``A = A^T`` and the Cholesky backends read one triangle, so there the solve
    itself is only defined on symmetric values: compare with finite differences
    along directions that move ``(i, j)`` and ``(j, i)`` together.

    Example::

        x = solve(pattern, values, b)            # inside jax.grad, jax.jacfwd or jax.jit
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
        fac = cached_factorization(pattern, np.asarray(values, np.float64), bool(symmetric), backend)
        return jnp.asarray(fac.solve(np.asarray(rhs, np.float64)))
    return _solve_jit(jnp.asarray(values, jnp.float64), jnp.asarray(rhs, jnp.float64),
                      pattern.rows, pattern.indices, pattern.indptr, np.int64(pattern.uid),
                      symmetric=bool(symmetric), backend=backend)


def _first(a: np.ndarray) -> np.ndarray:
    """``a`` without the leading (size-1, unbatched) axes that ``vmap_method="expand_dims"`` adds."""
    return a[(0,) * (a.ndim - 1)]


def _host_solve(symmetric, backend, transpose, trust, core_ndim, values, b, indptr, indices, uid):
    """The host side of the callback: ``A^{-1} b`` (``A^{-T} b`` if ``transpose``).

    ``trust``: the derivative (adjoint) solve, whose residual check is skipped when the factor
    has passed one already (``Factorization.solve``'s ``trust_checked``).

    Unbatched: ``values (nnz,)``, ``b`` of ``core_ndim`` axes.  Under ``vmap`` (``expand_dims``)
    every argument has the same number of leading batch axes, of size 1 where unbatched; the
    pattern's (``indptr``, ``indices``, ``uid``) must be unbatched.
    """
    values, b = np.asarray(values, np.float64), np.asarray(b, np.float64)
    uids = np.unique(np.asarray(uid))
    if uids.size != 1:
        raise SolverError("sparse.solve: every member of a jax.vmap batch must share one pattern; "
                          f"this batch has {uids.size}.", stage="solve")
    pattern = pattern_for_uid(int(uids[0]), _first(np.asarray(indptr)), _first(np.asarray(indices)))

    def solve_with(fac, rhs):
        return (fac.solve_transpose(rhs, trust_checked=trust) if transpose
                else fac.solve(rhs, trust_checked=trust)).reshape(rhs.shape)

    vlead, blead = values.shape[:-1], b.shape[:b.ndim - core_ndim]
    if not vlead and not blead:
        return solve_with(cached_factorization(pattern, values, symmetric, backend), b)
    # Batched: factorize each distinct matrix once; the right-hand sides that share one are
    # solved together, as the columns of one block.
    lead = np.broadcast_shapes(vlead, blead)
    core = b.shape[b.ndim - core_ndim:]
    n, k = pattern.n, int(np.prod(core[1:], dtype=np.int64))
    vflat, bflat = values.reshape(-1, pattern.nnz), b.reshape((-1,) + core)
    iv = np.broadcast_to(np.arange(vflat.shape[0]).reshape(vlead), lead).ravel()
    ib = np.broadcast_to(np.arange(bflat.shape[0]).reshape(blead), lead).ravel()
    x = np.empty((iv.size,) + core)
    for v in np.unique(iv):
        members = np.flatnonzero(iv == v)
        fac = cached_factorization(pattern, vflat[v], symmetric, backend)
        if members.size == 1:
            x[members[0]] = solve_with(fac, bflat[ib[members[0]]])
            continue
        block = bflat[ib[members]].reshape(members.size, n, k).transpose(1, 0, 2).reshape(n, members.size * k)
        xs = solve_with(fac, block)
        x[members] = xs.reshape(n, members.size, k).transpose(1, 0, 2).reshape((members.size,) + core)
    return x.reshape(lead + core)


def _callback(symmetric, backend, transpose, trust, values, b, indptr, cols, uid):
    return jax.pure_callback(functools.partial(_host_solve, symmetric, backend, transpose, trust, b.ndim),
                             jax.ShapeDtypeStruct(b.shape, jnp.float64), values, b, indptr, cols, uid,
                             vmap_method="expand_dims")


@functools.partial(jax.jit, static_argnames=("symmetric", "backend"))
def _solve_jit(values, rhs, rows, cols, indptr, uid, *, symmetric, backend):
    n = rhs.shape[0]

    def matvec(y):   # A y on the pattern: differentiated in the values (closed over) by JAX
        prod = values * y[cols] if y.ndim == 1 else values[:, None] * y[cols]
        return jax.ops.segment_sum(prod, rows, num_segments=n)

    def solve_a(_, b):
        return _callback(symmetric, backend, False, False, values, b, indptr, cols, uid)

    def solve_at(_, b):   # the adjoint: A^T (= A if symmetric), after the forward solve's check
        return _callback(symmetric, backend, not symmetric, True, values, b, indptr, cols, uid)

    # Not custom_linear_solve's symmetric=True even when A = A^T: that would take A's own product
    # as the transpose's, whose derivative in the values is dA, not dA^T; the values are
    # independent entries, so from the second order on the derivatives would be those of a
    # different function for unsymmetric tangents.  JAX transposes the product instead (exact at
    # every order); the host still solves A^T = A with A's factor.
    return jax.lax.custom_linear_solve(matvec, rhs, solve_a, solve_at)
