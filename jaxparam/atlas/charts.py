"""Cutting a surface into charts: topological disks whose normals stay within a cone.

All numpy (topology, computed once from concrete positions); the charts are a discrete
choice that no gradient goes through.

The route (chosen by measurement, see ``docs/design.md``, issue 18):

1. *Greedy cone growth.*  Charts are grown one after another from a seed face, in
   breadth-first rounds over the face adjacency; a face joins when its normal is within
   ``cone`` degrees of the chart's area-weighted mean normal.  The next seed is an
   unassigned face next to the charts grown so far, so the charts tile the surface
   front by front.
2. *Merging.*  Neighbouring charts are merged, smallest first, while the union stays a
   disk and within the cone (measured on the union's mean normal).
3. *Disks.*  Every chart is checked for disk topology (one face-connected piece, Euler
   characteristic 1, every chart-boundary vertex on exactly two chart-boundary edges);
   a chart that is not a disk is split in two along a breadth-first level set and the
   pieces are checked again.

Where the mesh is noisy, the cones test :func:`smoothed_normals` instead of the faces' own
(:func:`segment`'s ``normals="auto"``): where neighbouring vertices bend to opposite sides
along most edges, or where the smoothed normals' charts are at most half as many.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import MeshError, TopologyError
from ..host import vertex_normals
from ..triangles import face_angles

__all__ = ["face_adjacency", "face_normals", "grow_charts", "merge_charts", "make_disks",
           "disk_flags", "split_chart", "relabel", "segment", "chart_edges", "faces_are_disk",
           "face_csr", "face_neighbours", "smooth_charts", "smoothed_normals", "bumpy_share",
           "SMOOTH_ROUNDS", "NOISY_CHART_SHARE", "NOISY_SIGN_SHARE", "SLIT_ANGLE", "close_slits"]


def _unique(x: np.ndarray) -> np.ndarray:
    """The sorted distinct values of an int array ``x (k,)``.  A sort and a compare:
    numpy 2.4's ``np.unique`` without ``return_*`` takes a hash path that is ~70x slower
    on large-range int64 keys (0.22 s against 3 ms for 265k keys), and ``disk_flags`` runs
    in every split round."""
    s = np.sort(x, axis=None)
    if s.size < 2:
        return s
    keep = np.empty(s.size, bool)
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]


def face_adjacency(topology) -> np.ndarray:
    """``(2, k) int``: the pairs of faces sharing an interior edge (each pair once)."""
    ef = topology.edge_faces
    inner = (ef[:, 0] >= 0) & (ef[:, 1] >= 0)
    return ef[inner].T.copy()


def face_normals(V: np.ndarray, F: np.ndarray):
    """``(normals (m, 3) unit, areas (m,))`` of the 3D triangles."""
    c = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    a2 = np.linalg.norm(c, axis=1)
    return c / np.maximum(a2, 1e-300)[:, None], 0.5 * a2


def face_csr(topology) -> sp.csr_matrix:
    """The faces' adjacency (across interior edges) as a symmetric ``(m, m)`` CSR matrix."""
    return _csr(face_adjacency(topology), topology.n_faces)


def _csr(adj: np.ndarray, m: int) -> sp.csr_matrix:
    i, j = adj
    return sp.csr_matrix((np.ones(2 * i.size, np.int8), (np.r_[i, j], np.r_[j, i])), shape=(m, m))


