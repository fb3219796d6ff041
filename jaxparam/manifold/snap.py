"""Tips snapped: remesh samples moved onto the input's sharp vertices that the remesh cuts off.

A remesh through dyadic samples of the base domain passes a sharp tip of the input (an ear, a
horn, a hoof's corner) only where a sample happens to land on it; otherwise it cuts the tip
off, and the tip vertex is the input point farthest from the remesh (issue 13: cow's and
decimated-knight's level-4 Hausdorff error sits on such tips).  Each tip's own place in the
base domain is known (``vertex_face``, ``vertex_bary``: the MAPS map of the input vertex), so
the remesh sample nearest to the tip can be moved there exactly: the remesh then has a vertex
on the tip and keeps its subdivision connectivity.

A move is undone when a remesh triangle around the sample turns over, or shrinks below
``1e-3`` of its area, in its first corner's chart, or when its corners lie in base triangles
that share no edge (drawn across a base vertex, where unfolded sectors may overlap): the same
guards as :func:`~jaxparam.manifold.relax.relax_samples`.  It is undone too when one of
those triangles grows an edge past the remesh's longest, shrinks in 3D below ``1e-3`` of its
area, or has a point (centroid, edge midpoints, near its corners) farther from the input than
the tip was from the remesh (:data:`BEND`; points on a grid of step 1/6, :func:`bend`): a
remesh coarser than the tip would otherwise trade the cut-off tip for a spike of broad faces
beside the surface.  And it is undone when it leaves another tip farther from the remesh than
that tip was and than the moved sample's own tip was (neighbour tips take each other's
samples).  Base vertices are never moved.
"""
from __future__ import annotations

import numpy as np

from ..distance import grid_barycentric, point_triangle_distance
from .relax import BaseDomain, around_a_vertex, signed_chart_areas

__all__ = ["snap_tips", "bend", "longest_edges", "SNAP_ROUNDS", "SNAP_SHARE", "BEND", "CANDIDATES", "SNAP_GAIN"]

#: Barycentric points measured on each remesh face around a moved sample: a grid of step 1/6
#: without the corners (which lie on the input).  Seven points (centroid, edge midpoints, near
#: the corners) missed a bend of 0.6 % of cow's diagonal between them.
_GRID = 6
_FACE_POINTS = grid_barycentric(_GRID)
#: The fewer points that screen each tip's candidate moves (centroid, edge midpoints, near the
#: corners): a third of the cost; the chosen moves are measured on the full grid.
_SCREEN_POINTS = np.array([[2, 2, 2], [3, 3, 0], [0, 3, 3], [3, 0, 3], [4, 1, 1], [1, 4, 1],
                           [1, 1, 4]], np.float64) / 6

#: Rounds of snapping (each measures the tips' distances again), and the share of the
#: largest tip distance above which a sharp vertex is snapped in a round.
SNAP_ROUNDS = 3
SNAP_SHARE = 0.5
#: A move is undone when a point of the faces around the sample lies farther from the input
#: than this share of the tip's distance from the remesh before the move.
BEND = 1.0
#: How many of the samples nearest to a tip (in 3D) it tries (4 left cow's input -> remesh at
#: 0.538 % of the diagonal, 8 at 0.491 %).
CANDIDATES = 8
#: The snapped samples are kept when they lower the estimated distance to the input by more
#: than this share: an estimate whose maximum lies elsewhere is unchanged by the snapping up
#: to rounding (1e-7 relative for a mesh far from the origin), which is no gain.
SNAP_GAIN = 1e-6


