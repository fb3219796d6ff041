"""Sparse direct solves: the only module of jaxparam that factorizes a matrix.

Backends, fastest first:

- ``pardiso``: Intel MKL PARDISO (through the ``pypardiso`` package's MKL
  library, called directly so that a factorization is kept and reused):
  nested-dissection ordering (METIS), supernodal LU for general matrices
  (``mtype 11``) and Cholesky for symmetric positive definite ones
  (``mtype 2``), multithreaded.  The symbolic analysis is done once per
  sparsity pattern and reused for new values (phase 22 only).
- ``scipy``: SuperLU (``scipy.sparse.linalg.splu``), COLAMD ordering, or
  symmetric mode with no pivoting for symmetric matrices.  Always available.

:func:`solve` is differentiable in JAX: forward ``A x = b`` with a cached
factorization; backward one solve with ``A^T`` for the adjoint ``lam``, then
``d b = lam`` and ``d A_ij = -lam_i x_j`` on A's pattern.
"""
from __future__ import annotations

import ctypes
import functools
import hashlib
import threading
import weakref
from collections import OrderedDict, deque

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import tol
from .errors import SolverError

__all__ = ["Pattern", "Factorization", "factorize", "solve", "available_backends", "stats"]

#: Counters for tests and benchmarks: factorizations done, solves done, cache hits.
stats = {"factorizations": 0, "solves": 0, "cache_hits": 0, "analyses": 0}


class Pattern:
    """A fixed CSR sparsity pattern of a square ``n x n`` matrix (numpy, concrete).

    Hashable and compared by identity, so it can be a static argument of
    ``jax.jit`` and the key of cached symbolic analyses.

    **Fields:** ``indptr (n+1,) int64``, ``indices (nnz,) int64`` (column of each
    entry, sorted within rows), ``rows (nnz,) int64``, ``n``, ``nnz``.
    """

    def __init__(self, indptr, indices, n: int):
        self.indptr = np.ascontiguousarray(indptr, dtype=np.int64)
        self.indices = np.ascontiguousarray(indices, dtype=np.int64)
        self.n = int(n)
        self.nnz = int(self.indices.size)
        if self.indptr.shape != (self.n + 1,) or self.indptr[-1] != self.nnz:
            raise ValueError(f"Pattern: indptr must have shape ({self.n + 1},) and end at nnz "
                             f"({self.nnz}), got shape {self.indptr.shape} ending at {self.indptr[-1]}.")
        self._rows = None
        self.uid = _register(self)
        if self.nnz and (self.indices.min() < 0 or self.indices.max() >= self.n):
            raise ValueError(f"Pattern: column indices must lie in [0, {self.n}).")
        # 32-bit, 1-based copies for PARDISO, made once.
        self._ia = None
        self._ja = None
        self._upper = None

    @property
    def rows(self) -> np.ndarray:
        """``(nnz,) int64``: the row of each entry."""
        if self._rows is None:
            self._rows = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.indptr))
        return self._rows

    def matrix(self, values) -> sp.csr_matrix:
        """The scipy CSR matrix with these values."""
        return sp.csr_matrix((np.asarray(values, np.float64), self.indices, self.indptr),
                             shape=(self.n, self.n))

    def upper(self):
        """Entries on or above the diagonal: ``(indptr, indices, take)`` with ``take`` the
        positions of those entries in the full value array (for symmetric PARDISO)."""
        if self._upper is None:
            keep = np.flatnonzero(self.indices >= self.rows)
            indptr = np.zeros(self.n + 1, np.int64)
            np.cumsum(np.bincount(self.rows[keep], minlength=self.n), out=indptr[1:])
            self._upper = (indptr, self.indices[keep], keep)
        return self._upper

    def __repr__(self) -> str:
        return f"Pattern(n={self.n}, nnz={self.nnz})"


