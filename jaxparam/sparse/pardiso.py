"""Intel MKL PARDISO through ctypes: the runtime that ``pypardiso`` loads, called directly so
that factorizations are kept and reused.

Cholesky (``mtype 2``): one shared handle per pattern (:data:`handles`), one symbolic
analysis for it, and up to ``_PARDISO_SLOTS`` numeric factors in its slots (PARDISO's
``maxfct``/``mnum``).  LU (``mtype 11``): the analysis depends on the values (matching), so
each factorization has a handle of its own.  :class:`Pardiso` is one factorization.
"""
from __future__ import annotations

import ctypes
import functools
import itertools
import threading
import weakref

import numpy as np

from ..errors import SolverError
from .counters import stats
from .pattern import Pattern


@functools.lru_cache(maxsize=1)
def mkl():
    """The MKL ``pardiso`` entry point and the C type of its handle, or None.

    **Returns:** ``(fn, (ctypes integer type, numpy dtype))`` of the handle's 64 entries
    (int64 on 64-bit platforms), or None where MKL does not load.  Loaded once per process.
    """
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
        self.fn, (_, pt_dtype) = mkl()
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
            if b.ndim == 2 and 1 < b.shape[1] <= 8 and (self.symmetric or not transpose):
                # PARDISO's blocked multi-RHS solve costs 3-6x one column for k <= 8 (705k grid:
                # 0.08 s for one column, 0.5-0.6 s for two): solve the columns one by one.
                # Not the transposed LU solve (the adjoint of reverse mode): blocked, its 2 columns
                # take 0.85x the time of one by one at 11k unknowns (camelhead), 0.95x at 89k
                # (a 300 x 300 grid); pinned CPU time (issue 12).  Reproducible run to run.
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


#: The shared Cholesky handle of each pattern, kept while the pattern lives (weak keys: a
#: handle is dropped, and its memory freed by PARDISO's phase -1, once its pattern is
#: collected and no factorization holds the handle).
handles: "weakref.WeakKeyDictionary[Pattern, _PardisoHandle]" = weakref.WeakKeyDictionary()
_handles_lock = threading.Lock()
_tokens = itertools.count(1)


def _diagonally_dominant(pattern: Pattern, values: np.ndarray) -> bool:
    """Whether every row has a positive diagonal at least the sum of its off-diagonal sizes."""
    diag = pattern.indices == pattern.rows
    d = np.bincount(pattern.rows[diag], weights=values[diag], minlength=pattern.n)
    off = np.bincount(pattern.rows[~diag], weights=np.abs(values[~diag]), minlength=pattern.n)
    return bool(np.all(d > 0) and np.all(d >= off * (1 - 1e-12)))


class Pardiso:
    """One numeric factorization by PARDISO (a backend of :class:`Factorization`).

    **Arguments:** ``pattern``; ``values: (nnz,) float64`` the matrix's entries in pattern
    order; ``symmetric``: Cholesky in a slot of the pattern's shared handle, else LU in a
    handle of its own.  Its factor is freed (phase 0) when this object is collected.
    ``solve(b, transpose)`` takes ``b: (n,)`` or ``(n, k)`` and returns ``x`` (shape of ``b``)
    with ``A x = b``, or ``A^T x = b`` if ``transpose``.
    """

    def __init__(self, pattern: Pattern, values: np.ndarray, symmetric: bool):
        if symmetric:
            with _handles_lock:
                h = handles.get(pattern)
                if h is None:
                    h = handles[pattern] = _PardisoHandle(pattern, True)
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