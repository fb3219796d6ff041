"""Polygon faces of OBJ, OFF and PLY files split into triangles (used by every reader).

A polygon of more than three corners is first cleaned of repeated consecutive corners
(cyclically: ``a b c c`` and ``a b c a`` are the triangle ``a b c``, a common way exporters
write triangles in a quad-only format), then split:

- as a fan from its first corner, as always, when every fan triangle turns the same way as
  the polygon (its normal has a positive dot product with the polygon's Newell normal):
  every convex polygon whose fan has no flat triangle, so the triangles of such files do
  not change;
- else (a concave polygon, whose fan would fold back over itself) by ear clipping in the
  polygon's best-fit plane (the plane through its centroid normal to its Newell normal),
  each step cutting the ear of largest smallest angle.

Triangles keep the polygon's orientation.  Triangles (three corners) are kept as written,
repeated vertex or not: the mesh's checks report those by face number, which for triangles
is theirs.  A polygon that collapses to fewer than three distinct corners, visits a vertex
twice, or crosses itself raises a :class:`~jaxparam.errors.MeshError` naming its place in
the file (a well-formed file holding an invalid face, see ``docs/errors.md``).  A polygon
of zero area, with non-finite corners or with two consecutive corners at one position
(unwelded vertices) keeps its fan, as before: the mesh's checks name those (and
``load(validate=False)`` keeps them).

Polygons of one size are tested for the fan, and merged to triangles, at once (NumPy); only
the few left (concave, or invalid) go through the per-polygon loop.
"""
from __future__ import annotations

import itertools

import numpy as np

from .. import tol
from ..errors import DegenerateFaceError, MeshError

__all__ = ["triangulate", "polygon_corners"]

#: Polygons tested for the fan at once (bounds the temporary ``(chunk, k, 3)`` arrays).
_CHUNK = 65536


def polygon_corners(polygons):
    """``(flat (c,) int64, start (p,) int64)``: the polygons' corners one after another and
    where each polygon's begin in ``flat``; ``polygons`` a ``(p, k)`` array or a list of
    index sequences."""
    if isinstance(polygons, np.ndarray) and polygons.ndim == 2:
        p, k = polygons.shape
        return polygons.reshape(-1).astype(np.int64), np.arange(p, dtype=np.int64) * k
    sizes = np.fromiter((len(c) for c in polygons), np.int64, len(polygons))
    flat = np.fromiter(itertools.chain.from_iterable(polygons), np.int64, int(sizes.sum()))
    return flat, np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)


def triangulate(V, polygons, where, *, base: int = 0):
    """Triangles of polygon faces: ``(poly (m,), picks (m, 3))``, each triangle's polygon and
    its three corners as positions in that polygon (so per-corner data, such as texture
    coordinates, follows); triangles in polygon order.

    **Arguments:** ``V (n, 3)`` the vertices (every index in range); ``polygons`` a
    ``(p, k)`` integer array or a list of index sequences (at least three each); ``where(i)``
    the place of polygon ``i`` in the file for messages (``"mesh.obj, line 12"``); ``base``
    added to vertex indices in messages (1 for OBJ, whose file indices start at 1).

    Raises :class:`DegenerateFaceError` for a polygon of fewer than three distinct corners
    or one that visits a vertex twice, :class:`MeshError` for one that crosses itself.
    """
    V = np.asarray(V, np.float64)
    if isinstance(polygons, np.ndarray) and polygons.ndim == 2:
        groups = [(np.arange(polygons.shape[0]), polygons.astype(np.int64))]
    else:
        sizes = np.fromiter((len(c) for c in polygons), np.int64, len(polygons))
        groups = []
        for k in np.unique(sizes):
            idx = np.flatnonzero(sizes == k)
            groups.append((idx, np.asarray([polygons[i] for i in idx], np.int64).reshape(idx.size, k)))
    polys, picks = [], []
    for idx, R in groups:
        k = R.shape[1]
        fan = np.stack([np.zeros(k - 2, np.int64), np.arange(1, k - 1), np.arange(2, k)], 1)
        ok = np.ones(idx.size, bool) if k == 3 else np.concatenate(
            [fan_keeps_orientation(V, R[s:s + _CHUNK]) for s in range(0, idx.size, _CHUNK)])
        polys.append(np.repeat(idx[ok], k - 2))
        picks.append(np.tile(fan, (int(ok.sum()), 1)))
        rest = np.flatnonzero(~ok)
        if rest.size:                       # triangles written as polygons: `f a b c c`, ...
            keep = merged_corners(R[rest])
            three = np.count_nonzero(keep, axis=1) == 3
            polys.append(idx[rest[three]])
            picks.append(np.sort(np.where(keep[three], np.arange(k), k), axis=1)[:, :3])
            rest = rest[~three]
        for r in rest:
            tris = split_polygon(V, R[r], lambda r=r: where(int(idx[r])), base)
            polys.append(np.full(len(tris), idx[r], np.int64))
            picks.append(np.asarray(tris, np.int64).reshape(-1, 3))
    poly = np.concatenate(polys) if polys else np.zeros(0, np.int64)
    pick = np.concatenate(picks) if picks else np.zeros((0, 3), np.int64)
    if len(groups) > 1 or len(polys) > 1:
        order = np.argsort(poly, kind="stable")
        poly, pick = poly[order], pick[order]
    return poly, pick