def grow_charts(normals, areas, adj, *, cone: float) -> np.ndarray:
    """Greedy cone growth (step 1 of the module docstring).

    **Arguments:** ``normals (m, 3)``, ``areas (m,)``, ``adj (2, k)`` face pairs;
    ``cone``: the largest angle, in degrees, between a face normal and its chart's mean
    normal.  **Returns:** ``chart (m,) int``, labels ``0..c-1``.
    """
    m = normals.shape[0]
    A = _csr(adj, m)
    chart = np.full(m, -1, np.int64)
    cos_t = np.cos(np.radians(cone))
    frontier_pool = np.zeros(m, bool)
    c = 0
    start = 0
    while True:
        pool = np.flatnonzero(frontier_pool & (chart < 0))
        if pool.size:
            seed = int(pool[0])
        else:
            rest = np.flatnonzero(chart[start:] < 0)
            if rest.size == 0:
                break
            seed = start + int(rest[0])
            start = seed
        chart[seed] = c
        N = normals[seed] * areas[seed]
        new = np.array([seed])
        members = [new]
        while new.size:
            cand = A[new].indices
            cand = _unique(cand[chart[cand] < 0])
            if cand.size == 0:
                break
            n_hat = N / max(np.linalg.norm(N), 1e-300)
            ok = cand[normals[cand] @ n_hat >= cos_t]
            frontier_pool[cand] = True
            chart[ok] = c
            N = N + (normals[ok] * areas[ok, None]).sum(0)
            members.append(ok)
            new = ok
        c += 1
    return chart


def relabel(chart: np.ndarray) -> np.ndarray:
    """Labels renumbered ``0..c-1`` in order of each chart's first face."""
    _, first, inv = np.unique(chart, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first))
    return order[inv].astype(np.int64)


def chart_edges(topology, chart: np.ndarray) -> np.ndarray:
    """``(s,) int``: the edges (indices into ``topology.edges``) that are seams (their two
    faces lie in different charts) or mesh boundary."""
    ef = topology.edge_faces
    cut = (ef[:, 0] < 0) | (ef[:, 1] < 0)
    inner = ~cut
    cut[inner] = chart[ef[inner, 0]] != chart[ef[inner, 1]]
    return np.flatnonzero(cut)


