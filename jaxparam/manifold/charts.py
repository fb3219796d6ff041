"""Step 3 of :mod:`jaxparam.manifold`: surface triangles and their charts.

The paths cut the mesh into pieces (:func:`surface_triangles` checks there is one disk per
base triangle, bounded by that triangle's paths).  Each base triangle's chart is the
reference triangle :data:`REFERENCE`; path vertices sit on its sides by chord length, and
the vertices inside each surface triangle solve eq. (4) (:mod:`jaxparam.combination`), one
system for all surface triangles at once (:func:`charts`).

The discrete part (which vertices are fixed, on which base edge, the system's pattern) is
numpy, built once (:func:`chart_system`); the values (:func:`chart_values`: chord lengths,
weights, the solve) are JAX, so the charts are differentiable in the mesh's positions with
the discrete part held fixed (:meth:`~jaxparam.manifold.ManifoldParameterization.with_vertices`).
"""
from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .. import combination as comb
from .. import weights as wts
from ..errors import SolverError, first_few
from ..mesh import TriMesh
from ..triangles import signed_area2

__all__ = ["REFERENCE", "surface_triangles", "charts", "ChartSystem", "chart_system", "chart_values"]

#: The reference triangle every base triangle's chart uses.
REFERENCE = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3.0) / 2.0]])


