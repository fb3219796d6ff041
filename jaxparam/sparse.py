"""Sparse direct solves: the only module of jaxparam that factorizes a matrix.

Backends (:func:`available_backends`, fastest first):

- ``pardiso``: Intel MKL PARDISO, through the MKL runtime that the
  ``pypardiso`` package loads, called directly so that factorizations are
  kept and reused.  Nested-dissection ordering (METIS); supernodal LU with
  scaling and weighted matching for general matrices (``mtype 11``), Cholesky
  for symmetric positive definite ones (``mtype 2``); multithreaded.  The
  Cholesky analysis depends on the pattern only: it is done once per
  pattern, and every matrix of that pattern is factorized into its own slot
  of the same handle (PARDISO's ``maxfct``/``mnum``).  The LU analysis
  depends on the values (matching), so each LU has a handle of its own.
- ``cholespy``: CHOLMOD through ``cholespy``, symmetric positive definite only.
- ``scipy``: SuperLU (``scipy.sparse.linalg.splu``), COLAMD ordering, or
  symmetric mode without pivoting for symmetric matrices.  Always available.

``backend="auto"`` takes PARDISO when it loads, else CHOLMOD for symmetric
matrices, else SuperLU.  A backend that fails to factorize hands the matrix
to SuperLU; every solve checks its relative residual against
:data:`jaxparam.tol.SOLVE_RESIDUAL` and is redone once with SuperLU above it.

:func:`solve` is differentiable in JAX: forward ``A x = b`` with a cached
factorization; backward one solve with ``A^T`` (the same factorization) for
the adjoint ``lam``, then ``d b = lam`` and ``d A_ij = -lam_i . x_j`` on A's
pattern.
"""
from __future__ import annotations

import ctypes
import functools
import hashlib
import itertools
import operator
import threading
import weakref
from collections import OrderedDict

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import tol
from .errors import SolverError, first_few

__all__ = ["Pattern", "Factorization", "factorize", "solve", "available_backends", "stats"]

#: Counters for tests and benchmarks: numeric factorizations, PARDISO symbolic analyses,
#: solves (each ``Factorization.solve`` call), hits of :func:`solve`'s factorization
#: cache, and hand-overs to SuperLU (failed factorization or residual too large).
stats = {"factorizations": 0, "analyses": 0, "solves": 0, "cache_hits": 0, "fallbacks": 0}

BACKENDS = ("pardiso", "cholespy", "scipy")


# ---------------------------------------------------------------------------------------
# Pattern
# ---------------------------------------------------------------------------------------