# ---------------------------------------------------------------------------------------
# Backends
# ---------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=1)
def _mkl():
    """The MKL ``pardiso`` entry point, found through pypardiso, or None."""
    try:
        import pypardiso

        s = pypardiso.PyPardisoSolver()
        return s._mkl_pardiso, s._pt_type
    except Exception:  # not installed, or no MKL runtime on this platform
        return None


def available_backends() -> list[str]:
    """The backends usable here, fastest first."""
    return (["pardiso"] if _mkl() is not None else []) + ["scipy"]


_PARDISO_ERRORS = {
    -1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
    -4: "zero pivot, numerical factorization or iterative refinement problem (the matrix is "
        "singular or, for a symmetric solve, not positive definite)",
    -5: "unclassified (internal) error", -6: "reordering failed", -7: "diagonal matrix is singular",
    -8: "32-bit integer overflow problem", -9: "not enough memory for out-of-core",
    -10: "error opening out-of-core files", -11: "read/write error with out-of-core files",
}


class _PardisoHandle:
    """One PARDISO internal handle for one pattern and matrix type: the symbolic analysis
    (phase 11) is done once, and each new set of values is factorized with phase 22."""

    def __init__(self, pattern: Pattern, symmetric: bool):
        self.fn, pt_type = _mkl()
        self.pt = np.zeros(64, dtype=pt_type[1])
        self.pt_ctype = pt_type[0]
        self.mtype = 2 if symmetric else 11
        self.n = pattern.n
        if symmetric:
            indptr, indices, self.take = pattern.upper()
        else:
            indptr, indices, self.take = pattern.indptr, pattern.indices, None
        self.ia = (indptr + 1).astype(np.int32)
        self.ja = (indices + 1).astype(np.int32)
        self.iparm = np.zeros(64, dtype=np.int32)
        ip = self.iparm
        ip[0] = 1            # use the values below
        ip[1] = 0            # minimum degree: on mesh Laplacians as little fill as METIS, 3x faster
        ip[7] = 0            # no iterative refinement: the residual is checked after each solve
        ip[9] = 8 if symmetric else 13   # pivot perturbation 1e-8 / 1e-13
        ip[10] = 0 if symmetric else 1   # scaling
        ip[12] = 0 if symmetric else 1   # weighted matching
        ip[17] = -1          # report the number of nonzeros in the factor
        ip[20] = 1           # Bunch-Kaufman pivoting (symmetric indefinite fallback)
        ip[26] = 0           # no matrix checker
        self.lock = threading.Lock()
        self.current = None  # the Factorization whose values are factorized now
        self.values = None
        self.analyzed = False
        self._free_on_gc = weakref.finalize(self, _pardiso_release, self.fn, self.pt, self.pt_ctype,
                                            self.mtype, self.n, self.iparm)

    def call(self, phase: int, values, b=None, *, transpose: bool = False):
        nrhs = 1 if b is None or b.ndim == 1 else b.shape[1]
        if b is None:
            b = np.zeros(self.n)
            x = np.zeros(self.n)
        else:
            b = np.asfortranarray(b, dtype=np.float64)
            x = np.zeros_like(b)
        self.iparm[11] = 2 if transpose and self.mtype == 11 else 0
        err = ctypes.c_int32(0)
        i32 = ctypes.POINTER(ctypes.c_int32)
        f64 = ctypes.POINTER(ctypes.c_double)
        self.fn(self.pt.ctypes.data_as(ctypes.POINTER(self.pt_ctype)), ctypes.byref(ctypes.c_int32(1)),
                ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(self.mtype)),
                ctypes.byref(ctypes.c_int32(phase)), ctypes.byref(ctypes.c_int32(self.n)),
                values.ctypes.data_as(f64), self.ia.ctypes.data_as(i32), self.ja.ctypes.data_as(i32),
                None, ctypes.byref(ctypes.c_int32(nrhs)), self.iparm.ctypes.data_as(i32),
                ctypes.byref(ctypes.c_int32(0)), b.ctypes.data_as(f64), x.ctypes.data_as(f64),
                ctypes.byref(err))
        if err.value != 0:
            raise SolverError(
                f"sparse: PARDISO failed in phase {phase} with error {err.value} "
                f"({_PARDISO_ERRORS.get(err.value, 'unknown')}) on a {self.n} x {self.n} system.",
                stage="factorize" if phase < 33 else "solve")
        return np.ascontiguousarray(x)

    def factor(self, owner, values):
        vals = np.ascontiguousarray(values if self.take is None else values[self.take], np.float64)
        # The unsymmetric analysis also computes the scaling and matching from the values, so it
        # is redone for every matrix (results then depend on the input alone, bit for bit); the
        # symmetric positive definite analysis depends on the pattern only and is reused.
        if not self.analyzed or self.mtype == 11:
            self.call(11, vals)
            self.analyzed = True
            stats["analyses"] += 1
        self.call(22, vals)
        self.values = vals
        self.current = owner


