"""Sparse direct solves: the only package of jaxparam that factorizes a matrix.

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
:data:`jaxparam.tol.SOLVE_RESIDUAL` and is redone once with SuperLU above it (the adjoint
solves of reverse mode only until the factor has passed that check once).

:func:`solve` is differentiable in JAX, in both modes from one definition (a
``jax.lax.custom_linear_solve``): forward ``A x = b`` with a cached factorization;
forward mode ``dx = A^{-1} (db - dA x)``; reverse mode one solve with ``A^T`` (the same
factorization) for the adjoint ``lam``, then ``d b = lam`` and ``d A_ij = -lam_i . x_j``
on A's pattern; higher orders alike; ``jax.vmap`` batches its host callback.

Modules, one job each: :mod:`~jaxparam.sparse.counters` (:data:`stats`),
:mod:`~jaxparam.sparse.pattern` (:class:`Pattern` and its uid registry),
:mod:`~jaxparam.sparse.pardiso` (the MKL binding, its handles and slots),
:mod:`~jaxparam.sparse.backends` (CHOLMOD, SuperLU, the backend choice,
:class:`Factorization`, :func:`factorize`), :mod:`~jaxparam.sparse.differentiable`
(the factorization cache and :func:`solve`).
"""
from __future__ import annotations

from .backends import BACKENDS, Factorization, available_backends, factorize, warm_up
from .counters import stats
from .differentiable import cached_factorization, solve
from .pattern import Pattern

__all__ = ["Pattern", "Factorization", "factorize", "cached_factorization", "solve",
           "available_backends", "stats", "warm_up"]
