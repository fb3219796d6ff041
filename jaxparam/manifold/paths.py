"""Step 2 of :mod:`jaxparam.manifold`: room for the surface edges, and the surface edges themselves.

Every edge ``[v, w]`` of the base domain ``T^0`` becomes a path along the mesh's edges from
``v`` to ``w``; the paths share no vertex but their ends and leave and enter each base vertex
in the sector between its neighbours in ``T^0``'s cyclic order, so they cut the surface into
one disk per base triangle (:mod:`jaxparam.manifold.charts` checks that).

- :func:`room_for_paths` refines the mesh without moving its surface: 1-to-3 splits around
  base vertices with too few neighbours, then 1-to-4 splits of every face
  (:func:`refine_all`) until there are 40 vertices per base face;
- :func:`trace_paths` traces the base edges in Praun et al.'s order (a shortest spanning
  tree, then the ``2g`` edges that complete a cut graph, then the rest, each group shortest
  first), each a shortest path that keeps out of traced paths, of the base vertices'
  one-rings outside its own sectors and of other base vertices' *zones*; edges next to
  traced paths cost four times their length, and a path that would cut an untraced edge's
  sectors apart is retraced one vertex away from the traced paths.

Sequential by nature (one path at a time): Python loops over paths, numpy and scipy's
Dijkstra inside.
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from .. import topology as topo
from ..errors import SolverError
from ..mesh import TriMesh
from ..subdivision import dyadic_refine

__all__ = ["room_for_paths", "refine_all", "apply_steps", "trace_paths"]


def _ring_position(t: topo.Topology, v: int) -> dict:
    ring = t.ring_idx[t.ring_ptr[v]:t.ring_ptr[v + 1]]
    return {int(x): i for i, x in enumerate(ring)}


def _sector(order: list, traced: dict, i: int, pos: dict, k_ring: int):
    """Ring positions (around one base vertex) a new path to the ``i``-th base neighbour
    may use: strictly between the paths to the nearest traced base neighbours before and
    after it in the base domain's cyclic ``order``, leaving at least one free position for
    every untraced base neighbour between them on either side.  ``traced[j]`` is the ring
    position used by the path to base neighbour ``order[j]``."""
    k = len(order)
    back = next((j for j in range(1, k) if (i - j) % k in traced), None)
    if back is None:                                   # nothing traced here yet
        return set(range(k_ring))
    fwd = next(j for j in range(1, k) if (i + j) % k in traced)
    before, after = traced[(i - back) % k], traced[(i + fwd) % k]
    span = (after - before - 1) % k_ring if before != after else k_ring - 1
    # Untraced neighbours between `before` and this one, and between this one and `after`.
    c1, c2 = back - 1, fwd - 1
    # Leave in the middle of the room this path's share of the sector: paths that start far
    # apart leave corridors for the ones traced later.
    lo, hi = c1, span - c2                      # feasible offsets [lo, hi)
    if hi - lo > 2:
        share = (span + 1) / (c1 + c2 + 2)      # positions per path of this sector
        mid = (c1 + 1) * share - 1
        lo, hi = max(lo, int(np.floor(mid - share / 4))), min(hi, int(np.ceil(mid + share / 4)) + 1)
    return {(before + 1 + d) % k_ring for d in range(lo, hi)}


def room_for_paths(mesh: TriMesh, base_ids: np.ndarray, base_topo: topo.Topology,
                   base_faces: int, steps: list | None = None) -> TriMesh:
    """``mesh`` refined, without moving its surface (Fig. 24), until the paths of the base
    domain ``base_topo`` (over the mesh vertices ``base_ids``, ``base_faces`` faces) have room:
    1-to-3 splits of the faces around each base vertex until it has at least ``2 k + 2``
    neighbours for its ``k`` base edges (each split doubles its degree), then one 1-to-4
    split of every face (so a base vertex's neighbours are edge midpoints, none a dead end),
    and another while there are fewer than 40 vertices per base face.

    ``steps``: a list to which each refinement is appended as its new vertices' parents, an
    ``(k, p) int`` array (each new vertex the mean of its ``p`` parents), so
    :func:`apply_steps` recomputes the refined positions from the input's (a fixed linear
    map: differentiable)."""
    W = mesh
    need = 2 * np.diff(base_topo.ring_ptr) + 2
    for _ in range(3):
        t = W.topology
        short = base_ids[t.degree[base_ids] < need]
        if short.size == 0:
            break
        V, F = np.asarray(W.vertices), t.faces
        split = np.isin(F, short).any(axis=1)
        x = V.shape[0] + np.arange(int(split.sum()))
        a, b, c = F[split].T
        if steps is not None:
            steps.append(F[split].copy())
        V = np.concatenate([V, V[F[split]].mean(1)])
        F = np.concatenate([F[~split], np.stack([a, b, x], 1), np.stack([b, c, x], 1),
                            np.stack([c, a, x], 1)])
        W = TriMesh(V, F, validate=False, name=mesh.name)
    W = refine_all(W, steps)
    while W.n_vertices < 40 * base_faces:
        W = refine_all(W, steps)
    return W


def refine_all(W: TriMesh, steps: list | None = None) -> TriMesh:
    """Every face split 1-to-4 at its edge midpoints (as :func:`jaxparam.subdivision.midpoint_refine`):
    the same surface, new vertices last.  ``steps`` as in :func:`room_for_paths`."""
    V = np.asarray(W.vertices)
    F, parents, _ = dyadic_refine(W.faces, V.shape[0])
    if steps is not None:
        steps.append(np.asarray(parents, np.int64)[:, :2].copy())
    V = np.concatenate([V, 0.5 * (V[parents[:, 0]] + V[parents[:, 1]])])
    return TriMesh(V, F, validate=False, name=W.name)


def apply_steps(V, steps):
    """The refined positions ``(n_W, 3)`` from the input's ``V (n, 3)`` (numpy or JAX, traced
    or not): each step appends the means of its parents' positions, as
    :func:`room_for_paths` and :func:`refine_all` do."""
    xp = np if isinstance(V, np.ndarray) else jnp
    for parents in steps:
        if parents.shape[1] == 2:
            new = 0.5 * (V[parents[:, 0]] + V[parents[:, 1]])
        else:
            new = V[parents].mean(1)
        V = xp.concatenate([V, new])
    return V


def _tracing_order(base_topo: topo.Topology, length: np.ndarray) -> np.ndarray:
    """The order to trace the base edges in (Praun et al.'s rule): a shortest spanning tree
    first, so no base vertex is left an island a later path could pass on either side of;
    then the ``2g`` edges that complete a cut graph (the tree-cotree construction), so what
    is left of the surface is one disk; then the rest, shortest first.  Inside a disk a path
    between two sectors of its boundary splits it one way only, so on a genus-0 mesh the
    surface triangles always come out as the base domain's (given room for the paths)."""
    from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

    E = base_topo.edges
    n = base_topo.n_vertices
    G = sp.csr_matrix((length + 1e-12, (E[:, 0], E[:, 1])), shape=(n, n))
    T = minimum_spanning_tree(G).tocoo()
    tree_key = set(zip(np.minimum(T.row, T.col).tolist(), np.maximum(T.row, T.col).tolist()))
    in_tree = np.array([(int(a), int(b)) in tree_key for a, b in E])
    # Cotree: a spanning tree of the dual graph over the edges not in the tree.
    ef = base_topo.edge_faces
    m = base_topo.n_faces
    D = sp.csr_matrix((np.ones(int((~in_tree).sum())), (ef[~in_tree, 0], ef[~in_tree, 1])), shape=(m, m))
    order, pred = breadth_first_order(D, 0, directed=False, return_predecessors=True)
    dual_tree = set()
    for f in order[1:]:
        dual_tree.add((min(f, pred[f]), max(f, pred[f])))
    in_cotree = np.array([(min(a, b), max(a, b)) in dual_tree for a, b in ef.tolist()]) & ~in_tree
    handle = ~in_tree & ~in_cotree
    by_length = np.argsort(length, kind="stable")
    return np.concatenate([by_length[in_tree[by_length]], by_length[handle[by_length]],
                           by_length[in_cotree[by_length]]])


def _zones(t: topo.Topology, length: np.ndarray, base_ids: np.ndarray, in_ring: np.ndarray):
    """``(n,) int``: the base vertex whose zone each vertex is in, ``-1`` outside every zone.

    A zone is the part of a base vertex's geodesic Voronoi cell (along edges) within half
    the distance to the cell's border: only paths that end at that base vertex may enter it.
    Without zones a shortest path between two other base vertices wraps tightly round a
    base vertex's reserved one-ring and leaves no room for the paths still to leave it."""
    E = t.edges
    n = t.n_vertices
    G = sp.csr_matrix((length, (E[:, 0], E[:, 1])), shape=(n, n))
    dist, _, src = dijkstra(G, directed=False, indices=base_ids, min_only=True, return_predecessors=True)
    border = src[E[:, 0]] != src[E[:, 1]]
    radius = np.full(n, np.inf)
    np.minimum.at(radius, src[E[border, 0]], dist[E[border, 0]])
    np.minimum.at(radius, src[E[border, 1]], dist[E[border, 1]])
    zone = np.where(dist < 0.5 * radius[src], src, -1)
    for b in base_ids:
        zone[t.ring_idx[t.ring_ptr[b]:t.ring_ptr[b + 1]]] = b
    return zone


def trace_paths(W: TriMesh, base_ids: np.ndarray, base_topo: topo.Topology):
    """Shortest vertex-disjoint edge paths for the base domain's edges, each in its sectors.
    **Returns:** ``paths``: a list, for each base edge ``(a, b)`` of ``base_topo.edges``
    (base-vertex indices), of the mesh vertices from ``base_ids[a]`` to ``base_ids[b]``.
    Raises :class:`SolverError` (stage ``surface edges``) when earlier paths wall one off."""
    t = W.topology
    V = np.asarray(W.vertices)
    E = t.edges
    length = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    n = t.n_vertices
    blocked = np.zeros(n, bool)
    blocked[base_ids] = True
    ring_pos = {int(b): _ring_position(t, int(b)) for b in base_ids}
    in_ring = np.zeros(n, bool)
    for b in base_ids:
        in_ring[t.ring_idx[t.ring_ptr[b]:t.ring_ptr[b + 1]]] = True
    ring_of = {int(b): t.ring_idx[t.ring_ptr[b]:t.ring_ptr[b + 1]] for b in base_ids}
    zone = _zones(t, length, base_ids, in_ring)
    # Cyclic order of base neighbours at each base vertex, and the traced paths' ring slots.
    order = {a: list(base_topo.ring_idx[base_topo.ring_ptr[a]:base_topo.ring_ptr[a + 1]])
             for a in range(base_topo.n_vertices)}
    slots: dict = {a: {} for a in order}
    BE = base_topo.edges
    paths: list = [None] * len(BE)
    traced = np.zeros(len(BE), bool)
    halo_stop = zone >= 0                   # the halo rule does not apply inside zones

    def sector_vertices(x, i, block):
        vx = int(base_ids[x])
        pos = _sector(order[x], slots[x], i, ring_pos[vx], len(ring_of[vx]))
        return np.array(sorted(int(ring_of[vx][p]) for p in pos if not block[ring_of[vx][p]]), np.int64)

    def trace(e, avoid):
        a, b = (int(x) for x in BE[e])
        va, vb = int(base_ids[a]), int(base_ids[b])
        s_list = sector_vertices(a, order[a].index(b), blocked)
        e_list = sector_vertices(b, order[b].index(a), blocked)
        # Graph: free vertices (unblocked, outside every one-ring, outside other base
        # vertices' zones, and off ``avoid``), va joined only to its allowed start vertices
        # and vb only to its allowed end vertices (and to each other directly when both
        # allow it).  A path uses one ring vertex at each end and none elsewhere, so it never
        # eats another path's sector.
        free = ~blocked & ~in_ring & ((zone < 0) | (zone == va) | (zone == vb)) & ~avoid
        ok = free.copy()
        ok[s_list] = True
        ok[e_list] = True
        ring_a = np.zeros(n, bool)
        ring_a[s_list] = True
        ring_b = np.zeros(n, bool)
        ring_b[e_list] = True
        keep = (ok[E[:, 0]] & ok[E[:, 1]] & ~(ring_a[E[:, 0]] & ring_a[E[:, 1]])
                & ~(ring_b[E[:, 0]] & ring_b[E[:, 1]]))
        # Edges next to traced paths cost more, so paths keep apart and leave room.
        near = np.zeros(n, bool)
        near[E[blocked[E[:, 0]], 1]] = True
        near[E[blocked[E[:, 1]], 0]] = True
        near &= ~in_ring
        rows = [E[keep, 0], np.full(s_list.size, va), e_list]
        cols = [E[keep, 1], s_list, np.full(e_list.size, vb)]
        vals = [length[keep] * np.where(near[E[keep, 0]] | near[E[keep, 1]], 4.0, 1.0),
                np.linalg.norm(V[s_list] - V[va], axis=1), np.linalg.norm(V[e_list] - V[vb], axis=1)]
        if vb in s_list and va in e_list:
            rows.append(np.array([va]))
            cols.append(np.array([vb]))
            vals.append(np.array([np.linalg.norm(V[va] - V[vb])]))
        G = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
        dist, pred = dijkstra(G, directed=False, indices=va, return_predecessors=True)
        if not np.isfinite(dist[vb]):
            return None
        path = [vb]
        while path[-1] != va:
            path.append(int(pred[path[-1]]))
        return _shortcut(t, path[::-1])

    def separates(path) -> bool:
        """Whether blocking ``path`` would cut some untraced base edge's two sectors apart."""
        block = blocked.copy()
        block[path[1:-1]] = True
        free = ~block & ~in_ring
        keep = free[E[:, 0]] & free[E[:, 1]]
        _, label = connected_components(sp.csr_matrix((np.ones(int(keep.sum())), (E[keep, 0], E[keep, 1])),
                                                      shape=(n, n)), directed=False)
        ring_label = {}
        for x in range(base_topo.n_vertices):           # labels reachable from each ring vertex
            for r in ring_of[int(base_ids[x])]:
                nb = t.ring_idx[t.ring_ptr[r]:t.ring_ptr[r + 1]]
                ring_label[int(r)] = set(label[nb[free[nb]]].tolist())
        slots_after = {x: dict(v) for x, v in slots.items()}
        a, b = (int(x) for x in BE[e])
        slots_after[a][order[a].index(b)] = ring_pos[int(base_ids[a])][path[1]]
        slots_after[b][order[b].index(a)] = ring_pos[int(base_ids[b])][path[-2]]
        for f in np.flatnonzero(~traced):
            if f == e:
                continue
            x, y = (int(z) for z in BE[f])
            reach = []
            for u, w in ((x, y), (y, x)):
                vu = int(base_ids[u])
                pos = _sector(order[u], slots_after[u], order[u].index(w), ring_pos[vu], len(ring_of[vu]))
                labels = set()
                for p in pos:
                    r = int(ring_of[vu][p])
                    if not block[r]:
                        labels |= ring_label[r] | {("ring", r)}
                reach.append(labels)
            if not (reach[0] & reach[1]):
                return True
        return False

    for e in _tracing_order(base_topo, np.linalg.norm(V[base_ids[BE[:, 0]]] - V[base_ids[BE[:, 1]]], axis=1)):
        a, b = (int(x) for x in BE[e])
        va, vb = int(base_ids[a]), int(base_ids[b])
        path = trace(e, np.zeros(n, bool))
        if path is not None and separates(path):
            # Retrace keeping one vertex away from every traced path outside the zones.
            halo = np.zeros(n, bool)
            halo[E[blocked[E[:, 0]], 1]] = True
            halo[E[blocked[E[:, 1]], 0]] = True
            retry = trace(e, halo & ~halo_stop)
            if retry is not None and not separates(retry):
                path = retry
        if path is None:
            raise SolverError(f"manifold_map: no surface edge between base vertices {va} and {vb} "
                              "avoids the paths traced before it; try another base_faces count.",
                              stage="surface edges")
        paths[e] = np.array(path, np.int64)
        traced[e] = True
        blocked[path[1:-1]] = True
        slots[a][order[a].index(b)] = ring_pos[va][path[1]]
        slots[b][order[b].index(a)] = ring_pos[vb][path[-2]]
    return paths


def _shortcut(t: topo.Topology, path: list) -> list:
    """Drop the stretch between two vertices of ``path`` that an edge joins directly (the
    penalized path costs allow such detours; a face with three vertices on one path would
    be flat in its chart).  The first and last steps (the sectors) stay."""
    out = list(path)
    changed = True
    while changed and len(out) > 4:
        changed = False
        where = {v: i for i, v in enumerate(out)}
        for i in range(1, len(out) - 2):
            nb = t.ring_idx[t.ring_ptr[out[i]]:t.ring_ptr[out[i] + 1]]
            far = [where[x] for x in nb.tolist() if x in where and i + 1 < where[x] <= len(out) - 2]
            if far:
                out = out[:i + 1] + out[max(far):]
                changed = True
                break
    return out