def _pardiso_release(fn, pt, pt_ctype, mtype, n, iparm):
    """Free PARDISO's memory for a handle (phase -1); runs when the handle is collected."""
    try:
        err = ctypes.c_int32(0)
        dummy = np.zeros(1)
        idx = np.ones(2, np.int32)
        fn(pt.ctypes.data_as(ctypes.POINTER(pt_ctype)), ctypes.byref(ctypes.c_int32(1)),
           ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(mtype)),
           ctypes.byref(ctypes.c_int32(-1)), ctypes.byref(ctypes.c_int32(n)),
           dummy.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
           idx.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)),
           idx.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)), None, ctypes.byref(ctypes.c_int32(1)),
           iparm.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)),
           ctypes.byref(ctypes.c_int32(0)), dummy.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
           dummy.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), ctypes.byref(err))
    except Exception:  # interpreter shutdown
        pass


#: One PARDISO handle per (pattern, symmetric), kept while the pattern lives.
_handles: "weakref.WeakKeyDictionary[Pattern, dict]" = weakref.WeakKeyDictionary()


def _handle_for(pattern: Pattern, symmetric: bool) -> _PardisoHandle:
    per = _handles.setdefault(pattern, {})
    if symmetric not in per:
        per[symmetric] = _PardisoHandle(pattern, symmetric)
    return per[symmetric]


class Factorization:
    """A numeric factorization of one matrix; solves ``A x = b`` and ``A^T x = b``.

    **Fields:** ``n``, ``backend`` (``"pardiso"`` or ``"scipy"``), ``symmetric``.
    """

    def __init__(self, pattern: Pattern, values: np.ndarray, symmetric: bool, backend: str):
        self.pattern = pattern
        self.values = np.ascontiguousarray(values, np.float64)
        self.n = pattern.n
        self.symmetric = symmetric
        self.backend = backend
        self._matrix = None
        if backend == "pardiso":
            self._handle = _handle_for(pattern, symmetric)
            with self._handle.lock:
                self._handle.factor(self, self.values)
        else:
            A = pattern.matrix(self.values).tocsc()
            try:
                if symmetric:
                    self._lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                         options={"SymmetricMode": True})
                else:
                    self._lu = spla.splu(A, permc_spec="COLAMD")
            except RuntimeError as exc:
                raise SolverError(f"sparse: the {self.n} x {self.n} matrix is singular and cannot be "
                                  f"factorized ({exc}); check that every unknown is connected to a "
                                  "fixed (boundary) value.", stage="factorize") from None
        stats["factorizations"] += 1

    def _raw_solve(self, b: np.ndarray, transpose: bool) -> np.ndarray:
        if self.backend == "pardiso":
            h = self._handle
            with h.lock:
                if h.current is not self:      # another matrix of this pattern was factorized since
                    h.factor(self, self.values)
                    stats["factorizations"] += 1
                return h.call(33, h.values, b, transpose=transpose)
        return self._lu.solve(np.asarray(b, np.float64), trans="T" if transpose else "N")

    def matrix(self) -> sp.csr_matrix:
        if self._matrix is None:
            self._matrix = self.pattern.matrix(self.values)
        return self._matrix

    def _solve(self, b, transpose: bool, residual_tol: float = tol.SOLVE_RESIDUAL) -> np.ndarray:
        b = np.asarray(b, np.float64)
        if b.shape[0] != self.n or b.ndim not in (1, 2):
            raise SolverError(f"sparse: right-hand side must have shape ({self.n},) or ({self.n}, k), "
                              f"got {b.shape}.", stage="solve")
        stats["solves"] += 1
        x = self._raw_solve(b, transpose)
        A = self.matrix().T if transpose else self.matrix()
        res = np.linalg.norm(A @ x - b) / max(np.linalg.norm(b), np.finfo(float).tiny)
        if not np.isfinite(res) or res > residual_tol:
            if self.backend != "scipy":
                other = Factorization(self.pattern, self.values, self.symmetric, "scipy")
                return other._solve(b, transpose, residual_tol)
            raise SolverError(f"sparse: the solve of a {self.n} x {self.n} system left a relative "
                              f"residual of {res:.3g} (> {residual_tol:g}); the matrix is "
                              "singular or badly conditioned.", stage="solve")
        return x

    def solve(self, b, *, residual_tol: float = tol.SOLVE_RESIDUAL) -> np.ndarray:
        """``x`` with ``A x = b``; ``b: (n,)`` or ``(n, k)``.  The relative residual must reach
        ``residual_tol`` (a Newton direction, checked by a line search, may ask for less)."""
        return self._solve(b, False, residual_tol)

    def solve_transpose(self, b) -> np.ndarray:
        """``x`` with ``A^T x = b``."""
        return self._solve(b, True)