def snap_tips(D: BaseDomain, faces: np.ndarray, r: np.ndarray, b: np.ndarray, X: np.ndarray,
              P: np.ndarray, F: np.ndarray, tips: np.ndarray, vertex_face: np.ndarray,
              vertex_bary: np.ndarray, *, rounds: int = SNAP_ROUNDS, share: float = SNAP_SHARE):
    """Move remesh samples onto the input vertices ``tips`` that lie farthest from the remesh.

    **Arguments:** ``D`` the :class:`~jaxparam.manifold.relax.BaseDomain`; ``faces (m, 3)`` the
    remesh's triangles over its ``n`` samples; ``r (n,)``, ``b (n, 3)`` the samples' base faces
    and barycentric coordinates; ``X (n, 3)`` their surface points; ``P (N, 3)`` the input's
    vertices; ``tips (t,)`` the candidates (the input's sharpest vertices,
    :func:`~jaxparam.manifold.relax.sharpest_vertices`); ``vertex_face (N,)``,
    ``vertex_bary (N, 3)`` each input vertex's base face and coordinates.

    **Returns:** ``(r, b, X, source)``: new arrays, and ``source (n,)`` the input vertex each
    sample now sits on (``-1`` where it did not move).  In each round the tips farther from
    the remesh than ``share`` of the farthest one each take, of their :data:`CANDIDATES`
    nearest samples (in 3D) that are not base vertices and have not moved yet, the one whose
    move alone bends the faces around it least; a sample claimed by two tips goes to the
    farther, and moves that fail the guards together are undone, as is the move nearest to a
    tip it pushes off (farther than it was and than the moved sample's own tip)."""
    from scipy.spatial import cKDTree

    faces = np.asarray(faces, np.int64)
    n = X.shape[0]
    X_in, P_in = np.asarray(X, np.float64), np.asarray(P, np.float64)
    # Centred, so that the distances the choices compare are not computed on large
    # coordinates.  (The samples' own positions carry the rounding of the input's: bunny
    # moved by 1e6 has them 1e-10 apart, its guards' distances 1e-6 relative, and 5 of 800
    # guard tests there come out the other way: 4 of its 143 snapped samples differ.)
    centre = 0.5 * (P_in.min(0) + P_in.max(0))
    P, X = P_in - centre, X_in - centre
    r, b = np.array(r, np.int64), np.array(b, np.float64)
    pinned = (b > 1e-12).sum(1) == 1
    area0 = np.abs(signed_chart_areas(D, faces, r, b))
    # The faces around each sample (CSR over the corners).
    corner_order = np.argsort(faces.ravel(), kind="stable")
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(faces.ravel(), minlength=n), out=ptr[1:])
    source = np.full(n, -1, np.int64)
    tips = np.asarray(tips, np.int64)
    for _ in range(int(rounds)):
        d = point_triangle_distance(P[tips], X, faces)[0]
        if not d.size or not d.max() > 0:
            break
        far = tips[np.argsort(-d, kind="stable")][: int(np.count_nonzero(d > share * d.max()))]
        free = np.flatnonzero(~pinned & (source < 0))
        if not far.size or not free.size:
            break
        dist = np.zeros(P.shape[0])                        # each tip's distance, by vertex
        dist[tips] = d
        # Each tip tries its CANDIDATES nearest samples, each move alone, and takes the one
        # that bends the faces around it least (within the guards).
        k = min(CANDIDATES, free.size)
        near = free[cKDTree(X[free]).query(P[far], k=k)[1].reshape(far.size, k)]
        tip_d = dist[far]
        ok, off = _alone(D, faces, ptr, corner_order, r, b, X, pinned, area0, P, F,
                         near.ravel(), np.repeat(far, k), vertex_face, vertex_bary)
        score = np.where(ok & (off <= BEND * np.repeat(tip_d, k)), off, np.inf).reshape(far.size, k)
        pick = score.argmin(1)
        has = np.isfinite(score[np.arange(far.size), pick])
        if not has.any():
            break
        s, v = near[np.arange(far.size), pick][has], far[has]
        s, first = np.unique(s, return_index=True)        # far is sorted: first = farthest tip
        v = v[first]
        r1, b1, X1 = r.copy(), b.copy(), X.copy()
        r1[s], b1[s], X1[s] = vertex_face[v], vertex_bary[v], P[v]
        limit = np.full(n, np.inf)                        # a moved sample's tip distance
        limit[s] = dist[v]
        moved = np.zeros(n, bool)
        moved[s] = True
        off_face = np.full(faces.shape[0], np.nan)           # each face's bend, once per shape
        while moved.any():
            fs = np.unique(_faces_around(ptr, corner_order, np.flatnonzero(moved))[0])
            # A move must not turn a face over, draw it across a base vertex, or bend a face
            # farther from the input than the tip was from the remesh.
            new = fs[np.isnan(off_face[fs])]
            off_face[new] = bend(X1[faces[new]], P, F)
            off = off_face[fs]
            bad = fs[~(signed_chart_areas(D, faces[fs], r1, b1) > 1e-3 * area0[fs])
                     | _across_a_corner(D, faces[fs], r1, pinned)
                     | around_a_vertex(D, faces[fs], r1, b1)
                     | (off > BEND * np.where(moved[faces[fs]], limit[faces[fs]], np.inf).min(1))]
            back = np.zeros(n, bool)
            back[faces[bad].ravel()] = True
            back &= moved
            if not back.any():
                # A move must not leave another tip farther from the remesh than it was and
                # than the moved sample's own tip was: that trades one cut-off tip for another
                # (cow: a horn's sample taken by its neighbour tip cut the horn 0.45 -> 0.57 %).
                moved_ids = np.flatnonzero(moved)
                d1 = point_triangle_distance(P[tips], X1, faces)[0]
                near_moved = moved_ids[cKDTree(X1[moved_ids]).query(P[tips])[1]]
                worse = (d1 > d * (1 + SNAP_GAIN)) & (d1 > limit[near_moved])
                back[near_moved[worse]] = True
            if not back.any():
                break
            r1[back], b1[back], X1[back] = r[back], b[back], X[back]
            moved &= ~back
            off_face[_faces_around(ptr, corner_order, np.flatnonzero(back))[0]] = np.nan
        if not moved.any():
            break
        keep = moved[s]
        r, b, X = r1, b1, X1
        source[s[keep]] = v[keep]
    X = X_in.copy()
    X[source >= 0] = P_in[source[source >= 0]]
    return r, b, X, source


