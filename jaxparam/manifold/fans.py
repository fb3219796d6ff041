"""Base vertices' fans and base edges' middles contracted: remesh samples pulled towards them.

Near a base vertex the MAPS map behaves like the flattening it was built with (``z -> z^a``,
:mod:`jaxparam.manifold.maps`), and the dyadic samples around the vertex can land far from it on
the surface: on cow at level 4 over 100 base faces, the fan of a base vertex in a concave crease
had edges of 2.3 % of the diagonal where the remesh's median edge is 0.7 %, and its chords were
the remesh's farthest points from the input (0.607 %; rocker-arm's too, 0.554 %).  On
decimated-knight the farthest chords (0.696 %, 3.2 % long) crossed a saddle near the middle of
a base edge.

Each *region* gets a contraction ``alpha``: a base vertex's fan (in every base triangle at
``v``, the samples whose coordinate at ``v`` is ``1 - rho``, ``rho <`` :data:`RADIUS`), or the
middle of a base edge ``(u, w)`` (in both triangles at it, the samples with ``rho = max(|b_u -
b_w|, 2 b_x) <`` :data:`EDGE_RADIUS`, ``x`` the third corner).  ``rho`` is 1-homogeneous about
the region's centre (the vertex; the edge's midpoint), so a sample moving towards the centre
along its ray to ``rho' = rho (alpha + (1 - alpha) s(rho / radius))``, ``s(t) = 3 t^2 - 2 t^3``,
keeps its place on its level set's ray: ``rho'`` grows with ``rho``, has slope ``alpha`` at the
centre and meets ``rho`` with slope 1 at the radius.  Each base triangle is mapped onto itself
and each base edge onto itself (a sample on an edge has the same ``rho`` from either triangle
and stays there), so the samples stay a bijective image of the dyadic grid and keep their
subdivision connectivity.  The regions do not meet: a vertex's needs ``b_v > 0.7``, an edge's
``|b_u - b_w| < 0.4`` and ``b_x < 0.2``.

Each region takes, of :data:`ALPHAS`, the contraction whose remesh stands least far from the
input around it: the larger of the distance from the input of points on the remesh faces with
a corner in its region (:data:`SCREEN_POINTS`) and the distance from the remesh of the input's
points there (its vertices, and :data:`INPUT_GRID` on faces much longer than the remesh's
edges; a margin around the region too, where the faces across its rim stretch).  A
contraction is taken only where it lowers that by :data:`FAN_GAIN` and raises neither of the
two by more.  Only the regions that can decide the Hausdorff distance are tried (a screen of
the midpoints of the faces' longest edges, :data:`SCREEN_SHARE`); all are decided at once (one
pull-back per ``alpha``).
"""
from __future__ import annotations

import numpy as np

from ..distance import grid_barycentric, point_triangle_distance
from .snap import longest_edges

__all__ = ["contract_fans", "chosen_contractions", "regions", "region_count", "base_edges", "ALPHAS", "RADIUS",
           "EDGE_RADIUS", "FAN_GAIN", "SCREEN_POINTS", "SCREEN_SHARE", "IN_SHARE", "INPUT_GRID"]

#: The contractions tried in each region, 1 (none: the distances it is measured against) first.
ALPHAS = (1.0, 0.8, 0.65, 0.5, 0.4, 0.3)
#: The region of a base vertex: samples whose barycentric coordinate at it exceeds ``1 - RADIUS``.
RADIUS = 0.3
#: The region of a base edge: samples within this of its midpoint, ``max(|b_u - b_w|, 2 b_x)``
#: in a base triangle ``(u, w, x)`` (below 2/3 it meets no other edge of the triangle; it meets
#: no vertex's region, where ``b_u > 1 - RADIUS``).
EDGE_RADIUS = 0.4
#: A vertex's fan is contracted only where that lowers its distance by this share.
FAN_GAIN = 0.01
#: Barycentric points on each remesh face where its distance from the input is measured
#: (centroid, edge midpoints, near the corners: the corners lie on the input; without the
#: last three cow's level-4 remesh ended at 0.588 % of the diagonal instead of 0.520 %).
SCREEN_POINTS = np.array([[2, 2, 2], [3, 3, 0], [0, 3, 3], [3, 0, 3], [4, 1, 1], [1, 4, 1],
                          [1, 1, 4]], np.float64) / 6
#: Regions whose screened distance (see :func:`chosen_contractions`) is below this share of the
#: farthest region's are left alone: they do not decide the Hausdorff distance.
SCREEN_SHARE = 0.5
#: After the distances without a contraction, each region's input points closer to the remesh
#: than this share of its farthest one are not measured again.
IN_SHARE = 0.5
#: Points on the input faces more than three times as long as the remesh's median edge where their
#: distance from the remesh is measured (a grid of step 1/8; on decimated-knight's 1,000 faces
#: the 7 points above found 0.33 % of the diagonal where the grid finds 0.53 %).
INPUT_GRID = grid_barycentric(8)