def disk_flags(topology, chart: np.ndarray) -> np.ndarray:
    """``(c,) bool``: which charts are topological disks (one face-connected piece, Euler
    characteristic ``V - E + F = 1``, each vertex on 0 or 2 chart-boundary edges)."""
    c = int(chart.max()) + 1
    F = topology.faces
    m = F.shape[0]
    ef = topology.edge_faces
    E = topology.edges
    # faces per chart
    nF = np.bincount(chart, minlength=c)
    # vertices per chart: unique (chart, vertex) pairs
    cv = _unique(np.repeat(chart, 3) * np.int64(topology.n_vertices) + F.reshape(-1))
    nV = np.bincount(cv // topology.n_vertices, minlength=c)
    # edges per chart: an interior edge inside a chart counts once, a seam once per side
    e_side = np.r_[ef[:, 0], ef[:, 1]]
    e_id = np.r_[np.arange(len(E)), np.arange(len(E))]
    keep = e_side >= 0
    ce = _unique(chart[e_side[keep]] * np.int64(len(E)) + e_id[keep])
    nE = np.bincount(ce // len(E), minlength=c)
    euler_ok = (nV - nE + nF) == 1
    # chart-boundary edges per (chart, vertex)
    both = (ef[:, 0] >= 0) & (ef[:, 1] >= 0)
    same = np.zeros(len(E), bool)
    same[both] = chart[ef[both, 0]] == chart[ef[both, 1]]
    bsides = keep & ~np.r_[same, same]
    bc = chart[e_side[bsides]]
    be = e_id[bsides]
    key = np.r_[bc * np.int64(topology.n_vertices) + E[be, 0], bc * np.int64(topology.n_vertices) + E[be, 1]]
    uk, cnt = np.unique(key, return_counts=True)
    bad_keys = uk[cnt != 2]
    pinch = np.zeros(c, bool)
    pinch[_unique(bad_keys // topology.n_vertices)] = True
    has_boundary = np.zeros(c, bool)
    has_boundary[_unique(bc)] = True
    # connectivity: components of the within-chart face graph
    ia, ib = ef[both & same, 0], ef[both & same, 1]
    from scipy.sparse.csgraph import connected_components

    G = sp.csr_matrix((np.ones(ia.size, np.int8), (ia, ib)), shape=(m, m))
    _, comp = connected_components(G, directed=False)
    pieces = np.bincount(_unique(chart * np.int64(m) + comp) // m, minlength=c)
    return euler_ok & ~pinch & has_boundary & (pieces == 1)


def split_chart(faces_of: np.ndarray, adj_csr: sp.csr_matrix, *, merge_small: bool = False) -> list:
    """Split one chart (its face indices) in two along a breadth-first level set from a
    far face (two sweeps); each half is then split into its face-connected pieces.
    **Returns:** a list of face-index arrays."""
    from scipy.sparse.csgraph import connected_components, shortest_path

    sub = adj_csr[faces_of][:, faces_of]
    d0 = shortest_path(sub, unweighted=True, indices=0, directed=False)
    d0[~np.isfinite(d0)] = -1
    far = int(np.argmax(d0))
    d = shortest_path(sub, unweighted=True, indices=far, directed=False)
    d[~np.isfinite(d)] = np.inf
    finite = np.isfinite(d)
    half = np.zeros(faces_of.size, bool)
    if finite.all() and faces_of.size > 1:
        med = np.median(d)
        half = d <= med
        if half.all():
            half = d < med
        if not half.any() or half.all():
            half = np.arange(faces_of.size) < faces_of.size // 2
    else:
        half = finite
    # the pieces: connected components of each half; with merge_small, a piece under a
    # quarter of the chart joins the largest piece it touches (two charts, not a handful)
    label = np.full(faces_of.size, -1, np.int64)
    nxt = 0
    for part in (half, ~half):
        idx = np.flatnonzero(part)
        if idx.size == 0:
            continue
        n, lab = connected_components(sub[idx][:, idx], directed=False)
        label[idx] = lab + nxt
        nxt += n
    size = np.bincount(label, minlength=nxt)
    coo = sub.tocoo()
    for p in np.argsort(size):
        if (not merge_small or size[p] == 0 or size[p] >= 0.25 * faces_of.size
                or np.count_nonzero(size) <= 2):
            continue
        mine = label[coo.row] == p
        nb = _unique(label[coo.col[mine]])
        nb = nb[nb != p]
        if nb.size == 0:
            continue
        q = nb[np.argmax(size[nb])]
        label[label == p] = q
        size[q] += size[p]
        size[p] = 0
    return [faces_of[label == p] for p in np.flatnonzero(size)]


def make_disks(topology, chart: np.ndarray, adj_csr) -> np.ndarray:
    """Split every chart that is not a disk until all are (step 3).  The charts are
    checked at once (:func:`disk_flags`), the pieces of a split one by one
    (:func:`faces_are_disk`; a piece is face-connected): the charts that were disks are not
    checked again (cow x256, 1.4M faces: 18 whole-mesh checks before)."""
    chart = relabel(chart)
    ok = disk_flags(topology, chart)
    if ok.all():
        return chart
    F = topology.faces
    nxt = int(chart.max()) + 1
    todo = [np.flatnonzero(chart == c) for c in np.flatnonzero(~ok)]
    for _ in range(64):
        again = []
        for faces_of in todo:
            for k, piece in enumerate(split_chart(faces_of, adj_csr)):
                if k:
                    chart[piece] = nxt
                    nxt += 1
                if not faces_are_disk(F[piece]):
                    again.append(piece)
        todo = again
        if not todo:
            return relabel(chart)
    raise TopologyError(f"atlas: {len(todo)} charts did not become disks after 64 rounds of "
                        f"splits (first: the chart of face {int(todo[0][0])}); the mesh may have "
                        "degenerate faces: check it with `jaxparam info`.")


def faces_are_disk(F: np.ndarray) -> bool:
    """Whether the faces ``F (k, 3)`` (a face-connected set) form a topological disk: Euler
    characteristic 1 and every boundary vertex on exactly two boundary edges."""
    e = np.sort(np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], 1).reshape(-1, 2), axis=1)
    n = np.int64(F.max()) + 1
    ue, cnt = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)     # edge keys
    nV = _unique(F).size
    if nV - ue.size + F.shape[0] != 1:
        return False
    b = ue[cnt == 1]
    if b.size == 0:
        return False
    _, deg = np.unique(np.r_[b // n, b % n], return_counts=True)
    return bool(np.all(deg == 2))


def merge_charts(chart, normals, areas, adj, faces, *, cone: float,
                 max_area: float | None = None) -> np.ndarray:
    """Merge neighbouring charts, smallest first, into the neighbour of largest area whose
    union is a disk within the cone (step 2); with ``max_area``, only charts of at most
    that 3D area merge into a neighbour.  Loops over charts, not faces."""
    chart = relabel(chart)
    cos_t = np.cos(np.radians(cone))
    for _ in range(4):
        c = int(chart.max()) + 1
        order = np.argsort(chart, kind="stable")
        bounds = np.searchsorted(chart[order], np.arange(c + 1))
        members = {k: order[bounds[k]:bounds[k + 1]] for k in range(c)}
        N = np.zeros((c, 3))
        np.add.at(N, chart, normals * areas[:, None])
        area_c = np.bincount(chart, weights=areas, minlength=c)
        a, b = chart[adj[0]], chart[adj[1]]
        cross = a != b
        pair = np.unique(np.sort(np.stack([a[cross], b[cross]], 1), axis=1), axis=0)
        nbrs = {k: set() for k in range(c)}
        for p, q in pair:
            nbrs[int(p)].add(int(q))
            nbrs[int(q)].add(int(p))
        merged_any = False
        for s in np.argsort(area_c).tolist():
            if s not in members or (max_area is not None and area_c[s] > max_area):
                continue
            cands = sorted(nbrs[s], key=lambda q: -area_c[q])
            for q in cands:
                Nq = N[q] + N[s]
                n_hat = Nq / max(np.linalg.norm(Nq), 1e-300)
                fs = np.concatenate([members[s], members[q]])
                if np.min(normals[fs] @ n_hat) < cos_t:
                    continue
                if not faces_are_disk(faces[fs]):
                    continue
                members[q] = fs
                del members[s]
                N[q] = Nq
                area_c[q] += area_c[s]
                for r in nbrs[s]:
                    nbrs[r].discard(s)
                    if r != q:
                        nbrs[r].add(q)
                        nbrs[q].add(r)
                nbrs[q].discard(s)
                nbrs[q].discard(q)
                del nbrs[s]
                merged_any = True
                break
        for k, fs in members.items():
            chart[fs] = k
        chart = relabel(chart)
        if not merged_any:
            break
    return chart


def face_neighbours(topology) -> np.ndarray:
    """``(m, 3) int``: the face across each edge of each face (``-1`` across the boundary),
    in no particular edge order."""
    ef = topology.edge_faces
    inner = (ef[:, 0] >= 0) & (ef[:, 1] >= 0)
    a, b = ef[inner, 0], ef[inner, 1]
    src = np.r_[a, b]
    dst = np.r_[b, a]
    order = np.argsort(src, kind="stable")
    src, dst = src[order], dst[order]
    start = np.searchsorted(src, np.arange(topology.n_faces))
    k = np.arange(src.size) - start[src]
    out = np.full((topology.n_faces, 3), -1, np.int64)
    out[src, k] = dst
    return out


def smooth_charts(chart: np.ndarray, nbr: np.ndarray, *, rounds: int = 6) -> np.ndarray:
    """Move faces that stick out of their chart (at most one neighbour in it, two in one
    other chart) into that other chart; ``rounds`` passes, all faces at once (a
    majority filter along the seams: shorter, straighter seams that pack better)."""
    chart = chart.copy()
    for _ in range(rounds):
        nc = np.where(nbr >= 0, chart[np.maximum(nbr, 0)], -1)         # (m, 3)
        own = (nc == chart[:, None]).sum(1)
        ab = (nc[:, 0] == nc[:, 1]) & (nc[:, 0] >= 0)
        ac = (nc[:, 0] == nc[:, 2]) & (nc[:, 0] >= 0)
        bc = (nc[:, 1] == nc[:, 2]) & (nc[:, 1] >= 0)
        other = np.where(ab | ac, nc[:, 0], np.where(bc, nc[:, 1], -1))
        move = (own <= 1) & (other >= 0) & (other != chart)
        # a face and its neighbour must not swap into each other's charts in one pass
        move &= np.arange(chart.size) % 2 == _ % 2
        if not move.any():
            continue
        chart[move] = other[move]
    return chart


def keep_disks(topology, before: np.ndarray, after: np.ndarray, *, rounds: int = 8) -> np.ndarray:
    """``after`` with the face moves undone that touch a chart which is a disk in ``before``
    (same labels) but not in ``after``."""
    after = after.copy()
    ok_before = disk_flags(topology, before)
    for _ in range(rounds):
        ok = np.zeros(ok_before.size, bool)
        flags = disk_flags(topology, after)               # empty labels come out False
        ok[: flags.size] = flags
        bad = ~ok & ok_before
        moved = after != before
        undo = moved & (bad[after] | bad[before])
        if not undo.any():
            break
        after[undo] = before[undo]
    return after


#: Rounds of area-weighted averaging, over each face and its edge neighbours, that make the
#: smoothed normals of :func:`smoothed_normals`.
SMOOTH_ROUNDS = 2
#: :func:`segment` (``normals="auto"``) keeps the smoothed normals' charts when they are at
#: most this share of the raw normals' charts.  Noise of 0.1-0.3 % of the diagonal tilts small
#: faces by 30-100 degrees, and each such face leaves its chart; at the atlas's 88-degree cone
#: (fixed seeds): rocker-arm 56 charts clean, 661 at 0.3 % noise (smoothed 49), camelhead
#: 39 / 157 / 900 at 0, 0.1, 0.3 % (smoothed 67, 176), camel_b at 0.2 % 128 (42), snail at
#: 0.1 % 6 (1).  On the clean meshes of ``../shared/data`` the smoothed counts are 0.59
#: (decimated-knight) to 1.41 (rocker-arm) of the raw ones, so they keep their raw charts.
NOISY_CHART_SHARE = 0.5


#: ... or when at least this share of the interior edges join two vertices whose umbrella
#: vectors point to opposite sides of the surface (:func:`bumpy_share`): on a smooth surface
#: neighbours bend the same way except along inflection lines (the clean meshes of
#: ``../shared/data`` 0-0.30, a generated disk of random heights 0.37), noise makes the signs
#: random (0.44-0.57 at 0.3 % noise and more; lilium + 0.25 % noise 0.54, whose raw / smoothed
#: charts are 5 / 3, and whose atlas goes from 7 charts covering 62.3 % to 2 covering 83.8 %).
NOISY_SIGN_SHARE = 0.45


def bumpy_share(topology, V: np.ndarray) -> float:
    """The share of interior edges whose two ends bend to opposite sides: the sign of the
    umbrella vector (neighbours' mean minus the vertex) along the vertex normal (face normals
    summed by area) differs.  Ends bent by less than 1e-6 of the mean edge length count as
    flat and never differ (a plane's rounding).  Boundary vertices are left out."""
    E, n = topology.edges, topology.n_vertices
    ends, others = np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]]
    deg = np.maximum(np.bincount(ends, minlength=n), 1)
    umbrella = np.stack([np.bincount(ends, V[others, x], n) / deg - V[:, x] for x in range(3)], 1)
    h = np.einsum("ij,ij->i", umbrella, vertex_normals(V, topology.faces))
    tol = 1e-6 * float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean()) if len(E) else 0.0
    side = np.where(np.abs(h) > tol, np.sign(h), 0.0)
    inner = ~topology.is_boundary
    e = E[inner[E[:, 0]] & inner[E[:, 1]]]
    if e.size == 0:
        return 0.0
    return float(np.mean(side[e[:, 0]] * side[e[:, 1]] < 0))


def smoothed_normals(normals, areas, adj_csr, rounds: int = SMOOTH_ROUNDS) -> np.ndarray:
    """``(m, 3)`` unit normals: ``rounds`` passes of ``n_f <- sum a_g n_g`` over the face
    ``f`` and the faces ``g`` across its edges (area-weighted, so a small face tilted by
    noise takes its larger neighbours' direction).  ``adj_csr``: :func:`face_csr`."""
    w = normals * areas[:, None]
    for _ in range(int(rounds)):
        w = w + adj_csr @ w
    return w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300)


