"""NumPy kernels on triangles: planar orientation, barycentric coordinates, point location, 3D angles.

Shared by the reconstruction (:mod:`jaxparam.points`), the remesh (:mod:`jaxparam.remesh`) and the
closed-mesh charts (:mod:`jaxparam.manifold`).  Everything here is concrete numpy on index
arrays (:func:`barycentric` also takes JAX arrays, ``xp=jax.numpy``); the differentiable
counterparts of the rest live in :mod:`jaxparam.geometry`.
"""
from __future__ import annotations

import numpy as np

from .errors import MeshError, first_few

__all__ = ["orient", "signed_area2", "polygon_area", "doubled_areas", "barycentric", "locate", "cross_norm", "corner_angle",
           "face_angles"]


def orient(U: np.ndarray, a, b, c) -> np.ndarray:
    """Twice the signed area of the planar triangles ``(a, b, c)``: ``U (n, 2)``, ``a, b, c (m,) int``."""
    u, v = U[b] - U[a], U[c] - U[a]
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def signed_area2(uv: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``(m,)`` twice the signed areas of the planar faces ``F (m, 3)`` over ``uv (n, 2)``."""
    return orient(uv, F[:, 0], F[:, 1], F[:, 2])


def polygon_area(P: np.ndarray) -> float:
    """The signed area of the closed planar polygon ``P (k, 2)`` (shoelace; positive when it
    runs counter-clockwise)."""
    return 0.5 * float(np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1]))


def doubled_areas(T: np.ndarray) -> np.ndarray:
    """``(k,)`` twice the signed areas of triangles ``T (k, 3, 2)`` given by their corners
    (``nan`` where a corner is)."""
    return ((T[:, 1, 0] - T[:, 0, 0]) * (T[:, 2, 1] - T[:, 0, 1])
            - (T[:, 1, 1] - T[:, 0, 1]) * (T[:, 2, 0] - T[:, 0, 0]))


def barycentric(T: np.ndarray, p: np.ndarray, *, xp=np) -> np.ndarray:
    """Barycentric coordinates ``(k, 3)`` of points ``p (k, 2)`` in triangles ``T (k, 3, 2)``.

    ``xp`` the array module: ``numpy`` (the default), or ``jax.numpy`` for JAX arrays, where
    the coordinates are then differentiable in ``T`` and ``p`` (:func:`jaxparam.remesh` and
    :func:`jaxparam.fit_surface` use it so)."""
    a, b, c = T[:, 0], T[:, 1], T[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    l1 = ((b[:, 0] - p[:, 0]) * (c[:, 1] - p[:, 1]) - (b[:, 1] - p[:, 1]) * (c[:, 0] - p[:, 0])) / det
    l2 = ((c[:, 0] - p[:, 0]) * (a[:, 1] - p[:, 1]) - (c[:, 1] - p[:, 1]) * (a[:, 0] - p[:, 0])) / det
    return xp.stack([l1, l2, 1.0 - l1 - l2], axis=1)


def locate(uv: np.ndarray, faces: np.ndarray, query: np.ndarray, *, tol: float = 1e-7,
           where: str = "remesh"):
    """Point location in a planar triangulation.

    **Arguments:** ``uv (n, 2)``, ``faces (m, 3)`` (a one-to-one planar triangulation),
    ``query (k, 2)``; ``where`` names the caller in the error message.

    **Returns:** ``(face (k,) int, bary (k, 3))``: the containing face of each query point and
    its barycentric coordinates there (a point on an edge gets one of its faces; a point
    outside by less than ``tol`` in barycentric terms, as rounding leaves points placed on
    the boundary, gets its face with the coordinates clipped).  Raises :class:`MeshError`
    naming the points further outside.

    A uniform grid of about ``m`` cells holds the faces whose bounding box meets each cell;
    each query tests the faces of its cell and keeps the one it is deepest inside.
    """
    uv = np.asarray(uv, np.float64)
    F = np.asarray(faces, np.int64)
    q = np.asarray(query, np.float64)
    T = uv[F]                                               # (m, 3, 2)
    lo, hi = uv[F].min(1), uv[F].max(1)
    box_lo, box_hi = lo.min(0), hi.max(0)
    g = max(1, int(np.sqrt(F.shape[0])))
    cell = np.maximum((box_hi - box_lo) / g, 1e-300)

    def cell_of(x):
        return np.clip(np.floor((x - box_lo) / cell).astype(np.int64), 0, g - 1)

    c0, c1 = cell_of(lo), cell_of(hi)
    nx, ny = c1[:, 0] - c0[:, 0] + 1, c1[:, 1] - c0[:, 1] + 1
    cnt = nx * ny
    tri = np.repeat(np.arange(F.shape[0]), cnt)
    local = np.arange(tri.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    cx = c0[tri, 0] + local % nx[tri]
    cy = c0[tri, 1] + local // nx[tri]
    cid = cx * g + cy
    order = np.argsort(cid, kind="stable")
    cell_faces = tri[order]
    ptr = np.zeros(g * g + 1, np.int64)
    np.cumsum(np.bincount(cid, minlength=g * g), out=ptr[1:])

    qc = cell_of(q)
    qcell = qc[:, 0] * g + qc[:, 1]
    k = ptr[qcell + 1] - ptr[qcell]
    qi = np.repeat(np.arange(q.shape[0]), k)
    cand = cell_faces[np.repeat(ptr[qcell], k) + np.arange(qi.size) - np.repeat(np.cumsum(k) - k, k)]
    bary = barycentric(T[cand], q[qi])
    depth = bary.min(1)
    # Per query, the candidate it is deepest inside: sort by (query, -depth), take the first.
    best = np.lexsort((-depth, qi))
    head = best[np.concatenate([[True], qi[best][1:] != qi[best][:-1]])] if best.size else best
    face = np.full(q.shape[0], -1, np.int64)
    out = np.full((q.shape[0], 3), np.nan)
    face[qi[head]] = cand[head]
    out[qi[head]] = bary[head]
    bad = np.flatnonzero((face < 0) | ~(np.nan_to_num(out.min(1), nan=-np.inf) >= -tol))
    if bad.size:
        raise MeshError(
            f"{where}: {bad.size} sample points lie outside the parameter domain (points "
            f"{first_few(q[bad].round(6).tolist(), limit=3)}); the base domain must lie inside "
            "the parameterization's image: use a convex boundary map (circle, square) or fewer corners.")
    out = np.clip(out, 0.0, None)
    return face, out / out.sum(1, keepdims=True)


def cross_norm(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``|x_i x y_i|`` for rows of ``(m, 3)`` arrays (explicit components: np.cross and
    np.linalg.norm are 2x slower here)."""
    cx = x[:, 1] * y[:, 2] - x[:, 2] * y[:, 1]
    cy = x[:, 2] * y[:, 0] - x[:, 0] * y[:, 2]
    cz = x[:, 0] * y[:, 1] - x[:, 1] * y[:, 0]
    return np.sqrt(cx * cx + cy * cy + cz * cz)


def corner_angle(P: np.ndarray, at, u, v) -> np.ndarray:
    """``(m,)`` 3D angles (radians) at points ``at`` between the directions to ``u`` and ``v``."""
    x, y = P[u] - P[at], P[v] - P[at]
    return np.arctan2(cross_norm(x, y), np.einsum("ij,ij->i", x, y))


def face_angles(P: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``(m, 3)`` 3D angles (radians) at the corners of the faces ``F (m, 3)`` over ``P (n, 3)``."""
    X0, X1, X2 = P[F[:, 0]], P[F[:, 1]], P[F[:, 2]]
    a, b, c = X1 - X0, X2 - X1, X0 - X2
    # |e x f| at every corner is twice the area: one cross product serves all three angles.
    area2 = cross_norm(a, c)
    dots = -np.stack([np.einsum("ij,ij->i", a, c), np.einsum("ij,ij->i", b, a),
                      np.einsum("ij,ij->i", c, b)], axis=1)
    return np.arctan2(area2[:, None], dots)
