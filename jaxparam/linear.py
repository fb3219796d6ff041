"""Convex-combination and least-squares maps of disk meshes (survey §3–5).

The interior UVs solve eq. (4), assembled by :mod:`jaxparam.combination` (which also decides
the row normalization).  Both coordinates come from one factorization, through
:mod:`jaxparam.sparse`, which makes the map differentiable in the vertex positions, the weights
and the boundary UVs.  :func:`disk_check` and :func:`fill_holes` live in :mod:`jaxparam.disk`
and are re-exported here.
"""
from __future__ import annotations

import functools

import numpy as np

from .lazy_jax import jax, jnp  # JAX loads on first use (issue 17)
from . import boundary as bmap
from . import combination as comb
from . import host as _host
from . import sparse
from . import weights as wts
from .disk import disk_check, fill_holes
from .errors import MeshError, SolverError, first_few
from .mesh import TriMesh, concrete_values
from .io import as_mesh
from .options import choose, is_flag
from .triangles import face_angles, signed_area2

__all__ = ["InteriorSystem", "interior_system", "solve_interior", "convex_map", "check_unfolded",
           "least_squares_map", "fill_holes", "disk_check"]


#: eq. (4)'s system for a mesh: the one assembler of :mod:`jaxparam.combination`.
InteriorSystem = comb.CombinationSystem


@functools.lru_cache(maxsize=16)
def interior_system(topology) -> comb.CombinationSystem:
    """Build (once per topology) eq. (4)'s pattern for the interior vertices over their one-rings.

    The entries are :func:`jaxparam.weights.ring_entries`'s; the fixed vertices are the
    boundary vertices, indexed by their slot in ``topology.boundary``.
    """
    R = wts.ring_entries(topology)
    nbr_interior = ~topology.is_boundary[R.nbr]
    slot = topology.slot[R.nbr]
    return comb.combination_system(R.row, np.where(nbr_interior, slot, -1),
                                   np.where(nbr_interior, -1, slot), R.n_rows)


def solve_interior(topology, w, boundary_uv, *, symmetric: bool = False, backend: str = "auto"):
    """Solve eq. (4) for the interior UVs.

    **Arguments:** ``w: (k,)`` unnormalized weights on the ring entries of
    :func:`jaxparam.weights.ring_entries` (row sums need not be 1);
    ``boundary_uv: (nb, 2)`` UVs of ``topology.boundary`` in slot order.
    **Returns:** ``(ni, 2)`` UVs of ``topology.interior``.
    """
    S = interior_system(topology)
    vals, rhs = comb.assemble(S, w, boundary_uv, normalize=False)
    return sparse.solve(S.pattern, vals, rhs, symmetric=symmetric, backend=backend)


@functools.partial(jax.jit, static_argnames=("shape", "spacing", "corners", "nb"))
def _boundary_slots(V, loop, loop_slot, user_uv, *, shape, spacing, corners, nb):
    """The boundary map of the loop, as UVs in ``topology.boundary`` slot order ``(nb, 2)``."""
    uv_loop = _boundary_only(V, loop, user_uv, shape, spacing, corners)
    return jnp.zeros((nb, 2), V.dtype).at[loop_slot].set(uv_loop, unique_indices=True)


def _boundary_key(boundary, k: int):
    """Split a boundary argument into a static key and an optional array of user UVs."""
    if isinstance(boundary, str):
        shape = choose(boundary, bmap.SHAPES, what="boundary", where="boundary")
        return shape, np.zeros((k, 2))          # numpy: no eager compile per loop length
    if isinstance(boundary, dict) and "polygon" in boundary:
        C = np.asarray(boundary["polygon"], np.float64)
        bmap.polygon(np.zeros((3, 3)), C)       # validates shape and convexity up front
        return tuple(map(tuple, C.tolist())), np.zeros((k, 2))
    uv = jnp.asarray(boundary, dtype=jnp.float64)
    if uv.shape != (k, 2):
        raise MeshError(f"boundary: the user boundary UVs must have shape ({k}, 2), one row per "
                        f"vertex of the longest boundary loop in loop order, got {tuple(uv.shape)}.")
    bmap.check_user_uv(uv)
    return "user", uv


def _boundary_only(V, loop, user_uv, shape, spacing, corners):
    if shape == "user":
        return user_uv
    if isinstance(shape, tuple):
        return bmap.polygon(V[loop], np.asarray(shape), spacing=spacing, corner_positions=corners)
    return bmap.boundary_uv(V[loop], shape, spacing=spacing, corners=corners)