class Pattern:
    """A fixed CSR sparsity pattern of a square ``n x n`` matrix (numpy, concrete).

    Hashable and compared by identity, so it can be a static argument of
    ``jax.jit`` or a closure constant, and the key of cached analyses.  Its
    arrays are read-only.

    **Arguments:** ``indptr: (n+1,) int`` row starts; ``indices: (nnz,) int``
    the column of each entry, strictly increasing within each row (sorted, no
    duplicates); ``n`` the size.

    **Fields:** ``indptr (n+1,) int64``, ``indices (nnz,) int64``, ``rows (nnz,)
    int64`` (the row of each entry), ``n``, ``nnz``.
    """

    def __init__(self, indptr, indices, n: int, *, _uid: int | None = None):
        n = operator.index(n)
        indptr, indices = np.asarray(indptr), np.asarray(indices)
        for name, a in (("indptr", indptr), ("indices", indices)):
            if a.ndim != 1 or not (np.issubdtype(a.dtype, np.integer) or a.size == 0):
                raise ValueError(f"Pattern: {name} must be a 1-D integer array, got shape "
                                 f"{a.shape} of {a.dtype}.")
        if n < 0 or indptr.shape != (n + 1,):
            raise ValueError(f"Pattern: indptr must have shape ({n + 1},) for n = {n}, "
                             f"got {indptr.shape}.")
        counts = np.diff(indptr)
        if indptr[0] != 0 or indptr[-1] != indices.size or np.any(counts < 0):
            raise ValueError(f"Pattern: indptr must rise from 0 to nnz = {indices.size}; it runs "
                             f"from {indptr[0]} to {indptr[-1]}"
                             + (" and decreases" if np.any(counts < 0) else "") + ".")
        self.n, self.nnz = n, int(indices.size)
        self.indptr = _frozen(indptr)
        self.indices = _frozen(indices)
        self.rows = _frozen(np.repeat(np.arange(n, dtype=np.int64), counts))
        if self.nnz:
            out = np.flatnonzero((self.indices < 0) | (self.indices >= n))
            if out.size:
                raise ValueError(f"Pattern: column indices must lie in [0, {n}); entries "
                                 f"{first_few(out)} do not.")
            # Within a row the columns must strictly increase (PARDISO reads sorted rows).
            same_row = self.rows[1:] == self.rows[:-1]
            bad = np.flatnonzero(same_row & (self.indices[1:] <= self.indices[:-1]))
            if bad.size:
                raise ValueError(f"Pattern: columns must be sorted and unique within each row; rows "
                                 f"{first_few(np.unique(self.rows[bad]))} are not (use "
                                 "scipy's sum_duplicates() / sort_indices()).")
        #: rows with no entry (the matrix is then singular)
        self.empty_rows = np.flatnonzero(counts == 0)
        self._triangles: dict = {}
        self.uid = _register(self, _uid)

    def matrix(self, values) -> sp.csr_matrix:
        """The scipy CSR matrix with these values.  **Arguments:** ``values: (nnz,) float``."""
        return sp.csr_matrix((np.asarray(values, np.float64), self.indices, self.indptr),
                             shape=(self.n, self.n))

    def triangle(self, upper: bool):
        """The entries on and above (``upper``) or on and below the diagonal.

        **Returns:** ``(indptr (n+1,) int32, indices (m,) int32, take (m,) int64)``,
        a CSR pattern and the positions of its entries in the full value array.
        """
        if upper not in self._triangles:
            keep = np.flatnonzero(self.indices >= self.rows if upper else self.indices <= self.rows)
            indptr = np.zeros(self.n + 1, np.int64)
            np.cumsum(np.bincount(self.rows[keep], minlength=self.n), out=indptr[1:])
            self._triangles[upper] = (indptr.astype(np.int32), self.indices[keep].astype(np.int32), keep)
        return self._triangles[upper]

    @functools.cached_property
    def has_diagonal(self) -> bool:
        """Whether every diagonal entry is in the pattern."""
        return int(np.count_nonzero(self.indices == self.rows)) == self.n

    @functools.cached_property
    def int32(self):
        """``(indptr, indices)`` as int32, for the C backends."""
        if self.nnz >= 2 ** 31:
            raise SolverError(f"sparse: {self.nnz} entries exceed the 32-bit indices of the "
                              "backends.", stage="factorize")
        return self.indptr.astype(np.int32), self.indices.astype(np.int32)

    def __repr__(self) -> str:
        return f"Pattern(n={self.n}, nnz={self.nnz})"


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=np.int64, copy=True)
    a.flags.writeable = False
    return a


#: Live patterns by uid, so a host callback can find its pattern from a traced integer.
_registry: "weakref.WeakValueDictionary[int, Pattern]" = weakref.WeakValueDictionary()
_uids = itertools.count(1)


def _register(pattern: Pattern, uid: int | None) -> int:
    uid = next(_uids) if uid is None else uid
    _registry[uid] = pattern
    return uid


# ---------------------------------------------------------------------------------------
# Backends
# ---------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=1)
def _mkl():
    """The MKL ``pardiso`` entry point and the C type of its handle, or None."""
    # The MKL runtime that pypardiso pulls in lives in the environment's own library folder;
    # loading it from there directly skips pypardiso's search (ldconfig and gcc subprocesses
    # and a recursive glob of site-packages: 0.4-0.8 s in every new process).
    import glob
    import sys

    pt = (ctypes.c_int64, np.int64) if ctypes.sizeof(ctypes.c_void_p) == 8 else (ctypes.c_int32, np.int32)
    for pattern in ("lib/libmkl_rt.so*", "lib/libmkl_rt*.dylib", "Library/bin/mkl_rt*.dll"):
        for path in sorted(glob.glob(f"{sys.prefix}/{pattern}"), key=len):
            try:
                return ctypes.CDLL(path).pardiso, pt
            except (OSError, AttributeError):
                continue
    try:
        import pypardiso

        s = pypardiso.PyPardisoSolver()
        return s._mkl_pardiso, s._pt_type
    except Exception:  # not installed, or no MKL runtime on this platform
        return None


