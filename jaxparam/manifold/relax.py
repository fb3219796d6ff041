"""Error-driven relaxation of a closed remesh's samples across base edges (the MAPS route).

The dyadic samples of the base domain ``T^0`` mapped by the MAPS map are spread unevenly on
the surface (their spacing varies 0.05-3.3x between base triangles), and the worst input
points sit where they are sparse.  Before the finest level ``L`` is made, the samples of
level ``L - 1`` are relaxed in the base domain, free to cross base edges: each moves to the
weighted mean of its neighbours in its base triangle's chart (the neighbours' triangles
unfolded into it, :class:`~jaxparam.manifold.overlay.Unfolding`), with weights

    ``w_ij = (|x_i - x_j| + c |x_ij - (x_i + x_j) / 2|) / |p_i - p_j|``

(``x`` surface points, ``p`` chart points, ``x_ij`` the surface point of the edge's chart
midpoint, which is the level-``L`` sample on that edge): an edge that is long on the
surface or whose midpoint leaves the chord (curvature, sharp features) pulls its ends
together, so the samples gather where the surface needs them and the interpolation error
evens out.  The base vertices stay put.  A move that would turn a level-``L - 1`` triangle
over in its chart, or leave a neighbour outside the triangles sharing a vertex with it, is
undone (until none does: an undone move can turn over a triangle its neighbour's move left
standing).  The level-``L`` samples are then the chart midpoints of the relaxed edges, each
drawn in a base face that holds both ends where one does (a point on a base edge belongs to
the faces on both sides; drawn from the other side of a base vertex, whose sectors need not
close up, the midpoint landed in the wrong sector: cow had 7 level-4 triangles turned over
in the base domain at 100 base faces, decimated-knight 9; session 24).

Then the finest samples are relaxed too (:data:`FINEST_ITERATIONS` sweeps, their own edges'
midpoints lifted).  The sweeps lift through a :class:`GridLift` (one exact pull-back of a grid
one level finer, then interpolation), since the exact pull-back of every sweep's points was
most of the cost.  Neither relaxation is closer to the input on every mesh, so the remesh
keeps the candidate (plain, relaxed, relaxed at the finest level too) that
:func:`estimated_distance` finds closest.

Only the sample positions in the base domain change: the map of the input onto the base
domain (``vertex_face``, ``vertex_bary``) and its exact inverse are untouched, and the remesh
keeps its subdivision connectivity.  Measured on the closed meshes of ``../shared/data``
(level 4, 100 base faces): see ``benchmarks/README.md``.
"""
from __future__ import annotations

import numpy as np

from .. import topology as topo
from ..distance import point_triangle_distance
from ..host import vertex_normals
from .overlay import base_charts, unfolding

__all__ = ["BaseDomain", "GridLift", "relax_samples", "ITERATIONS", "STEP", "CURVATURE_WEIGHT", "FINEST_ITERATIONS",
           "GRID_MAX_POINTS", "sharpest_vertices", "around_a_vertex", "estimated_distance", "ESTIMATE_POINTS",
           "signed_chart_areas"]

#: Relaxation sweeps, the share of the move taken per sweep, and ``c`` in the weights.
ITERATIONS = 8
STEP = 0.8
CURVATURE_WEIGHT = 10.0

#: Sweeps of the finest level's own samples afterwards (their edges' midpoints lifted too,
#: through a :class:`GridLift`, so they cost about as much as the level ``L - 1`` sweeps).
#: Measured, level 4 at 100 base faces: decimated-knight 1.09 -> 0.94 %, cow 1.00 -> 0.85 %
#: Hausdorff, but bunny 0.72 -> 0.77 %, rocker-arm 0.63 -> 0.73 %: the remesh keeps the
#: candidate closest to the input (``ManifoldParameterization.remesh``).
FINEST_ITERATIONS = 8

#: The finest level's sweeps lift through a :class:`GridLift` of the next level; above this
#: many grid points (level 6 over 1,000 base faces is 8.4M) they are skipped.
GRID_MAX_POINTS = 4_000_000

#: How many of the input's sharpest vertices, and of the remesh's longest edges and largest
#: faces, :func:`estimated_distance` measures exactly.
ESTIMATE_POINTS = 2000


