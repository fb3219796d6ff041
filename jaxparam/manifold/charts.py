"""Step 3 of :mod:`jaxparam.manifold`: surface triangles and their charts.

The paths cut the mesh into pieces (:func:`surface_triangles` checks there is one disk per
base triangle, bounded by that triangle's paths).  Each base triangle's chart is the
reference triangle :data:`REFERENCE`; path vertices sit on its sides by chord length, and
the vertices inside each surface triangle solve eq. (4) (:mod:`jaxparam.combination`), one
system for all surface triangles at once (:func:`charts`).
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .. import combination as comb
from .. import weights as wts
from ..errors import SolverError, first_few
from ..mesh import TriMesh
from ..triangles import barycentric, signed_area2

__all__ = ["REFERENCE", "surface_triangles", "charts"]

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


def charts(W: TriMesh, base_ids, F0, base_topo, paths, region, weights: str):
    """Chart coordinates of every mesh face's corners (step 3): path vertices by chord length
    on the reference triangle's sides, the rest by one convex-combination solve.

    **Arguments:** ``W`` the mesh; ``base_ids (n0,)`` its base vertices; ``F0 (m0, 3)`` and
    ``base_topo`` the base domain; ``paths`` from :func:`~jaxparam.manifold.paths.trace_paths`;
    ``region (m,)`` from :func:`surface_triangles`; ``weights`` a kind of
    :data:`jaxparam.weights.KINDS`.

    **Returns:** ``(face_uv (m, 3, 2), vertex_face (n,), vertex_bary (n, 3))`` as
    :class:`~jaxparam.manifold.ManifoldParameterization` stores them.  Raises
    :class:`SolverError` (stage ``charts``) when a face comes out flipped."""
    t = W.topology
    n = t.n_vertices
    V = np.asarray(W.vertices)
    # Path vertices: their base edge and chord-length parameter from the edge's first end.
    on_edge = np.full(n, -1, np.int64)
    param = np.zeros(n)
    for e, p in enumerate(paths):
        seg = np.linalg.norm(np.diff(V[p], axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(seg)]) / max(seg.sum(), 1e-300)
        on_edge[p[1:-1]] = e
        param[p[1:-1]] = s[1:-1]
    is_base = np.zeros(n, bool)
    is_base[base_ids] = True
    base_index = np.full(n, -1, np.int64)
    base_index[base_ids] = np.arange(base_ids.size)
    fixed = is_base | (on_edge >= 0)

    def chart(r, v):
        """Chart coordinates ``(k, 2)`` of fixed vertices ``v (k,)`` in base faces ``r (k,)``."""
        corners = F0[r]                                          # (k, 3) base-vertex indices
        out = np.zeros((v.size, 2))
        b = base_index[v]
        isb = b >= 0
        out[isb] = REFERENCE[np.argmax(corners[isb] == b[isb, None], axis=1)]
        e = on_edge[v[~isb]]
        a0, a1 = base_topo.edges[e, 0], base_topo.edges[e, 1]
        c = corners[~isb]
        pa = REFERENCE[np.argmax(c == a0[:, None], axis=1)]
        pb = REFERENCE[np.argmax(c == a1[:, None], axis=1)]
        s = param[v[~isb]][:, None]
        out[~isb] = (1 - s) * pa + s * pb
        return out

    # Free vertices: region of one of their faces; weights on the whole mesh's one-rings
    # (a closed mesh: every vertex has a ring), eq. (4) for the free ones.  A fixed
    # neighbour's UV depends on the chart of the row's region, so each entry from a free
    # vertex to a fixed one gets its own row of fixed UVs.
    vertex_face = np.empty(n, np.int64)
    vertex_face[t.faces.ravel()] = np.repeat(np.arange(t.n_faces), 3)
    free_region = region[vertex_face]
    free = np.flatnonzero(~fixed)
    uv = np.zeros((n, 2))
    if free.size:
        w, _ = wts.entry_weights(W.vertices, t, weights)
        sel = ~fixed[t.ring_row]
        row, col = t.ring_row[sel], t.ring_idx[sel]
        slot = np.full(n, -1, np.int64)
        slot[free] = np.arange(free.size)
        to_fixed = fixed[col]
        nbr_fixed = np.full(row.size, -1, np.int64)
        nbr_fixed[to_fixed] = np.arange(int(to_fixed.sum()))
        system = comb.combination_system(slot[row], slot[col], nbr_fixed, free.size)
        uv_fixed = chart(free_region[row[to_fixed]], col[to_fixed])
        vals, rhs = comb.assemble(system, jnp.asarray(w)[np.flatnonzero(sel)], jnp.asarray(uv_fixed),
                                  normalize=comb.normalizes(weights))
        uv[free] = np.asarray(comb.solve(system, vals, rhs, symmetric=weights in wts.SYMMETRIC_KINDS))
    # Corners of every face in its region's chart.
    Fw = t.faces
    r3 = np.repeat(region, 3)
    v3 = Fw.ravel()
    face_uv = uv[v3].copy()
    fx = fixed[v3]
    face_uv[fx] = chart(r3[fx], v3[fx])
    bad = np.flatnonzero(signed_area2(face_uv, np.arange(face_uv.shape[0]).reshape(-1, 3)) <= 0)
    face_uv = face_uv.reshape(-1, 3, 2)
    if bad.size:
        raise SolverError(f"manifold_map: faces {first_few(bad)} are flipped or degenerate in their "
                          "surface triangle's chart; try another base_faces count.", stage="charts")
    # phi^{-1} of every vertex: a face containing it, barycentric in that face's base face.
    cidx = np.empty(n, np.int64)
    cidx[v3] = np.arange(v3.size)
    vface = region[cidx // 3]
    q = face_uv.reshape(-1, 2)[cidx]
    return face_uv, vface, barycentric(np.broadcast_to(REFERENCE, (n, 3, 2)), q)
