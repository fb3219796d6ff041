"""The factorizing backends and the choice among them, and :class:`Factorization`: one
matrix's factor, whose solves check their residual and go to SuperLU when it is too large.

``cholespy`` (CHOLMOD, symmetric positive definite only) and ``scipy`` (SuperLU, always
available) live here; ``pardiso`` in :mod:`jaxparam.sparse.pardiso`.
"""
from __future__ import annotations

import functools
import threading

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .. import tol
from ..errors import SolverError, first_few
from .counters import stats
from .pardiso import Pardiso, mkl
from .pattern import Pattern

#: The backends' names, fastest first (``"auto"`` picks among them: :func:`choose_backend`).
BACKENDS = ("pardiso", "cholespy", "scipy")


@functools.lru_cache(maxsize=1)
def _cholespy():
    try:
        import cholespy

        return cholespy
    except Exception:
        return None


def available_backends() -> list[str]:
    """The backends usable here, fastest first, e.g. ``["pardiso", "cholespy", "scipy"]``."""
    return ((["pardiso"] if mkl() is not None else [])
            + (["cholespy"] if _cholespy() is not None else []) + ["scipy"])


def choose_backend(backend: str, symmetric: bool) -> str:
    """The backend that factorizes: ``backend`` (``"auto"`` or one of :data:`BACKENDS`) checked
    against :func:`available_backends` and ``symmetric``, ``"auto"`` resolved (PARDISO, else
    CHOLMOD for symmetric matrices, else SuperLU).  Raises :class:`SolverError`
    (``stage="factorize"``) for an unknown, unavailable or unsuitable one."""
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


_IMPLS = {"pardiso": Pardiso, "cholespy": _Cholespy, "scipy": _SuperLU}

class Factorization:
    """A numeric factorization of one matrix; solves ``A x = b`` and ``A^T x = b``.

    Made by :func:`factorize`.  Holds its backend's factor (PARDISO: its own
    numeric factor in the handle of its pattern, freed when this object is
    collected).

    **Fields:** ``n``, ``backend`` (``"pardiso"``, ``"cholespy"`` or
    ``"scipy"``), ``symmetric``, ``pattern``, ``values (nnz,) float64``,
    ``verified`` (a solve has passed the residual check).
    """

    def __init__(self, pattern: Pattern, values: np.ndarray, symmetric: bool, backend: str):
        self.pattern, self.n, self.symmetric, self.backend = pattern, pattern.n, symmetric, backend
        self.values = np.array(values, np.float64)
        self.values.flags.writeable = False
        self._impl = _IMPLS[backend](pattern, self.values, symmetric) if self.n else None
        self._matrix = None
        self._fallback = None   # a SuperLU factorization, made when this one's residual is too large
        #: Whether a solve with this factor has passed the residual check (see ``_solve``'s
        #: ``checked_factor``); set by the first solve that passes it.
        self.verified = False

    def matrix(self) -> sp.csr_matrix:
        """The factorized matrix, as scipy CSR."""
        if self._matrix is None:
            self._matrix = self.pattern.matrix(self.values)
        return self._matrix

    def solve(self, b, *, residual_tol: float = tol.SOLVE_RESIDUAL,
              trust_checked: bool = False) -> np.ndarray:
        """Solve ``A x = b``.

        **Arguments:** ``b: (n,)`` or ``(n, k)``; ``residual_tol`` the largest
        relative residual ``|A x - b| / |b|`` (per column) accepted;
        ``trust_checked``: skip the residual check when an earlier solve with this
        factor has passed it (:attr:`verified`; the derivative solves of
        :func:`jaxparam.sparse.solve` do this, see ``_solve``).
        **Returns:** ``x`` with the shape of ``b``.
        """
        return self._solve(b, False, residual_tol, trust_checked)

    def solve_transpose(self, b, *, residual_tol: float = tol.SOLVE_RESIDUAL,
                        trust_checked: bool = False) -> np.ndarray:
        """Solve ``A^T x = b``; as :meth:`solve`."""
        return self._solve(b, True, residual_tol, trust_checked)

    def _solve(self, b, transpose: bool, residual_tol: float, trust_checked: bool = False) -> np.ndarray:
        """The solve, its residual check and the SuperLU fallback.

        The check (``|A x - b| / |b| <= residual_tol``, 0.6-1 ms per 2-column solve at 11k
        unknowns) guards against a bad factor: a nearly singular matrix, perturbed pivots, a
        backend failing silently.  With ``trust_checked`` it is skipped once this factor (or
        the SuperLU factor that replaced it) has passed it on an earlier solve, and the
        solution is only checked to be finite (a non-finite one gets the full check, and the
        fallback).  Why that is sound: a direct solve's backward error, in either direction,
        is bounded by the one factor (``|E| <= c u |L||U|`` for ``(A + E) x = b`` and for
        ``(A + E)^T y = c`` alike; for Cholesky ``A^T = A`` and it is the same solve), so
        what can make a solve wrong is the factor, which the passed check has vetted; a
        right-hand side cannot.  What it does not re-vet: a relative residual also grows
        with ``|A| |x| / |b|``, up to ``u cond(A)``, and an adjoint right-hand side that
        excites ``A``'s smallest singular vector more than the forward's did could exceed
        the tolerance where the forward's did not.  That is an ill-conditioned matrix,
        whose gradient would then be as inaccurate as ``cond(A)`` says; the forward check
        still refuses the matrix once ``u cond(A)`` exceeds it for the forward's data.
        :func:`jaxparam.sparse.solve` passes it for the derivative solves (reverse and
        forward mode), which always come after the forward solve of the same values
        (issue 12: the check was 20-30 % of the adjoint's host time).
        """
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
        if trust_checked and fac.verified and np.all(np.isfinite(x)):
            stats["checks_skipped"] += 1
            return x
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
        fac.verified = True
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
    name = choose_backend(backend, bool(symmetric))
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


def warm_up() -> threading.Thread:
    """Start the fastest backend's runtime in a background thread and return the thread.

    PARDISO's first call in a process initializes MKL (0.1-0.4 s, in C with the GIL released),
    so a one-off command (``jaxparam flatten``) runs it while it reads and checks its input;
    join the thread before the first :func:`factorize` (its two 2x2 factorizations are taken
    back out of :data:`stats`, which assumes nothing else factorizes meanwhile).  Does nothing
    when PARDISO is not available.
    """
    def run():
        before = dict(stats)
        try:
            if mkl() is not None:
                P = Pattern(np.array([0, 1, 2]), np.array([0, 1]), 2)
                Factorization(P, np.array([2.0, 1.0]), True, "pardiso").solve(np.ones(2))
                Factorization(P, np.array([2.0, 1.0]), False, "pardiso").solve(np.ones(2))
        except Exception:       # a failing backend shows itself, with its message, when used
            pass
        for key in stats:
            stats[key] = before.get(key, 0)

    thread = threading.Thread(target=run, name="jaxparam-sparse-warm-up", daemon=True)
    thread.start()
    return thread
