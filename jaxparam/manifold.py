"""Closed meshes of any genus (survey §9): a base domain by decimation, surface triangles,
a global parameterization over the base domain, and semi-regular remeshing.

The method of Floater, Hormann and Reimers (the survey's ref. [11]), in four steps:

1. **Base domain** ``T^0`` (:func:`decimate`): quadric-error half-edge collapses of the mesh
   until ``base_faces`` triangles remain.  A collapse keeps the surviving vertex where it
   is, so ``V^0 ⊂ V``; the link condition keeps the genus, and collapses that would turn a
   face over are refused.
2. **Surface edges**: every edge ``[v, w]`` of ``T^0`` becomes a shortest path along the
   mesh's edges between ``v`` and ``w`` (shortest first).  Paths share no vertex but their
   ends, and each leaves and enters its base vertices in the sector between its
   neighbours in ``T^0``'s cyclic order, so the paths cut the surface into one disk, a
   *surface triangle*, per base triangle.  The mesh is refined once (1-to-4 splits, which
   do not move the surface) when it has too few vertices for the paths.
3. **Parameterization**: each base triangle is the reference triangle
   ``(0, 0), (1, 0), (1/2, sqrt(3)/2)``; path vertices are placed on its sides by chord
   length, and the vertices inside each surface triangle by one convex-combination solve
   (mean value weights by default) for all surface triangles at once.
4. **Remesh** (:meth:`ManifoldParameterization.remesh`): the ``j``-fold dyadic refinement
   of ``T^0``, each vertex mapped to the surface through its base triangle's chart, as
   eq. (11); the result has subdivision connectivity and feeds :mod:`jaxparam.wavelets`.

Steps 1 and 2 are sequential by nature (one collapse, one path at a time) and run as
Python loops over collapses and paths; everything per vertex or per face is vectorized.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from . import sparse
from . import topology as topo
from . import weights as wts
from .errors import MeshError, SolverError, TopologyError, first_few
from .mesh import TriMesh
from .remesh import CHILDREN, Hierarchy, dyadic_refine
from .triangles import barycentric, locate, signed_area2

#: The reference triangle every base triangle's chart uses.
REFERENCE = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3.0) / 2.0]])


# ------------------------------------------------------------------------------------------
# 1. Base domain by decimation
# ------------------------------------------------------------------------------------------

def _plane_quadrics(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)``: the sum over each vertex's faces of the area-weighted plane quadrics."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    area2 = np.linalg.norm(n, axis=1)
    unit = n / np.maximum(area2, 1e-300)[:, None]
    p = np.concatenate([unit, -np.sum(unit * V[F[:, 0]], 1, keepdims=True)], axis=1)
    K = 0.5 * area2[:, None, None] * p[:, :, None] * p[:, None, :]
    Q = np.zeros((V.shape[0], 4, 4))
    for c in range(3):
        np.add.at(Q, F[:, c], K)
    return Q


def decimate(mesh: TriMesh, base_faces: int):
    """Quadric-error half-edge collapses down to ``base_faces`` faces (step 1).

    **Arguments:** ``mesh`` a closed manifold mesh; ``base_faces`` the faces wanted (even;
    at least the fewest a surface of the mesh's genus needs).

    **Returns:** ``(kept (n0,) int, faces (base_faces, 3) int)``: the surviving vertices
    (indices into ``mesh``'s vertices, increasing) and the base faces over them (indices
    into ``kept``), oriented as the mesh.
    """
    t = mesh.topology
    V = np.asarray(mesh.vertices, np.float64)
    F = np.array(t.faces, np.int64)
    n, m = V.shape[0], F.shape[0]
    scale = float(np.linalg.norm(np.ptp(V, axis=0)))
    Q = _plane_quadrics(V, F)
    vf = [set() for _ in range(n)]
    for f, (a, b, c) in enumerate(F.tolist()):
        vf[a].add(f)
        vf[b].add(f)
        vf[c].add(f)
    dead = np.zeros(n, bool)
    version = np.zeros(n, np.int64)
    heap: list = []
    Vh = np.concatenate([V, np.ones((n, 1))], axis=1)

    def nbrs(v):
        out = set()
        for f in vf[v]:
            out.update(F[f].tolist())
        out.discard(v)
        return out

    def cost(u, w):
        x = Vh[w]
        return max(0.0, float(x @ (Q[u] + Q[w]) @ x))      # >= 0 but for rounding

    def push(u):
        version[u] += 1
        for w in nbrs(u):
            heapq.heappush(heap, (cost(u, w), int(version[u]), u, w))

    def valid(u, w) -> bool:
        Nu, Nw = nbrs(u), nbrs(w)
        common = Nu & Nw
        shared = vf[u] & vf[w]
        if len(common) != 2 or len(shared) != 2:            # link condition (closed manifold)
            return False
        if len(Nu | Nw) - 2 < 3 or any(len(nbrs(x)) - 1 < 3 for x in common):
            return False
        for f in vf[u] - shared:
            a, b, c = F[f]
            P = V[[a, b, c]]
            old = np.cross(P[1] - P[0], P[2] - P[0])
            P[[a, b, c].index(u)] = V[w]
            new = np.cross(P[1] - P[0], P[2] - P[0])
            ln = np.linalg.norm(new)
            if ln <= 1e-12 * scale * scale or old @ new <= 0.2 * np.linalg.norm(old) * ln:
                return False
            if strict:
                # No base triangle with an angle over 140 degrees: a base vertex almost on
                # the segment between two others leaves no room for the surface edges.
                e = P[[1, 2, 0]] - P
                cosines = -np.sum(e * e[[2, 0, 1]], 1) / (np.linalg.norm(e, axis=1)
                                                          * np.linalg.norm(e[[2, 0, 1]], axis=1))
                if cosines.min() < np.cos(np.radians(140)):
                    return False
        return True

    for v in range(n):
        push(v)
    faces_left = m
    strict = True
    while faces_left > base_faces:
        if not heap:
            if not strict:
                break
            strict = False                 # stuck on the shape rule: finish without it
            for v in np.flatnonzero(~dead):
                push(int(v))
            continue
        c, ver, u, w = heapq.heappop(heap)
        if dead[u] or dead[w] or ver != version[u] or not (vf[u] & vf[w]):
            continue
        c2 = cost(u, w)
        if c2 > c + 1e-9 * abs(c) + 1e-300:                # stale: its quadrics grew
            heapq.heappush(heap, (c2, ver, u, w))
            continue
        if not valid(u, w):
            continue
        shared = vf[u] & vf[w]
        for f in shared:
            for x in F[f].tolist():
                vf[x].discard(f)
        for f in list(vf[u]):
            F[f][F[f] == u] = w
            vf[w].add(f)
        vf[u].clear()
        dead[u] = True
        Q[w] += Q[u]
        faces_left -= 2
        touched = nbrs(w) | {w}
        for x in touched:
            push(x)
    if faces_left > base_faces:
        raise SolverError(f"manifold_map: decimation stopped at {faces_left} faces (no collapse "
                          f"keeps the topology and the faces' orientation); ask for more than "
                          f"{faces_left} base faces.", stage="decimate")
    alive = sorted(set().union(*[vf[v] for v in range(n) if not dead[v]]))
    Fb = F[alive]
    kept = np.flatnonzero(~dead)
    return kept, np.searchsorted(kept, Fb)


# ------------------------------------------------------------------------------------------
# 2. Surface edges and surface triangles
# ------------------------------------------------------------------------------------------

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


def _room_for_paths(mesh: TriMesh, base_ids: np.ndarray, base_topo: topo.Topology,
                    base_faces: int) -> TriMesh:
    """The mesh refined, without moving its surface (Fig. 24), until the paths have room:
    1-to-3 splits of the faces around each base vertex until it has at least ``2 k + 2``
    neighbours for its ``k`` base edges (each split doubles its degree), then one 1-to-4
    split of every face (so a base vertex's neighbours are edge midpoints, none a dead end),
    and another while there are fewer than 40 vertices per base face."""
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
        V = np.concatenate([V, V[F[split]].mean(1)])
        F = np.concatenate([F[~split], np.stack([a, b, x], 1), np.stack([b, c, x], 1),
                            np.stack([c, a, x], 1)])
        W = TriMesh(V, F, validate=False, name=mesh.name)
    W = _split_all(W)
    while W.n_vertices < 40 * base_faces:
        W = _split_all(W)
    return W


def _split_all(W: TriMesh) -> TriMesh:
    """Every face split 1-to-4 at its edge midpoints: the same surface, new vertices last."""
    F, parents, _ = dyadic_refine(W.faces, W.n_vertices)
    V = np.asarray(W.vertices)
    return TriMesh(np.concatenate([V, V[parents].mean(1)]), F, validate=False, name=W.name)


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


def _trace_paths(W: TriMesh, base_ids: np.ndarray, base_topo: topo.Topology):
    """Shortest vertex-disjoint edge paths for the base domain's edges, each in its sectors.
    **Returns:** ``paths``: a list, for each base edge ``(a, b)`` of ``base_topo.edges``
    (base-vertex indices), of the mesh vertices from ``base_ids[a]`` to ``base_ids[b]``."""
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


def _surface_triangles(W: TriMesh, base_ids, base_faces, base_topo, paths):
    """Cut the mesh along the paths. **Returns:** ``region (m,) int``: the base face of every
    mesh face; raises :class:`SolverError` when the pieces do not match the base domain."""
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


# ------------------------------------------------------------------------------------------
# 3. The parameterization
# ------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ManifoldParameterization:
    """A parameterization of a closed mesh over its base domain ``T^0`` (survey §9).

    - ``mesh``: the mesh parameterized (the input, or the input refined once, whose first
      vertices are the input's);
    - ``base_vertices (n0,)``: the mesh vertices that are ``T^0``'s vertices;
    - ``base_faces (m0, 3)``: ``T^0``'s faces over ``base_vertices``;
    - ``region (m,)``: the base face of each mesh face (its surface triangle);
    - ``face_uv (m, 3, 2)``: each mesh face's corners in its base face's chart (the
      reference triangle :data:`REFERENCE`);
    - ``vertex_face (n,)``, ``vertex_bary (n, 3)``: a base face of each vertex and its
      barycentric coordinates there (``phi^{-1}`` of the vertex).
    """

    mesh: TriMesh
    base_vertices: np.ndarray
    base_faces: np.ndarray
    region: np.ndarray
    face_uv: np.ndarray
    vertex_face: np.ndarray
    vertex_bary: np.ndarray

    def remesh(self, levels: int = 3) -> TriMesh:
        """The ``levels``-fold dyadic refinement of ``T^0`` mapped onto the surface (§9,
        Fig. 26 (c)): a closed :class:`TriMesh` with subdivision connectivity whose vertices
        lie on the mesh; ``.hierarchy`` for :mod:`jaxparam.wavelets`, ``.base_faces``."""
        if not (isinstance(levels, (int, np.integer)) and 0 <= levels <= 8):
            raise MeshError(f"manifold remesh: levels must be an integer in [0, 8], got {levels!r}.")
        F = np.asarray(self.base_faces, np.int64)
        n = int(F.max()) + 1
        bary = np.broadcast_to(np.eye(3), (F.shape[0], 3, 3)).copy()   # corner -> bary in base face
        counts, parents, faces = [n], [], [F]
        for _ in range(levels):
            F, par, _ = dyadic_refine(F, counts[-1])
            mid = (bary[:, [1, 2, 0]] + bary[:, [2, 0, 1]]) / 2      # w1, w2, w3
            bary = np.concatenate([bary, mid], axis=1)[:, CHILDREN].reshape(-1, 3, 3)
            counts.append(counts[-1] + par.shape[0])
            parents.append(par)
            faces.append(F)
        H = Hierarchy(tuple(counts), tuple(parents), tuple(faces))
        base_of_face = np.arange(F.shape[0]) // (4 ** levels)
        # One corner per vertex gives its base face and barycentric coordinates.
        corner = np.full(counts[-1], -1, np.int64)
        corner[F.ravel()[::-1]] = np.arange(F.size)[::-1]
        r = base_of_face[corner // 3]
        q = bary.reshape(-1, 3)[corner] @ REFERENCE
        X = self.lift(r, q)
        out = TriMesh(X, F, validate=False, name="manifold_remesh")
        out.hierarchy = H
        out.base_faces = H.faces[0]
        return out

    def lift(self, region: np.ndarray, uv: np.ndarray):
        """Surface points ``(k, 3)`` of chart points ``uv (k, 2)`` in base faces ``region (k,)``.

        Every chart is the reference triangle; the charts are laid out side by side in one
        plane so a single point location serves all of them."""
        m0 = self.base_faces.shape[0]
        cols = int(np.ceil(np.sqrt(m0)))
        offset = 2.0 * np.stack([np.arange(m0) % cols, np.arange(m0) // cols], 1)
        corners = (self.face_uv + offset[self.region][:, None, :]).reshape(-1, 2)
        tri = np.arange(corners.shape[0]).reshape(-1, 3)
        face, b = locate(corners, tri, np.asarray(uv) + offset[np.asarray(region)])
        idx = jnp.asarray(self.mesh.faces[face])
        return jnp.einsum("kc,kcd->kd", jnp.asarray(b), jnp.asarray(self.mesh.vertices)[idx])


def manifold_map(mesh: TriMesh, base_faces: int = 100, *, weights: str = "mean_value"):
    """Parameterize a closed mesh of any genus over a decimated base domain (survey §9).

    **Arguments:** ``mesh`` closed, one component, orientable; ``base_faces`` the size of the
    base domain ``T^0`` (even; at least ``4`` for genus 0 and about ``14 g + 10`` for genus
    ``g``); ``weights`` the convex-combination weights inside the surface triangles.

    **Returns:** ``(base, param)``: ``base`` a :class:`TriMesh` ``T^0`` whose vertices are
    mesh vertices (``param.base_vertices``), and a :class:`ManifoldParameterization`
    (``param.remesh(levels)`` remeshes with subdivision connectivity).

    Example::

        base, param = jp.manifold_map(mesh, base_faces=100)
        semi = param.remesh(3)
    """
    t = mesh.topology
    if not t.is_closed:
        raise TopologyError(f"manifold_map: the mesh has {len(t.boundary_loops)} boundary loops; "
                            "it needs a closed surface (disks: jp.convex_map and jp.remesh).")
    if t.n_components != 1:
        raise TopologyError(f"manifold_map: the mesh has {t.n_components} connected components; "
                            "parameterize each on its own.")
    least = 4 if t.genus == 0 else 14 * t.genus + 10
    if not (isinstance(base_faces, (int, np.integer)) and base_faces % 2 == 0
            and least <= base_faces < t.n_faces):
        raise MeshError(f"manifold_map: base_faces must be an even integer in [{least}, "
                        f"{t.n_faces}) for this genus-{t.genus} mesh of {t.n_faces} faces, got "
                        f"{base_faces!r}.")
    if weights not in wts.KINDS:
        raise MeshError(f"manifold_map: unknown weights {weights!r}; use one of {wts.KINDS}.")
    kept, F0 = decimate(mesh, int(base_faces))
    base_topo = topo.build(F0, kept.size, where="manifold_map")
    if base_topo.genus != t.genus:                      # the link condition should prevent it
        raise SolverError(f"manifold_map: the base domain has genus {base_topo.genus}, the mesh "
                          f"{t.genus}.", stage="decimate")
    W = _room_for_paths(mesh, kept, base_topo, int(base_faces))
    # A path can find its corridor walled off by earlier ones where the surface is narrow
    # in vertices: refine everywhere (4x the vertices, the surface unchanged) and retrace.
    for attempt in range(3):
        try:
            paths = _trace_paths(W, kept, base_topo)
            region = _surface_triangles(W, kept, F0, base_topo, paths)
            face_uv, vface, vbary = _charts(W, kept, F0, base_topo, paths, region, weights)
            break
        except SolverError:
            if attempt == 2 or W.n_vertices > 100_000:     # bounded work when it fails
                raise
            W = _split_all(W)
    base = TriMesh(np.asarray(mesh.vertices)[kept], F0, base_topo, validate=False, name="base_domain")
    return base, ManifoldParameterization(W, kept, F0, region, face_uv, vface, vbary)


def _charts(W, base_ids, F0, base_topo, paths, region, weights):
    """Chart coordinates of every mesh face's corners (step 3): path vertices by chord length
    on the reference triangle's sides, the rest by one convex-combination solve."""
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

    # Free vertices: region of one of their faces; weights on the whole mesh's one-rings.
    vertex_face = np.empty(n, np.int64)
    vertex_face[t.faces.ravel()] = np.repeat(np.arange(t.n_faces), 3)
    free_region = region[vertex_face]
    w, _ = wts.entry_weights(W.vertices, t, weights)
    w = np.asarray(w)
    row, col = t.ring_row, t.ring_idx
    lam = w / np.bincount(row, weights=w, minlength=n)[row]
    free = np.flatnonzero(~fixed)
    uv = np.zeros((n, 2))
    if free.size:
        slot = np.full(n, -1, np.int64)
        slot[free] = np.arange(free.size)
        inner = ~fixed[row] & ~fixed[col]
        to_fixed = ~fixed[row] & fixed[col]
        A = sp.csr_matrix((np.concatenate([np.ones(free.size), -lam[inner]]),
                           (np.concatenate([np.arange(free.size), slot[row[inner]]]),
                            np.concatenate([np.arange(free.size), slot[col[inner]]]))),
                          shape=(free.size, free.size))
        A.sum_duplicates()
        A.sort_indices()
        rhs = np.zeros((free.size, 2))
        np.add.at(rhs, slot[row[to_fixed]],
                  lam[to_fixed, None] * chart(free_region[row[to_fixed]], col[to_fixed]))
        pattern = sparse.Pattern(A.indptr.astype(np.int64), A.indices.astype(np.int64), free.size)
        uv[free] = np.asarray(sparse.factorize(pattern, A.data, symmetric=False).solve(rhs))
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
