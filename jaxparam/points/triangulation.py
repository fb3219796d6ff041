"""The triangulation steps of :func:`~jaxparam.points.reconstruct_surface`: Delaunay in the
parameter plane, flips towards 3D Delaunay, peeling of bridges and ears, and the largest
manifold disk.  Numpy on concrete arrays; faces ``(m, 3) int64``, anticlockwise in the plane."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components
from scipy.spatial import Delaunay

from .. import topology as topo
from ..errors import PointCloudError
from ..topology import half_edge_twins
from ..triangles import corner_angle, face_angles, orient, polygon_area
from .defaults import CHORD_ROUNDS, CHORD_TOL, EAR_MAX_BASE
from .graph import PointGraph

__all__ = ["delaunay", "onto_chords", "flip_towards_3d_delaunay", "longest_edges", "long_faces",
           "lone_points", "outside_bridges", "interior_holes", "peel_ears", "largest_manifold_disk"]


def delaunay(U: np.ndarray) -> np.ndarray:
    """Delaunay triangles ``(m, 3)`` of planar points ``(N, 2)``, anticlockwise, no zero-area
    ones.  Shewchuk's Triangle (the optional ``triangle`` package: 1M points in about 1 s)
    when it is installed, else SciPy's Qhull (about 13 s for 1M points)."""
    try:
        import triangle
    except ImportError:
        triangle = None
    if triangle is not None:
        F = np.asarray(triangle.triangulate({"vertices": np.array(U, np.float64)}, "Qz")["triangles"], np.int64)
    else:
        F = Delaunay(U).simplices.astype(np.int64)
    cross = orient(U, F[:, 0], F[:, 1], F[:, 2])
    F[cross < 0] = F[cross < 0][:, [0, 2, 1]]
    return F[cross != 0]


