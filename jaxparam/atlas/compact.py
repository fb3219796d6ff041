"""Splitting flattened charts into more convex pieces, so that they pack tighter.

The packer fills the square with the charts' rasters; what it cannot fill are the gaps
that the charts' concave outlines leave (session 8: the raster cells hold 93-97 % chart
area but fill only 60-77 % of the square).  :func:`plan_splits` cuts a chart whose
flattened outline is far from convex by a straight line in its UV plane (the faces whose
UV centroid lies on one side), chosen among 8 directions and 17 positions so that the two
pieces' convex hulls hold the least area; both pieces must be face-connected disks.
Charts are cut greedily, the largest hull-area gain first, up to a number of new charts.

A piece's restriction of its parent's map is flip-free and does not cross itself, so the
cut keeps every triangle's distortion; :func:`jaxparam.atlas.atlas` then minimizes each
piece again from that restriction (a descent: the energy of a piece can only fall) so
that every chart is its own free-boundary optimum, as :func:`~jaxparam.atlas.atlas_uv`
expects.  Topology and geometry here are NumPy (concrete charts, small per-chart work).
"""
from __future__ import annotations

import heapq

import numpy as np
import scipy.sparse as sp

from .charts import faces_are_disk
from .pack import boundary_segments, min_area_rotation

__all__ = ["hull_area", "hull_areas", "chart_rim", "best_cut", "straight_cuts", "two_disks", "plan_splits",
           "plan_strips", "STRIP_SHARE", "STRIP_ASPECT", "STRIP_CURVED_ASPECT", "STRIP_MIN_FACES"]

#: Cut directions (radians, in the chart's minimal-area-rectangle frame) and positions
#: (quantiles of the face centroids' coordinate along the direction).
DIRECTIONS = np.arange(8) * np.pi / 8
QUANTILES = np.linspace(0.1, 0.9, 17)
#: :func:`straight_cuts`' default positions (the packing cut's, `atlas/build.py`).
CUT_QUANTILES = np.linspace(0.1, 0.9, 9)

#: Above this many distinct UV points in a chart, :func:`best_cut` measures each piece's hull
#: with one Qhull call on the piece's outline points (about 0.1 ms each, whatever the size)
#: instead of :func:`hull_areas`' batch, whose loop over the points grows with the chart:
#: 272 pieces of a 20,000-point chart took 6.7 s batched, 0.08 s by Qhull; below about 150
#: points the batch is the faster (session 12).
BATCHED_MAX_POINTS = 150


def hull_area(P: np.ndarray) -> float:
    """Area of the convex hull of the points ``P (k, 2)`` (0 when degenerate)."""
    from scipy.spatial import ConvexHull, QhullError
    if P.shape[0] < 3:
        return 0.0
    try:
        return float(ConvexHull(P).volume)
    except (QhullError, ValueError):
        return 0.0


