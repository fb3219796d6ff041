"""Equation (4), assembled once: the free vertices as convex combinations of their neighbours.

For free vertices ``v`` (interior vertices, interior points, or a chart's free vertices) with
neighbours ``w`` and weights ``w_vw``, eq. (4) reads::

    sum_w w_vw u_v - sum_{w free} w_vw u_w = sum_{w fixed} w_vw u_w

i.e. ``A x = rhs`` with ``A = diag(rowsum w) - W_free`` on a fixed CSR pattern and
``rhs = W_fixed u_fixed``.  With ``normalize=True`` the weights are first divided by their row
sums (eq. (3)'s ``lambda_vw``), which keeps the system well scaled when one weight is huge (a
nearly flat angle makes mean-value weights grow like ``1 / angle``); spring weights stay
unnormalized and symmetric, so a Cholesky factorization serves.  :func:`normalizes` is the one
rule that decides it for every caller: :func:`jaxparam.convex_map`,
:func:`jaxparam.meshless_map` and the charts of :func:`jaxparam.manifold_map`.

The combinatorics (:func:`combination_system`) are numpy, built once per connectivity; the
values (:func:`assemble`) are JAX, so the map is differentiable in the weights and in the fixed
UVs; :func:`solve` goes through :mod:`jaxparam.sparse`.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .lazy_jax import jax, jnp  # JAX loads on first use (issue 17)
from . import sparse

__all__ = ["CombinationSystem", "combination_system", "assemble", "solve", "scatter",
           "normalizes", "UNNORMALIZED_KINDS"]

#: Weight kinds whose weights are symmetric (spring weights): solved unnormalized (Cholesky).
UNNORMALIZED_KINDS = ("uniform", "inverse_distance", "harmonic")


def normalizes(kind: str) -> bool:
    """Whether weights of this kind are divided by their row sums before the solve."""
    return kind not in UNNORMALIZED_KINDS


@dataclass(frozen=True, eq=False)
class CombinationSystem:
    """The pattern of eq. (4) and the index maps from weight entries to its values (numpy).

    **Fields** (``k`` weight entries, ``n_free`` free vertices):

    - ``pattern``: ``A``'s CSR pattern over the free vertices, the diagonal included;
    - ``entry_row (k,)``: the free slot of each entry's centre vertex;
    - ``diag_pos (n_free,)``, ``off_pos (k_ff,)``: where the diagonal and the free-free entries
      sit in ``A``'s value array;
    - ``free_entries (k_ff,)``, ``fixed_entries (k_fx,)``: the entries whose neighbour is free /
      fixed;
    - ``fixed_slot (k_fx,)``: the neighbour's row in ``uv_fixed`` for each fixed entry;
    - ``n_free``.
    """

    pattern: sparse.Pattern
    entry_row: np.ndarray
    diag_pos: np.ndarray
    off_pos: np.ndarray
    free_entries: np.ndarray
    fixed_entries: np.ndarray
    fixed_slot: np.ndarray
    n_free: int


def combination_system(entry_row, nbr_free, nbr_fixed, n_free: int) -> CombinationSystem:
    """The pattern and index maps of eq. (4) for weight entries ``(centre, neighbour)``.

    **Arguments:** ``entry_row (k,) int``: the free slot (``0 .. n_free-1``) of each entry's
    centre; ``nbr_free (k,) int``: the neighbour's free slot, ``-1`` where it is fixed;
    ``nbr_fixed (k,) int``: where the neighbour is fixed, its row in the ``uv_fixed`` array
    that :func:`assemble` takes (any value elsewhere).  No (centre, neighbour) pair may repeat.
    """
    entry_row = np.asarray(entry_row, np.int64)
    nbr_free = np.asarray(nbr_free, np.int64)
    nbr_fixed = np.asarray(nbr_fixed, np.int64)
    ff = np.flatnonzero(nbr_free >= 0)
    fx = np.flatnonzero(nbr_free < 0)
    n = int(n_free)
    r = np.concatenate([np.arange(n), entry_row[ff]])
    c = np.concatenate([np.arange(n), nbr_free[ff]])
    # CSR order by one stable sort of (row, column) keys (6x faster than a COO build plus
    # per-row column sorts on 12M entries).
    order = np.argsort(r * np.int64(max(n, 1)) + c, kind="stable")
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(r, minlength=n), out=indptr[1:])
    pos = np.empty(r.size, np.int64)
    pos[order] = np.arange(r.size)
    return CombinationSystem(pattern=sparse.Pattern(indptr, c[order], n), entry_row=entry_row,
                             diag_pos=pos[:n], off_pos=pos[n:], free_entries=ff, fixed_entries=fx,
                             fixed_slot=nbr_fixed[fx], n_free=n)


def assemble(system: CombinationSystem, w, uv_fixed, *, normalize: bool, host: bool = False):
    """Values of ``A`` on ``system.pattern`` and the right-hand side of eq. (4).

    **Arguments:** ``w (k,)`` weights on the entries; ``uv_fixed (n_fixed, 2)`` the fixed
    UVs, indexed by ``system.fixed_slot``; ``normalize``: divide ``w`` by its row sums first
    (see :func:`normalizes`).  **Returns:** ``(vals (nnz,), rhs (n_free, 2))``.

    ``host=True`` with concrete ``w`` and ``uv_fixed`` computes in NumPy and returns NumPy
    arrays, with no compilation (the cheap path of one-off calls; equal to the JAX kernel to
    rounding, about 1e-16 relative, not bitwise); otherwise, and always for tracers, the
    jitted kernel.
    """
    S = system
    if host and not any(isinstance(x, jax.core.Tracer) for x in (w, uv_fixed)):
        return _assemble_host(S, w, uv_fixed, normalize=bool(normalize))
    return _assemble(w, uv_fixed, S.entry_row, S.free_entries, S.fixed_entries, S.fixed_slot,
                     S.diag_pos, S.off_pos, normalize=bool(normalize), n_free=S.n_free,
                     nnz=S.pattern.nnz)


@functools.partial(jax.jit, static_argnames=("normalize", "n_free", "nnz"))
def _assemble(w, uv_fixed, row, ff, fx, fixed_slot, diag_pos, off_pos, *, normalize, n_free, nnz):
    if normalize:
        w = w / jax.ops.segment_sum(w, row, num_segments=n_free)[row]
    rowsum = jax.ops.segment_sum(w, row, num_segments=n_free)
    vals = jnp.zeros(nnz, w.dtype).at[diag_pos].set(rowsum).at[off_pos].add(-w[ff])
    rhs = jax.ops.segment_sum(w[fx][:, None] * uv_fixed[fixed_slot], row[fx], num_segments=n_free)
    return vals, rhs


def _assemble_host(S: CombinationSystem, w, uv_fixed, *, normalize: bool):
    """The NumPy twin of ``_assemble`` (same formulas, sums by ``np.bincount``)."""
    w = np.asarray(w, np.float64)
    if normalize:
        w = w / np.bincount(S.entry_row, w, minlength=S.n_free)[S.entry_row]
    vals = np.zeros(S.pattern.nnz, np.float64)
    vals[S.diag_pos] = np.bincount(S.entry_row, w, minlength=S.n_free)
    vals[S.off_pos] -= w[S.free_entries]
    wf = w[S.fixed_entries][:, None] * np.asarray(uv_fixed, np.float64)[S.fixed_slot]
    rows = S.entry_row[S.fixed_entries]
    rhs = np.stack([np.bincount(rows, wf[:, 0], minlength=S.n_free),
                    np.bincount(rows, wf[:, 1], minlength=S.n_free)], 1)
    return vals, rhs


def solve(system: CombinationSystem, vals, rhs, *, symmetric: bool, backend: str = "auto"):
    """``x (n_free, 2)`` solving ``A x = rhs``.

    Called with concrete values it factorizes on the host directly, so a
    :class:`~jaxparam.SolverError` reaches the caller as itself (the CLI exits with 4 and the
    stage); under ``jit``/``grad`` it takes the differentiable route,
    :func:`jaxparam.sparse.solve` (inside its callback an error arrives wrapped in JAX's
    runtime error).
    """
    if isinstance(vals, jax.core.Tracer) or isinstance(rhs, jax.core.Tracer):
        return sparse.solve(system.pattern, vals, rhs, symmetric=symmetric, backend=backend)
    fac = sparse.factorize(system.pattern, np.asarray(vals), symmetric=symmetric, backend=backend)
    return fac.solve(np.asarray(rhs, np.float64))


@functools.partial(jax.jit, static_argnames=("n",))
def scatter(x, uv_fixed, free, fixed, *, n: int):
    """``(n, 2)`` UVs: ``x`` at the ``free`` vertices, ``uv_fixed`` at the ``fixed`` ones, nan elsewhere."""
    uv = jnp.full((n, 2), jnp.nan, x.dtype)
    return uv.at[free].set(x).at[fixed].set(uv_fixed)