def _nearest_corner(F0: np.ndarray, r: np.ndarray, b: np.ndarray):
    """``(vertex (k,), corner (k,), rho (k,))``: the base vertex of base face ``r`` nearest to each
    point ``b (k, 3)``, its corner there and ``1 -`` the point's coordinate at it."""
    corner = np.argmax(b, 1)
    return F0[r, corner], corner, 1.0 - b[np.arange(r.size), corner]


def base_edges(F0: np.ndarray) -> np.ndarray:
    """``(m0, 3)``: the base edge opposite each corner of each base face, numbered from 0."""
    n0 = int(F0.max()) + 1
    a, b = np.roll(F0, -1, axis=1), np.roll(F0, 1, axis=1)
    key = np.minimum(a, b) * n0 + np.maximum(a, b)
    return np.unique(key.ravel(), return_inverse=True)[1].reshape(F0.shape)


def regions(F0: np.ndarray, r: np.ndarray, b: np.ndarray, scale: float = 1.0):
    """``(region (k,), rho (k,), centre (k, 3), radius (k,))`` of points ``(r, b)``: the region
    (a base vertex ``v``, or ``n0 +`` a base edge's number; -1 for none) whose radius, times
    ``scale``, holds the point, its distance ``rho`` from the region's centre (1-homogeneous
    about it) and the centre's barycentric coordinates in face ``r``."""
    k, n0 = r.size, int(F0.max()) + 1
    vertex, corner, rho_v = _nearest_corner(F0, r, b)
    # About the midpoint of the edge opposite corner c: max(|b_{c+1} - b_{c+2}|, 2 b_c).
    d = np.stack([np.maximum(np.abs(b[:, (c + 1) % 3] - b[:, (c + 2) % 3]), 2.0 * b[:, c])
                  for c in range(3)], 1)
    ce = np.argmin(d, 1)
    rho_e = d[np.arange(k), ce]
    region = np.full(k, -1, np.int64)
    rho, radius, centre = np.zeros(k), np.ones(k), np.zeros((k, 3))
    on_e = rho_e < min(scale * EDGE_RADIUS, 0.5)
    region[on_e] = n0 + base_edges(F0)[r[on_e], ce[on_e]]
    rho[on_e], radius[on_e] = rho_e[on_e], EDGE_RADIUS
    centre[on_e] = 0.5
    centre[on_e, ce[on_e]] = 0.0
    on_v = rho_v < min(scale * RADIUS, 0.45)
    region[on_v] = vertex[on_v]
    rho[on_v], radius[on_v] = rho_v[on_v], RADIUS
    centre[on_v] = 0.0
    centre[on_v, corner[on_v]] = 1.0
    return region, rho, centre, radius


def region_count(F0: np.ndarray) -> int:
    """How many regions :func:`contract_fans` knows: the base vertices, then the base edges."""
    return int(F0.max()) + 1 + int(base_edges(F0).max()) + 1


def contract_fans(F0: np.ndarray, r: np.ndarray, b: np.ndarray, alpha: np.ndarray):
    """``(b' (k, 3), moved (k,) bool)``: samples ``(r (k,), b (k, 3))`` of base faces ``F0``
    with each region contracted by ``alpha[region]`` (``(region_count(F0),)``: the base
    vertices' fans, then the base edges' midpoints; see the module's notes)."""
    r = np.asarray(r, np.int64)
    b = np.array(b, np.float64)
    region, rho, centre, radius = regions(F0, r, b)
    a = np.where(region >= 0, np.asarray(alpha, np.float64)[np.maximum(region, 0)], 1.0)
    moved = (rho > 0) & (region >= 0) & (a != 1.0)
    t = rho[moved] / radius[moved]
    k = a[moved] + (1.0 - a[moved]) * (3.0 * t * t - 2.0 * t ** 3)        # rho' / rho
    b[moved] = centre[moved] + k[:, None] * (b[moved] - centre[moved])
    return b, moved