def hull_areas(P: np.ndarray, members: np.ndarray) -> np.ndarray:
    """Areas of the convex hulls of many subsets of one point set, at once.

    **Arguments:** ``P (n, 2)``; ``members (s, n)`` bool, the points of each subset.
    **Returns:** ``(s,)`` areas (0 for fewer than three points or none enclosed).

    Andrew's monotone chain, run for all subsets together: the points are sorted once, and
    each step pushes the next point onto the chains of the subsets that hold it after
    popping, in every such chain, the points that no longer turn left.  The Python loop is
    over the points (and the pops), not the subsets: :func:`best_cut`'s 272 hulls of one
    chart cost a few numpy passes instead of 272 Qhull calls (about 0.1 ms each).  Same
    areas as :func:`hull_area` to rounding (tested)."""
    P = np.asarray(P, np.float64)
    members = np.asarray(members, bool)
    s, n = members.shape
    order = np.lexsort((P[:, 1], P[:, 0]))
    X, Y = P[order, 0], P[order, 1]
    M = members[:, order]
    area2 = np.zeros(s)
    rows = np.arange(s)
    for sweep in (range(n), range(n - 1, -1, -1)):          # lower chain, then upper chain
        H = np.zeros((s, n + 1), np.int64)
        k = np.zeros(s, np.int64)
        first = np.full(s, -1)
        for i in sweep:
            on = M[:, i]
            if not on.any():
                continue
            while True:
                r = rows[on & (k >= 2)]
                if r.size == 0:
                    break
                a, b = H[r, k[r] - 2], H[r, k[r] - 1]
                cross = (X[b] - X[a]) * (Y[i] - Y[a]) - (Y[b] - Y[a]) * (X[i] - X[a])
                pop = r[cross <= 0]
                if pop.size == 0:
                    break
                k[pop] -= 1
            r = rows[on]
            H[r, k[r]] = i
            k[r] += 1
            first[r] = np.where(first[r] < 0, i, first[r])
        # the chain's shoelace terms (x_j y_{j+1} - x_{j+1} y_j) along it
        j = np.arange(n)[None, :]
        valid = j < (k - 1)[:, None]
        a, b = H[:, :-1], H[:, 1:]
        term = X[a] * Y[b] - X[b] * Y[a]
        area2 += np.sum(np.where(valid, term, 0.0), axis=1)
    return np.where(members.sum(1) >= 3, np.maximum(0.5 * area2, 0.0), 0.0)


def chart_rim(faces: np.ndarray, n: int) -> np.ndarray:
    """``(n,) bool``: the points on the boundary of the consistently oriented faces
    ``faces (f, 3)`` (:func:`~jaxparam.atlas.pack.boundary_segments`), of ``n`` points."""
    rim = np.zeros(n, bool)
    rim[boundary_segments(faces, np.zeros(faces.shape[0], np.int64))[0].ravel()] = True
    return rim


def _connected(sub: sp.csr_matrix, keep: np.ndarray) -> bool:
    from scipy.sparse.csgraph import connected_components
    idx = np.flatnonzero(keep)
    return connected_components(sub[idx][:, idx], directed=False)[0] == 1


def joined_slabs(sub: sp.csr_matrix, slab: np.ndarray, passes: int = 8,
                 tip_share: float = 0.25) -> np.ndarray:
    """``slab (f,)`` labels of a chart's faces (``sub (f, f)`` their adjacency) with the tips
    joined: each slab keeps its largest face-connected piece, and a face of another piece
    holding under ``tip_share`` of its slab's faces takes the slab of a neighbour in a kept
    piece, pass after pass (a slab cut by a ragged outline leaves tips across the line, which
    belong with the slab beside them).  Larger pieces (a hairpin's other arm) and faces still
    unjoined after ``passes`` keep their label, which the caller's checks refuse."""
    from scipy.sparse.csgraph import connected_components

    slab = slab.copy()
    rows, cols = sub.nonzero()
    for _ in range(passes):
        same = slab[rows] == slab[cols]
        g = sp.csr_matrix((np.ones(int(same.sum())), (rows[same], cols[same])), shape=sub.shape)
        n, piece = connected_components(g, directed=False)
        size = np.bincount(piece, minlength=n)
        # the largest piece of each slab (ties: the lowest piece id)
        piece_slab = np.empty(n, np.int64)
        piece_slab[piece] = slab
        order = np.lexsort((np.arange(n), -size, piece_slab))
        lead = order[np.r_[True, piece_slab[order][1:] != piece_slab[order][:-1]]]
        best = np.full(int(slab.max()) + 1, -1)
        best[piece_slab[lead]] = lead
        kept = best[slab] == piece
        tip = ~kept & (size[piece] < tip_share * np.bincount(slab)[slab])
        if not tip.any():
            break
        # a tip's face with a kept neighbour takes that neighbour's slab
        edge = tip[rows] & kept[cols]
        take = np.full(slab.size, -1)
        take[rows[edge]] = slab[cols[edge]]
        slab = np.where(take >= 0, take, slab)
    return slab


