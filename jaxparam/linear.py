"""Convex-combination and least-squares maps of disk meshes (survey §3–5).

The interior UVs solve eq. (4): ``u_v - sum_w lambda_vw u_w = sum_{w in V_B}
lambda_vw u_w``.  Written with unnormalized weights ``w`` the system is
``(diag(sum_w w_vw) - W_II) x = W_IB u_B``, which is symmetric for spring
weights (so a Cholesky factorization serves) and the same solution.  Both
coordinates come from one factorization, through :func:`jaxparam.sparse.solve`,
which makes the map differentiable in the vertex positions, the weights and
the boundary UVs.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from . import boundary as bmap
from . import sparse
from . import topology as topo
from . import weights as wts
from .errors import MeshError, TopologyError, first_few
from .mesh import TriMesh

__all__ = ["InteriorSystem", "interior_system", "solve_interior", "convex_map",
           "least_squares_map", "fill_holes", "disk_check"]


@dataclass(frozen=True, eq=False)
class InteriorSystem:
    """Index maps from ring entries to the interior matrix ``A`` and right-hand side (numpy).

    ``pattern`` is ``A``'s CSR pattern (interior slots, with the diagonal);
    ``diag_pos (ni,)`` and ``off_pos (k_II,)`` place the diagonal and the
    interior-interior entries in ``A``'s value array; ``is_ii (k,)`` marks
    those entries among the ring entries; ``bd_slot (k_IB,)`` is the boundary
    slot of each interior-boundary entry's neighbour.
    """

    pattern: sparse.Pattern
    diag_pos: np.ndarray
    off_pos: np.ndarray
    is_ii: np.ndarray
    ii_entries: np.ndarray
    ib_entries: np.ndarray
    bd_slot: np.ndarray
    ib_row: np.ndarray


@functools.lru_cache(maxsize=16)
def interior_system(topology) -> InteriorSystem:
    """Build (once per topology) the sparsity pattern of eq. (4) and its index maps."""
    R = wts.ring_entries(topology)
    ni = R.n_rows
    nbr_interior = ~topology.is_boundary[R.nbr]
    ii = np.flatnonzero(nbr_interior)
    ib = np.flatnonzero(~nbr_interior)
    rows = np.concatenate([np.arange(ni), R.row[ii]])
    cols = np.concatenate([np.arange(ni), topology.slot[R.nbr[ii]]])
    # Let scipy's compiled CSR conversion sort the columns; the data carry each entry's id.
    ids = np.arange(1, rows.size + 1, dtype=np.float64)
    M = sp.csr_matrix((ids, (rows, cols)), shape=(ni, ni))
    M.sort_indices()
    pos = np.empty(rows.size, np.int64)
    pos[M.data.astype(np.int64) - 1] = np.arange(rows.size)
    pattern = sparse.Pattern(M.indptr, M.indices, ni)
    return InteriorSystem(pattern=pattern, diag_pos=pos[:ni], off_pos=pos[ni:], is_ii=nbr_interior,
                          ii_entries=ii, ib_entries=ib, bd_slot=topology.slot[R.nbr[ib]],
                          ib_row=R.row[ib])


def _assemble(w, uv_b, row, ii, ib, bd_slot, ib_row, diag_pos, off_pos, ni, nnz):
    """Values of ``A = diag(rowsum w) - W_II`` on the pattern and ``rhs = W_IB u_B``."""
    rowsum = jax.ops.segment_sum(w, row, num_segments=ni)
    vals = jnp.zeros(nnz, w.dtype).at[diag_pos].set(rowsum).at[off_pos].add(-w[ii])
    rhs = jax.ops.segment_sum(w[ib][:, None] * uv_b[bd_slot], ib_row, num_segments=ni)
    return vals, rhs


@functools.partial(jax.jit, static_argnames=("ni", "nnz"))
def _assemble_jit(w, uv_b, row, ii, ib, bd_slot, ib_row, diag_pos, off_pos, *, ni, nnz):
    return _assemble(w, uv_b, row, ii, ib, bd_slot, ib_row, diag_pos, off_pos, ni, nnz)


@functools.partial(jax.jit, static_argnames=("shape", "spacing", "corners", "ni", "nnz", "nb"))
def _boundary_and_assemble(w, V, loop, loop_slot, user_uv, row, ii, ib, bd_slot, ib_row, diag_pos,
                           off_pos, *, shape, spacing, corners, ni, nnz, nb):
    """Boundary map of the loop and the interior system, in one compiled function."""
    if shape == "user":
        uv_loop = user_uv
    elif isinstance(shape, tuple):
        uv_loop = bmap.polygon(V[loop], np.asarray(shape), spacing=spacing, corner_positions=corners)
    else:
        uv_loop = bmap.boundary_uv(V[loop], shape, spacing=spacing, corners=corners)
    uv_b = jnp.zeros((nb, 2), V.dtype).at[loop_slot].set(uv_loop)
    vals, rhs = _assemble(w, uv_b, row, ii, ib, bd_slot, ib_row, diag_pos, off_pos, ni, nnz)
    return vals, rhs, uv_b


@functools.partial(jax.jit, static_argnames=("n",))
def _scatter(x, uv_b, interior, boundary, *, n):
    uv = jnp.full((n, 2), jnp.nan, x.dtype)
    return uv.at[interior].set(x).at[boundary].set(uv_b)


def solve_interior(topology, w, boundary_uv, *, symmetric: bool = False, backend: str = "auto"):
    """Solve eq. (4) for the interior UVs.

    **Arguments:** ``w: (k,)`` unnormalized weights on the ring entries of
    :func:`jaxparam.weights.ring_entries` (row sums need not be 1);
    ``boundary_uv: (nb, 2)`` UVs of ``topology.boundary`` in slot order.
    **Returns:** ``(ni, 2)`` UVs of ``topology.interior``.
    """
    S = interior_system(topology)
    R = wts.ring_entries(topology)
    vals, rhs = _assemble_jit(w, boundary_uv, R.row, S.ii_entries, S.ib_entries, S.bd_slot, S.ib_row,
                              S.diag_pos, S.off_pos, ni=R.n_rows, nnz=S.pattern.nnz)
    return sparse.solve(S.pattern, vals, rhs, symmetric=symmetric, backend=backend)


def _solve(pattern, vals, rhs, symmetric: bool, backend: str):
    """:func:`jaxparam.sparse.solve`, run straight on the host when nothing is traced.

    Inside ``jax.pure_callback`` a :class:`SolverError` reaches the caller wrapped in
    JAX's runtime error; called directly it stays itself (so the CLI exits with 4 and
    the stage).  Under ``jit``/``grad`` the differentiable route is taken.
    """
    if isinstance(vals, jax.core.Tracer) or isinstance(rhs, jax.core.Tracer):
        return sparse.solve(pattern, vals, rhs, symmetric=symmetric, backend=backend)
    fac = sparse.factorize(pattern, np.asarray(vals), symmetric=symmetric, backend=backend)
    return fac.solve(np.asarray(rhs, np.float64))


def disk_check(mesh: TriMesh, where: str) -> None:
    """Raise :class:`TopologyError` unless the mesh is one connected surface with a boundary."""
    t = mesh.topology
    if t.n_components > 1:
        sizes = np.bincount(t.components[t.components >= 0])
        raise TopologyError(
            f"{where}: the mesh has {t.n_components} connected components (vertex counts "
            f"{first_few(sizes.tolist())}); parameterize each on its own "
            "(e.g. trimesh's split) or keep the largest.")
    if t.is_closed:
        raise TopologyError(
            f"{where}: the mesh is closed (no boundary, genus {t.genus}); a disk method needs a "
            "boundary: cut the mesh open along a path, or parameterize it over a base domain with "
            "jp.manifold_map (closed meshes of any genus).")
    if t.genus != 0:
        raise TopologyError(
            f"{where}: the mesh has genus {t.genus} with {len(t.boundary_loops)} boundary loops; a "
            "disk method needs genus 0: cut the handles open first.")


def fill_holes(mesh: TriMesh) -> tuple[TriMesh, int]:
    """Close every boundary loop but the longest with a fan around a new centre vertex.

    **Returns:** ``(filled, n_added)``: the new mesh (its first ``n`` vertices
    are the original ones, in order; the centres, at the loops' centroids, follow).
    """
    t = mesh.topology
    holes = t.boundary_loops[1:]
    if not holes:
        return mesh, 0
    n = t.n_vertices
    centres = []
    faces = [t.faces]
    for h, loop in enumerate(holes):
        c = n + h
        # The hole's boundary edges run a -> b with the surface on their left: the fan uses b -> a.
        faces.append(np.stack([np.roll(loop, -1), loop, np.full(loop.size, c)], axis=1))
        centres.append(loop)
    if isinstance(mesh.vertices, jax.core.Tracer):
        C = jnp.stack([jnp.mean(mesh.vertices[l], axis=0) for l in centres])
        V = jnp.concatenate([mesh.vertices, C], axis=0)
    else:
        V0 = np.asarray(mesh.vertices)
        V = np.concatenate([V0, np.stack([V0[l].mean(0) for l in centres])])
    F = np.concatenate(faces)
    filled = TriMesh(V, F, topo.build(F, n + len(holes), where="fill_holes"), validate=False)
    return filled, len(holes)


def _boundary_key(boundary, k: int):
    """Split a boundary argument into a static key and an optional array of user UVs."""
    if isinstance(boundary, str):
        if boundary not in bmap.SHAPES:
            raise MeshError(f"boundary: unknown boundary {boundary!r}; use one of {bmap.SHAPES}, a "
                            "(k, 2) array of boundary UVs, or {'polygon': corners}.")
        return boundary, jnp.zeros((k, 2))
    if isinstance(boundary, dict) and "polygon" in boundary:
        C = np.asarray(boundary["polygon"], np.float64)
        bmap.polygon(np.zeros((3, 3)), C)       # validates shape and convexity up front
        return tuple(map(tuple, C.tolist())), jnp.zeros((k, 2))
    uv = jnp.asarray(boundary, dtype=jnp.float64)
    if uv.shape != (k, 2):
        raise MeshError(f"boundary: the user boundary UVs must have shape ({k}, 2), one row per "
                        f"vertex of the longest boundary loop in loop order, got {tuple(uv.shape)}.")
    return "user", uv


def _boundary_only(V, loop, user_uv, shape, spacing, corners):
    if shape == "user":
        return user_uv
    if isinstance(shape, tuple):
        return bmap.polygon(V[loop], np.asarray(shape), spacing=spacing, corner_positions=corners)
    return bmap.boundary_uv(V[loop], shape, spacing=spacing, corners=corners)


def _map_with(mesh: TriMesh, w_of, symmetric: bool, boundary, spacing, corners, backend, where):
    disk_check(mesh, where)
    if spacing not in bmap.SPACINGS:
        raise MeshError(f"{where}: unknown spacing {spacing!r}; use one of {bmap.SPACINGS}.")
    work, added = fill_holes(mesh)
    t = work.topology
    V = jnp.asarray(work.vertices, dtype=jnp.float64)
    loop = t.boundary_loops[0]
    shape, user_uv = _boundary_key(boundary, loop.size)
    corners = None if corners is None else tuple(int(c) for c in corners)
    if t.interior.size == 0:
        # No interior vertex: the map is the boundary map itself.
        uv_b = _boundary_only(V, loop, user_uv, shape, spacing, corners)
        uv = jnp.full((t.n_vertices, 2), jnp.nan).at[loop].set(uv_b)
        return uv[: mesh.n_vertices]
    w = w_of(work)
    S = interior_system(t)
    R = wts.ring_entries(t)
    vals, rhs, uv_b = _boundary_and_assemble(
        w, V, loop, t.slot[loop], user_uv, R.row, S.ii_entries, S.ib_entries, S.bd_slot, S.ib_row,
        S.diag_pos, S.off_pos, shape=shape, spacing=spacing, corners=corners, ni=R.n_rows,
        nnz=S.pattern.nnz, nb=t.boundary.size)
    x = _solve(S.pattern, vals, rhs, symmetric, backend)
    uv = _scatter(x, uv_b, t.interior, t.boundary, n=t.n_vertices)
    return uv[: mesh.n_vertices] if added else uv


def convex_map(mesh: TriMesh, *, weights: str = "shape_preserving", boundary="circle",
               spacing: str = "chord", corners=None, backend: str = "auto"):
    """A convex-combination parameterization (survey §3–4, eq. (3)).

    **Arguments:**

    - ``mesh``: a :class:`TriMesh` of disk topology; further boundary loops
      (holes) are filled virtually with a temporary centre vertex each and the
      longest loop goes to the boundary.
    - ``weights``: ``"uniform"``, ``"inverse_distance"``, ``"shape_preserving"``,
      ``"mean_value"`` or ``"harmonic"``.
    - ``boundary``: ``"circle"``, ``"square"``, ``"plane"``, a ``(k, 2)`` array of
      UVs for the longest boundary loop, or ``{"polygon": corners}``.
    - ``spacing``: ``"chord"`` or ``"uniform"``; ``corners``: loop positions of
      the square's (or polygon's) corners.

    **Returns:** ``uv: (n, 2)`` in the mesh's vertex order (``nan`` for
    unreferenced vertices).  One-to-one when the weights are positive and the
    boundary convex (Theorem 1; see :func:`jaxparam.metrics.theorem1`).

    Differentiable: ``jax.grad`` flows to ``mesh.vertices`` through the
    weights, the boundary map and the sparse solve.

    Example::

        uv = jp.convex_map(mesh, weights="mean_value", boundary="square")
    """
    if weights not in wts.KINDS:
        raise MeshError(f"convex_map: unknown weights {weights!r}; use one of {wts.KINDS}.")
    symmetric = weights in wts.SYMMETRIC_KINDS

    def w_of(work):
        w = wts.entry_weights(work.vertices, work.topology, weights)[0]
        # Unit row sums (eq. (3)'s lambdas) keep the system well scaled when one weight is huge
        # (a nearly flat angle makes mean-value weights ~1/angle); spring weights stay as they are,
        # symmetric for Cholesky.
        return w if symmetric else wts.normalize(w, work.topology)

    return _map_with(mesh, w_of, symmetric, boundary, spacing, corners, backend, "convex_map")


def least_squares_map(mesh: TriMesh, *, mu=None, boundary="circle", spacing: str = "chord",
                      corners=None, backend: str = "auto"):
    """The least-squares (spring) map of eq. (8): minimizes ``sum mu_vw |u_v - u_w|^2``.

    **Arguments:** ``mu``: ``(e,)`` positive edge weights in ``mesh.topology.edges``
    order, or a function ``mu(vertices, edges) -> (e,)``; default
    ``1 / |v - w|``.  Other arguments as in :func:`convex_map`.

    **Returns:** ``uv: (n, 2)``.

    Example::

        uv = jp.least_squares_map(mesh, mu=lambda V, E: 1 / jnp.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1))
    """
    def w_of(work):
        E = work.topology.edges
        if mu is None:
            vals = 1.0 / jnp.linalg.norm(work.vertices[E[:, 0]] - work.vertices[E[:, 1]], axis=1)
        elif callable(mu):
            vals = mu(jnp.asarray(work.vertices), E)
        else:
            vals = jnp.asarray(mu, dtype=jnp.float64)
            if work.topology is not mesh.topology:
                vals = _extend_edge_values(vals, mesh.topology, work.topology)
        if not isinstance(vals, jax.core.Tracer):
            arr = np.asarray(vals)
            if arr.shape == (E.shape[0],):
                bad = np.flatnonzero(~(arr > 0))
                if bad.size:
                    raise MeshError(
                        f"least_squares_map: edge weights mu must be positive; edges "
                        f"{first_few([tuple(E[i]) for i in bad])} have mu <= 0 or nan "
                        f"(mu[{int(bad[0])}] = {arr[bad[0]]}); use positive weights (eq. (8)).")
        return wts.edge_values_to_entries(vals, work.topology)

    return _map_with(mesh, w_of, True, boundary, spacing, corners, backend, "least_squares_map")


def _extend_edge_values(vals, old_topo, new_topo):
    """User edge weights for a hole-filled mesh: the fan edges get the mean weight."""
    n = old_topo.n_vertices
    keys_old = old_topo.edges[:, 0] * np.int64(new_topo.n_vertices) + old_topo.edges[:, 1]
    keys_new = new_topo.edges[:, 0] * np.int64(new_topo.n_vertices) + new_topo.edges[:, 1]
    pos = np.searchsorted(keys_old, keys_new)
    found = (pos < keys_old.size) & (keys_old[np.minimum(pos, keys_old.size - 1)] == keys_new)
    del n
    return jnp.where(jnp.asarray(found), vals[np.minimum(pos, keys_old.size - 1)], jnp.mean(vals))