def _alone(D, faces, ptr, corner_order, r, b, X, pinned, area0, P, F, s, v, vertex_face,
           vertex_bary):
    """Each move of sample ``s[i]`` onto input vertex ``v[i]`` made alone: ``(ok (p,), off
    (p,))``, whether the faces around the sample pass the chart guards, and the farthest
    distance from the input of their points (:func:`bend`).  The moved samples are appended
    as new samples ``n + i``, and each move's faces drawn over them."""
    n, p = X.shape[0], s.size
    fid, pair = _faces_around(ptr, corner_order, s)
    tri = np.where(faces[fid] == s[pair][:, None], (n + pair)[:, None], faces[fid])
    r2 = np.concatenate([r, vertex_face[v]])
    b2 = np.concatenate([b, vertex_bary[v]])
    X2 = np.concatenate([X, P[v]])
    pinned2 = np.concatenate([pinned, np.zeros(p, bool)])
    T, T0 = X2[tri], X[faces[fid]]
    good = ((signed_chart_areas(D, tri, r2, b2) > 1e-3 * area0[fid])
            & ~_across_a_corner(D, tri, r2, pinned2)
            & ~around_a_vertex(D, tri, r2, b2)
            & (longest_edges(T) <= longest_edges(X[faces]).max())
            & (_doubled_areas(T) >= 1e-3 * _doubled_areas(T0)))
    off = np.zeros(p)
    np.maximum.at(off, pair, bend(X2[tri], P, F, _SCREEN_POINTS))
    return np.bincount(pair, ~good, minlength=p) == 0, off


def bend(T: np.ndarray, P: np.ndarray, F: np.ndarray, points: np.ndarray = _FACE_POINTS) -> np.ndarray:
    """``(k,)``: how far each triangle ``T (k, 3, 3)`` (corners on the input) stands off the
    input mesh ``(P, F)``: the largest distance of its barycentric ``points (q, 3)`` (a grid
    of step 1/6 without the corners), units of ``P``."""
    if not T.shape[0]:
        return np.zeros(0)
    pts = np.einsum("pc,fcd->fpd", points, T).reshape(-1, 3)
    return point_triangle_distance(pts, P, F)[0].reshape(T.shape[0], -1).max(1, initial=0.0)


def _faces_around(ptr, corner_order, s):
    """``(faces (q,), owner (q,))``: the faces around each sample ``s[i]`` (from the corners'
    CSR ``ptr``, ``corner_order``), and ``i`` for each."""
    counts = ptr[s + 1] - ptr[s]
    at = np.repeat(ptr[s] - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
    return corner_order[at] // 3, np.repeat(np.arange(s.size), counts)


def longest_edges(T: np.ndarray) -> np.ndarray:
    """``(k,)``: the longest edge of each triangle ``T (k, 3, 3)``."""
    return np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2).max(1)


def _doubled_areas(T: np.ndarray) -> np.ndarray:
    """``(k,)``: twice the area of each triangle ``T (k, 3, 3)``."""
    return np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)


def _across_a_corner(D: BaseDomain, tri: np.ndarray, r: np.ndarray, pinned: np.ndarray) -> np.ndarray:
    """``(k,)``: triangles ``tri (k, 3)`` with two corners, neither a base vertex, in base
    faces that are not the same and share no edge."""
    out = np.zeros(tri.shape[0], bool)
    for a, c in ((0, 1), (1, 2), (2, 0)):
        ra, rc = r[tri[:, a]], r[tri[:, c]]
        Fa, Fc = D.F0[ra], D.F0[rc]
        shared = sum((Fa[:, i, None] == Fc).any(1).astype(np.int64) for i in range(3))
        out |= (ra != rc) & (shared < 2) & ~pinned[tri[:, a]] & ~pinned[tri[:, c]]
    return out