def best_cut(corner_uv: np.ndarray, faces: np.ndarray, sub_adj: sp.csr_matrix,
             *, accept: float = 0.9, min_faces: int = 2):
    """The best straight cut of one flattened chart.

    **Arguments:** ``corner_uv (f, 3, 2)``: the chart's UVs at its faces' corners;
    ``faces (f, 3)``: its faces (vertex ids); ``sub_adj (f, f)``: face adjacency within the
    chart; ``accept``: the largest ratio of the pieces' hull areas to the chart's hull area
    that is worth a new chart; ``min_faces``: the fewest faces in a piece.
    **Returns:** ``(gain, side (f,) bool)``, ``gain`` the hull area saved (UV units^2, 0 and
    ``None`` when no cut qualifies).
    """
    P = corner_uv.reshape(-1, 2)
    R = min_area_rotation(P)
    Q = (corner_uv @ R.T)
    H0 = hull_area(Q.reshape(-1, 2))
    if H0 <= 0 or faces.shape[0] < 2 * min_faces:
        return 0.0, None
    # The two pieces' hulls hold at least the chart's own UV area, whatever the cut: a chart
    # that fills more than `accept` of its hull has no cut to find, and skips the 272 hulls
    # below (on cow, 22 of the 220 charts tried: 49k -> 43k hulls; the result is the same).
    e1, e2 = Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]
    if 0.5 * np.sum(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])) > accept * H0:
        return 0.0, None
    S = straight_cuts(corner_uv, quantiles=QUANTILES, min_faces=min_faces, rotation=R)
    cuts = range(len(S))
    cands = []
    if len(S):
        # the pieces' points: the corners of their faces (each corner point once)
        pts, corner = np.unique(Q.reshape(-1, 2), axis=0, return_inverse=True)
        corner = corner.reshape(-1, 3)
        members = np.zeros((2 * len(cuts), pts.shape[0]), bool)
        for piece, faces_in in enumerate(np.concatenate([S, ~S])):
            members[piece, corner[faces_in].ravel()] = True
        # A piece's hull is the hull of its outline: the points on the chart's boundary and
        # those it shares with the other piece.  Its other points are inside the flip-free,
        # one-to-one map of their whole fan, so none is extreme (same areas, few points).
        members &= chart_rim(corner, pts.shape[0]) | np.roll(members, len(cuts), axis=0)
        if pts.shape[0] <= BATCHED_MAX_POINTS:
            areas = hull_areas(pts, members)
        else:
            areas = np.array([hull_area(pts[m]) for m in members])
        for i in cuts:
            s = (areas[i] + areas[len(cuts) + i]) / H0
            if s <= accept:
                cands.append((s, i))
    for s, i in sorted(cands):          # ties: the cuts' order (direction, then position)
        if two_disks(S[i], faces, sub_adj):
            return H0 * (1.0 - s), S[i]
    return 0.0, None


def straight_cuts(corner_uv: np.ndarray, *, quantiles=CUT_QUANTILES, min_faces: int = 2,
                  rotation=None) -> np.ndarray:
    """The straight cuts of one flattened chart ``corner_uv (f, 3, 2)`` along
    :data:`DIRECTIONS` (in the frame of the chart's minimal-area rectangle) at ``quantiles``
    of the face centroids' coordinate: ``(c, f) bool``, each row the faces whose UV centroid
    lies before the line, both sides at least ``min_faces`` faces, in the order direction,
    then position.  Whether the pieces are disks is :func:`two_disks`' to say.  ``rotation``:
    that frame's :func:`~jaxparam.atlas.pack.min_area_rotation`, when the caller has it."""
    R = min_area_rotation(corner_uv.reshape(-1, 2)) if rotation is None else rotation
    Q = corner_uv @ R.T
    C = Q.mean(1)
    out = []
    for th in DIRECTIONS:
        x = C @ np.array([np.cos(th), np.sin(th)])
        for t in np.unique(np.quantile(x, quantiles)):
            side = x < t
            if min_faces <= int(side.sum()) <= side.size - min_faces:
                out.append(side)
    return np.array(out, bool).reshape(-1, corner_uv.shape[0])