@functools.lru_cache(maxsize=1)
def _cholespy():
    try:
        import cholespy

        return cholespy
    except Exception:
        return None


def available_backends() -> list[str]:
    """The backends usable here, fastest first, e.g. ``["pardiso", "cholespy", "scipy"]``."""
    return ((["pardiso"] if _mkl() is not None else [])
            + (["cholespy"] if _cholespy() is not None else []) + ["scipy"])


def _choose_backend(backend: str, symmetric: bool) -> str:
    if backend not in ("auto",) + BACKENDS:
        raise SolverError(f"sparse: unknown backend {backend!r}; expected 'auto' or one of "
                          f"{list(BACKENDS)}.", stage="factorize")
    have = available_backends()
    if backend == "auto":
        return "pardiso" if "pardiso" in have else ("cholespy" if symmetric and "cholespy" in have
                                                   else "scipy")
    if backend not in have:
        raise SolverError(f"sparse: backend {backend!r} is not available here (its package is not "
                          f"installed or does not load); available: {have}.", stage="factorize")
    if backend == "cholespy" and not symmetric:
        raise SolverError("sparse: backend 'cholespy' factorizes only symmetric positive definite "
                          "matrices (symmetric=True); use 'pardiso' or 'scipy' for this one.",
                          stage="factorize")
    return backend


_PARDISO_ERRORS = {
    -1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
    -4: "zero pivot: the matrix is singular or, for a symmetric solve, not positive definite",
    -5: "unclassified (internal) error", -6: "reordering failed", -7: "diagonal matrix is singular",
    -8: "32-bit integer overflow problem", -9: "not enough memory for out-of-core",
    -10: "error opening out-of-core files", -11: "read/write error with out-of-core files",
}

#: Matrices of one pattern whose Cholesky factors a shared PARDISO handle holds at once;
#: a further one evicts the least recently used (which is refactorized if used again).
_PARDISO_SLOTS = 8


def _pardiso_call(fn, pt, maxfct, mnum, mtype, phase, n, a, ia, ja, iparm, b, x) -> int:
    i32, f64 = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_double)
    err = ctypes.c_int32(0)
    c = lambda v: ctypes.byref(ctypes.c_int32(v))  # noqa: E731
    nrhs = 1 if b.ndim == 1 else b.shape[1]
    fn(pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64 if pt.dtype == np.int64 else ctypes.c_int32)),
       c(maxfct), c(mnum), c(mtype), c(phase), c(n), a.ctypes.data_as(f64), ia.ctypes.data_as(i32),
       ja.ctypes.data_as(i32), None, c(nrhs), iparm.ctypes.data_as(i32), c(0),
       b.ctypes.data_as(f64), x.ctypes.data_as(f64), ctypes.byref(err))
    return err.value


def _pardiso_free(fn, pt, maxfct, mtype, n, ia, ja, iparm):
    """Phase -1: release all of a handle's memory (run when the handle is collected)."""
    try:
        z = np.zeros(1)
        _pardiso_call(fn, pt, maxfct, 1, mtype, -1, n, z, ia, ja, iparm, z, z.copy())
    except Exception:  # interpreter shutdown
        pass