#: The most 3D angle (radians) a chart may hold around one of its boundary vertices: a fan of
#: more than a full turn cannot be flattened without folding over itself or being squeezed,
#: and its chart's map crossed its own boundary and was split in two.  On noisy meshes 12 of
#: the 13 self-crossing charts of cow + 0.5 % noise had such a vertex (2.01-3.15 pi).
SLIT_ANGLE = 2 * np.pi


def _wide_fans(topology, angles, chart, limit):
    """Per (chart, vertex) pair: ``(chart, vertex, angle, wide)``, ``angle`` the chart's own
    corner angles at the vertex summed, ``wide`` where that passes ``limit`` at a vertex
    inside the mesh that another chart meets too (a chart-boundary vertex)."""
    n = topology.n_vertices
    key = np.repeat(chart, 3) * np.int64(n) + topology.faces.reshape(-1)
    uk, inv = np.unique(key, return_inverse=True)
    angle = np.bincount(inv, weights=angles.reshape(-1))
    kc, kv = uk // n, uk % n
    shared = np.bincount(kv, minlength=n)[kv] > 1
    return kc, kv, angle, (angle > limit) & ~topology.is_boundary[kv] & shared


def _moved(F, chart, owner, vertex, dest, n, own):
    """``chart`` with the faces at ``vertex[i]`` (those in chart ``owner[i]`` if ``own``, else
    those in any other chart) given to chart ``dest[i]``; a face at two such vertices goes
    with the first in order."""
    slot = np.full(n, -1)
    once, first_at = np.unique(vertex, return_index=True)
    slot[once] = first_at                                          # each vertex's first entry
    corner_f = np.repeat(np.arange(F.shape[0]), 3)
    hit = slot[F.reshape(-1)] >= 0
    faces, which = corner_f[hit], slot[F.reshape(-1)[hit]]
    mine = chart[faces] == owner[which]
    faces, which = (faces[mine], which[mine]) if own else (faces[~mine], which[~mine])
    order = np.lexsort((which, faces))
    faces, which = faces[order], which[order]
    first = np.r_[True, faces[1:] != faces[:-1]]
    after = chart.copy()
    after[faces[first]] = dest[which[first]]
    return after