def two_disks(side: np.ndarray, faces: np.ndarray, sub_adj: sp.csr_matrix) -> bool:
    """Whether the cut ``side (f,) bool`` of a chart's faces ``faces (f, 3)`` (face adjacency
    ``sub_adj``) leaves two face-connected disks."""
    return bool(_connected(sub_adj, side) and _connected(sub_adj, ~side)
                and faces_are_disk(faces[side]) and faces_are_disk(faces[~side]))


#: :func:`plan_strips` cuts a chart longer than ``STRIP_SHARE`` times the side of the square
#: that the atlas's UV area fills at 75 %: a straight one at least ``STRIP_ASPECT`` times
#: longer than wide (its minimal-area rectangle), a curved one (an arc, a spiral) whose length
#: ``D`` along it and area ``A`` have ``D^2 > STRIP_CURVED_ASPECT A`` (a strip of aspect ``a``
#: has ``D^2 / A`` about ``a``, a square 2, a disk 1.3).
STRIP_SHARE = 1.0
STRIP_ASPECT = 2.0
STRIP_CURVED_ASPECT = 3.0
#: Charts of fewer faces are not cut.
STRIP_MIN_FACES = 2


def _along(corner_uv: np.ndarray, sub: sp.csr_matrix, area: float) -> np.ndarray:
    """``(f,)``: each face's distance along a chart (UV centroids, paths through the face
    adjacency ``sub``) from its end: the faces within the chart's width (``area`` over its
    length) of the face farthest from another (two sweeps), so that the level sets run across
    the chart rather than around one corner face."""
    from scipy.sparse.csgraph import dijkstra

    c = corner_uv.mean(1)
    coo = sp.triu(sub, 1).tocoo()
    w = np.linalg.norm(c[coo.row] - c[coo.col], axis=1) + 1e-300
    G = sp.csr_matrix((w, (coo.row, coo.col)), shape=sub.shape)

    def far(d):
        return int(np.argmax(np.where(np.isfinite(d), d, -1)))
    d = dijkstra(G, directed=False, indices=far(dijkstra(G, directed=False, indices=0)))
    d = np.where(np.isfinite(d), d, 0.0)
    end = np.flatnonzero(d <= area / max(float(d.max()), 1e-300))
    d = dijkstra(G, directed=False, indices=end, min_only=True)
    return np.where(np.isfinite(d), d, 0.0)