def surface_triangles(W: TriMesh, base_ids, base_faces, base_topo, paths):
    """Cut the mesh ``W`` along the ``paths`` of the base domain (``base_faces (m0, 3)`` and
    ``base_topo`` over the mesh vertices ``base_ids``).  **Returns:** ``region (m,) int``: the
    base face of every mesh face; raises :class:`SolverError` (stage ``surface triangles``)
    when the pieces are not one disk per base face, bounded by that face's paths."""
    t = W.topology
    m = t.n_faces
    n = t.n_vertices
    key_of = t.edges[:, 0] * np.int64(n) + t.edges[:, 1]
    on_path = np.zeros(t.n_edges, bool)
    for p in paths:
        k = np.minimum(p[:-1], p[1:]) * np.int64(n) + np.maximum(p[:-1], p[1:])
        on_path[np.searchsorted(key_of, k)] = True
    ef = t.edge_faces[~on_path]
    A = sp.csr_matrix((np.ones(len(ef)), (ef[:, 0], ef[:, 1])), shape=(m, m))
    n_comp, label = connected_components(A, directed=False)
    if n_comp != len(base_faces):
        raise SolverError(f"manifold_map: the surface edges cut the mesh into {n_comp} pieces, not "
                          f"the {len(base_faces)} surface triangles of the base domain; try another "
                          "base_faces count.", stage="surface triangles")
    # The face left of each path's first edge lies in the base face left of that base edge.
    half = {}
    for f, (a, b, c) in enumerate(base_faces.tolist()):
        half[(a, b)], half[(b, c)], half[(c, a)] = f, f, f
    Fw = t.faces
    src = Fw.ravel()
    dst = Fw[:, [1, 2, 0]].ravel()
    hkey = src * np.int64(n) + dst
    order = np.argsort(hkey)
    region_of_label = np.full(n_comp, -1)
    for e, p in enumerate(paths):
        a, b = (int(x) for x in base_topo.edges[e])
        for (x, y, fa) in ((p[0], p[1], half.get((a, b))), (p[1], p[0], half.get((b, a)))):
            k = x * np.int64(n) + y
            i = order[np.searchsorted(hkey[order], k)]
            lab = label[i // 3]
            if fa is None or (region_of_label[lab] not in (-1, fa)):
                raise SolverError("manifold_map: a surface triangle is bounded by paths of two "
                                  "different base triangles; try another base_faces count.",
                                  stage="surface triangles")
            region_of_label[lab] = fa
    if np.any(region_of_label < 0) or np.unique(region_of_label).size != n_comp:
        raise SolverError("manifold_map: the surface triangles do not match the base triangles one "
                          "to one; try another base_faces count.", stage="surface triangles")
    region = region_of_label[label]
    # Each surface triangle must be a disk: V - E + F = 1 over its closed faces.
    counts_f = np.bincount(region, minlength=n_comp)
    e_reg = np.where(on_path, -1, region[np.maximum(t.edge_faces[:, 0], 0)])
    inner_e = np.bincount(e_reg[e_reg >= 0], minlength=n_comp)
    path_e = np.zeros(n_comp, np.int64)                   # path edges on each piece's border
    for side in (0, 1):
        np.add.at(path_e, region[t.edge_faces[on_path, side]], 1)
    verts = np.unique(np.stack([np.repeat(region, 3), t.faces.ravel()], 1), axis=0)
    counts_v = np.bincount(verts[:, 0], minlength=n_comp)
    euler = counts_v - inner_e - path_e + counts_f
    bad = np.flatnonzero(euler != 1)
    if bad.size:
        raise SolverError(f"manifold_map: surface triangles {first_few(bad)} are not disks; try "
                          "another base_faces count.", stage="surface triangles")
    return region


@dataclass(frozen=True, eq=False)
class ChartSystem:
    """The discrete part of the charts (numpy), for :func:`chart_values`.

    **Fields** (``n`` mesh vertices, ``m`` faces): ``path_pad (P, L)``, ``path_mask (P, L-1)``
    the paths' vertices padded to one length and which segments are real; ``inner_vertex``,
    ``inner_path``, ``inner_pos`` each path's inner vertices and their place on it;
    ``free (n_free,)`` the vertices the solve places; ``system`` the
    :class:`~jaxparam.combination.CombinationSystem` (``None`` when nothing is free);
    ``entries`` the weight entries it uses; ``fix_v``, ``fix_pa``, ``fix_pb`` its fixed UVs
    (vertex ``v`` at ``(1 - s_v) pa + s_v pb``, ``s_v`` its chord-length parameter, ``0`` at
    base vertices where ``pa = pb``); ``corner_fixed`` the face corners (flat, ``3 m``) at
    fixed vertices and their ``corner_v``, ``corner_pa``, ``corner_pb``; ``corner_vertex
    (3 m,)`` the vertex of every corner; ``vertex_corner (n,)`` one corner of every vertex;
    ``weights``, ``normalize``, ``symmetric`` the weights' kind and how they are solved."""

    n: int
    path_pad: np.ndarray
    path_mask: np.ndarray
    inner_vertex: np.ndarray
    inner_path: np.ndarray
    inner_pos: np.ndarray
    free: np.ndarray
    system: object
    entries: np.ndarray
    fix_v: np.ndarray
    fix_pa: np.ndarray
    fix_pb: np.ndarray
    corner_fixed: np.ndarray
    corner_v: np.ndarray
    corner_pa: np.ndarray
    corner_pb: np.ndarray
    corner_vertex: np.ndarray
    vertex_corner: np.ndarray
    weights: str
    normalize: bool
    symmetric: bool


def chart_system(W: TriMesh, base_ids, F0, base_topo, paths, region, weights: str) -> ChartSystem:
    """The discrete part of :func:`charts` (arguments as there): which vertices are fixed and
    where on the reference triangle's sides, and the pattern of the solve for the rest."""
    t = W.topology
    n = t.n_vertices
    on_edge = np.full(n, -1, np.int64)
    for e, p in enumerate(paths):
        on_edge[p[1:-1]] = e
    L = max(len(p) for p in paths)
    path_pad = np.stack([np.concatenate([p, np.full(L - len(p), p[-1])]) for p in paths]).astype(np.int64)
    path_mask = np.arange(L - 1)[None, :] < np.array([len(p) - 1 for p in paths])[:, None]
    inner_vertex = np.concatenate([p[1:-1] for p in paths]).astype(np.int64)
    inner_path = np.concatenate([np.full(len(p) - 2, e) for e, p in enumerate(paths)]).astype(np.int64)
    inner_pos = np.concatenate([np.arange(1, len(p) - 1) for p in paths]).astype(np.int64)
    is_base = np.zeros(n, bool)
    is_base[base_ids] = True
    base_index = np.full(n, -1, np.int64)
    base_index[base_ids] = np.arange(base_ids.size)
    fixed = is_base | (on_edge >= 0)

    def chart(r, v):
        """Ends ``pa, pb (k, 2)`` of fixed vertices ``v (k,)`` in base faces ``r (k,)``: the
        vertex sits at ``(1 - s) pa + s pb``."""
        corners = F0[r]                                          # (k, 3) base-vertex indices
        pa = np.zeros((v.size, 2))
        pb = np.zeros((v.size, 2))
        b = base_index[v]
        isb = b >= 0
        pa[isb] = pb[isb] = REFERENCE[np.argmax(corners[isb] == b[isb, None], axis=1)]
        e = on_edge[v[~isb]]
        a0, a1 = base_topo.edges[e, 0], base_topo.edges[e, 1]
        c = corners[~isb]
        pa[~isb] = REFERENCE[np.argmax(c == a0[:, None], axis=1)]
        pb[~isb] = REFERENCE[np.argmax(c == a1[:, None], axis=1)]
        return pa, pb

    # Free vertices: weights on the whole mesh's one-rings (a closed mesh: every vertex has
    # a ring), eq. (4) for the free ones.  A fixed neighbour's UV depends on the chart of the
    # row's region (the region of one of the free vertex's faces), so each entry from a free
    # vertex to a fixed one gets its own row of fixed UVs.
    vertex_face = np.empty(n, np.int64)
    vertex_face[t.faces.ravel()] = np.repeat(np.arange(t.n_faces), 3)
    free_region = region[vertex_face]
    free = np.flatnonzero(~fixed)
    system, entries = None, np.zeros(0, np.int64)
    fix_v, fix_pa, fix_pb = np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 2))
    if free.size:
        sel = ~fixed[t.ring_row]
        row, col = t.ring_row[sel], t.ring_idx[sel]
        slot = np.full(n, -1, np.int64)
        slot[free] = np.arange(free.size)
        to_fixed = fixed[col]
        nbr_fixed = np.full(row.size, -1, np.int64)
        nbr_fixed[to_fixed] = np.arange(int(to_fixed.sum()))
        system = comb.combination_system(slot[row], slot[col], nbr_fixed, free.size)
        entries = np.flatnonzero(sel)
        fix_v = col[to_fixed]
        fix_pa, fix_pb = chart(free_region[row[to_fixed]], fix_v)
    # Corners of every face in its region's chart.
    r3 = np.repeat(region, 3)
    v3 = t.faces.ravel()
    corner_fixed = np.flatnonzero(fixed[v3])
    corner_pa, corner_pb = chart(r3[corner_fixed], v3[corner_fixed])
    cidx = np.empty(n, np.int64)
    cidx[v3] = np.arange(v3.size)
    return ChartSystem(n=n, path_pad=path_pad, path_mask=path_mask, inner_vertex=inner_vertex,
                       inner_path=inner_path, inner_pos=inner_pos, free=free, system=system,
                       entries=entries, fix_v=fix_v, fix_pa=fix_pa, fix_pb=fix_pb,
                       corner_fixed=corner_fixed, corner_v=v3[corner_fixed], corner_pa=corner_pa,
                       corner_pb=corner_pb, corner_vertex=v3, vertex_corner=cidx, weights=weights,
                       normalize=comb.normalizes(weights), symmetric=weights in wts.SYMMETRIC_KINDS)


