"""Combinatorics of a triangle mesh, computed once from the (concrete) face array.

Everything here is numpy and vectorized: no Python loop runs over vertices or
faces.  One sort of the half-edges by undirected edge pairs every half-edge
with its twin; the wedges around all vertices are then ordered by walking
every fan at once (:func:`_walk_fans`), and boundary loops by pointer jumping
(:func:`_rank_linked_lists`).

Conventions: faces are counter-clockwise; a boundary loop runs along the
faces' orientation (interior on its left); a one-ring lists a vertex's
neighbours anticlockwise, and for a boundary vertex it starts at the
neighbour across the outgoing boundary edge and ends at the one across the
incoming boundary edge.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .errors import DegenerateFaceError, MeshError, NonManifoldError, first_few

__all__ = [
    "Topology",
    "build",
    "boundary_loops",
    "check_faces",
    "renumber",
    "permute_rows",
]


def check_faces(faces, n_vertices: int, *, where: str = "TriMesh") -> np.ndarray:
    """Validate a face array and return it as ``(m, 3) int64``.

    Raises :class:`MeshError` for a wrong shape, a non-integer dtype or an
    index out of ``[0, n_vertices)``, and :class:`DegenerateFaceError` for a
    face that repeats a vertex.
    """
    F = np.asarray(faces)
    if F.ndim != 2 or F.shape[1] != 3:
        raise MeshError(f"{where}: faces must have shape (m, 3), got {F.shape}; "
                        "pass triangles only (triangulate polygons first, e.g. with trimesh).")
    if F.shape[0] == 0:
        raise MeshError(f"{where}: the mesh has no faces; give at least one triangle.")
    if not np.issubdtype(F.dtype, np.integer):
        if np.issubdtype(F.dtype, np.floating) and np.all(np.isfinite(F)) and np.all(F == np.round(F)):
            F = F.astype(np.int64)
        else:
            raise MeshError(f"{where}: faces must be integer vertex indices, got dtype {F.dtype}.")
    F = F.astype(np.int64, copy=False)
    bad = np.flatnonzero(np.any((F < 0) | (F >= n_vertices), axis=1))
    if bad.size:
        raise MeshError(
            f"{where}: faces {first_few(bad)} index vertices outside [0, {n_vertices}) "
            f"(face {int(bad[0])} is {tuple(int(v) for v in F[bad[0]])}); "
            "fix the indices (OBJ indices are 1-based in the file, 0-based here).")
    rep = np.flatnonzero((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2]))
    if rep.size:
        raise DegenerateFaceError(
            f"{where}: faces {first_few(rep)} repeat a vertex "
            f"(face {int(rep[0])} is {tuple(int(v) for v in F[rep[0]])}); remove them.")
    return F


def _rank_linked_lists(succ: np.ndarray, max_len: int):
    """Order the disjoint paths and cycles of a successor array by pointer jumping.

    **Arguments:** ``succ: (k,) int``, ``succ[i]`` is the element after ``i``,
    or ``-1`` at the end of a path; every element has at most one predecessor.
    ``max_len`` bounds the length of any list (it sets the number of doublings).

    **Returns:** ``(root, pos, is_cycle)``, each ``(k,)``: the first element of
    the list that holds ``i`` (a cycle is cut just before its smallest
    element, which becomes its first), the position of ``i`` in its list, and
    whether that list is a cycle.
    """
    k = succ.size
    idx = np.arange(k)
    rounds = int(np.ceil(np.log2(max(int(max_len), 2)))) + 1

    def jump(ptr):
        valid = ptr >= 0
        safe = np.where(valid, ptr, idx)
        return valid, safe

    # 1. Which lists are cycles, and each cycle's smallest element.
    nxt, low, reach_end = succ.copy(), idx.copy(), succ < 0
    for _ in range(rounds):
        valid, safe = jump(nxt)
        low = np.where(valid, np.minimum(low, low[safe]), low)
        reach_end = reach_end | (valid & reach_end[safe])
        nxt = np.where(valid, nxt[safe], -1)
    is_cycle = ~reach_end
    # 2. Cut every cycle just before its smallest element.
    cut = succ.copy()
    cut[is_cycle & (succ >= 0) & (np.where(succ >= 0, succ, 0) == low)] = -1
    # 3. Distance to the end and the root (first element), both by doubling.
    dist = (cut >= 0).astype(np.int64)
    nxt = cut.copy()
    pred = np.full(k, -1)
    pred[cut[cut >= 0]] = idx[cut >= 0]
    root, up = idx.copy(), pred
    for _ in range(rounds):
        valid, safe = jump(nxt)
        dist = dist + np.where(valid, dist[safe], 0)
        nxt = np.where(valid, nxt[safe], -1)
        valid, safe = jump(up)
        root = np.where(valid, root[safe], root)
        up = np.where(valid, up[safe], -1)
    pos = dist[root] - dist
    return root, pos, is_cycle


def _raise_edge_error(a, b, hf, n, where):
    """Explain a bad edge: duplicate faces, an edge shared by more than two faces, or two
    faces running the same way."""
    S = np.sort(a.reshape(-1, 3), axis=1)          # a is the face array, flattened
    _, inv, cnt = np.unique(S, axis=0, return_inverse=True, return_counts=True)
    dup = np.flatnonzero(cnt[inv.reshape(-1)] > 1)
    if dup.size:
        twins = dup[inv.reshape(-1)[dup] == inv.reshape(-1)[dup[0]]]
        raise NonManifoldError(
            f"{where}: faces {first_few(dup)} are duplicate faces (faces {int(twins[0])} and "
            f"{int(twins[1])} both join vertices {tuple(int(v) for v in S[twins[0]])}); remove the "
            "duplicates (e.g. trimesh's unique_faces).")
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    uniq, counts = np.unique(lo * np.int64(n) + hi, return_counts=True)
    over = np.flatnonzero(counts > 2)
    if over.size:
        e = [(int(k // n), int(k % n)) for k in uniq[over]]
        raise NonManifoldError(
            f"{where}: edges {first_few(e)} are shared by more than two faces (edge {e[0]} by "
            f"{int(counts[over[0]])} faces); the mesh is non-manifold: split it into manifold "
            "pieces (e.g. trimesh's split) or remove the extra faces.")
    twisted = _twisted_faces(lo * np.int64(n) + hi, a < b, hf)
    if twisted is not None:
        f, g = twisted
        raise NonManifoldError(
            f"{where}: the surface is not orientable (a Moebius strip, or a Klein bottle, inside "
            f"it): no choice of the faces' windings makes every shared edge run opposite ways in "
            f"its two faces (a loop of faces through faces {f} and {g} comes back turned over), "
            "so fix_winding cannot help. jaxparam maps orientable surfaces only: cut the mesh "
            "along a curve that crosses the twist into pieces that are orientable.")
    keys = a * np.int64(n) + b
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    dup = np.flatnonzero(ks[1:] == ks[:-1])
    e = [(int(k // n), int(k % n)) for k in ks[dup]]
    raise NonManifoldError(
        f"{where}: edges {first_few(e)} are traversed in the same direction by two faces "
        f"(edge {e[0]} by faces {int(hf[order[dup[0]]])} and {int(hf[order[dup[0] + 1]])}); the "
        "faces' orientation is inconsistent (or there are duplicate faces): orient the faces "
        "consistently (e.g. trimesh.repair.fix_winding) and remove duplicates.")


def _twisted_faces(edge_key: np.ndarray, forward: np.ndarray, hf: np.ndarray):
    """``None`` when the faces can be wound consistently, else two adjacent faces ``(f, g)`` on
    a loop that comes back turned over (the surface is not orientable).

    ``edge_key (H,)`` the undirected edge of each half-edge (at most two per key),
    ``forward (H,)`` whether it runs from the smaller vertex, ``hf (H,)`` its face.  Two faces
    sharing an edge need opposite windings when they run it the same way; a breadth-first
    tree (from a virtual face joined to one face of each component) fixes each face's winding,
    summed along the tree by pointer doubling, and an edge off the tree that disagrees is the
    twist."""
    from scipy.sparse.csgraph import breadth_first_order

    order = np.argsort(edge_key, kind="stable")
    k = edge_key[order]
    pair = np.flatnonzero(k[1:] == k[:-1])
    f, g = hf[order[pair]], hf[order[pair + 1]]
    flip = (forward[order[pair]] == forward[order[pair + 1]]).astype(np.int64)
    m = int(hf.max()) + 1
    _, label = connected_components(sp.coo_matrix((np.ones(f.size), (f, g)), shape=(m, m)),
                                     directed=False)
    first = np.unique(label, return_index=True)[1]
    # edge weights: 1 + whether the windings must differ (0 would be no edge); the virtual
    # face m joins each component's first face with "same"
    src = np.r_[f, g, np.full(first.size, m)]
    dst = np.r_[g, f, first]
    w = np.r_[flip, flip, np.zeros(first.size, np.int64)] + 1
    W = sp.csr_matrix((w.astype(np.float64), (src, dst)), shape=(m + 1, m + 1))
    seq, pred = breadth_first_order(W, m, directed=True, return_predecessors=True)
    child = seq[1:]
    par = np.zeros(m + 1, np.int64)
    par[child] = np.asarray(W[pred[child], child]).ravel().astype(np.int64) - 1
    anc = pred.copy()
    anc[m] = -1
    while np.any(anc >= 0):             # pointer doubling: the winding relative to the root
        up = anc >= 0
        par[up] ^= par[anc[up]]
        anc[up] = anc[anc[up]]
    bad = np.flatnonzero((par[f] ^ par[g]) != flip)
    return None if bad.size == 0 else (int(f[bad[0]]), int(g[bad[0]]))


def _walk_fans(a: np.ndarray, succ: np.ndarray, n: int):
    """Order every vertex's wedges by walking all fans at once.

    Each vertex starts at a wedge without predecessor (the first of a
    boundary vertex's fan) or, for a closed fan, at any wedge; the walks
    advance together, one wedge per vertex per step, so the work is the
    number of wedges and the number of steps the largest degree.

    **Returns:** ``pos (H,)`` the wedge's position in its vertex's fan (-1 if
    a second fan left it unvisited) and ``closed (n,)`` whether the walk came
    back to its start (an interior vertex).
    """
    H = a.size
    has_pred = np.zeros(H, bool)
    has_pred[succ[succ >= 0]] = True
    start = np.full(n, -1, np.int64)
    start[a] = np.arange(H)
    heads = np.flatnonzero(~has_pred)
    start[a[heads]] = heads
    verts = np.flatnonzero(start >= 0)
    cur = start[verts]
    first = cur
    pos = np.full(H, -1, np.int64)
    closed = np.zeros(n, bool)
    step = 0
    while cur.size:
        pos[cur] = step
        nxt = succ[cur]
        back = nxt == first
        closed[verts[back]] = True
        keep = (nxt >= 0) & ~back
        verts, cur, first = verts[keep], nxt[keep], first[keep]
        step += 1
        if step > H:  # a successor structure with a cycle not through the start: never for faces
            raise MeshError("topology: internal error walking vertex fans")
    return pos, closed


@dataclass(frozen=True, eq=False)
class Topology:
    """Who is next to whom in a manifold triangle mesh (all numpy, immutable).

    Hashable by identity, so it can travel as static data through ``jax.jit``.

    **Fields** (``n`` vertices, ``m`` faces, ``e`` edges, ``b`` boundary edges):

    - ``n_vertices``, ``faces (m, 3) int64``
    - ``edges (e, 2) int64``: each undirected edge once, ``edges[:, 0] < edges[:, 1]``
    - ``edge_faces (e, 2) int64``: the faces on either side (``-1`` for none)
    - ``boundary_loops``: tuple of ``(k,) int64`` arrays, each a boundary loop in
      the faces' orientation, longest first
    - ``ring_ptr (n+1,)``, ``ring_idx (nnz,)``: anticlockwise one-rings in CSR
    - ``ring_prev (nnz,)``, ``ring_next (nnz,)``: the neighbour before / after
      each entry in its ring (``-1`` past the end of a boundary vertex's fan)
    - ``ring_row (nnz,)``: the centre vertex of each entry; ``ring_wedge (nnz,)``:
      the corner ``3 f + c`` of the face whose wedge at the centre starts at
      this entry (``-1`` for a boundary vertex's last entry)
    - ``is_boundary (n,) bool``, ``referenced (n,) bool``
    - ``interior (ni,)``, ``boundary (nb,)``: vertex indices; ``slot (n,)``:
      position of a vertex in ``interior`` or in ``boundary``
    - ``components (n,) int``: component label of each referenced vertex (-1 unreferenced)
    - ``n_components``, ``euler``, ``genus``
    - ``dividing_edges (k, 2)``: interior edges whose two ends lie on the boundary
    """

    n_vertices: int
    faces: np.ndarray
    edges: np.ndarray
    edge_faces: np.ndarray
    boundary_loops: tuple
    ring_ptr: np.ndarray
    ring_idx: np.ndarray
    ring_prev: np.ndarray
    ring_next: np.ndarray
    ring_row: np.ndarray
    ring_wedge: np.ndarray
    is_boundary: np.ndarray
    referenced: np.ndarray
    interior: np.ndarray
    boundary: np.ndarray
    slot: np.ndarray
    components: np.ndarray
    n_components: int
    euler: int
    genus: int
    dividing_edges: np.ndarray

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def n_edges(self) -> int:
        return int(self.edges.shape[0])

    @property
    def degree(self) -> np.ndarray:
        """``(n,) int``: number of neighbours of each vertex."""
        return np.diff(self.ring_ptr)

    @property
    def is_closed(self) -> bool:
        return len(self.boundary_loops) == 0

    @property
    def is_disk(self) -> bool:
        return self.n_components == 1 and len(self.boundary_loops) == 1 and self.genus == 0

    def summary(self) -> dict:
        """Plain-Python facts for ``jaxparam info`` and reports."""
        return {
            "vertices": int(self.n_vertices),
            "referenced_vertices": int(self.referenced.sum()),
            "unreferenced_vertices": int((~self.referenced).sum()),
            "faces": self.n_faces,
            "edges": self.n_edges,
            "boundary_loops": len(self.boundary_loops),
            "boundary_loop_lengths": [int(len(l)) for l in self.boundary_loops],
            "components": int(self.n_components),
            "euler_characteristic": int(self.euler),
            "genus": int(self.genus),
            "dividing_edges": int(len(self.dividing_edges)),
            "max_degree": int(self.degree.max()) if self.n_vertices else 0,
        }


def build(faces, n_vertices: int | None = None, *, where: str = "TriMesh") -> Topology:
    """Compute the :class:`Topology` of a triangle mesh.

    **Arguments:** ``faces: (m, 3) int`` counter-clockwise triangles;
    ``n_vertices`` the number of vertices (default ``faces.max() + 1``).

    **Returns:** a :class:`Topology`.

    Raises :class:`NonManifoldError` for an edge with more than two faces, an
    edge used twice in the same direction (inconsistent orientation, named as
    such), or a vertex whose faces form more than one fan (a bowtie).

    Example::

        topo = build(np.array([[0, 1, 2], [0, 2, 3]]))
        topo.boundary_loops  # (array([0, 1, 2, 3]),)
    """
    F0 = np.asarray(faces)
    if n_vertices is None:
        n_vertices = int(F0.max()) + 1 if F0.size else 0
    F = check_faces(F0, n_vertices, where=where)
    n = int(n_vertices)
    m = F.shape[0]
    # Half-edges: corner c of face f goes a=F[f,c] -> b=F[f,c+1]; wedge at a spans b -> c=F[f,c+2].
    a = F.reshape(-1)
    b = F[:, [1, 2, 0]].reshape(-1)
    c = F[:, [2, 0, 1]].reshape(-1)

    # One sort by undirected edge: a half-edge and its twin end up side by side.
    H = a.size
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    ukey = lo * np.int64(n) + hi
    order = np.argsort(ukey, kind="stable")   # faster than the default here (runs of sorted keys)
    us = ukey[order]
    backward = (a > b)[order]                 # each sorted half-edge runs hi -> lo
    same_next = us[1:] == us[:-1]
    pair = np.flatnonzero(same_next)
    # twins run opposite ways: two half-edges of one edge both backward (or both forward) are
    # two faces running the same way
    if (pair.size > 1 and np.any(same_next[1:] & same_next[:-1])) or np.any(backward[pair] == backward[pair + 1]):
        _raise_edge_error(a, b, np.repeat(np.arange(m), 3), n, where)
    h1, h2 = order[pair], order[pair + 1]
    twin = np.full(H, -1, np.int64)
    twin[h1] = h2
    twin[h2] = h1
    is_bd_he = twin < 0

    # Undirected edges (sorted), and the faces on either side: side 0 where it runs lo -> hi.
    first = np.ones(us.size, bool)
    first[1:] = ~same_next
    edge_of = np.cumsum(first) - 1
    ukeys = us[first]
    edges = np.stack([ukeys // n, ukeys % n], axis=1)
    ne = edges.shape[0]
    edge_faces = np.full(2 * ne, -1, np.int64)
    edge_faces[2 * edge_of + backward] = order // 3       # half-edge 3 f + c lies in face f
    edge_faces = edge_faces.reshape(ne, 2)

    # Wedges around each vertex: wedge w (at a[w], from b[w] to c[w]) is followed by the wedge
    # that starts with the half-edge a[w] -> c[w], the twin of the face's half-edge c[w] -> a[w]
    # (half-edge 3 f + (c + 2) % 3).
    succ = twin.reshape(-1, 3)[:, [2, 0, 1]].reshape(-1)
    pos, closed = _walk_fans(a, succ, n)
    wedge_count = np.bincount(a, minlength=n)
    covered = np.bincount(a[pos >= 0], minlength=n)
    referenced = wedge_count > 0
    bow = np.flatnonzero(covered < wedge_count)
    if bow.size:
        raise NonManifoldError(
            f"{where}: vertices {first_few(bow)} are non-manifold (vertex {int(bow[0])} joins "
            "several separate fans of faces, a 'bowtie'); split such vertices into one copy per fan.")
    # A vertex is on the boundary when its fan is a path (not a cycle).
    is_boundary = referenced & ~closed

    # One-ring CSR: interior vertex: neighbours b of its wedges in fan order;
    # boundary vertex: the same plus c of the last wedge.
    deg = wedge_count + is_boundary.astype(np.int64)
    ring_ptr = np.zeros(n + 1, np.int64)
    np.cumsum(deg, out=ring_ptr[1:])
    slot_w = ring_ptr[a] + pos
    ring_idx = np.empty(ring_ptr[-1], np.int64)
    ring_idx[slot_w] = b
    last = succ < 0
    ring_idx[slot_w[last] + 1] = c[last]
    ring_row = np.repeat(np.arange(n), deg)
    # The wedge (half-edge index 3 f + corner) that starts at each ring entry; -1 after the last.
    ring_wedge = np.full(ring_idx.size, -1, np.int64)
    ring_wedge[slot_w] = np.arange(H)
    # prev/next within each ring (cyclic for interior vertices): the ring shifted by one entry,
    # with each row's ends fixed up (plain copies; no per-entry lookup of the row bounds).
    ring_next = np.empty_like(ring_idx)
    ring_prev = np.empty_like(ring_idx)
    ring_next[:-1], ring_prev[1:] = ring_idx[1:], ring_idx[:-1]
    has = np.flatnonzero(deg > 0)
    first, last = ring_ptr[has], ring_ptr[has + 1] - 1
    bd_has = is_boundary[has]
    ring_next[last] = np.where(bd_has, -1, ring_idx[first])
    ring_prev[first] = np.where(bd_has, -1, ring_idx[last])

    loops = _boundary_loops_from(a[is_bd_he], b[is_bd_he], n)

    # Components over the vertex graph of the faces.
    g = sp.csr_matrix((np.ones(ne, np.int8), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    comp = np.full(n, -1, np.int64)
    ref_idx = np.flatnonzero(referenced)
    _, comp_ref = np.unique(lab[ref_idx], return_inverse=True)
    comp[ref_idx] = comp_ref
    n_comp = int(comp_ref.max()) + 1 if comp_ref.size else 0

    V = int(referenced.sum())
    euler = V - ne + m
    nb = len(loops)
    genus = (2 * n_comp - euler - nb) // 2 if n_comp else 0

    interior = np.flatnonzero(referenced & ~is_boundary)
    boundary = np.flatnonzero(is_boundary)
    slot = np.full(n, -1, np.int64)
    slot[interior] = np.arange(interior.size)
    slot[boundary] = np.arange(boundary.size)
    dividing = _dividing_edges(ring_ptr, ring_idx, boundary, is_boundary)

    return Topology(
        n_vertices=n, faces=F, edges=edges, edge_faces=edge_faces, boundary_loops=loops,
        ring_ptr=ring_ptr, ring_idx=ring_idx, ring_prev=ring_prev, ring_next=ring_next,
        ring_row=ring_row, ring_wedge=ring_wedge, is_boundary=is_boundary, referenced=referenced, interior=interior,
        boundary=boundary, slot=slot, components=comp, n_components=n_comp, euler=int(euler),
        genus=int(genus), dividing_edges=dividing)


def _dividing_edges(ring_ptr, ring_idx, boundary, is_boundary) -> np.ndarray:
    """``(k, 2)``: the interior edges whose two ends lie on the boundary, sorted as ``edges``.

    Read from the boundary vertices' one-rings alone: a boundary vertex's ring starts and ends
    with its two boundary edges, so an entry strictly inside it that is a boundary vertex is
    such an edge (kept once, from its smaller end)."""
    if boundary.size == 0:
        return np.zeros((0, 2), np.int64)
    deg = ring_ptr[boundary + 1] - ring_ptr[boundary]
    inner = np.maximum(deg - 2, 0)
    v = np.repeat(boundary, inner)
    at = np.repeat(ring_ptr[boundary] + 1 - np.cumsum(inner) + inner, inner) + np.arange(int(inner.sum()))
    w = ring_idx[at]
    keep = is_boundary[w] & (v < w)
    v, w = v[keep], w[keep]
    o = np.lexsort((w, v))
    return np.stack([v[o], w[o]], axis=1)


def half_edge_twins(F: np.ndarray, n: int) -> np.ndarray:
    """``(3m,)``: the half-edge running the other way along each half-edge ``h = 3 f + j``
    (from ``F[f, j]`` to ``F[f, j+1]``) of a manifold triangulation ``F (m, 3)`` over ``n``
    vertices, ``-1`` on the boundary.  Unchecked: for faces already known to be manifold."""
    src, dst = F.reshape(-1), F[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(src, dst) * np.int64(n) + np.maximum(src, dst)
    order = np.argsort(key, kind="stable")
    pair = np.flatnonzero(key[order[1:]] == key[order[:-1]])
    twin = np.full(key.size, -1, np.int64)
    twin[order[pair]], twin[order[pair + 1]] = order[pair + 1], order[pair]
    return twin


def permute_rows(indptr: np.ndarray, old_of: np.ndarray):
    """Reorder the rows of a CSR structure: new row ``r`` is old row ``old_of[r]``.

    **Returns:** ``(indptr (n+1,), src (nnz,))``, ``src`` the old position of each new
    entry (gather any per-entry array with it).
    """
    deg = np.diff(indptr)[old_of]
    ptr = np.zeros(old_of.size + 1, np.int64)
    np.cumsum(deg, out=ptr[1:])
    return ptr, np.repeat(indptr[:-1][old_of] - ptr[:-1], deg) + np.arange(ptr[-1])


def renumber(t: Topology, new_id: np.ndarray) -> Topology:
    """The same topology with vertex ``v`` renamed ``new_id[v]`` (a permutation of
    ``range(n)``); equal, field by field, to :func:`build` of the renamed faces, at a third
    of its cost (no sorting of half-edges, no fan walks)."""
    new_id = np.asarray(new_id, np.int64)
    n = t.n_vertices
    old_of = np.empty(n, np.int64)
    old_of[new_id] = np.arange(n)
    # Edges: renamed, re-sorted; the face on the lo -> hi side stays in column 0.
    e = new_id[t.edges]
    swap = e[:, 0] > e[:, 1]
    e = np.sort(e, axis=1)
    order = np.argsort(e[:, 0] * np.int64(n) + e[:, 1], kind="stable")
    edges = e[order]
    ef = np.where(swap[:, None], t.edge_faces[:, ::-1], t.edge_faces)[order]
    # One-rings: row r is the old row old_of[r], its entries renamed.
    ring_ptr, src = permute_rows(t.ring_ptr, old_of)
    ren = lambda a: np.where(a >= 0, new_id[np.maximum(a, 0)], -1)   # noqa: E731
    is_boundary, referenced = t.is_boundary[old_of], t.referenced[old_of]
    interior = np.flatnonzero(referenced & ~is_boundary)
    boundary = np.flatnonzero(is_boundary)
    slot = np.full(n, -1, np.int64)
    slot[interior] = np.arange(interior.size)
    slot[boundary] = np.arange(boundary.size)
    # Components numbered by their smallest vertex, as build() numbers them.
    comp = t.components[old_of]
    ref = comp >= 0
    first = np.full(t.n_components, n, np.int64)
    np.minimum.at(first, comp[ref], np.flatnonzero(ref))
    rank = np.empty(t.n_components, np.int64)
    rank[np.argsort(first)] = np.arange(t.n_components)
    comp = np.where(ref, rank[np.maximum(comp, 0)], -1)
    loops = [new_id[l] for l in t.boundary_loops]
    loops.sort(key=lambda l: (-len(l), int(l.min())))
    ring_idx = new_id[t.ring_idx[src]]
    return Topology(
        n_vertices=n, faces=new_id[t.faces], edges=edges, edge_faces=ef, boundary_loops=tuple(loops),
        ring_ptr=ring_ptr, ring_idx=ring_idx, ring_prev=ren(t.ring_prev[src]),
        ring_next=ren(t.ring_next[src]), ring_row=np.repeat(np.arange(n), np.diff(ring_ptr)),
        ring_wedge=t.ring_wedge[src], is_boundary=is_boundary, referenced=referenced,
        interior=interior, boundary=boundary, slot=slot, components=comp,
        n_components=t.n_components, euler=t.euler, genus=t.genus,
        dividing_edges=_dividing_edges(ring_ptr, ring_idx, boundary, is_boundary))


def _boundary_loops_from(ba: np.ndarray, bb: np.ndarray, n: int) -> tuple:
    """Order boundary half-edges ``ba -> bb`` into loops, longest first."""
    if ba.size == 0:
        return ()
    order = np.argsort(ba, kind="stable")
    sa = ba[order]
    # On a manifold mesh each boundary vertex starts exactly one boundary half-edge.
    pos = np.searchsorted(sa, bb)
    succ = order[np.minimum(pos, sa.size - 1)]
    succ = np.where(sa[np.minimum(pos, sa.size - 1)] == bb, succ, -1)
    root, p, _ = _rank_linked_lists(succ, ba.size)
    # Group by root, order by position.
    key = np.lexsort((p, root))
    roots_sorted = root[key]
    splits = np.flatnonzero(np.diff(roots_sorted)) + 1
    loops = np.split(ba[key], splits)
    loops.sort(key=lambda l: (-len(l), int(l.min())))
    return tuple(np.ascontiguousarray(l) for l in loops)


def boundary_loops(faces, n_vertices: int | None = None) -> tuple:
    """The boundary loops of a manifold mesh, each ordered along the faces' orientation.

    **Arguments:** ``faces: (m, 3) int``.  **Returns:** a tuple of ``(k,) int64``
    vertex-index arrays, longest loop first; empty for a closed mesh.

    Example::

        boundary_loops(np.array([[0, 1, 2]]))  # (array([0, 1, 2]),)
    """
    return build(faces, n_vertices, where="boundary_loops").boundary_loops