def fan_keeps_orientation(V, R) -> np.ndarray:
    """``(p,)`` bool: polygons ``R (p, k)`` without a repeated vertex whose fan triangles all
    turn the polygon's way (positive dot product with its Newell normal)."""
    S = np.sort(R, axis=1)
    distinct = ~np.any(S[:, 1:] == S[:, :-1], axis=1)
    P = V[R]
    P = P - P.mean(axis=1, keepdims=True)
    N = np.cross(P, np.roll(P, -1, axis=1)).sum(axis=1)
    T = np.cross(P[:, 1:-1] - P[:, :1], P[:, 2:] - P[:, :1])
    with np.errstate(invalid="ignore"):
        return distinct & np.all(np.einsum("ptj,pj->pt", T, N) > 0, axis=1)


def merged_corners(R) -> np.ndarray:
    """``(p, k)`` bool: the corners of polygons ``R (p, k)`` kept once repeated consecutive
    corners are merged, cyclically (a run keeps its first corner; a closing run equal to the
    first corner goes): ``a b c c`` and ``a b c a`` keep ``a b c``."""
    keep = np.ones(R.shape, bool)
    keep[:, 1:] = R[:, 1:] != R[:, :-1]
    closing = np.flip(np.logical_and.accumulate(np.flip(R == R[:, :1], axis=1), axis=1), axis=1)
    closing[:, 0] = False
    return keep & ~closing


def split_polygon(V, corners, where, base: int = 0) -> list:
    """The triangles of one polygon as position triples into ``corners`` (see the module
    docstring); ``where()`` names its place in the file for messages."""
    c = [int(v) for v in corners]
    pos = np.flatnonzero(merged_corners(np.asarray([c]))[0]).tolist()
    shown = ", ".join(str(v + base) for v in c)
    if len(pos) < 3:
        raise DegenerateFaceError(
            f"{where()}: the polygon with vertices ({shown}) has only {len(pos)} distinct "
            "corner(s) once repeated ones are merged; a face needs three: remove the face or "
            "fix its indices.")
    vals = [c[p] for p in pos]
    if len(set(vals)) < len(vals):
        dup = next(v for i, v in enumerate(vals) if v in vals[:i])
        raise DegenerateFaceError(
            f"{where()}: the polygon with vertices ({shown}) visits vertex {dup + base} twice, "
            "so it is not a simple polygon; split it into simple polygons (or triangles).")
    fan = [[pos[0], pos[t], pos[t + 1]] for t in range(1, len(pos) - 1)]
    if len(pos) == 3:
        return fan
    P = V[vals]
    if not np.all(np.isfinite(P)) or np.any(np.all(P == np.roll(P, -1, axis=0), axis=1)):
        return fan          # non-finite or coincident corners: the mesh's checks name them
    P = P - P.mean(axis=0)
    N = np.cross(P, np.roll(P, -1, axis=0)).sum(axis=0)
    extent2 = float(np.max(np.ptp(P, axis=0))) ** 2
    if np.linalg.norm(N) <= tol.DEGENERATE_AREA_REL * max(extent2, np.finfo(float).tiny):
        return fan                          # no area: the mesh's zero-area check names it
    T = np.cross(P[1:-1] - P[0], P[2:] - P[0])
    if np.all(T @ N > 0):
        return fan
    Q = plane_coordinates(P, N)
    crossing = crossing_edges(Q)
    if crossing is not None:
        i, j = crossing
        raise MeshError(
            f"{where()}: the polygon with vertices ({shown}) crosses itself (its edges "
            f"{vals[i] + base}-{vals[(i + 1) % len(vals)] + base} and "
            f"{vals[j] + base}-{vals[(j + 1) % len(vals)] + base} meet in its plane), so it "
            "cannot be split into triangles; split it into simple polygons (or triangles).")
    tris = ear_clip(Q)
    if tris is None:
        raise MeshError(
            f"{where()}: the polygon with vertices ({shown}) cannot be split into triangles "
            "that keep its orientation (it is nearly flat or folds onto itself in its plane); "
            "split it into triangles in your modeller.")
    return [[pos[a], pos[b], pos[c]] for a, b, c in tris]


def plane_coordinates(P, N) -> np.ndarray:
    """``(k, 2)`` coordinates of the points ``P (k, 3)`` in the plane normal to ``N``, with
    axes ``(u, w)`` such that ``u x w`` points along ``N`` (counter-clockwise is ``N``'s
    turning sense)."""
    n = N / np.linalg.norm(N)
    e = np.zeros(3)
    e[int(np.argmin(np.abs(n)))] = 1.0
    u = np.cross(n, e)
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    return np.stack([P @ u, P @ w], axis=1)