class _PardisoHandle:
    """One PARDISO handle (its ``pt`` array) for one pattern and matrix type.

    ``shared`` (Cholesky): one analysis (phase 11) for the pattern, and up to
    ``_PARDISO_SLOTS`` numeric factors (phase 22, ``mnum`` = slot + 1) owned by
    different factorizations.  Not shared (LU): one owner; each factorization
    redoes the analysis, which for ``mtype 11`` depends on the values.
    """

    def __init__(self, pattern: Pattern, symmetric: bool, pivoting: bool = True):
        self.fn, (_, pt_dtype) = _mkl()
        self.n, self.symmetric = pattern.n, symmetric
        self.mtype = 2 if symmetric else 11
        self.maxfct = _PARDISO_SLOTS if symmetric else 1
        if symmetric:
            self.ia, self.ja, self.take = pattern.triangle(upper=True)
        else:
            (self.ia, self.ja), self.take = pattern.int32, None
        self.pt = np.zeros(64, dtype=pt_dtype)
        ip = self.iparm = np.zeros(64, dtype=np.int32)
        ip[0] = 1                          # the values below, not the defaults
        ip[1] = 3                          # METIS nested dissection, OpenMP-parallel (serial: 1.5x slower)
        ip[7] = 0                          # refinement only after perturbed pivots; residuals are checked
        ip[9] = 8 if symmetric else 13     # pivot perturbation 1e-8 / 1e-13
        # LU: scaling and weighted matching only where pivoting may be needed; a diagonally
        # dominant matrix with a positive diagonal (I - Lambda of the convex-combination maps)
        # needs none, and matching cost 0.2 s at 726k unknowns.
        ip[10] = ip[12] = 1 if pivoting else 0
        ip[23] = 0 if symmetric else 10    # LU: the improved two-level factorization (0.99 s vs 1.34 s)
        ip[17] = -1                        # report the factor's nonzeros
        ip[24] = 1                         # sequential forward/backward solve: bitwise reproducible
        ip[34] = 1                         # zero-based indices
        self.lock = threading.RLock()
        self.analyzed = False
        self.owner = [None] * self.maxfct  # token of the factorization in each slot
        self.used = [0] * self.maxfct      # last use, for evicting the least recent
        self._clock = itertools.count(1)
        weakref.finalize(self, _pardiso_free, self.fn, self.pt, self.maxfct, self.mtype, self.n,
                         self.ia, self.ja, self.iparm)

    def _call(self, phase: int, a: np.ndarray, mnum: int = 1, b=None, transpose: bool = False):
        b = np.zeros(self.n) if b is None else np.asfortranarray(b, dtype=np.float64)
        x = np.zeros_like(b)
        self.iparm[11] = 2 if transpose and not self.symmetric else 0
        err = _pardiso_call(self.fn, self.pt, self.maxfct, mnum, self.mtype, phase, self.n, a,
                            self.ia, self.ja, self.iparm, b, x)
        if err != 0:
            raise SolverError(f"sparse: PARDISO failed in phase {phase} with error {err} "
                              f"({_PARDISO_ERRORS.get(err, 'unknown')}) on a {self.n} x {self.n} "
                              "system.", stage="factorize" if phase < 33 else "solve")
        return np.ascontiguousarray(x)

    def factor(self, token: int, a: np.ndarray) -> int:
        """Factorize values ``a`` (this handle's entries) into a slot for ``token``; its index."""
        with self.lock:
            free = [i for i, t in enumerate(self.owner) if t is None]
            slot = free[0] if free else int(np.argmin(self.used))
            self.owner[slot] = None
            if not self.analyzed or not self.symmetric:
                self._call(11, a)
                self.analyzed = True
                stats["analyses"] += 1
            self._call(22, a, slot + 1)
            stats["factorizations"] += 1
            if self.iparm[13] > 0:   # pivots below 1e-13 |A| (after scaling): singular to working precision
                raise SolverError(f"sparse: PARDISO perturbed {self.iparm[13]} pivots of the {self.n} x "
                                  f"{self.n} matrix: it is singular or nearly so.", stage="factorize")
            self.owner[slot], self.used[slot] = token, next(self._clock)
            return slot

    def solve(self, token: int, slot: int, a: np.ndarray, b: np.ndarray, transpose: bool):
        """Solve with ``token``'s factor; refactorizes first if it was evicted.
        **Returns:** ``(x, slot)``."""
        with self.lock:
            if self.owner[slot] != token:
                slot = self.factor(token, a)
            self.used[slot] = next(self._clock)
            if b.ndim == 2 and 1 < b.shape[1] <= 8:
                # PARDISO's blocked multi-RHS solve costs 3-6x one column for k <= 8 (705k grid:
                # 0.08 s for one column, 0.5-0.6 s for two): solve the columns one by one.
                x = np.stack([self._call(33, a, slot + 1, b[:, j], transpose) for j in range(b.shape[1])], 1)
            else:
                x = self._call(33, a, slot + 1, b, transpose)
            return x, slot

    def release(self, token: int, slot_box: list):
        """Phase 0: free ``token``'s numeric factor (when its factorization is collected)."""
        try:
            with self.lock:
                slot = slot_box[0]
                if self.owner[slot] == token:
                    self.owner[slot] = None
                    if self.symmetric:
                        self._call(0, np.zeros(1), slot + 1)
        except Exception:  # interpreter shutdown
            pass