def _bary_reference(q):
    """Barycentric coordinates ``(k, 3)`` of points ``q (k, 2)`` in :data:`REFERENCE` (JAX)."""
    (ax, ay), (bx, by), (cx, cy) = REFERENCE
    det = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    l1 = ((bx - q[:, 0]) * (cy - q[:, 1]) - (by - q[:, 1]) * (cx - q[:, 0])) / det
    l2 = ((cx - q[:, 0]) * (ay - q[:, 1]) - (cy - q[:, 1]) * (ax - q[:, 0])) / det
    return jnp.stack([l1, l2, 1.0 - l1 - l2], axis=1)


def chart_values(S: ChartSystem, W: TriMesh):
    """The charts of ``W`` (whose connectivity ``S`` was built for) at its positions:
    chord-length parameters on the paths, the weights and one solve, all JAX, so
    differentiable in ``W.vertices`` (traced or not) with ``S`` held fixed.

    **Returns:** ``(face_uv (m, 3, 2), vertex_bary (n, 3))`` JAX arrays."""
    V = jnp.asarray(W.vertices, jnp.float64)
    d = V[S.path_pad[:, 1:]] - V[S.path_pad[:, :-1]]
    d = jnp.where(S.path_mask[..., None], d, 1.0)          # padding: no 0/0 in the norm's derivative
    seg = jnp.where(S.path_mask, jnp.sqrt(jnp.sum(d * d, axis=-1)), 0.0)
    cum = jnp.cumsum(seg, axis=1)
    total = jnp.maximum(cum[:, -1], 1e-300)
    s = jnp.zeros(S.n, V.dtype).at[S.inner_vertex].set(cum[S.inner_path, S.inner_pos - 1] / total[S.inner_path])
    uv = jnp.zeros((S.n, 2), V.dtype)
    if S.system is not None:
        w, _ = wts.entry_weights(V, W.topology, S.weights)
        sf = s[S.fix_v][:, None]
        uv_fixed = (1.0 - sf) * S.fix_pa + sf * S.fix_pb
        vals, rhs = comb.assemble(S.system, jnp.asarray(w)[S.entries], uv_fixed, normalize=S.normalize)
        uv = uv.at[S.free].set(jnp.asarray(comb.solve(S.system, vals, rhs, symmetric=S.symmetric)))
    sc = s[S.corner_v][:, None]
    face_uv = uv[S.corner_vertex].at[S.corner_fixed].set((1.0 - sc) * S.corner_pa + sc * S.corner_pb)
    return face_uv.reshape(-1, 3, 2), _bary_reference(face_uv[S.vertex_corner])