def factorize(pattern: Pattern, values, *, symmetric: bool = False, backend: str = "auto") -> Factorization:
    """Factorize the matrix with this pattern and these values.

    **Arguments:** ``values: (nnz,) float``; ``symmetric=True`` promises
    ``A = A^T`` positive definite (a Cholesky factorization is used);
    ``backend``: ``"auto"``, ``"pardiso"`` or ``"scipy"``.

    Example::

        fac = factorize(pattern, values, symmetric=True)
        x = fac.solve(b)
    """
    values = np.asarray(values, np.float64)
    if values.shape != (pattern.nnz,):
        raise SolverError(f"sparse: values must have shape ({pattern.nnz},) to match the pattern, "
                          f"got {values.shape}.", stage="factorize")
    if not np.all(np.isfinite(values)):
        bad = np.flatnonzero(~np.isfinite(values))
        raise SolverError(f"sparse: the matrix has {bad.size} non-finite entries (first in row "
                          f"{int(pattern.rows[bad[0]])}); a degenerate triangle or weight upstream?",
                          stage="factorize")
    if backend == "auto":
        backend = available_backends()[0]
    if backend not in available_backends():
        raise SolverError(f"sparse: backend {backend!r} is not available here; available: "
                          f"{available_backends()}.", stage="factorize")
    try:
        return Factorization(pattern, values, symmetric, backend)
    except SolverError:
        if backend == "pardiso":
            return Factorization(pattern, values, symmetric, "scipy")
        raise


# ---------------------------------------------------------------------------------------
# Differentiable solve
# ---------------------------------------------------------------------------------------

_cache: "OrderedDict[tuple, Factorization]" = OrderedDict()
_CACHE_SIZE = 4


def _cached_factorization(pattern, values, symmetric, backend) -> Factorization:
    values = np.ascontiguousarray(values, np.float64)
    key = (id(pattern), symmetric, backend, hashlib.blake2b(values.view(np.uint8), digest_size=16).digest())
    fac = _cache.get(key)
    if fac is not None and fac.pattern is pattern:
        _cache.move_to_end(key)
        stats["cache_hits"] += 1
        return fac
    fac = factorize(pattern, values, symmetric=symmetric, backend=backend)
    _cache[key] = fac
    while len(_cache) > _CACHE_SIZE:
        _cache.popitem(last=False)
    return fac


