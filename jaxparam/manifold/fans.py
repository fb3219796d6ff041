"""Base vertices' fans contracted: remesh samples near a base vertex pulled towards it.

Near a base vertex the MAPS map behaves like the flattening it was built with (``z -> z^a``,
:mod:`jaxparam.manifold.maps`), and the dyadic samples around the vertex can land far from it on
the surface: on cow at level 4 over 100 base faces, the fan of a base vertex in a concave crease
had edges of 2.3 % of the diagonal where the remesh's median edge is 0.7 %, and its chords were
the remesh's farthest points from the input (0.607 %; rocker-arm's too, 0.554 %).

Each base vertex ``v`` gets a contraction ``alpha_v`` of its fan: in every base triangle at
``v``, a sample whose coordinate at ``v`` is ``1 - rho`` with ``rho <`` :data:`RADIUS` moves
towards ``v`` to ``rho' = rho (alpha + (1 - alpha) s(rho / RADIUS))``, ``s(t) = 3 t^2 - 2 t^3``:
``rho'`` grows with ``rho``, has slope ``alpha`` at ``v`` and meets ``rho`` with slope 1 at
the radius.  Each base triangle is mapped onto itself and each base edge onto itself (a sample
on an edge stays there, where either triangle places it alike), so the samples stay a
bijective image of the dyadic grid and keep their subdivision connectivity; the regions of two
base vertices do not meet (``RADIUS < 1/2``).

Each vertex takes, of :data:`ALPHAS`, the contraction whose remesh stands least far from the
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

__all__ = ["contract_fans", "chosen_contractions", "ALPHAS", "RADIUS", "FAN_GAIN", "SCREEN_POINTS",
           "SCREEN_SHARE", "IN_SHARE", "INPUT_GRID"]

#: The contractions tried at each base vertex (1: none).
ALPHAS = (1.0, 0.8, 0.65, 0.5, 0.4, 0.3)
#: The region of a base vertex: samples whose barycentric coordinate at it exceeds ``1 - RADIUS``.
RADIUS = 0.3
#: A vertex's fan is contracted only where that lowers its distance by this share.
FAN_GAIN = 0.01
#: Barycentric points on each remesh face where its distance from the input is measured
#: (centroid, edge midpoints, near the corners: the corners lie on the input).
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


def contract_fans(F0: np.ndarray, r: np.ndarray, b: np.ndarray, alpha: np.ndarray,
                  radius: float = RADIUS):
    """``(b' (k, 3), moved (k,) bool)``: samples ``(r (k,), b (k, 3))`` of base faces ``F0``
    with each base vertex ``v``'s fan contracted by ``alpha[v]`` (see the module's notes)."""
    r = np.asarray(r, np.int64)
    b = np.array(b, np.float64)
    vertex, corner, rho = _nearest_corner(F0, r, b)
    a = np.asarray(alpha, np.float64)[vertex]
    moved = (rho > 0) & (rho < radius) & (a != 1.0)
    t = rho[moved] / radius
    k = a[moved] + (1.0 - a[moved]) * (3.0 * t * t - 2.0 * t ** 3)        # rho' / rho
    e = np.zeros((int(moved.sum()), 3))
    e[np.arange(e.shape[0]), corner[moved]] = 1.0
    b[moved] = e + k[:, None] * (b[moved] - e)
    return b, moved


def chosen_contractions(F0: np.ndarray, G: np.ndarray, r: np.ndarray, b: np.ndarray,
                        X: np.ndarray, lift, P: np.ndarray, Fm: np.ndarray,
                        vertex_face: np.ndarray, vertex_bary: np.ndarray, *,
                        max_edge: float = np.inf,
                        alphas=ALPHAS, radius: float = RADIUS, gain: float = FAN_GAIN):
    """``alpha (n0,)``: the contraction of each base vertex's fan (see the module's notes).

    **Arguments:** ``F0 (m0, 3)`` the base faces; ``G (q, 3)`` the remesh faces over samples
    ``r (k,)``, ``b (k, 3)`` whose surface points are ``X (k, 3)``; ``lift(r, b) -> (j, 3)``
    the surface points of base-domain points; ``(P, Fm)`` the input mesh, ``vertex_face``,
    ``vertex_bary`` its vertices' places in the base domain; ``max_edge`` the longest remesh
    edge allowed (units of ``P``)."""
    n0 = int(F0.max()) + 1
    alpha = np.ones(n0)
    vertex, _, rho = _nearest_corner(F0, np.asarray(r, np.int64), np.asarray(b))
    inside = rho < radius
    owner = np.where(inside[G], vertex[G], -1).max(1)          # the region a face belongs to
    faces = np.flatnonzero(owner >= 0)
    if not faces.size:
        return alpha
    # Screen: the midpoint of each face's longest edge (where a chord across a crease stands
    # farthest off); only regions within SCREEN_SHARE of the farthest are tried.
    T = X[G[faces]]
    longest = np.argmax(np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2), 1)
    ends = T[np.arange(faces.size), longest], T[np.arange(faces.size), longest - 1]
    screen = np.zeros(n0)
    mid = 0.5 * (ends[0] + ends[1])
    np.maximum.at(screen, owner[faces], point_triangle_distance(mid, P, Fm)[0])
    tried = screen >= SCREEN_SHARE * screen.max()
    faces = faces[tried[owner[faces]]]
    pts = SCREEN_POINTS.shape[0]
    iv, _, irho = _nearest_corner(F0, np.asarray(vertex_face, np.int64), np.asarray(vertex_bary))
    # The input's vertices in the regions and a margin around them (the remesh faces across
    # a region's rim stretch), and points on its faces there (a coarse input's farthest
    # points from the remesh are inside its faces).
    inside_input = (irho < min(1.5 * radius, 0.5)) & tried[iv]
    T = P[Fm]
    big = np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2).max(1) > 3.0 * np.median(
        np.linalg.norm(X[G] - X[np.roll(G, 1, axis=1)], axis=2))
    in_faces = np.flatnonzero(inside_input[Fm].any(1) & big)
    in_points = np.concatenate([P[inside_input], np.einsum("pc,fcd->fpd", INPUT_GRID,
                                                          T[in_faces]).reshape(-1, 3)])
    in_owner = np.concatenate([iv[inside_input], np.repeat(
        np.where(inside_input[Fm[in_faces]], iv[Fm[in_faces]], -1).max(1), INPUT_GRID.shape[0])])
    outs, ins = np.zeros((len(alphas), n0)), np.zeros((len(alphas), n0))
    for i, a in enumerate(alphas):
        Y = X
        if a != 1.0:
            b2, moved = contract_fans(F0, r, b, np.where(tried, a, 1.0), radius)
            Y = X.copy()
            if moved.any():
                Y[moved] = lift(np.asarray(r)[moved], b2[moved])
        T = Y[G[faces]]
        Q = np.einsum("pc,fcd->fpd", SCREEN_POINTS, T).reshape(-1, 3)
        out = point_triangle_distance(Q, P, Fm)[0].reshape(faces.size, pts).max(1)
        # A face longer than the guard allows rules the contraction out (the remesh is kept
        # only if its longest edge stays within max_edge, ManifoldParameterization.remesh).
        out[np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2).max(1) > max_edge] = np.inf
        np.maximum.at(outs[i], owner[faces], out)
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
    better = scores[best, np.arange(n0)] < (1.0 - gain) * scores[0]
    alpha[better] = np.asarray(alphas, np.float64)[best[better]]
    return alpha