def charts(W: TriMesh, base_ids, F0, base_topo, paths, region, weights: str):
    """Chart coordinates of every mesh face's corners (step 3): path vertices by chord length
    on the reference triangle's sides, the rest by one convex-combination solve.

    **Arguments:** ``W`` the mesh; ``base_ids (n0,)`` its base vertices; ``F0 (m0, 3)`` and
    ``base_topo`` the base domain; ``paths`` from :func:`~jaxparam.manifold.paths.trace_paths`;
    ``region (m,)`` from :func:`surface_triangles`; ``weights`` a kind of
    :data:`jaxparam.weights.KINDS`.

    **Returns:** ``(face_uv (m, 3, 2), vertex_face (n,), vertex_bary (n, 3), system)``, the
    first three numpy as :class:`~jaxparam.manifold.ManifoldParameterization` stores them,
    ``system`` the :class:`ChartSystem` that recomputes them (:func:`chart_values`).  Raises
    :class:`SolverError` (stage ``charts``) when a face comes out flipped."""
    S = chart_system(W, base_ids, F0, base_topo, paths, region, weights)
    face_uv, vbary = (np.asarray(x) for x in chart_values(S, W))
    flat = face_uv.reshape(-1, 2)
    bad = np.flatnonzero(signed_area2(flat, np.arange(flat.shape[0]).reshape(-1, 3)) <= 0)
    if bad.size:
        raise SolverError(f"manifold_map: faces {first_few(bad)} are flipped or degenerate in their "
                          "surface triangle's chart; try another base_faces count.", stage="charts")
    return face_uv, region[S.vertex_corner // 3], vbary, S