def _orient(a, b, c):
    """Twice the signed area of the triangles ``(a, b, c)`` (arrays of 2D points)."""
    return ((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
            - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))


def crossing_edges(Q, block: int = 256):
    """The first pair ``(i, j)`` of non-adjacent edges (edge ``i`` joins corners ``i`` and
    ``i + 1``) of the closed polygon ``Q (k, 2)`` that cross or touch, or None; edges are
    compared ``block`` at a time against all later ones."""
    k = Q.shape[0]
    E0, E1 = Q, np.roll(Q, -1, axis=0)
    lo, hi = np.minimum(E0, E1), np.maximum(E0, E1)
    for s in range(0, k - 2, block):
        i = np.arange(s, min(s + block, k - 2))[:, None]
        j = np.arange(k)[None, :]
        pair = (j >= i + 2) & ~((i == 0) & (j == k - 1))
        a, b, c, d = E0[i], E1[i], E0[j], E1[j]
        d1, d2, d3, d4 = _orient(a, b, c), _orient(a, b, d), _orient(c, d, a), _orient(c, d, b)
        boxes = np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=2)
        meet = np.argwhere(pair & (d1 * d2 <= 0) & (d3 * d4 <= 0) & boxes)
        if meet.size:
            return int(i[meet[0, 0], 0]), int(meet[0, 1])
    return None


def ear_clip(Q, block: int = 256):
    """Triangles ``[(a, b, c)]`` (corner positions) of the simple counter-clockwise polygon
    ``Q (k, 2)``, cutting at each step the ear of largest smallest angle; None when no ear
    can be cut (a polygon that is not simple, or is flat in places).

    An ear is a convex corner whose triangle holds no other corner (on its edges included);
    only the non-convex corners need testing (a corner inside the triangle means a
    non-convex one inside).  Cutting an ear changes only its two neighbours' ears (corners
    only turn from non-convex to convex), so each step retests those two: O(k r) in all for
    ``r`` non-convex corners, the first test of all ``k`` corners ``block`` at a time."""
    k = Q.shape[0]
    prv, nxt = np.roll(np.arange(k), 1), np.roll(np.arange(k), -1)
    eps = tol.DEGENERATE_AREA_REL * float(np.max(np.ptp(Q, axis=0))) ** 2
    alive = np.ones(k, bool)
    reflex = np.zeros(k, bool)
    quality = np.full(k, -np.inf)               # an ear's smallest angle; -inf: not an ear

    def update(v):
        A, B, C = Q[prv[v]], Q[v], Q[nxt[v]]
        convex = _orient(A, B, C) > eps
        reflex[v] = ~convex
        O = Q[np.flatnonzero(reflex & alive)][None]                     # (1, r, 2)
        ear = convex
        if O.size:
            a, b, c = A[:, None], B[:, None], C[:, None]
            inside = (_orient(a, b, O) >= 0) & (_orient(b, c, O) >= 0) & (_orient(c, a, O) >= 0)
            own = np.all(O == a, axis=2) | np.all(O == b, axis=2) | np.all(O == c, axis=2)
            ear = convex & ~np.any(inside & ~own, axis=1)
        quality[v] = np.where(ear, _smallest_angles(A, B, C), -np.inf)

    every = np.arange(k)
    reflex[:] = _orient(Q[prv], Q, Q[nxt]) <= eps
    for s in range(0, k, block):
        update(every[s:s + block])
    tris = []
    for _ in range(k - 3):
        b = int(np.argmax(quality))
        if quality[b] == -np.inf:
            return None
        a, c = int(prv[b]), int(nxt[b])
        tris.append((a, b, c))
        alive[b], reflex[b], quality[b] = False, False, -np.inf
        nxt[a], prv[c] = c, a
        update(np.array([a, c]))
    b = int(np.flatnonzero(alive)[0])
    last = (int(prv[b]), b, int(nxt[b]))
    if _orient(Q[last[0]], Q[last[1]], Q[last[2]]) <= eps:
        return None
    tris.append(last)
    return tris


def _smallest_angles(A, B, C) -> np.ndarray:
    """The smallest angle (radians) of each triangle ``(A, B, C)`` (arrays ``(c, 2)``)."""
    P = np.stack([A, B, C], axis=1)                  # (c, 3, 2)
    E = np.roll(P, -1, axis=1) - P                  # edges a->b, b->c, c->a
    L = np.linalg.norm(E, axis=2)
    cos = -np.sum(E * np.roll(E, 1, axis=1), axis=2) / np.maximum(L * np.roll(L, 1, axis=1), 1e-300)
    return np.min(np.arccos(np.clip(cos, -1, 1)), axis=1)