def _bary(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``(k, 3)`` of points ``p (k, 2)`` in triangles ``T (k, 3, 2)``."""
    a, b, c = T[:, 0], T[:, 1], T[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    l0 = ((b[:, 0] - p[:, 0]) * (c[:, 1] - p[:, 1]) - (b[:, 1] - p[:, 1]) * (c[:, 0] - p[:, 0])) / det
    l1 = ((c[:, 0] - p[:, 0]) * (a[:, 1] - p[:, 1]) - (c[:, 1] - p[:, 1]) * (a[:, 0] - p[:, 0])) / det
    return np.stack([l0, l1, 1.0 - l0 - l1], 1)


class BaseDomain:
    """The base domain laid out for moving points across its edges: each base triangle's
    chart (its own shape), the :class:`~jaxparam.manifold.overlay.Unfolding` of the
    triangles sharing a vertex with it, and those triangles, padded, ``near (m0, K)``."""

    def __init__(self, base_positions: np.ndarray, base_faces: np.ndarray):
        F0 = np.asarray(base_faces, np.int64)
        n0 = int(F0.max()) + 1
        self.F0 = F0
        self.charts = base_charts(np.asarray(base_positions, np.float64), F0)
        self.U = unfolding(F0, n0, self.charts)
        t = topo.build(F0, n0, where="manifold_map")
        face = t.ring_wedge // 3                                 # faces around each vertex
        vptr = t.ring_ptr
        # Faces sharing a vertex with face f: the rings of its three corners (with repeats).
        cnt = np.diff(vptr)[F0]                                  # (m0, 3)
        tot = cnt.sum(1)
        K = int(tot.max())
        rows = np.repeat(np.arange(F0.shape[0]), tot)
        corner_v = np.repeat(F0.ravel(), cnt.ravel())
        start = np.repeat(vptr[F0.ravel()], cnt.ravel())
        off = np.arange(corner_v.size) - np.repeat(np.cumsum(cnt.ravel()) - cnt.ravel(), cnt.ravel())
        g = face[start + off]
        near = np.repeat(np.arange(F0.shape[0])[:, None], K, 1)  # pad with the face itself
        slot = np.arange(rows.size) - np.repeat(np.cumsum(tot) - tot, tot)
        near[rows, slot] = g
        self.near = near
        # The face across the edge opposite each corner (each directed edge once, closed).
        a, c = np.roll(F0, -1, axis=1).ravel(), np.roll(F0, 1, axis=1).ravel()
        order = np.argsort(a * n0 + c, kind="stable")
        at = np.searchsorted((a * n0 + c)[order], c * n0 + a)
        self.across = (order[np.clip(at, 0, order.size - 1)] // 3).reshape(F0.shape)

    def other_side(self, r: np.ndarray, b: np.ndarray):
        """``(has (k,), g (k,), b' (k, 3))``: for points ``(r, b)`` on a base edge (one
        coordinate zero), the face across that edge and their coordinates there; the points
        as given elsewhere (``has`` false)."""
        has = (b > 1e-12).sum(1) == 2
        g, bg = np.array(r, np.int64), np.array(b, np.float64)
        e = np.flatnonzero(has)
        g[e] = self.across[r[e], np.argmin(b[e], 1)]
        Fr, Fg = self.F0[r[e]], self.F0[g[e]]
        bg[e] = np.einsum("kgr,kr->kg", (Fg[:, :, None] == Fr[:, None, :]).astype(np.float64), b[e])
        return has, g, bg

    def point(self, r: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Chart points ``(k, 2)`` of barycentric coordinates ``b`` in base faces ``r``."""
        return np.einsum("kc,kcd->kd", b, self.charts[r])

    def carry(self, r: np.ndarray, g: np.ndarray, b: np.ndarray):
        """Points with barycentric coordinates ``b`` in base faces ``g``, drawn in the charts
        of base faces ``r``: ``(found (k,), p (k, 2))`` (not found: ``r`` and ``g`` share no
        vertex)."""
        found, C = self.U.get(r, g)
        return found, np.einsum("kc,kcd->kd", b, C)

    def locate(self, r: np.ndarray, p: np.ndarray):
        """The base face and barycentric coordinates ``((k,), (k, 3))`` of chart points ``p
        (k, 2)`` of base faces ``r``: among the faces sharing a vertex with ``r`` that hold
        every corner of ``r`` on whose side the point lies (so a point past an edge goes to
        the face across it, one past a corner to a face around that corner: unfolded sectors
        around a corner may overlap), the one the point is deepest in, clamped inside.  A point
        strictly inside its own triangle ``r`` stays there (no other face is allowed then), so
        only the others are searched."""
        r = np.asarray(r, np.int64)
        own = _bary(self.charts[r], p)
        out = np.flatnonzero(~((own[:, 0] > 0) & (own[:, 1] > 0) & (own[:, 2] > 0)))
        if out.size < r.size:
            g, b = r.copy(), own
            if out.size:
                g[out], b[out] = self._search(r[out], p[out])
            return g, b
        return self._search(r, p)

    def _search(self, r: np.ndarray, p: np.ndarray):
        """:meth:`locate` among every face sharing a vertex with ``r``."""
        K = self.near.shape[1]
        cand = self.near[r]                                       # (k, K)
        rr, gg = np.repeat(r, K), cand.ravel()
        ok, C = self.U.get(rr, gg)
        bb = _bary(C, np.repeat(p, K, 0))
        side = _bary(self.charts[r], p) > 0                      # (k, 3)
        # Allowed: g holds every corner of r on whose side the point lies (the corners
        # and sides one by one: small-axis reductions were most of the search's time).
        Fg, Fr = self.F0[cand], self.F0[r]                       # (k, K, 3), (k, 3)
        allowed = np.ones(cand.shape, bool)
        for c in range(3):
            v = Fr[:, c, None]
            allowed &= (Fg[:, :, 0] == v) | (Fg[:, :, 1] == v) | (Fg[:, :, 2] == v) | ~side[:, c, None]
        depth = np.where(ok & allowed.ravel(), np.minimum(np.minimum(bb[:, 0], bb[:, 1]), bb[:, 2]),
                         -np.inf).reshape(-1, K)
        pick = np.arange(r.size) * K + depth.argmax(1)
        b = np.clip(bb[pick], 0.0, None)
        return gg[pick], b / b.sum(1, keepdims=True)


class GridLift:
    """A cheap stand-in for an exact ``lift(r, b) -> (k, 3)`` while samples are relaxed: the
    exact lift of a triangular grid of ``N = 2**level`` intervals per base face (one
    pull-back, at the start), then piecewise-linear interpolation in that grid.

    Why: each relaxation sweep lifts every sample and every edge midpoint, and the exact
    pull-back through the decimation's levels was most of a remesh's time (8 sweeps of the
    finest level's 51k points: about 60 % of 8-11 CPU s on cow).  The relaxation only needs
    the surface lengths and the midpoints' distances from the chords for its weights; the
    remesh's vertices are still lifted exactly.  Grid points are exact, so a dyadic sample of
    level at most ``level`` is lifted exactly.

    **Arguments:** ``lift`` the exact lift; ``m0`` the base faces; ``level`` the grid's."""

    def __init__(self, lift, m0: int, level: int):
        N = 2 ** int(level)
        i, j = np.meshgrid(np.arange(N + 1), np.arange(N + 1), indexing="ij")
        keep = (i + j) <= N
        i, j = i[keep], j[keep]
        b = np.stack([i, j, N - i - j], 1) / N
        X = lift(np.repeat(np.arange(m0), i.size), np.tile(b, (m0, 1)))
        self.N = N
        self.X = np.zeros((m0, N + 1, N + 1, 3))
        self.X[:, i, j] = X.reshape(m0, i.size, 3)

    @staticmethod
    def points(m0: int, level: int) -> int:
        """How many points the grid of ``level`` over ``m0`` base faces lifts."""
        N = 2 ** int(level)
        return m0 * (N + 1) * (N + 2) // 2

    def __call__(self, r: np.ndarray, b: np.ndarray) -> np.ndarray:
        N, X = self.N, self.X
        t0, t1 = b[:, 0] * N, b[:, 1] * N
        i0 = np.clip(np.floor(t0).astype(np.int64), 0, N - 1)
        j0 = np.minimum(np.clip(np.floor(t1).astype(np.int64), 0, None), N - 1 - i0)
        f0, f1 = (t0 - i0)[:, None], (t1 - j0)[:, None]
        i1, j1 = i0 + 1, np.minimum(j0 + 1, N - i0)       # the upper cell exists when used
        low = (1 - f0 - f1) * X[r, i0, j0] + f0 * X[r, i1, j0] + f1 * X[r, i0, j0 + 1]
        up = (f0 + f1 - 1) * X[r, i1, j1] + (1 - f0) * X[r, i0, j1] + (1 - f1) * X[r, i1, j0]
        return np.where(f0 + f1 > 1, up, low)


def signed_chart_areas(D: BaseDomain, faces: np.ndarray, r: np.ndarray, b: np.ndarray):
    """Each face's signed area in its first corner's chart (``nan`` when a corner's base
    triangle shares no vertex with the first's)."""
    a = faces[:, 0]
    p0 = D.point(r[a], b[a])
    ok = np.ones(faces.shape[0], bool)
    ps = []
    for c in (1, 2):
        v = faces[:, c]
        found, p = D.carry(r[a], r[v], b[v])
        ok &= found
        ps.append(p)
    d1, d2 = ps[0] - p0, ps[1] - p0
    out = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    return np.where(ok, out, np.nan)


def around_a_vertex(D: BaseDomain, tri: np.ndarray, r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(k,)``: triangles ``tri (k, 3)`` over samples ``(r, b)`` with no base vertex among their
    corners that need three base faces, however each corner on a base edge is written (its
    face or the one across the edge).  Three base faces sharing edges pairwise are the three
    at a base vertex of valence 3, and such a triangle goes around it: it covers the base
    vertex's own triangles.  At a vertex of higher valence two of the faces share no edge,
    which the edge guards catch.  :func:`~jaxparam.manifold.snap.snap_tips` refuses such
    moves.  :func:`relax_samples` does not: its sweeps pull the samples around a stretched
    base vertex of valence 3 towards it from all sides (bunny, level 3 over 100 base faces:
    1-5 such triangles a sweep), and refusing those moves left the samples there unrelaxed
    and the level-4 remesh farther from the input (bunny 0.370 -> 0.456 %, cow 0.502 ->
    0.536 % of the diagonal; session 24)."""
    tri = np.asarray(tri, np.int64)
    pinned = (b[tri] > 1e-12).sum(2) == 1                             # (k, 3)
    _, g, _ = D.other_side(r[tri.ravel()], b[tri.ravel()])
    opts = np.stack([r[tri], g.reshape(tri.shape)], 2)               # (k, 3, 2)
    out = ~pinned.any(1)
    best = np.full(tri.shape[0], 3)
    for a in range(2):
        for c in range(2):
            for e in range(2):
                f0, f1, f2 = opts[:, 0, a], opts[:, 1, c], opts[:, 2, e]
                best = np.minimum(best, 1 + (f1 != f0) + ((f2 != f0) & (f2 != f1)))
    return out & (best >= 3)


def _moved(r1: np.ndarray, b1: np.ndarray, r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(n,)``: the samples whose base face or coordinates differ between ``(r1, b1)`` and
    ``(r, b)``."""
    return (r1 != r) | np.any(b1 != b, axis=1)


def relax_samples(D: BaseDomain, lift, faces: np.ndarray, edges: np.ndarray, r: np.ndarray,
                  b: np.ndarray, *, iterations: int = ITERATIONS, step: float = STEP,
                  curvature: float = CURVATURE_WEIGHT):
    """Relax samples of the base domain (see the module's notes) and give the midpoints of
    their edges.

    **Arguments:** ``D`` the :class:`BaseDomain`; ``lift(r, b) -> (k, 3)`` surface points of
    base faces ``r (k,)`` and barycentric coordinates ``b (k, 3)`` (numpy, concrete);
    ``faces (m, 3)`` and ``edges (e, 2)`` the level-``L - 1`` triangles and their edges over
    the ``n`` samples; ``r (n,)``, ``b (n, 3)`` the samples' base faces and coordinates.

    **Returns:** ``(r (n + e,), b (n + e, 3))``: the relaxed samples, then the chart
    midpoint of each edge (the level-``L`` samples, in :func:`~jaxparam.subdivision.dyadic_refine`'s
    order when ``edges`` are its ``parents``)."""
    r = np.array(r, np.int64)
    b = np.array(b, np.float64)
    n = r.size
    pinned = (b > 1e-12).sum(1) == 1                       # the base vertices
    at_vertex = D.F0[r, np.argmax(b, 1)]
    e0, e1 = edges[:, 0], edges[:, 1]
    # Each edge is drawn in the chart of an end that is not a base vertex (if any).
    swap = pinned[e0] & ~pinned[e1]
    i, j = np.where(swap, e1, e0), np.where(swap, e0, e1)
    hi = np.concatenate([i, j])                            # half-edges (from, to)
    hj = np.concatenate([j, i])

    def seen_from(rs, v, r, b, alt=None):
        """Sample ``v``'s base face and coordinates as seen from base faces ``rs``: a base
        vertex of ``rs``, or a point on an edge of ``rs`` written in the face across it, is
        written in ``rs`` itself (exact, no unfolding around a base vertex, whose sectors
        need not close up).  ``alt``: ``D.other_side(r, b)`` of every sample, if made."""
        rv, bv = r[v].copy(), b[v].copy()
        corner = D.F0[rs] == at_vertex[v][:, None]
        own = pinned[v] & (corner[:, 0] | corner[:, 1] | corner[:, 2])
        rv[own] = rs[own]
        bv[own] = corner[own].astype(np.float64)
        has, g, bg = D.other_side(r[v], b[v]) if alt is None else (a[v] for a in alt)
        across = has & (g == rs) & (rv != rs)
        rv[across], bv[across] = rs[across], bg[across]
        return rv, bv

    def straddling(r, b, es):
        """Whether edges ``es`` have ends in base faces that share no edge (drawn across a
        corner, where unfolded sectors can overlap)."""
        rj, _ = seen_from(r[i[es]], j[es], r, b)
        Fi, Fj = D.F0[r[i[es]]], D.F0[rj]
        shared = np.zeros(es.size, np.int64)
        for a in range(3):
            for c in range(3):
                shared += Fi[:, a] == Fj[:, c]
        return shared < 2

    def midpoints(r, b, alt):
        # Drawn in end i's face, or in the face across the edge i lies on when only that one
        # holds j too: a point on a base edge seen from the other side of a base vertex is
        # unfolded around the vertex, and the midpoint lands in the wrong sector (cow: a
        # level-3 triangle at a base vertex of valence 3, its ends on two edges recorded in
        # the two other faces; its children turned over).
        ri, bi = r[i].copy(), b[i].copy()
        has, g, bg = (a[i] for a in alt)
        switch = (has & (seen_from(ri, j, r, b, alt)[0] != ri)
                  & (seen_from(g, j, r, b, alt)[0] == g))
        ri[switch], bi[switch] = g[switch], bg[switch]
        rj, bj = seen_from(ri, j, r, b, alt)
        found, pj = D.carry(ri, rj, bj)
        pm = 0.5 * (D.point(ri, bi) + pj)
        rm, bm = D.locate(ri, pm)
        bad = ~found                                        # should not happen: keep the end
        rm[bad], bm[bad] = ri[bad], bi[bad]
        return rm, bm

    area0 = np.abs(signed_chart_areas(D, faces, r, b))
    for _ in range(int(iterations)):
        alt = D.other_side(r, b)
        rm, bm = midpoints(r, b, alt)
        X = lift(np.concatenate([r, rm]), np.concatenate([b, bm]))
        Xv, Xm = X[:n], X[n:]
        L3 = np.linalg.norm(Xv[i] - Xv[j], axis=1)
        dev = np.linalg.norm(Xm - 0.5 * (Xv[i] + Xv[j]), axis=1)
        rq, bq = seen_from(r[hi], hj, r, b, alt)
        found, q = D.carry(r[hi], rq, bq)                  # neighbour in the sample's chart
        p = D.point(r, b)
        L2 = np.linalg.norm(p[hi] - q, axis=1)
        w = np.tile((L3 + curvature * dev), 2) / np.maximum(L2, 1e-300)
        w = np.where(found & (L2 > 0), w, 0.0)
        ws = np.bincount(hi, weights=w, minlength=n)
        tgt = np.stack([np.bincount(hi, weights=w * q[:, d], minlength=n) for d in (0, 1)], 1)
        blocked = np.bincount(hi, weights=~found, minlength=n) > 0
        move = np.flatnonzero(~pinned & ~blocked & (ws > 0))
        newp = p[move] + step * (tgt[move] / ws[move, None] - p[move])
        r1, b1 = r.copy(), b.copy()
        r1[move], b1[move] = D.locate(r[move], newp)
        # Undo moves that turn a triangle over (or squeeze it flat) or lose a neighbour, until
        # none does (an undone move can turn over a triangle its neighbour's move left
        # standing; only the triangles and edges at the samples just changed are measured
        # again).  Stopping after a few passes left turned-over triangles behind.
        changed = _moved(r1, b1, r, b)
        while changed.any():
            fs = np.flatnonzero(changed[faces].any(1))
            es = np.flatnonzero(changed[i] | changed[j])
            bad_f = fs[~(signed_chart_areas(D, faces[fs], r1, b1) > 1e-3 * area0[fs])]
            bad_e = es[straddling(r1, b1, es)]
            back = np.zeros(n, bool)
            back[faces[bad_f].ravel()] = True
            back[i[bad_e]] = True
            back[j[bad_e]] = True
            back &= _moved(r1, b1, r, b)
            r1[back], b1[back] = r[back], b[back]
            changed = back
        r, b = r1, b1
    rm, bm = midpoints(r, b, D.other_side(r, b))
    return np.concatenate([r, rm]), np.concatenate([b, bm])


def sharpest_vertices(V: np.ndarray, F: np.ndarray, k: int = ESTIMATE_POINTS) -> np.ndarray:
    """The ``k`` vertices ``(k,)`` of mesh ``(V (n, 3), F (m, 3))`` whose incident faces' normals
    turn furthest from the vertex normal (tips and creases first): where a remesh cuts the
    surface, the input points far from it are there."""
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    vn = vertex_normals(V, F, N)
    nf = N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-300)
    turn = np.zeros(V.shape[0])
    for c in range(3):
        np.maximum.at(turn, F[:, c], 1.0 - np.einsum("ij,ij->i", nf, vn[F[:, c]]))
    return np.argsort(-turn, kind="stable")[:k]


def estimated_distance(V: np.ndarray, F: np.ndarray, sharp: np.ndarray, X: np.ndarray,
                       G: np.ndarray, k: int = ESTIMATE_POINTS) -> float:
    """An estimate of the Hausdorff distance (both ways, units of ``V``) between the input
    ``(V, F)`` and a remesh ``(X (p, 3), G (q, 3))`` whose vertices lie on it: the exact
    distances of the input's ``sharp`` vertices (:func:`sharpest_vertices`) to the remesh and
    of the midpoints of the remesh's ``k`` longest edges, the centroids of its ``k`` largest
    faces and the sharp vertices' closest points on the remesh (a face across a crease) to
    the input.  Cost: ``4 k`` point-to-mesh distances, independent of the sizes."""
    d_in, _, foot = point_triangle_distance(V[sharp], X, G)
    E = np.concatenate([G[:, [0, 1]], G[:, [1, 2]], G[:, [2, 0]]])
    length = np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1)
    area = np.linalg.norm(np.cross(X[G[:, 1]] - X[G[:, 0]], X[G[:, 2]] - X[G[:, 0]]), axis=1)
    e = E[np.argsort(-length, kind="stable")[:2 * k]]            # each edge is there twice
    f = G[np.argsort(-area, kind="stable")[:k]]
    Q = np.concatenate([0.5 * (X[e[:, 0]] + X[e[:, 1]]), X[f].mean(1), foot])
    d_out = point_triangle_distance(Q, V, F)[0]
    return float(max(d_in.max(initial=0.0), d_out.max(initial=0.0)))