def solve(pattern: Pattern, values, rhs, *, symmetric: bool = False, backend: str = "auto"):
    """Differentiable ``x = A^{-1} rhs`` for JAX.

    **Arguments:** ``values: (nnz,)`` A's entries on ``pattern`` (may be tracers,
    under ``jit`` and ``grad``); ``rhs: (n, k)`` or ``(n,)``.
    **Returns:** ``x`` with the shape of ``rhs``.

    The factorization happens on the host (``jax.pure_callback``) and is
    cached, so the backward pass (one solve with ``A^T``) does not factorize
    again.  The pattern travels as operands (its id and index arrays), so the
    compiled code depends on the sizes only and is shared by every mesh of
    the same size.

    Example::

        x = solve(pattern, values, b)            # inside jax.grad or jax.jit
    """
    values = jnp.asarray(values, dtype=jnp.float64)
    rhs = jnp.asarray(rhs, dtype=jnp.float64)
    if values.shape != (pattern.nnz,):
        raise SolverError(f"sparse.solve: values must have shape ({pattern.nnz},), got "
                          f"{tuple(values.shape)}.", stage="solve")
    if rhs.ndim not in (1, 2) or rhs.shape[0] != pattern.n:
        raise SolverError(f"sparse.solve: rhs must have shape ({pattern.n},) or ({pattern.n}, k), "
                          f"got {tuple(rhs.shape)}.", stage="solve")
    # The host callback runs asynchronously: keep the pattern alive until it has.
    _recent.append(pattern)
    return _solve_jit(values, rhs, pattern.rows, pattern.indices, np.int64(pattern.uid),
                      symmetric=symmetric, backend=backend)


#: Live patterns by id, so host callbacks can find a pattern from a traced integer.
_registry: "weakref.WeakValueDictionary[int, Pattern]" = weakref.WeakValueDictionary()
_next_uid = [0]
#: The patterns of the latest solves, held strongly (a pattern made for one solve may
#: otherwise be collected before its asynchronous callback runs).
_recent: "deque[Pattern]" = deque(maxlen=64)


def _register(pattern: Pattern) -> int:
    _next_uid[0] += 1
    _registry[_next_uid[0]] = pattern
    return _next_uid[0]


def _host_solve(symmetric, backend, transpose, values, b, uid):
    pattern = _registry.get(int(uid))
    if pattern is None:
        raise SolverError("sparse: the matrix pattern was garbage-collected during a solve.", stage="solve")
    fac = _cached_factorization(pattern, np.asarray(values), symmetric, backend)
    b = np.asarray(b)
    return (fac.solve_transpose(b) if transpose else fac.solve(b)).astype(np.float64).reshape(b.shape)


def _callback(symmetric, backend, transpose, values, b, uid):
    return jax.pure_callback(
        functools.partial(_host_solve, symmetric, backend, transpose),
        jax.ShapeDtypeStruct(b.shape, jnp.float64), values, b, uid, vmap_method="sequential")


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1))
def _solve_core(symmetric, backend, values, rhs, rows, cols, uid):
    return _callback(symmetric, backend, False, values, rhs, uid)


def _solve_fwd(symmetric, backend, values, rhs, rows, cols, uid):
    x = _callback(symmetric, backend, False, values, rhs, uid)
    return x, (values, x, rows, cols, uid)


def _solve_bwd(symmetric, backend, res, g):
    values, x, rows, cols, uid = res
    lam = _callback(symmetric, backend, not symmetric, values, g, uid)
    if x.ndim == 1:
        dvals = -lam[rows] * x[cols]
    else:
        dvals = -jnp.sum(lam[rows] * x[cols], axis=1)
    return dvals, lam, None, None, None


_solve_core.defvjp(_solve_fwd, _solve_bwd)


@functools.partial(jax.jit, static_argnames=("symmetric", "backend"))
def _solve_jit(values, rhs, rows, cols, uid, *, symmetric, backend):
    return _solve_core(symmetric, backend, values, rhs, rows, cols, uid)
