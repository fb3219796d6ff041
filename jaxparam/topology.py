"""Combinatorics of a triangle mesh, computed once from the (concrete) face array.

Everything here is numpy and vectorized: no Python loop runs over vertices or
faces.  The central tool is :func:`_rank_linked_lists`, which orders the
successor lists that a manifold mesh defines (the wedges around a vertex, the
edges of a boundary loop) by pointer jumping in ``O(len * log(max length))``.

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


def _halfedge_lookup(a: np.ndarray, b: np.ndarray, n: int):
    """Sorted keys for directed edges ``a -> b``; returns (keys_sorted, order)."""
    keys = a * np.int64(n) + b
    order = np.argsort(keys, kind="stable")
    return keys[order], order


def _find(keys_sorted, order, query):
    """Index of each query key in the original arrays, or -1."""
    pos = np.searchsorted(keys_sorted, query)
    pos_c = np.minimum(pos, keys_sorted.size - 1)
    found = keys_sorted[pos_c] == query
    return np.where(found, order[pos_c], -1)


def _raise_edge_error(a, b, hf, n, keys_sorted, korder, dup, where):
    """Explain duplicated directed half-edges: a non-manifold edge or inconsistent orientation."""
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    uniq, counts = np.unique(lo * np.int64(n) + hi, return_counts=True)
    over = np.flatnonzero(counts > 2)
    if over.size:
        e = [(int(k // n), int(k % n)) for k in uniq[over]]
        raise NonManifoldError(
            f"{where}: edges {first_few(e)} are shared by more than two faces (edge {e[0]} by "
            f"{int(counts[over[0]])} faces); the mesh is non-manifold: split it into manifold "
            "pieces (e.g. trimesh's split) or remove the extra faces.")
    e = [(int(k // n), int(k % n)) for k in keys_sorted[dup]]
    raise NonManifoldError(
        f"{where}: edges {first_few(e)} are traversed in the same direction by two faces "
        f"(edge {e[0]} by faces {int(hf[korder[dup[0]]])} and {int(hf[korder[dup[0] + 1]])}); the "
        "faces' orientation is inconsistent (or there are duplicate faces): orient the faces "
        "consistently (e.g. trimesh.repair.fix_winding) and remove duplicates.")


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
    hf = np.repeat(np.arange(m), 3)

    # One sort of the directed half-edges serves twins, duplicates and wedge successors.
    keys_sorted, korder = _halfedge_lookup(a, b, n)
    dup = np.flatnonzero(keys_sorted[1:] == keys_sorted[:-1])
    if dup.size:
        _raise_edge_error(a, b, hf, n, keys_sorted, korder, dup, where)
    twin = _find(keys_sorted, korder, b * np.int64(n) + a)
    is_bd_he = twin < 0

    # Undirected edges: each interior edge once (from its a < b side), each boundary half-edge.
    own = np.flatnonzero((a < b) | is_bd_he)
    lo, hi = np.minimum(a[own], b[own]), np.maximum(a[own], b[own])
    eorder = np.argsort(lo * np.int64(n) + hi, kind="stable")
    own = own[eorder]
    edges = np.stack([lo[eorder], hi[eorder]], axis=1)
    ne = edges.shape[0]
    edge_faces = np.full((ne, 2), -1, np.int64)
    # Side 0: the face where the edge runs lo -> hi; side 1: hi -> lo.
    fwd = a[own] < b[own]
    edge_faces[:, 0] = np.where(fwd, hf[own], np.where(twin[own] >= 0, hf[np.maximum(twin[own], 0)], -1))
    edge_faces[:, 1] = np.where(fwd, np.where(twin[own] >= 0, hf[np.maximum(twin[own], 0)], -1), hf[own])

    # Wedges around each vertex: wedge w (at a[w], from b[w] to c[w]) is followed by the wedge
    # that starts with the half-edge a[w] -> c[w], the twin of the face's half-edge c[w] -> a[w].
    prev_he = (np.arange(a.size) // 3) * 3 + (np.arange(a.size) + 2) % 3
    succ = twin[prev_he]
    root, pos, is_cycle = _rank_linked_lists(succ, int(np.bincount(a).max()))

    referenced = np.zeros(n, bool)
    referenced[a] = True
    # Fans per vertex: one head per fan. A manifold vertex has exactly one.
    is_head = root == np.arange(a.size)
    fans = np.bincount(a[is_head], minlength=n)
    bow = np.flatnonzero(fans > 1)
    if bow.size:
        raise NonManifoldError(
            f"{where}: vertices {first_few(bow)} are non-manifold (vertex {int(bow[0])} joins "
            f"{int(fans[bow[0]])} separate fans of faces, a 'bowtie'); split such vertices "
            "into one copy per fan.")
    # A vertex is on the boundary when its fan is a path (not a cycle).
    is_boundary = np.zeros(n, bool)
    is_boundary[a[~is_cycle]] = True

    # One-ring CSR: interior vertex: neighbours b of its wedges in fan order;
    # boundary vertex: the same plus c of the last wedge.
    wedge_count = np.bincount(a, minlength=n)
    deg = wedge_count + is_boundary.astype(np.int64)
    ring_ptr = np.zeros(n + 1, np.int64)
    np.cumsum(deg, out=ring_ptr[1:])
    slot_w = ring_ptr[a] + pos
    ring_idx = np.empty(ring_ptr[-1], np.int64)
    ring_idx[slot_w] = b
    last = ~is_cycle & (succ < 0)
    ring_idx[slot_w[last] + 1] = c[last]
    ring_row = np.repeat(np.arange(n), deg)
    # prev/next within each ring (cyclic for interior vertices).
    k = np.arange(ring_idx.size)
    start = ring_ptr[ring_row]
    end = ring_ptr[ring_row + 1]
    nxt = k + 1
    prv = k - 1
    bd_row = is_boundary[ring_row]
    nxt = np.where(nxt >= end, np.where(bd_row, -1, start), nxt)
    prv = np.where(prv < start, np.where(bd_row, -1, end - 1), prv)
    ring_next = np.where(nxt >= 0, ring_idx[np.maximum(nxt, 0)], -1)
    ring_prev = np.where(prv >= 0, ring_idx[np.maximum(prv, 0)], -1)

    loops = _boundary_loops_from(a[is_bd_he], b[is_bd_he], n)

    # Components over the vertex graph of the faces.
    g = sp.coo_matrix((np.ones(a.size, np.int8), (a, b)), shape=(n, n)).tocsr()
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
    both = is_boundary[edges[:, 0]] & is_boundary[edges[:, 1]] & (edge_faces.min(axis=1) >= 0)
    dividing = edges[both]

    return Topology(
        n_vertices=n, faces=F, edges=edges, edge_faces=edge_faces, boundary_loops=loops,
        ring_ptr=ring_ptr, ring_idx=ring_idx, ring_prev=ring_prev, ring_next=ring_next,
        ring_row=ring_row, is_boundary=is_boundary, referenced=referenced, interior=interior,
        boundary=boundary, slot=slot, components=comp, n_components=n_comp, euler=int(euler),
        genus=int(genus), dividing_edges=dividing)


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