def close_slits(topology, V: np.ndarray, chart: np.ndarray, *, limit: float = SLIT_ANGLE,
                rounds: int = 4) -> np.ndarray:
    """``chart`` with its wide boundary fans removed: where a chart holds more than ``limit``
    of 3D angle around a boundary vertex (:data:`SLIT_ANGLE`), the other charts' faces at
    that vertex join it (the slit closes, the vertex becomes interior); where that would
    leave a chart that is not a disk, the chart's fan goes instead to the chart that holds
    the most angle there after it.  Moves that break a disk are undone
    (:func:`keep_disks`); ``rounds`` passes, widest fans first."""
    F, n = topology.faces, topology.n_vertices
    angles = face_angles(np.asarray(V, np.float64), F)
    for _ in range(rounds):
        kc, kv, angle, wide = _wide_fans(topology, angles, chart, limit)
        if not wide.any():
            break
        o = np.argsort(-angle[wide], kind="stable")
        c, v = kc[wide][o], kv[wide][o]
        after = keep_disks(topology, chart, _moved(F, chart, c, v, c, n, own=False))
        kc, kv, angle, wide = _wide_fans(topology, angles, after, limit)
        if wide.any():
            others = np.flatnonzero(~wide & np.isin(kv, kv[wide]))
            others = others[np.lexsort((angle[others], kv[others]))]
            last = np.r_[kv[others][1:] != kv[others][:-1], True]   # each vertex's largest angle
            widest = np.full(n, -1)
            widest[kv[others[last]]] = kc[others[last]]
            o = np.argsort(-angle[wide], kind="stable")
            c, v = kc[wide][o], kv[wide][o]
            ok = widest[v] >= 0
            if ok.any():
                after = keep_disks(topology, after, _moved(F, after, c[ok], v[ok], widest[v[ok]], n,
                                                           own=True))
        if np.array_equal(after, chart):
            break
        chart = relabel(after)
    return chart


