"""The mesh's faces drawn in the base triangles' charts, and point location there.

Every base triangle's chart is the reference triangle :data:`~jaxparam.manifold.charts.REFERENCE`.
A mesh face whose corners lie in different base triangles (as the MAPS route leaves them) is
drawn in the chart of each base triangle it may meet: the neighbours of a base triangle ``r``
around each of its corners ``v`` are unfolded into ``r``'s chart, each a 60-degree sector
around ``v`` (every chart is equilateral), going the shorter way round ``v``.

Charts here are each base triangle's own shape (:func:`base_charts`), so unfolding is an
isometry of the piecewise-flat base domain.  :func:`draw_faces` gives the
:class:`~jaxparam.manifold.ManifoldParameterization` its ``face_uv``; the remesh does not
use these straight drawings (it pulls points back exactly, :class:`~jaxparam.manifold.maps.MapsHistory`).
"""
from __future__ import annotations

import numpy as np

from .. import topology as topo
from ..triangles import doubled_areas
from .charts import REFERENCE

__all__ = ["Unfolding", "base_charts", "unfolding", "draw_faces"]

#: :class:`Unfolding` looks pairs up in a table of ``m0 ** 2`` entries up to this size
#: (1,000 base faces), and searches its sorted keys above.
TABLE_MAX = 1 << 20


class Unfolding:
    """For pairs ``(r, g)`` of base triangles sharing a vertex: ``g``'s corners (in ``g``'s
    corner order) in ``r``'s chart, ``(3, 2)``; :meth:`get` looks pairs up in bulk."""

    def __init__(self, keys: np.ndarray, corners: np.ndarray, m0: int):
        order = np.argsort(keys, kind="stable")
        keys = keys[order]
        first = np.concatenate([[True], keys[1:] != keys[:-1]])
        self.keys, self.corners, self.m0 = keys[first], corners[order][first], m0
        # The search's answer for every pair, looked up instead of searched when the table is
        # small (the relaxation asks about a million pairs per remesh; issue 13).
        self.table = (np.clip(np.searchsorted(self.keys, np.arange(m0 * m0)), 0, self.keys.size - 1)
                      if m0 * m0 <= TABLE_MAX else None)

    def get(self, r: np.ndarray, g: np.ndarray):
        """``(found (k,) bool, corners (k, 3, 2))`` for pairs ``(r[i], g[i])``."""
        q = np.asarray(r, np.int64) * self.m0 + np.asarray(g, np.int64)
        if self.table is not None:
            at = self.table[q]
        else:
            at = np.clip(np.searchsorted(self.keys, q), 0, self.keys.size - 1)
        return self.keys[at] == q, self.corners[at]


def base_charts(B: np.ndarray, F0: np.ndarray) -> np.ndarray:
    """``(m0, 3, 2)``: every base triangle laid flat with its own shape (positions ``B (n0,
    3)``), first corner at the origin, second on the ``+x`` axis, counter-clockwise."""
    P = B[F0]
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    l1 = np.maximum(np.linalg.norm(e1, axis=1), 1e-300)
    x2 = np.einsum("ij,ij->i", e1, e2) / l1
    y2 = np.linalg.norm(np.cross(e1, e2), axis=1) / l1
    C = np.zeros((F0.shape[0], 3, 2))
    C[:, 1, 0] = l1
    C[:, 2, 0], C[:, 2, 1] = x2, np.maximum(y2, 1e-12 * l1)
    return C


