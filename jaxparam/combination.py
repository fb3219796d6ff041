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
UVs; :func:`solve` goes through :mod:`jaxparam.sparse`.  :func:`solve_weights` is assemble +
solve under one hand-written derivative (the maps' reverse pass, issue 12).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .lazy_jax import jax, jnp  # JAX loads on first use (issue 17)
from . import sparse

__all__ = ["CombinationSystem", "combination_system", "assemble", "solve", "solve_weights",
           "scatter", "normalizes", "UNNORMALIZED_KINDS"]

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
    - ``n_free``;
    - ``nbr (k,)``: each entry's neighbour in the stacked ``[x; uv_fixed]`` order (its free
      slot, or ``n_free`` + its row in ``uv_fixed``), for :func:`solve_weights`'s derivative.
    """

    pattern: sparse.Pattern
    entry_row: np.ndarray
    diag_pos: np.ndarray
    off_pos: np.ndarray
    free_entries: np.ndarray
    fixed_entries: np.ndarray
    fixed_slot: np.ndarray
    n_free: int
    nbr: np.ndarray


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
                             fixed_slot=nbr_fixed[fx], n_free=n,
                             nbr=np.where(nbr_free >= 0, nbr_free, n + nbr_fixed))


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
    # From the differentiable solve's cache: under an eager jax.grad the custom_jvp's forward
    # solve comes here with concrete values and its adjoint solve goes through the cache, which
    # then holds this factor, checked (it used to factorize again and check the adjoint's
    # residual, which an ill-conditioned matrix could fail after a forward that passed).
    fac = sparse.cached_factorization(system.pattern, np.asarray(vals, np.float64), bool(symmetric),
                                      backend)
    return fac.solve(np.asarray(rhs, np.float64))


def solve_weights(system: CombinationSystem, w, uv_fixed, *, normalize: bool, symmetric: bool,
                  backend: str = "auto"):
    """``x (n_free, 2)``: eq. (4) assembled from the weights and solved, with a hand-written
    derivative.

    **Arguments:** as :func:`assemble` (``w (k,)``, ``uv_fixed (n_fixed, 2)``, ``normalize``)
    and :func:`solve` (``symmetric``, ``backend``).  The values are those of
    ``solve(system, *assemble(system, w, uv_fixed, normalize=normalize), ...)``, bitwise: it
    is that computation.

    **Derivative** (a ``jax.custom_jvp``: forward and reverse mode, ``vmap``, higher orders).
    With ``c`` the weights after normalization and ``y = [x; uv_fixed]``, row ``i`` of eq. (4)
    reads ``sum_e c_e (x_i - y_nbr(e)) = 0`` over its entries ``e``; so
    ``A dx = -sum_e dc_e (x_i - y_nbr(e)) + sum_{e fixed} c_e du_slot(e)``: one more solve with
    ``A`` (in reverse mode, the adjoint ``A^T lam = g``; then ``dc_e = -lam_i . (x_i - y_nbr(e))``
    and ``du_slot(e) += c_e lam_i``).  The values' cotangent on ``A``'s pattern
    (``-lam_i x_j``) and the transpose of the assembly that JAX would take otherwise are not
    formed: the reverse pass reads 3 gathers per entry instead of 7 (issue 12), and
    ``x_i - y_nbr(e)`` is formed before the product, so the large, nearly equal terms
    ``lam_i . x_i`` and ``lam_i . x_j`` no longer cancel.
    """
    return _solve_weights()(system, bool(normalize), bool(symmetric), backend, w, uv_fixed)


@functools.lru_cache(maxsize=1)
def _solve_weights():
    """The ``custom_jvp`` function, made on first use (importing this module loads no JAX)."""
    f = jax.custom_jvp(_solve_weights_primal, nondiff_argnums=(0, 1, 2, 3))
    f.defjvp(_solve_weights_jvp, symbolic_zeros=True)
    return f


def _solve_weights_primal(S, normalize, symmetric, backend, w, uv_fixed):
    vals, rhs = assemble(S, w, uv_fixed, normalize=normalize)
    return solve(S, vals, rhs, symmetric=symmetric, backend=backend)


def _solve_weights_jvp(S, normalize, symmetric, backend, primals, tangents):
    from jax.custom_derivatives import SymbolicZero

    w, uv_fixed = primals
    dw, du = tangents
    vals, rhs = assemble(S, w, uv_fixed, normalize=normalize)
    x = solve(S, vals, rhs, symmetric=symmetric, backend=backend)
    zw, zu = isinstance(dw, SymbolicZero), isinstance(du, SymbolicZero)
    if zw and zu:
        return x, jnp.zeros_like(x)
    t = _tangent_rhs(w, None if zw else dw, uv_fixed, None if zu else du, x, S.entry_row, S.nbr,
                     S.fixed_entries, S.fixed_slot, normalize=normalize, n_free=S.n_free)
    return x, sparse.solve(S.pattern, vals, t, symmetric=symmetric, backend=backend)


@functools.partial(jax.jit, static_argnames=("normalize", "n_free"))
def _tangent_rhs(w, dw, uv_fixed, du, x, row, nbr, fx, fixed_slot, *, normalize, n_free):
    """``-sum_e dc_e (x_i - y_nbr(e)) + sum_{e fixed} c_e du_slot(e)`` per free row ``i``,
    ``(n_free, k)``; ``dw`` or ``du`` None for a zero tangent.  Column by column: XLA on the
    CPU reduces a size-2 axis slowly (see ``sparse.differentiable``)."""
    def normalized(w):
        return w / jax.ops.segment_sum(w, row, num_segments=n_free)[row] if normalize else w

    c = normalized(w)
    cols = []
    y = jnp.concatenate([x, uv_fixed]) if dw is not None else None
    dc = jax.jvp(normalized, (w,), (dw,))[1] if dw is not None else None
    for j in range(x.shape[1]):
        t = jnp.zeros(n_free, x.dtype)
        if dw is not None:
            t = t - jax.ops.segment_sum(dc * (x[:, j][row] - y[:, j][nbr]), row, num_segments=n_free)
        if du is not None:
            t = t + jax.ops.segment_sum(c[fx] * du[:, j][fixed_slot], row[fx], num_segments=n_free)
        cols.append(t)
    return jnp.stack(cols, axis=1)


@functools.partial(jax.jit, static_argnames=("n",))
def scatter(x, uv_fixed, free, fixed, *, n: int):
    """``(n, 2)`` UVs: ``x`` at the ``free`` vertices, ``uv_fixed`` at the ``fixed`` ones, nan elsewhere."""
    uv = jnp.full((n, 2), jnp.nan, x.dtype)
    # Disjoint, duplicate-free index sets: unique_indices spares the JVP of .set its scatter of
    # update ids (which decides between colliding writes), in every map's gradient (issue 12).
    return uv.at[free].set(x, unique_indices=True).at[fixed].set(uv_fixed, unique_indices=True)