def chosen_contractions(F0: np.ndarray, G: np.ndarray, r: np.ndarray, b: np.ndarray,
                        X: np.ndarray, lift, P: np.ndarray, Fm: np.ndarray,
                        vertex_face: np.ndarray, vertex_bary: np.ndarray, *,
                        max_edge: float = np.inf, alphas=ALPHAS, gain: float = FAN_GAIN):
    """``alpha (region_count(F0),)``: the contraction of each region, the base vertices' fans
    then the base edges' middles (see the module's notes; 1: none).

    **Arguments:** ``F0 (m0, 3)`` the base faces; ``G (q, 3)`` the remesh faces over samples
    ``r (k,)``, ``b (k, 3)`` whose surface points are ``X (k, 3)``; ``lift(r, b) -> (j, 3)``
    the surface points of base-domain points; ``(P, Fm)`` the input mesh, ``vertex_face``,
    ``vertex_bary`` its vertices' places in the base domain; ``max_edge`` the longest remesh
    edge allowed (units of ``P``)."""
    if alphas[0] != 1.0:
        raise ValueError("chosen_contractions: alphas must start with 1 (no contraction).")
    n_regions = region_count(F0)
    alpha = np.ones(n_regions)
    r = np.asarray(r, np.int64)
    region, _, _, _ = regions(F0, r, np.asarray(b))
    # the regions each face has a corner in (up to three)
    corner_region = region[G]
    faces = np.flatnonzero((corner_region >= 0).any(1))
    if not faces.size:
        return alpha
    # Screen: the midpoint of each face's longest edge (where a chord across a crease stands
    # farthest off); only regions within SCREEN_SHARE of the farthest are tried.
    T = X[G[faces]]
    longest = np.argmax(np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2), 1)
    ends = T[np.arange(faces.size), longest], T[np.arange(faces.size), longest - 1]
    screen = np.zeros(n_regions)
    mid_d = point_triangle_distance(0.5 * (ends[0] + ends[1]), P, Fm)[0]
    for c in range(3):
        own = corner_region[faces, c] >= 0
        np.maximum.at(screen, corner_region[faces[own], c], mid_d[own])
    tried = screen >= SCREEN_SHARE * screen.max()
    faces = faces[(tried[np.maximum(corner_region[faces], 0)] & (corner_region[faces] >= 0)).any(1)]
    pts = SCREEN_POINTS.shape[0]
    # The input's points in the tried regions and a margin around them (the remesh faces
    # across a region's rim stretch): its vertices, and a grid on its faces much longer than
    # the remesh's edges (a coarse input's farthest points from the remesh are inside them).
    iv, _, _, _ = regions(F0, np.asarray(vertex_face, np.int64), np.asarray(vertex_bary), 1.5)
    inside_input = (iv >= 0) & tried[np.maximum(iv, 0)]
    T = P[Fm]
    big = longest_edges(T) > 3.0 * np.median(
        np.linalg.norm(X[G] - X[np.roll(G, 1, axis=1)], axis=2))
    in_faces = np.flatnonzero(inside_input[Fm].any(1) & big)
    in_points = np.concatenate([P[inside_input], np.einsum("pc,fcd->fpd", INPUT_GRID,
                                                          T[in_faces]).reshape(-1, 3)])
    in_owner = np.concatenate([iv[inside_input], np.repeat(
        np.where(inside_input[Fm[in_faces]], iv[Fm[in_faces]], -1).max(1), INPUT_GRID.shape[0])])
    outs, ins = np.zeros((len(alphas), n_regions)), np.zeros((len(alphas), n_regions))
    for i, a in enumerate(alphas):
        Y = X
        if a != 1.0:
            b2, moved = contract_fans(F0, r, b, np.where(tried, a, 1.0))
            Y = X.copy()
            if moved.any():
                Y[moved] = lift(np.asarray(r)[moved], b2[moved])
        T = Y[G[faces]]
        Q = np.einsum("pc,fcd->fpd", SCREEN_POINTS, T).reshape(-1, 3)
        out = point_triangle_distance(Q, P, Fm)[0].reshape(faces.size, pts).max(1)
        # A face longer than the guard allows rules the contraction out (the remesh is kept
        # only if its longest edge stays within max_edge, ManifoldParameterization.remesh).
        out[longest_edges(T) > max_edge] = np.inf
        for c in range(3):
            own = corner_region[faces, c] >= 0
            np.maximum.at(outs[i], corner_region[faces[own], c], out[own])
        if in_points.size:
            d = point_triangle_distance(in_points, Y, G)[0]
            np.maximum.at(ins[i], in_owner, d)
            if i == 0:      # then only each region's farthest points (those that decide it)
                keep = d >= IN_SHARE * ins[0][in_owner]
                in_points, in_owner = in_points[keep], in_owner[keep]
    # Neither way may get farther (a contraction that trades the input's distance from the
    # remesh for the remesh's from the input is refused), and the larger must fall.
    scores = np.maximum(outs, ins)
    scores[(outs > (1.0 + gain) * outs[0]) | (ins > (1.0 + gain) * ins[0])] = np.inf
    best = np.argmin(scores, 0)
    better = scores[best, np.arange(n_regions)] < (1.0 - gain) * scores[0]
    alpha[better] = np.asarray(alphas, np.float64)[best[better]]
    return alpha