def onto_chords(U: np.ndarray, bnd: np.ndarray, *, tol: float = CHORD_TOL) -> np.ndarray | None:
    """The boundary polygon ``bnd (b,)`` with the interior points that lie on its chords
    inserted, or ``None`` when none does.

    The polygon is the map's boundary, ``U[bnd]`` (a convex polygon: points on a circle or a
    square, in order); an interior point lies on the chord ``a-c`` when its distance from the
    chord's line, on the inside, is at most ``tol`` times the chord's length (or it is
    outside).  Delaunay then gives it a face of zero area over that chord.  Such a point lies
    beyond the segment ``a-c`` of its tangent plane: a boundary point the detection missed.
    With the shape-preserving weights, a planar fan with an angular gap ``g > pi`` has 3D
    angles summing to ``2 (2 pi - g)``; scaled to ``2 pi`` the gap becomes exactly ``pi``, so
    the point is the convex combination of the gap's two neighbours alone, on their chord (11
    random points of a plane: a face of parameter area 5.8e-16, 3D area 0.086).  A cluster
    whose neighbours outside it are ``a`` and ``c`` alone lands on the chord too.  Each point
    is inserted between ``a`` and ``c`` (several on one chord in their order along it), so
    that the map gives it its own place on the boundary."""
    N, b = U.shape[0], bnd.size
    B = np.asarray(U[bnd], np.float64)
    mirror = polygon_area(B) < 0
    if mirror:                                     # a clockwise polygon (user's boundary order)
        U, B = U * [1.0, -1.0], B * [1.0, -1.0]
    c = B.mean(0)                                  # inside the convex polygon
    th = np.arctan2(B[:, 1] - c[1], B[:, 0] - c[0])
    th = th[0] + np.mod(th - th[0], 2 * np.pi)
    if np.any(np.diff(th) < 0):                    # not a convex polygon around c: no chords
        return None
    inside = np.ones(N, bool)
    inside[bnd] = False
    iv = np.flatnonzero(inside)
    phi = th[0] + np.mod(np.arctan2(U[iv, 1] - c[1], U[iv, 0] - c[0]) - th[0], 2 * np.pi)
    e = np.clip(np.searchsorted(th, phi, side="right") - 1, 0, b - 1)
    A, C = B[e], B[(e + 1) % b]
    d, w = C - A, U[iv] - A
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    on = d[:, 0] * w[:, 1] - d[:, 1] * w[:, 0] <= tol * length * length
    if not on.any():
        return None
    e, iv, d, w = e[on], iv[on], d[on], w[on]
    t = np.einsum("ij,ij->i", w, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    key_edge = np.concatenate([np.arange(b), e])
    key_t = np.concatenate([np.full(b, -np.inf), t])
    return np.concatenate([bnd, iv])[np.lexsort((key_t, key_edge))]


def _nxt(h):
    """The next half-edge of the same face (``h = 3 f + j``)."""
    return h - h % 3 + (h + 1) % 3


def _prv(h):
    """The previous half-edge of the same face."""
    return h - h % 3 + (h + 2) % 3


def flip_towards_3d_delaunay(F: np.ndarray, P: np.ndarray, U: np.ndarray, rounds: int, *,
                             return_twin: bool = False):
    """Flip interior edges ``a-b`` (faces ``(a, b, c)``, ``(b, a, d)``) whose opposite 3D angles
    at ``c`` and ``d`` sum to more than pi, and to more than the new diagonal's, into
    ``(a, d, c)``, ``(d, b, c)``, when both new faces keep a positive parameter-plane area.
    The planar embedding is kept, so the result still triangulates the same points one-to-one
    in the plane.

    **Arguments:** ``F (m, 3)`` a manifold triangulation, anticlockwise in ``U (N, 2)``;
    ``P (N, 3)`` the points in 3D; at most ``rounds`` rounds.  **Returns:** the new
    ``(m, 3)`` faces (a copy; face ``f`` of a flipped pair stays at row ``f``); with
    ``return_twin`` also their half-edge twins ``(3m,)``
    (:func:`~jaxparam.topology.half_edge_twins` of the new faces, kept up to date).

    Half-edge ``h = 3 f + j`` runs from ``F[f, j]`` to ``F[f, j+1]``; ``twin`` is kept up to
    date through the flips, so after the first round only the edges of flipped faces (and
    candidates that lost a conflict) are looked at again.  Each round flips an independent set:
    a flip claims its two faces and their (up to four) neighbours, the largest excess angle
    first, so no two flips of a round touch the same twins."""
    F = np.array(F, np.int64)
    m = len(F)
    Ff = F.reshape(-1)                      # a view: writes to F show here
    twin = half_edge_twins(F, len(P))
    cand = np.flatnonzero(twin > np.arange(3 * m))
    angles = face_angles(P, F).reshape(-1)             # angles[h]: at corner h % 3 of face h // 3
    nxt, prv = _nxt, _prv
    for _ in range(rounds):
        cand = cand[twin[cand] >= 0]
        h1 = np.sort(np.minimum(cand, twin[cand]))
        h1 = h1[np.concatenate([[True], h1[1:] != h1[:-1]])]
        excess = angles[prv(h1)] + angles[prv(twin[h1])] - np.pi
        over = np.flatnonzero(excess > 1e-9)
        h1, excess = h1[over], excess[over]
        a, b, c, d = Ff[h1], Ff[nxt(h1)], Ff[prv(h1)], Ff[prv(twin[h1])]
        after = corner_angle(P, a, c, d) + corner_angle(P, b, c, d) - np.pi
        scale = np.sum((U[a] - U[b]) ** 2, axis=1) + np.sum((U[c] - U[d]) ** 2, axis=1)
        ok = ((after < excess - 1e-12) & (orient(U, a, d, c) > 1e-12 * scale)
              & (orient(U, d, b, c) > 1e-12 * scale))
        if not ok.any():
            break
        h1, pr = h1[ok], excess[ok]
        h2 = twin[h1]
        outer = twin[np.stack([nxt(h1), prv(h1), nxt(h2), prv(h2)], 1)]   # b-c, c-a, a-d, d-b
        claims = np.concatenate([np.stack([h1 // 3, h2 // 3], 1), np.where(outer >= 0, outer // 3, -1)], 1)
        valid = claims >= 0
        fe = claims[valid]
        ee = np.broadcast_to(np.arange(h1.size)[:, None], claims.shape)[valid]
        best = np.full(m, -np.inf)
        np.maximum.at(best, fe, pr[ee])
        win = np.ones(h1.size, bool)
        np.logical_and.at(win, ee, pr[ee] == best[fe])
        # Equal excesses can leave two winners on one face: the lowest candidate keeps it.
        first = np.full(m, h1.size)
        np.minimum.at(first, fe[win[ee]], ee[win[ee]])
        np.logical_and.at(win, ee, first[fe] == ee)
        lost = h1[~win]
        h1, h2, outer = h1[win], h2[win], outer[win]
        a, b, c, d = Ff[h1], Ff[nxt(h1)], Ff[prv(h1)], Ff[prv(h2)]
        g1, g2 = h1 - h1 % 3, h2 - h2 % 3
        F[g1 // 3] = np.stack([a, d, c], 1)
        F[g2 // 3] = np.stack([d, b, c], 1)
        t_bc, t_ca, t_ad, t_db = outer.T
        twin[g1], twin[g1 + 1], twin[g1 + 2] = t_ad, g2 + 2, t_ca
        twin[g2], twin[g2 + 1], twin[g2 + 2] = t_db, t_bc, g1 + 1
        for t, h in ((t_ad, g1), (t_ca, g1 + 2), (t_db, g2), (t_bc, g2 + 1)):
            twin[t[t >= 0]] = h[t >= 0]
        changed = np.concatenate([g1, g2]) // 3
        angles.reshape(m, 3)[changed] = face_angles(P, F[changed])
        cand = np.concatenate([g1, g1 + 1, g1 + 2, g2, g2 + 1, g2 + 2, lost])
    return (F, twin) if return_twin else F


def peel_ears(F: np.ndarray, P: np.ndarray, graph: PointGraph, *, min_angle: float = 0.45 * np.pi,
              rounds: int = 3, max_base: float = EAR_MAX_BASE, twin: np.ndarray | None = None,
              alive: np.ndarray | None = None, return_mask: bool = False) -> np.ndarray:
    """Remove boundary "ears" that cover empty space: a face ``(b1, b2, p)`` whose edge
    ``b1-b2`` is on the boundary and whose third vertex ``p`` is not, when none of ``p``'s
    neighbours in ``graph`` lies inside the face's angle at ``p`` (seen in ``p``'s tangent
    plane) and that angle is at least ``min_angle`` (regular boundary faces have apex
    angles near 45 or 60 degrees; on camelhead.xyz exactly the three ears reach 81).  Such
    a face spans a concave notch of the boundary whose point ``p`` the boundary detection
    missed; peeling it puts ``p`` on the boundary.  Each round peels faces with no vertex in
    common, so the result stays a manifold disk.

    Only ears whose boundary edge ``b1-b2`` is at most ``max_base`` times ``p``'s spacing
    are peeled: a densely sampled boundary with a point far inside is a notch of the surface
    (camelhead.xyz's three: 0.81-1.03), while a longer base is a sparse boundary whose
    triangle covers the surface (on 20k-point sets with eightfold density, peeling those left
    the source up to 1.9 % of the diagonal from the faces instead of 1.3 %).

    ``alive (m,) bool``: peel only within these faces (default: all); ``twin``: the
    :func:`~jaxparam.topology.half_edge_twins` of all of ``F``, if known.
    **Returns:** the faces kept, in order (``return_mask``: ``(m,) bool``, which faces)."""
    n, m = len(P), len(F)
    deg = np.diff(graph.indptr)
    src, dst, opp = F.reshape(-1), F[:, [1, 2, 0]].reshape(-1), F[:, [2, 0, 1]].reshape(-1)
    twin = half_edge_twins(F, n) if twin is None else twin
    alive = np.ones(m, bool) if alive is None else alive.copy()
    for _ in range(rounds):
        # Boundary half-edges: alive, with no alive face across.
        bd = np.flatnonzero(np.repeat(alive, 3) & ((twin < 0) | ~alive[np.maximum(twin, 0) // 3]))
        on_bd = np.zeros(n, bool)
        on_bd[src[bd]] = True
        h = bd[~on_bd[opp[bd]]]
        faces = h // 3
        h = h[np.bincount(faces, minlength=m)[faces] == 1]   # one boundary edge only
        if h.size == 0:
            break
        b1, b2, p = src[h], dst[h], opp[h]
        # The neighbours of each apex, padded with the apex's b1 (ignored below).
        width_max = int(deg[p].max())
        col = np.arange(width_max)
        near = graph.indices[np.minimum(graph.indptr[p][:, None] + col, graph.indices.size - 1)]
        near = np.where(col < deg[p][:, None], near, b1[:, None])
        nrm = graph.normal[p]
        ref = np.where(np.abs(nrm[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
        e1 = np.cross(nrm, ref)
        e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
        e2 = np.cross(nrm, e1)

        def angle(q):                                       # (c, m) angles of points q around p
            d = P[q] - P[p][:, None, :]
            return np.arctan2(np.einsum("cmd,cd->cm", d, e2), np.einsum("cmd,cd->cm", d, e1))

        t1, t2 = angle(b1[:, None])[:, 0], angle(b2[:, None])[:, 0]
        width = np.mod(t2 - t1, 2 * np.pi)
        start = np.where(width > np.pi, t2, t1)
        width = np.where(width > np.pi, 2 * np.pi - width, width)
        rel = np.mod(angle(near) - start[:, None], 2 * np.pi)
        others = (near != b1[:, None]) & (near != b2[:, None])
        inside = others & (rel > 1e-6) & (rel < width[:, None] - 1e-6)
        short = np.linalg.norm(P[b1] - P[b2], axis=1) <= max_base * graph.spacing[p]
        ear = np.flatnonzero((width >= min_angle) & ~inside.any(axis=1) & short)
        if ear.size == 0:
            break
        # Independent: no two peeled faces share a vertex in this round.
        verts = np.stack([b1[ear], b2[ear], p[ear]], 1)
        first = np.full(n, ear.size)
        np.minimum.at(first, verts.reshape(-1), np.repeat(np.arange(ear.size), 3))
        ok = np.all(first[verts] == np.arange(ear.size)[:, None], axis=1)
        alive[h[ear[ok]] // 3] = False
    return alive if return_mask else F[alive]


def longest_edges(F: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``(m,)``: the longest 3D edge of each face ``F (m, 3)`` over points ``P (N, 3)``."""
    L = np.stack([np.linalg.norm(P[F[:, i]] - P[F[:, (i + 1) % 3]], axis=1) for i in range(3)], 1)
    return L.max(1)


def long_faces(F: np.ndarray, P: np.ndarray, spacing: np.ndarray, factor: float,
               reduce=np.median, *, longest: np.ndarray | None = None) -> np.ndarray:
    """``(m,) bool``: the faces ``F (m, 3)`` whose longest 3D edge exceeds ``factor`` times the
    ``reduce`` (median, or min) of the ``spacing (N,)`` of their three vertices (``P (N, 3)``;
    not the mean, so that a vertex off the surface, whose own spacing is large, does not
    excuse its faces).  ``longest (m,)``: :func:`longest_edges` of ``F`` already computed."""
    longest = longest_edges(F, P) if longest is None else longest
    if reduce is np.median:        # the middle of three, exactly (np.median's sort: 10x slower)
        a, b, c = spacing[F[:, 0]], spacing[F[:, 1]], spacing[F[:, 2]]
        local = np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))
    else:
        local = reduce(spacing[F], axis=1)
    return longest > factor * local


def lone_points(F: np.ndarray, long: np.ndarray, n: int, keep: np.ndarray) -> np.ndarray:
    """The vertices (increasing, not in ``keep``) of the faces ``F (m, 3)`` over ``n`` vertices
    all of whose faces are ``long (m,) bool``: points off the surface that every triangle to
    them bridges."""
    faces = np.bincount(F.reshape(-1), minlength=n)
    longs = np.bincount(F[long].reshape(-1), minlength=n)
    lone = (faces > 0) & (longs == faces)
    lone[keep] = False
    return np.flatnonzero(lone)


def _bad_neighbours(bad: np.ndarray, twin: np.ndarray):
    """``(a, b)``: the pairs of faces both flagged ``bad (m,) bool`` that share an edge, each
    pair once (``twin`` the faces' :func:`~jaxparam.topology.half_edge_twins`)."""
    h = np.flatnonzero(twin > np.arange(twin.size))          # each interior edge once
    a, b = h // 3, twin[h] // 3
    both = bad[a] & bad[b]
    return a[both], b[both]


def outside_bridges(F: np.ndarray, bad: np.ndarray, n: int, *,
                    twin: np.ndarray | None = None) -> np.ndarray:
    """``(m,) bool``: the faces flagged ``bad (m,) bool`` that reach the triangulation's
    outside through bad faces only (``F (m, 3)`` manifold over ``n`` vertices; ``twin`` its
    :func:`~jaxparam.topology.half_edge_twins`, if known)."""
    m = len(F)
    twin = half_edge_twins(F, n) if twin is None else twin
    a, b = _bad_neighbours(bad, twin)
    hull_faces = np.unique(np.flatnonzero(twin < 0) // 3)
    hull_faces = hull_faces[bad[hull_faces]]
    out = m
    rows = np.concatenate([a, b, np.full(hull_faces.size, out)])
    cols = np.concatenate([b, a, hull_faces])
    G = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(m + 1, m + 1))
    reached = breadth_first_order(G, out, directed=False, return_predecessors=False)
    mask = np.zeros(m + 1, bool)
    mask[reached] = True
    return mask[:m]


def interior_holes(F: np.ndarray, P: np.ndarray, bad: np.ndarray, rim: np.ndarray,
                   spacing: np.ndarray, *, share: float, inradius: float, faces: int,
                   twin: np.ndarray | None = None) -> np.ndarray:
    """``(m,) bool``: the faces flagged ``bad (m,) bool`` (too long, and not peeled from the
    outside) that span a hole inside the sampled surface.

    The bad faces fall into groups joined by edges.  A group spans a hole when it has at
    least ``faces`` faces, at least ``share`` of its vertices are ``rim (N,) bool`` points
    (an angular gap in their neighbourhood: the hole's edge), and its fattest face's 3D
    inradius is at least ``inradius`` times the median ``spacing (N,)`` of the group's
    vertices (an empty disk, not a sliver: long thin faces across a crease, or where two
    sheets of the surface lie close, have vertices that see neighbours all around, and the
    faces next to an outlier or a sparse patch are thin).  ``F (m, 3)`` manifold over the
    points ``P (N, 3)``; ``twin`` its :func:`~jaxparam.topology.half_edge_twins`, if known."""
    m, n = len(F), len(P)
    if not bad.any():
        return np.zeros(m, bool)
    twin = half_edge_twins(F, n) if twin is None else twin
    a, b = _bad_neighbours(bad, twin)
    G = sp.csr_matrix((np.ones(2 * a.size), (np.r_[a, b], np.r_[b, a])), shape=(m, m))
    _, label = connected_components(G, directed=False)
    ids = np.flatnonzero(bad)
    group = label[ids]
    # Each group's distinct vertices: how many, how many on a rim, their median spacing.
    pairs = np.unique(np.c_[np.repeat(group, 3), F[ids].reshape(-1)], axis=0)
    total = np.bincount(pairs[:, 0], minlength=m)
    on_rim = np.bincount(pairs[:, 0], weights=rim[pairs[:, 1]], minlength=m)
    order = np.lexsort((spacing[pairs[:, 1]], pairs[:, 0]))
    first = np.searchsorted(pairs[order, 0], np.arange(m))
    median = np.zeros(m)
    has = total > 0
    median[has] = spacing[pairs[order, 1]][first[has] + (total[has] - 1) // 2]
    # The fattest face of each group: inradius = 2 area / perimeter.
    X = P[F[ids]]
    e = np.linalg.norm(X - np.roll(X, -1, axis=1), axis=2)
    area2 = np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)
    fattest = np.zeros(m)
    np.maximum.at(fattest, group, area2 / np.maximum(e.sum(1), 1e-300))
    count = np.bincount(group, minlength=m)
    hole = (count >= faces) & (on_rim >= share * np.maximum(total, 1)) & (fattest >= inradius * median)
    return bad & hole[label]


def largest_manifold_disk(F: np.ndarray, n: int, *, max_rounds: int = 50,
                          twin: np.ndarray | None = None, alive: np.ndarray | None = None):
    """Make a subset ``F (m, 3)`` of a planar triangulation over ``n`` vertices a manifold
    disk: drop the faces at vertices where the boundary touches itself (more than two
    boundary edges: a bowtie left by the peeling), then keep the largest edge-connected
    component, until neither is left (at most ``max_rounds`` times).

    ``alive (m,) bool``: start from these faces of ``F`` (default: all); ``twin``: the
    :func:`~jaxparam.topology.half_edge_twins` of all of ``F``, if known.

    **Returns:** ``(faces, topology)``, the faces kept in their order and their
    :class:`~jaxparam.topology.Topology`."""
    # A face subset's twins: these, or -1 across a gap.
    twin = half_edge_twins(F, n) if twin is None else twin
    src = F.reshape(-1)
    alive = np.ones(len(F), bool) if alive is None else alive.copy()
    for _ in range(max_rounds):
        # Boundary half-edges leaving each vertex: more than one at a bowtie.
        bd = np.repeat(alive, 3) & ((twin < 0) | ~alive[np.maximum(twin, 0) // 3])
        bowtie = np.bincount(src[bd], minlength=n) > 1
        if bowtie.any():
            alive &= ~bowtie[F].any(1)
            continue
        t = topo.build(F[alive], n, where="reconstruct_surface")
        if t.n_components > 1:
            big = int(np.argmax(np.bincount(t.components[t.components >= 0])))
            alive[np.flatnonzero(alive)[t.components[F[alive][:, 0]] != big]] = False
            continue
        return F[alive], t
    raise PointCloudError("reconstruct_surface: could not extract a manifold disk from the "
                          "triangulation; try a larger k or bridge_factor.")