def plan_strips(corner_uv: np.ndarray, faces: np.ndarray, chart: np.ndarray, adj_csr: sp.csr_matrix,
                *, share: float = STRIP_SHARE, aspect: float = STRIP_ASPECT,
                curved_aspect: float = STRIP_CURVED_ASPECT, curved: bool = True):
    """Cut long charts along their length into pieces of equal length.

    A long chart bounds the packing's scale by its length alone: a strip of aspect ``a``
    alone in the square covers at most ``1 / a`` of it (a held-out capsule, 8 x 0.3, packed
    as 3 charts covered 19.3 %), while ``k`` pieces side by side fill it (best near
    ``k = sqrt(a)``).  A chart longer than ``share`` times the side ``sqrt(A / 0.75)`` of the
    square that the atlas's UV area ``A`` would fill at 75 % is cut into ``n = ceil(length /
    (share side))`` slabs of equal length:

    - straight: its minimal-area rectangle at least ``aspect`` times longer than wide, the
      slabs by lines across the rectangle's long axis (faces by their UV centroid);
    - else curved (an arc, the spiral of a helical tube's side): its length ``D`` the largest
      distance along it (:func:`_along`), ``D^2 > curved_aspect`` times its area, the slabs
      by that distance from one end.

    A chart whose slabs are not all face-connected disks (a hairpin, whose slabs hold both
    arms) is left whole; so is every curved one with ``curved=False``.

    **Arguments and returns:** as :func:`plan_splits` (``corner_uv (m, 3, 2)`` at 3D scale,
    ``faces (m, 3)``, ``chart (m,)``, ``adj_csr`` the face adjacency); ``(chart (m,), parent
    (c_new,))``."""
    chart = np.asarray(chart, np.int64).copy()
    k = int(chart.max()) + 1
    parent = list(range(k))
    d1, d2 = corner_uv[:, 1] - corner_uv[:, 0], corner_uv[:, 2] - corner_uv[:, 0]
    fa = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    limit = share * np.sqrt(fa.sum() / 0.75)
    order = np.argsort(chart, kind="stable")
    bounds = np.searchsorted(chart[order], np.arange(k + 1))

    def slabs(t, length, sub, fk):
        """Slab labels ``(f,)`` of coordinate ``t`` (from 0 at the chart's end to ``length``)
        along the chart, or None (not all disks)."""
        n = int(np.ceil(length / limit))
        slab = joined_slabs(sub, np.clip((t / length * n).astype(np.int64), 0, n - 1))
        ok = all((slab == j).any() and _connected(sub, slab == j) and faces_are_disk(faces[fk[slab == j]])
                 for j in range(n))
        return slab if ok else None

    for c in range(k):
        fk = order[bounds[c]:bounds[c + 1]]
        if fk.size < STRIP_MIN_FACES:
            continue
        T = corner_uv[fk]
        Q = T @ min_area_rotation(T.reshape(-1, 2)).T                  # long axis: u
        length, width = np.ptp(Q[..., 0]), np.ptp(Q[..., 1])
        straight = length > limit and length > aspect * width
        # a path along the chart is at most a face's longest edge per face: a cheap bound first
        reach = fk.size * float(np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2).max())
        if not (straight or (curved and reach > limit)):
            continue
        sub = adj_csr[fk][:, fk]
        slab = slabs(Q[..., 0].mean(1) - Q[..., 0].min(), length, sub, fk) if straight else None
        if slab is None and curved and reach > limit:
            t = _along(T, sub, float(fa[fk].sum()))
            D = float(t.max())
            if D > limit and D * D > curved_aspect * fa[fk].sum():
                slab = slabs(t, D, sub, fk)
        if slab is None:
            continue
        for j in range(1, int(slab.max()) + 1):
            chart[fk[slab == j]] = len(parent)
            parent.append(c)
    return chart, np.asarray(parent, np.int64)


def plan_splits(corner_uv: np.ndarray, faces: np.ndarray, chart: np.ndarray,
                adj_csr: sp.csr_matrix, *, max_new: int, accept: float = 0.9):
    """Cut flattened charts into more convex pieces, the largest hull-area gain first.

    **Arguments:** ``corner_uv (m, 3, 2)`` every face's corner UVs (charts at 3D scale);
    ``faces (m, 3)``; ``chart (m,)``; ``adj_csr``: the mesh's face adjacency
    (:func:`~jaxparam.atlas.charts.face_csr`); ``max_new``: the most new charts;
    ``accept``: see :func:`best_cut`.
    **Returns:** ``(chart (m,), parent (c_new,))``: the new face charts (the old labels
    kept, new pieces numbered after them) and each chart's label before the cuts.
    """
    chart = np.asarray(chart, np.int64).copy()
    k = int(chart.max()) + 1
    parent = list(range(k))
    order = np.argsort(chart, kind="stable")
    bounds = np.searchsorted(chart[order], np.arange(k + 1))
    heap = []

    def push(c, fk):
        sub = adj_csr[fk][:, fk]
        gain, side = best_cut(corner_uv[fk], faces[fk], sub, accept=accept)
        if side is not None:
            heapq.heappush(heap, (-gain, c, fk, side))

    if max_new > 0:
        for c in range(k):
            push(c, order[bounds[c]:bounds[c + 1]])
    made = 0
    while heap and made < max_new:
        _, c, fk, side = heapq.heappop(heap)
        nxt = len(parent)
        chart[fk[~side]] = nxt
        parent.append(parent[c])
        made += 1
        push(c, fk[side])
        push(nxt, fk[~side])
    return chart, np.asarray(parent, np.int64)