def _charts_from(t, normals, areas, adj, adj_csr, cone, merge_cone, small_cone, small_area):
    chart = grow_charts(normals, areas, adj, cone=cone)
    chart = make_disks(t, chart, adj_csr)
    chart = merge_charts(chart, normals, areas, adj, t.faces, cone=merge_cone or cone)
    if small_cone is not None:
        chart = merge_charts(chart, normals, areas, adj, t.faces, cone=small_cone,
                             max_area=small_area * float(areas.sum()))
    chart = keep_disks(t, chart, smooth_charts(chart, face_neighbours(t)))
    return make_disks(t, chart, adj_csr)


def segment(mesh, *, cone: float = 60.0, merge_cone: float | None = None,
            small_cone: float | None = None, small_area: float = 0.01,
            normals: str = "auto") -> np.ndarray:
    """Charts of a mesh: ``chart (m,) int`` labels ``0..c-1``, every chart a disk.

    **Arguments:** ``mesh`` (concrete vertices); ``cone`` in degrees (grow step);
    ``merge_cone`` (merge step; default ``cone``); ``small_cone``: a second merge step in
    which only charts under ``small_area`` of the total area merge, within this wider
    cone (``None``: no second step); ``normals``: the face normals the cones test,
    ``"raw"``, ``"smoothed"`` (:func:`smoothed_normals`) or ``"auto"``: the smoothed ones
    where the mesh is noisy, that is where at least :data:`NOISY_SIGN_SHARE` of its edges
    bend both ways (:func:`bumpy_share`) or where the smoothed normals' charts are at most
    :data:`NOISY_CHART_SHARE` of the raw ones'.  With the smoothed normals, the slits of
    the charts' outlines are closed (:func:`close_slits`): the noise that tilts triangles
    also gathers more than a full turn of angle around boundary vertices.
    """
    if normals not in ("auto", "raw", "smoothed"):
        raise MeshError(f"segment: normals must be 'auto', 'raw' or 'smoothed', got {normals!r}.")
    t = mesh.topology
    V = np.asarray(mesh.vertices, np.float64)
    raw, areas = face_normals(V, t.faces)
    adj = face_adjacency(t)
    adj_csr = _csr(adj, t.n_faces)

    def charts(n):
        return _charts_from(t, n, areas, adj, adj_csr, cone, merge_cone, small_cone, small_area)

    if normals == "raw":
        return charts(raw)
    smooth = charts(smoothed_normals(raw, areas, adj_csr))
    if normals == "auto" and bumpy_share(t, V) < NOISY_SIGN_SHARE:
        plain = charts(raw)
        if smooth.max() + 1 > NOISY_CHART_SHARE * (plain.max() + 1):
            return plain
    return make_disks(t, close_slits(t, V, smooth), adj_csr)