#: The shared Cholesky handle of each pattern, kept while the pattern lives.
_handles: "weakref.WeakKeyDictionary[Pattern, _PardisoHandle]" = weakref.WeakKeyDictionary()
_handles_lock = threading.Lock()
_tokens = itertools.count(1)


def _diagonally_dominant(pattern: Pattern, values: np.ndarray) -> bool:
    """Whether every row has a positive diagonal at least the sum of its off-diagonal sizes."""
    diag = pattern.indices == pattern.rows
    d = np.bincount(pattern.rows[diag], weights=values[diag], minlength=pattern.n)
    off = np.bincount(pattern.rows[~diag], weights=np.abs(values[~diag]), minlength=pattern.n)
    return bool(np.all(d > 0) and np.all(d >= off * (1 - 1e-12)))


class _Pardiso:
    def __init__(self, pattern: Pattern, values: np.ndarray, symmetric: bool):
        if symmetric:
            with _handles_lock:
                h = _handles.get(pattern)
                if h is None:
                    h = _handles[pattern] = _PardisoHandle(pattern, True)
        else:
            h = _PardisoHandle(pattern, False, pivoting=not _diagonally_dominant(pattern, values))
        self.handle = h
        self.a = np.ascontiguousarray(values if h.take is None else values[h.take])
        self.token = next(_tokens)
        self.slot = [h.factor(self.token, self.a)]
        weakref.finalize(self, h.release, self.token, self.slot)

    def solve(self, b, transpose):
        x, self.slot[0] = self.handle.solve(self.token, self.slot[0], self.a, b, transpose)
        return x


class _Cholespy:
    def __init__(self, pattern: Pattern, values: np.ndarray, symmetric: bool):
        chol = _cholespy()
        # CHOLMOD reads the lower triangle.
        indptr, indices, take = pattern.triangle(upper=False)
        try:
            self.solver = chol.CholeskySolverD(pattern.n, indptr, indices,
                                               np.ascontiguousarray(values[take]), chol.MatrixType.CSR)
        except (ValueError, RuntimeError) as exc:
            raise SolverError(f"sparse: CHOLMOD could not factorize the {pattern.n} x {pattern.n} "
                              f"matrix ({exc}): it is singular or not positive definite.",
                              stage="factorize") from None
        stats["factorizations"] += 1

    def solve(self, b, transpose):
        b = np.array(b, np.float64, order="C", copy=not (b.flags.c_contiguous and b.flags.writeable))
        x = np.empty_like(b)
        self.solver.solve(b, x)
        return x


class _SuperLU:
    def __init__(self, pattern: Pattern, values: np.ndarray, symmetric: bool):
        # A's CSR arrays read as CSC are A^T: SuperLU factorizes A^T and the solves swap "T"/"N".
        At = sp.csc_matrix((values, pattern.indices, pattern.indptr), shape=(pattern.n, pattern.n))
        self.lu = None
        if symmetric:   # no pivoting, A + A^T ordering; plain LU below if a pivot is zero
            try:
                self.lu = spla.splu(At, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                    options={"SymmetricMode": True})
            except RuntimeError:
                pass
        if self.lu is None:
            try:
                self.lu = spla.splu(At, permc_spec="COLAMD")
            except RuntimeError as exc:
                raise SolverError(f"sparse: the {pattern.n} x {pattern.n} matrix is singular and "
                                  f"cannot be factorized (SuperLU: {exc}); check that every unknown "
                                  "is connected to a fixed (boundary) value.", stage="factorize") from None
        stats["factorizations"] += 1

    def solve(self, b, transpose):
        return self.lu.solve(np.asarray(b, np.float64), trans="N" if transpose else "T")