def _map_with(mesh: TriMesh, w_of, symmetric: bool, normalize: bool, boundary, spacing, corners,
              backend, where, host: bool = False):
    if not is_flag(host):
        raise MeshError(f"{where}: host must be True or False, got {host!r}.")
    disk_check(mesh, where)
    spacing = choose(spacing, bmap.SPACINGS, what="spacing", where=where)
    work, added = fill_holes(mesh)
    t = work.topology
    V = (work.vertices if host and isinstance(work.vertices, np.ndarray)   # no JAX on the host path
         else jnp.asarray(work.vertices, dtype=jnp.float64))
    loop = t.boundary_loops[0]
    shape, user_uv = _boundary_key(bmap.in_loop_order(boundary, loop), loop.size)
    if shape == "plane":
        # Refuse a loop that projects to no simple polygon now, on concrete positions (the
        # boundary map itself runs inside a jit, where values are tracers).
        bmap.check_plane_boundary(work.vertices[loop], loop)
    corners = None if corners is None else tuple(int(c) for c in corners)
    if t.interior.size == 0:
        # No interior vertex: the map is the boundary map itself.
        uv_b = _boundary_only(V, loop, user_uv, shape, spacing, corners)
        uv = jnp.full((t.n_vertices, 2), jnp.nan).at[loop].set(uv_b)
        return uv[: mesh.n_vertices]
    w = w_of(work)
    S = interior_system(t)
    if host and shape == "circle" and isinstance(w, np.ndarray):
        # The default boundary, in NumPy too: no kernel to trace for a new loop length.
        uv_b = np.zeros((t.boundary.size, 2))
        uv_b[t.slot[loop]] = _host.circle(np.asarray(work.vertices, np.float64)[loop], spacing)
    else:
        uv_b = _boundary_slots(V, loop, t.slot[loop], user_uv, shape=shape, spacing=spacing,
                               corners=corners, nb=t.boundary.size)
    if host and isinstance(w, np.ndarray) and wts.is_concrete(uv_b):
        # The cheap path (issue 17): NumPy assembly, a host factorization, a NumPy scatter.
        uv_b = np.asarray(uv_b)
        vals, rhs = comb.assemble(S, w, uv_b, normalize=normalize, host=True)
        x = comb.solve(S, vals, rhs, symmetric=symmetric, backend=backend)
        uv = np.full((t.n_vertices, 2), np.nan)
        uv[t.interior], uv[t.boundary] = x, uv_b
        return uv[: mesh.n_vertices] if added else uv
    x = comb.solve_weights(S, w, uv_b, normalize=normalize, symmetric=symmetric, backend=backend)
    uv = comb.scatter(x, uv_b, t.interior, t.boundary, n=t.n_vertices)
    return uv[: mesh.n_vertices] if added else uv


def convex_map(mesh: TriMesh, *, weights: str = "shape_preserving", boundary="circle",
               spacing: str = "chord", corners=None, backend: str = "auto", boundary_indices=None,
               host: bool = False):
    """A convex-combination parameterization (survey §3–4, eq. (3)).

    **Arguments:**

    - ``mesh``: a :class:`TriMesh` of disk topology; further boundary loops
      (holes) are filled virtually with a temporary centre vertex each and the
      longest loop goes to the boundary.
    - ``weights``: ``"uniform"``, ``"inverse_distance"``, ``"shape_preserving"``,
      ``"mean_value"`` or ``"harmonic"``.
    - ``boundary``: ``"circle"``, ``"square"``, ``"plane"``, a ``(k, 2)`` array of
      UVs for the longest boundary loop (in :func:`jaxparam.boundary.boundary_loop`'s
      order, or in any order with ``boundary_indices (k,)`` naming each row's vertex), a
      mapping ``{vertex: (u, v)}`` over that loop's vertices, or ``{"polygon": corners}``.
    - ``spacing``: ``"chord"`` or ``"uniform"``; ``corners``: loop positions of
      the square's (or polygon's) corners.
    - ``host``: with concrete (untraced) vertices, compute the weights, the assembly and the
      scatter in NumPy, with no tracing or compilation (the cheap path for a one-off call: the
      CLI uses it); the result is a NumPy array equal to the default JAX path to rounding
      (1e-13 of the UV extent; not bitwise).  Ignored under ``jax.grad``/``jit``/``vmap``.

    **Returns:** ``uv: (n, 2)`` in the mesh's vertex order (``nan`` for
    unreferenced vertices).  One-to-one when the weights are positive and the
    boundary convex (Theorem 1; see :func:`jaxparam.metrics.theorem1`).

    Differentiable: ``jax.grad`` flows to ``mesh.vertices`` through the
    weights, the boundary map and the sparse solve.

    Example::

        uv = jp.convex_map(mesh, weights="mean_value", boundary="square")
    """
    mesh = as_mesh(mesh, "convex_map")
    boundary = bmap.user_boundary(boundary, boundary_indices)
    weights = choose(weights, wts.KINDS, what="weights", where="convex_map")
    symmetric = weights in wts.SYMMETRIC_KINDS

    def w_of(work):
        return wts.entry_weights(work.vertices, work.topology, weights, host=host)[0]

    try:
        return _map_with(mesh, w_of, symmetric, comb.normalizes(weights), boundary, spacing,
                         corners, backend, "convex_map", host=host)
    except SolverError as exc:
        if weights != "harmonic" or isinstance(mesh.vertices, jax.core.Tracer):
            raise
        raise SolverError(f"{exc} {_needle_hint(mesh)}", stage=exc.stage) from None