def unfolding(F0: np.ndarray, n0: int, charts: np.ndarray | None = None) -> Unfolding:
    """The :class:`Unfolding` of the base domain ``F0 (m0, 3)`` over ``n0`` vertices, each
    base triangle's chart ``charts (m0, 3, 2)`` (default: the reference triangle)."""
    m0 = F0.shape[0]
    if charts is None:
        charts = np.broadcast_to(REFERENCE, (m0, 3, 2))
    t = topo.build(F0, n0, where="manifold_map")
    deg = np.diff(t.ring_ptr)
    pos = np.arange(t.ring_idx.size) - t.ring_ptr[t.ring_row]
    face, corner = t.ring_wedge // 3, t.ring_wedge % 3
    # Corner angle and the two side lengths of each wedge, in its own chart.
    Cw = charts[face]
    ar = np.arange(face.size)
    p0, p1, p2 = Cw[ar, corner], Cw[ar, (corner + 1) % 3], Cw[ar, (corner + 2) % 3]
    d1, d2 = p1 - p0, p2 - p0
    ang = np.arctan2(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0], np.einsum("ij,ij->i", d1, d2))
    len1, len2 = np.linalg.norm(d1, axis=1), np.linalg.norm(d2, axis=1)
    start = np.cumsum(ang) - ang
    start = start - start[t.ring_ptr[t.ring_row]]             # angle where each wedge starts
    total = np.bincount(t.ring_row, weights=ang, minlength=n0)
    # Every ordered pair (i, j) of wedges in one ring.
    cnt = deg[t.ring_row]
    i = np.repeat(np.arange(t.ring_idx.size), cnt)
    j = t.ring_ptr[t.ring_row[i]] + (np.arange(i.size) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    k = deg[t.ring_row[i]]
    s = (pos[j] - pos[i]) % k
    half = k // 2
    back = s > half                                           # the shorter way round
    tot = total[t.ring_row[i]]
    turn = start[j] - start[i]
    turn = turn + np.where(~back & (pos[j] < pos[i]), tot, 0.0) - np.where(back & (pos[j] > pos[i]), tot, 0.0)
    s = np.where(back, s - k, s)
    ci, cj = corner[i], corner[j]
    Pv = p0[i]
    alpha = np.arctan2(d1[i, 1], d1[i, 0])
    a0 = alpha + turn
    a1 = a0 + ang[j]
    C = np.zeros((i.size, 3, 2))
    ai = np.arange(i.size)
    C[ai, cj] = Pv
    C[ai, (cj + 1) % 3] = Pv + len1[j, None] * np.stack([np.cos(a0), np.sin(a0)], 1)
    C[ai, (cj + 2) % 3] = Pv + len2[j, None] * np.stack([np.cos(a1), np.sin(a1)], 1)
    # Pairs sharing an edge appear in two rings with the same unfolding; s == 0 first.
    order = np.argsort(np.abs(s), kind="stable")
    keys = face[i] * np.int64(m0) + face[j]
    U = Unfolding(keys[order], C[order], m0)
    U.charts = np.asarray(charts)
    return U


def draw_faces(faces: np.ndarray, vertex_face: np.ndarray, vertex_bary: np.ndarray, U: Unfolding):
    """Every mesh face drawn in one base triangle's chart, the other corners unfolded into it
    (straight between the corners' images): the chart of the first corner whose base triangle
    gives the face a positive drawing with every corner found, else the first corner's.

    **Arguments:** ``faces (m, 3)`` the mesh's; ``vertex_face (n,)``, ``vertex_bary (n, 3)``
    each vertex's base triangle and barycentric coordinates; ``U`` the base domain's
    :class:`Unfolding` (with its ``charts``).

    **Returns:** ``(region (m,), face_uv (m, 3, 2))``; corners in a base triangle that does
    not share a vertex with the region's (a face larger than the base triangles around it)
    are ``nan``.  Why a choice of chart: unfolding goes the shorter way round each base
    vertex, so a face around a base vertex is drawn differently from each of its corners'
    triangles, and a face reaching two triangles beyond the first corner's is found only from
    a nearer one (drawings turned over or missing at 100 base faces, first corner's chart ->
    chosen: bunny 10 -> 6, cow 122 -> 86, 3holes 8 -> 0, decimated-knight 42 -> 16,
    rocker-arm 16 -> 1)."""
    F = np.asarray(faces, np.int64)
    region, uv = _drawn_in(F, F[:, 0], vertex_face, vertex_bary, U)
    for c in (1, 2):
        bad = ~(doubled_areas(uv) > 0)
        if not bad.any():
            break
        r2, uv2 = _drawn_in(F[bad], F[bad, c], vertex_face, vertex_bary, U)
        good = doubled_areas(uv2) > 0
        take = np.flatnonzero(bad)[good]
        region[take], uv[take] = r2[good], uv2[good]
    return region, uv


def _drawn_in(F, owner, vertex_face, vertex_bary, U):
    """``(region (k,), uv (k, 3, 2))``: faces ``F (k, 3)`` drawn in the chart of the base
    triangle of vertices ``owner (k,)``."""
    region = vertex_face[owner]
    uv = np.zeros((F.shape[0], 3, 2))
    for c in range(3):
        v = F[:, c]
        found, C = U.get(region, vertex_face[v])
        uv[:, c] = np.where(found[:, None], np.einsum("kc,kcd->kd", vertex_bary[v], C), np.nan)
    return region, uv