_IMPLS = {"pardiso": _Pardiso, "cholespy": _Cholespy, "scipy": _SuperLU}


# ---------------------------------------------------------------------------------------
# Factorization
# ---------------------------------------------------------------------------------------

class Factorization:
    """A numeric factorization of one matrix; solves ``A x = b`` and ``A^T x = b``.

    Made by :func:`factorize`.  Holds its backend's factor (PARDISO: its own
    numeric factor in the handle of its pattern, freed when this object is
    collected).

    **Fields:** ``n``, ``backend`` (``"pardiso"``, ``"cholespy"`` or
    ``"scipy"``), ``symmetric``, ``pattern``, ``values (nnz,) float64``.
    """

    def __init__(self, pattern: Pattern, values: np.ndarray, symmetric: bool, backend: str):
        self.pattern, self.n, self.symmetric, self.backend = pattern, pattern.n, symmetric, backend
        self.values = np.array(values, np.float64)
        self.values.flags.writeable = False
        self._impl = _IMPLS[backend](pattern, self.values, symmetric) if self.n else None
        self._matrix = None
        self._fallback = None   # a SuperLU factorization, made when this one's residual is too large

    def matrix(self) -> sp.csr_matrix:
        """The factorized matrix, as scipy CSR."""
        if self._matrix is None:
            self._matrix = self.pattern.matrix(self.values)
        return self._matrix

    def solve(self, b, *, residual_tol: float = tol.SOLVE_RESIDUAL) -> np.ndarray:
        """Solve ``A x = b``.

        **Arguments:** ``b: (n,)`` or ``(n, k)``; ``residual_tol`` the largest
        relative residual ``|A x - b| / |b|`` (per column) accepted.
        **Returns:** ``x`` with the shape of ``b``.
        """
        return self._solve(b, False, residual_tol)

    def solve_transpose(self, b, *, residual_tol: float = tol.SOLVE_RESIDUAL) -> np.ndarray:
        """Solve ``A^T x = b``; as :meth:`solve`."""
        return self._solve(b, True, residual_tol)

    def _solve(self, b, transpose: bool, residual_tol: float) -> np.ndarray:
        b = np.asarray(b, np.float64)
        if b.ndim not in (1, 2) or b.shape[0] != self.n:
            raise SolverError(f"sparse: the right-hand side must have shape ({self.n},) or "
                              f"({self.n}, k), got {b.shape}.", stage="solve")
        if not np.all(np.isfinite(b)):
            raise SolverError(f"sparse: the right-hand side has {np.count_nonzero(~np.isfinite(b))} "
                              "non-finite entries.", stage="solve")
        stats["solves"] += 1
        if self.n == 0 or b.size == 0:
            return np.zeros_like(b)
        fac = self._fallback or self
        x = fac._impl.solve(b, transpose).reshape(b.shape)
        res = self._residual(x, b, transpose)
        if not res <= residual_tol and fac.backend != "scipy":
            stats["fallbacks"] += 1
            self._fallback = fac = Factorization(self.pattern, self.values, self.symmetric, "scipy")
            x = fac._impl.solve(b, transpose).reshape(b.shape)
            res = self._residual(x, b, transpose)
        if not res <= residual_tol:
            raise SolverError(f"sparse: the solve of a {self.n} x {self.n} system left a relative "
                              f"residual of {res:.3g} (> {residual_tol:g}); the matrix is "
                              "singular or badly conditioned.", stage="solve")
        return x

    def _residual(self, x, b, transpose: bool) -> float:
        """The largest relative residual ``|A x - b| / |b|`` over the columns (0 for b = 0)."""
        A = self.matrix().T if transpose else self.matrix()
        r = np.linalg.norm((A @ x - b).reshape(self.n, -1), axis=0)
        nb = np.linalg.norm(b.reshape(self.n, -1), axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(nb > 0, r / nb, np.where(r > 0, np.inf, 0.0))
        return float(np.max(rel))

    def __repr__(self) -> str:
        return f"Factorization(n={self.n}, backend={self.backend!r}, symmetric={self.symmetric})"


def factorize(pattern: Pattern, values, *, symmetric: bool = False, backend: str = "auto") -> Factorization:
    """Factorize the matrix with this pattern and these values.

    **Arguments:** ``values: (nnz,) float`` A's entries in pattern order;
    ``symmetric=True`` promises ``A = A^T`` positive definite (Cholesky; all
    entries of both triangles are still given); ``backend``: ``"auto"``,
    ``"pardiso"``, ``"cholespy"`` or ``"scipy"``.

    **Returns:** a :class:`Factorization`.  If the chosen backend fails, the
    matrix goes to SuperLU (``Factorization.backend`` then says ``"scipy"``).
    Raises :class:`SolverError` (``stage="factorize"``) for a singular matrix.

    Example::

        fac = factorize(pattern, values, symmetric=True)
        x = fac.solve(b)
    """
    if not isinstance(pattern, Pattern):
        raise TypeError(f"sparse.factorize: pattern must be a sparse.Pattern, got {type(pattern).__name__}.")
    values = np.asarray(values, np.float64)
    if values.shape != (pattern.nnz,):
        raise SolverError(f"sparse: values must have shape ({pattern.nnz},) to match the pattern, "
                          f"got {values.shape}.", stage="factorize")
    if not np.all(np.isfinite(values)):
        bad = np.flatnonzero(~np.isfinite(values))
        raise SolverError(f"sparse: the matrix has {bad.size} non-finite entries (in rows "
                          f"{first_few(np.unique(pattern.rows[bad]))}); a degenerate triangle or "
                          "weight upstream?", stage="factorize")
    name = _choose_backend(backend, bool(symmetric))
    if pattern.empty_rows.size:
        raise SolverError(f"sparse: the {pattern.n} x {pattern.n} matrix is singular: rows "
                          f"{first_few(pattern.empty_rows)} have no entries; check that every "
                          "unknown is connected to a fixed (boundary) value.", stage="factorize")
    if symmetric and name != "scipy" and not pattern.has_diagonal:
        name = "scipy"   # Cholesky needs the whole diagonal (an SPD matrix has it)
    try:
        return Factorization(pattern, values, bool(symmetric), name)
    except SolverError as first:
        if name == "scipy":
            raise
        stats["fallbacks"] += 1
        try:
            return Factorization(pattern, values, bool(symmetric), "scipy")
        except SolverError as second:
            raise SolverError(f"{second} (Before: {first})", stage="factorize") from None


# ---------------------------------------------------------------------------------------
# Differentiable solve
# ---------------------------------------------------------------------------------------

#: Recent factorizations of :func:`solve`, by (pattern uid, symmetric, backend, values hash).
_cache: "OrderedDict[tuple, Factorization]" = OrderedDict()
_CACHE_SIZE = 4
_cache_lock = threading.Lock()


def _cached_factorization(pattern: Pattern, values: np.ndarray, symmetric: bool, backend: str):
    values = np.ascontiguousarray(values, np.float64)
    key = (pattern.uid, symmetric, backend,
           hashlib.blake2b(values.view(np.uint8), digest_size=16).digest())
    with _cache_lock:
        fac = _cache.get(key)
        if fac is not None:
            _cache.move_to_end(key)
            stats["cache_hits"] += 1
            return fac
    fac = factorize(pattern, values, symmetric=symmetric, backend=backend)
    with _cache_lock:
        _cache[key] = fac
        while len(_cache) > _CACHE_SIZE:
            _cache.popitem(last=False)
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
    _choose_backend(backend, bool(symmetric))
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
    uid = int(uid)
    pattern = _registry.get(uid)
    if pattern is None:   # collected since tracing: rebuild it from the operands, same uid
        pattern = Pattern(np.asarray(indptr), np.asarray(indices), np.asarray(indptr).size - 1, _uid=uid)
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