def _needle_hint(mesh: TriMesh) -> str:
    """Why harmonic weights may leave a system singular: the triangle whose smallest angle is
    the smallest (its cotangent, unbounded there), and what to do."""
    F = np.asarray(mesh.faces)
    ang = face_angles(np.asarray(mesh.vertices, np.float64), F)
    f = int(np.argmin(ang.min(1)))
    t = float(ang[f].min())
    return (f"Harmonic (cotangent) weights are unbounded on needle triangles, and face {f} "
            f"(vertices {', '.join(str(int(v)) for v in F[f])}) has an angle of {t:.2g} rad (its "
            f"cotangent {1 / np.tan(t) if t > 0 else float('inf'):.2g}): use weights 'mean_value' "
            "or 'shape_preserving' (positive and bounded for any triangle), or remove the sliver.")


def least_squares_map(mesh: TriMesh, *, mu=None, boundary="circle", spacing: str = "chord",
                      corners=None, backend: str = "auto", boundary_indices=None):
    """The least-squares (spring) map of eq. (8): minimizes ``sum mu_vw |u_v - u_w|^2``.

    **Arguments:** ``mu``: ``(e,)`` positive edge weights in ``mesh.topology.edges``
    order, or a function ``mu(vertices, edges) -> (e,)``; default
    ``1 / |v - w|``.  Other arguments as in :func:`convex_map`.

    **Returns:** ``uv: (n, 2)``.

    Example::

        uv = jp.least_squares_map(mesh, mu=lambda V, E: 1 / jnp.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1))
    """
    mesh = as_mesh(mesh, "least_squares_map")
    boundary = bmap.user_boundary(boundary, boundary_indices)
    def w_of(work):
        E = work.topology.edges
        if mu is None:
            vals = 1.0 / jnp.linalg.norm(work.vertices[E[:, 0]] - work.vertices[E[:, 1]], axis=1)
        elif callable(mu):
            vals = mu(jnp.asarray(work.vertices), E)
        else:
            dt = getattr(mu, "dtype", None)      # a tracer's too (gradients in mu)
            dt = np.dtype(dt if dt is not None else np.asarray(mu).dtype)
            if isinstance(mu, str) or dt.kind not in "biuf":
                raise MeshError(f"least_squares_map: mu must be None (inverse edge lengths), an "
                                f"({E.shape[0]},) array of positive edge weights or a function "
                                f"(V, E) -> weights, got {mu!r}.")
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

    return _map_with(mesh, w_of, True, False, boundary, spacing, corners, backend,
                     "least_squares_map")


def _extend_edge_values(vals, old_topo, new_topo):
    """User edge weights for a hole-filled mesh: the fan edges get the mean weight."""
    keys_old = old_topo.edges[:, 0] * np.int64(new_topo.n_vertices) + old_topo.edges[:, 1]
    keys_new = new_topo.edges[:, 0] * np.int64(new_topo.n_vertices) + new_topo.edges[:, 1]
    pos = np.searchsorted(keys_old, keys_new)
    found = (pos < keys_old.size) & (keys_old[np.minimum(pos, keys_old.size - 1)] == keys_new)
    return jnp.where(jnp.asarray(found), vals[np.minimum(pos, keys_old.size - 1)], jnp.mean(vals))


def check_unfolded(mesh, uv, weights: str, where: str) -> None:
    """Raise :class:`MeshError` when the convex map ``uv (n, 2)`` (of ``weights``) flips or
    collapses a face, for a caller that minimizes from it (a minimization keeps its start's
    triangles unflipped, so it needs one with none).  Harmonic weights are negative where
    angles are obtuse and their map can fold on a noisy mesh (session 21: "the start has
    infinite energy" was all ``jaxparam remesh --weights harmonic`` said).  Under a JAX
    transformation (no concrete values) it checks nothing."""
    known = concrete_values(uv)
    if known is None:
        return
    S = signed_area2(np.nan_to_num(np.asarray(known, np.float64)), np.asarray(mesh.faces))
    bad = np.flatnonzero(~(S > 0))
    if bad.size:
        why = " (harmonic weights are negative where angles are obtuse)" if weights == "harmonic" else ""
        raise MeshError(f"{where}: the convex map with {weights!r} weights folds: faces "
                        f"{first_few(bad)} are flipped or degenerate in it, and the minimization "
                        f"starts from it{why}; use weights 'shape_preserving' (the default) or "
                        "'mean_value', which never fold (jaxparam remesh --weights).")
