"""Neighbourhoods of unorganized points: kNN graphs, tangent frames, angular fans, steep-pair
pruning, angular gaps and the Morton (Z-curve) order the large computations run in.

Everything here is numpy on concrete points: neighbourhoods are topology, computed once
and handed to the JAX parts (weights, solve) as index arrays.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..blocks import for_blocks
from ..errors import PointCloudError, first_few
from ..options import is_integer
from ..topology import permute_rows
from .defaults import K, K_DETECT, K_FRAME, MAX_SLOPE, MIN_NORMAL_DOT
from .orientation import orient_normals, warn_non_orientable

__all__ = ["BLOCK", "nearest_neighbours", "knn_graph", "PointGraph", "point_graph", "point_graph_in_order",
           "tangent_frames", "drop_steep_pairs", "global_frame", "spatial_order", "morton_keys",
           "angular_gaps", "knn_gaps", "robust_frames", "refresh_frames", "Frames",
           "unreachable"]

#: Points per block in the dense neighbourhood computations: the (block, k, 3) temporaries
#: stay in cache instead of streaming (N, k, 3) arrays through memory (1M points: 4 s -> ~1 s).
BLOCK = 1 << 15

#: Rows per block in the dense ``(block, k, 3)`` computations (robust frames, angular gaps, steep
#: pairs): smaller still, about 2 MB temporaries (100k points: 25 % faster than :data:`BLOCK`).
#: Every row is computed on its own, so the block size does not change any result.
DENSE_BLOCK = 1 << 12


def nearest_neighbours(P: np.ndarray, k: int):
    """``(dist (N, k), idx (N, k))``: each point's ``k`` nearest other points, nearest first."""
    dist, idx = cKDTree(P).query(P, k + 1, workers=-1)
    return dist[:, 1:], idx[:, 1:]


def knn_graph(points, k: int = K, *, radius: float | None = None, symmetric: bool = True,
              nearest=None):
    """The neighbour graph G of §8 as a CSR ``(indptr (N+1,), indices)``, self excluded,
    column indices sorted in each row.

    ``k`` nearest neighbours (or all within ``radius``); ``symmetric`` adds
    ``v -> w`` whenever ``w -> v``; ``nearest`` an ``(N, >= k)`` index array of
    nearest neighbours already queried.
    """
    P = np.asarray(points, np.float64)
    N = P.shape[0]
    if radius is not None:
        pairs = cKDTree(P).query_pairs(radius, output_type="ndarray")
        rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
        cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
        G = sp.csr_matrix((np.ones(rows.size, np.int8), (rows, cols)), shape=(N, N))
        G.sum_duplicates()
    else:
        idx = nearest_neighbours(P, k)[1] if nearest is None else np.asarray(nearest)[:, :k]
        # Rows of exactly k sorted columns are already a canonical CSR; G + G^T merges in
        # linear time (a COO build of the 2Nk symmetric entries sorts them: 5x slower).
        G = sp.csr_matrix((np.ones(idx.size, np.int8), np.sort(idx, axis=1).reshape(-1),
                           np.arange(0, idx.size + 1, k)), shape=(N, N))
        if symmetric:
            G = (G + G.T.tocsr()).tocsr()
    G.sort_indices()
    return G.indptr.astype(np.int64), G.indices.astype(np.int64)


@dataclass(frozen=True, eq=False)
class PointGraph:
    """Neighbour fans of a point set (numpy, from concrete points).

    **Fields** (``N`` points):

    - ``indptr (N+1,)``, ``indices``: each point's neighbours as CSR rows, sorted
      anticlockwise around it in its PCA tangent plane (a star-shaped fan);
    - ``gap (N,)``: the largest angular gap between consecutive fan neighbours (radians);
    - ``normal (N, 3)``: unit normals, oriented consistently over the neighbour graph
      (:func:`~jaxparam.points.orientation.orient_normals`), each component turned towards
      the best-fit plane's normal;
    - ``spacing (N,)``: the mean distance to the fan's neighbours;
    - ``detect_k``: how many nearest neighbours ``detect_gap`` and ``detect_spacing`` were
      computed for (0: not computed, both ``None``);
    - ``detect_gap (N,)``, ``detect_spacing (N,)``: the same gap and spacing for the
      ``detect_k`` nearest neighbours (boundary detection).
    """

    indptr: np.ndarray
    indices: np.ndarray
    gap: np.ndarray
    normal: np.ndarray
    spacing: np.ndarray
    detect_k: int = 0
    detect_gap: np.ndarray | None = None
    detect_spacing: np.ndarray | None = None

    @property
    def n_points(self) -> int:
        """The number of points ``N`` (rows of the graph)."""
        return self.indptr.size - 1

    @property
    def rows(self) -> np.ndarray:
        """``(nnz,)`` the row (centre point) of each entry of ``indices``."""
        return np.repeat(np.arange(self.indptr.size - 1), np.diff(self.indptr))


def point_graph(points, k: int = K, *, radius: float | None = None, symmetric: bool = True,
                k_detect: int = K_DETECT, max_slope: float = MAX_SLOPE) -> PointGraph:
    """Neighbours, tangent planes and angularly sorted fans of every point; with ``k`` nearest
    neighbours, also the angular gaps of the ``k_detect`` nearest (for
    :func:`~jaxparam.points.detect_boundary`) from the same tree query (0 skips them).

    Neighbour pairs that leave either point's tangent plane steeply (``|n . d| / |d| >
    max_slope``, about 37 degrees by default) are dropped: on a part of the surface
    thinner than the point spacing they join its two sides (a thin part of
    camelhead.xyz's head), and the map folds that part onto itself.  ``max_slope=1`` keeps
    every pair.

    Computed in Morton order (:func:`point_graph_in_order`) and returned in the input's order.
    """
    P0 = np.asarray(points, np.float64)
    if P0.ndim != 2 or P0.shape[1] != 3:
        raise PointCloudError(f"point_graph: points must be an (N, 3) array, got shape {P0.shape}.")
    N = P0.shape[0]
    if radius is None and (not is_integer(k) or not 1 <= k < N):
        raise PointCloudError(f"point_graph: k (neighbours per point) must be an integer in "
                              f"[1, {N}) for {N} points, got {k!r}; the default is {K}.")
    # Work in a space-filling-curve order, so that neighbours sit close in memory (the tree
    # query and the gathers run 1.3-2x faster on a large shuffled cloud); every result is
    # mapped back to the input's order at the end.
    perm = spatial_order(P0)
    G = point_graph_in_order(P0[perm], k, radius=radius, symmetric=symmetric, k_detect=k_detect,
                             max_slope=max_slope, names=perm)
    # Back to the input's order: row v of the result is row inv[v] here, neighbours renamed.
    inv = np.empty(N, np.int64)
    inv[perm] = np.arange(N)
    ptr, src = permute_rows(G.indptr, inv)
    back = lambda x: None if x is None else x[inv]      # noqa: E731
    return PointGraph(ptr, perm[G.indices[src]], G.gap[inv], G.normal[inv], G.spacing[inv],
                      G.detect_k, back(G.detect_gap), back(G.detect_spacing))


def point_graph_in_order(P: np.ndarray, k: int = K, *, radius: float | None = None,
                         symmetric: bool = True, k_detect: int = K_DETECT,
                         max_slope: float = MAX_SLOPE, names: np.ndarray | None = None,
                         nearest=None, frames: Frames | None = None,
                         exempt: np.ndarray | None = None) -> PointGraph:
    """:func:`point_graph` computed in the points' own order, without reordering (fast when
    that order is spatially coherent, e.g. :func:`spatial_order`'s).

    ``names[i]`` is point ``i``'s index in the user's order, for messages (default: ``i``);
    ``nearest = (dist (N, q), near (N, q))`` neighbours already queried (``q >= max(k,
    k_detect, K_FRAME)``), ``frames`` their :func:`robust_frames`; ``exempt (N,) bool`` the
    points whose steep pairs are kept (:func:`drop_steep_pairs`).  With ``k`` neighbours the
    tangent frames are :func:`robust_frames` of the ``K_FRAME`` nearest; with ``radius``, the
    PCA of the graph's neighbours.
    """
    N = P.shape[0]
    names = np.arange(N) if names is None else np.asarray(names)
    k_detect = min(k_detect, N - 1) if radius is None else 0
    if radius is None and nearest is None:
        nearest = nearest_neighbours(P, min(max(k, k_detect, K_FRAME), N - 1))
    dist, near = nearest if radius is None else (None, None)
    indptr, indices = knn_graph(P, k, radius=radius, symmetric=symmetric, nearest=near)
    _check_degree(indptr, names, 2)
    if radius is None:
        frames = robust_frames(P, near[:, :K_FRAME]) if frames is None else frames
        normal, e1, e2 = frames.normal, frames.e1, frames.e2
    else:
        normal, e1, e2 = tangent_frames(P, indptr, indices)
    # Signs propagated over the graph (not only turned towards the best-fit plane), so that
    # the two sides of a part thinner than the spacing get opposed normals ...
    flip = np.einsum("ij,ij->i", orient_normals(P, indptr, indices, normal, global_frame(P)[2]),
                     normal) < 0
    if flip.any():
        normal, e1 = np.where(flip[:, None], -normal, normal), np.where(flip[:, None], -e1, e1)
    if max_slope < 1:
        # ... and pairs between them (opposed normals) leave the graph with the steep ones.
        counts = {}
        indptr, indices = drop_steep_pairs(P, indptr, indices, normal, max_slope, exempt,
                                           min_dot=MIN_NORMAL_DOT, counts=counts)
        warn_non_orientable(counts["opposed"], N, k if radius is None else None)
        _check_degree(indptr, names, 2)
    deg = np.diff(indptr)
    gap, spacing = np.empty(N), np.empty(N)
    fans = np.empty_like(indices)

    def fan_block(r0, r1):
        lo, hi = indptr[r0], indptr[r1]
        ptr, dg, idx = indptr[r0:r1 + 1] - lo, deg[r0:r1], indices[lo:hi]
        starts = ptr[:-1]
        D = P[idx] - np.repeat(P[r0:r1], dg, axis=0)
        ang = np.arctan2(np.einsum("ij,ij->i", D, np.repeat(e2[r0:r1], dg, axis=0)),
                         np.einsum("ij,ij->i", D, np.repeat(e1[r0:r1], dg, axis=0)))
        spacing[r0:r1] = np.add.reduceat(np.sqrt(np.einsum("ij,ij->i", D, D)), starts) / dg
        # One sort on a combined key (row, then angle): ang + pi lies in [0, 2 pi] < 8; np.lexsort
        # on two keys is 4x slower.
        rows = np.repeat(np.arange(r1 - r0), dg)
        order = np.argsort(rows * 8.0 + (ang + np.pi))
        fans[lo:hi], ang = idx[order], ang[order]
        # Largest angular gap per point (including the wrap-around one).
        nxt = np.arange(hi - lo) + 1
        nxt = np.where(nxt >= ptr[rows + 1], ptr[rows], nxt)
        gap[r0:r1] = np.maximum.reduceat(np.mod(ang[nxt] - ang, 2 * np.pi), starts)

    for_blocks(fan_block, N, BLOCK)                # blocks of rows: temporaries stay in cache
    indices = fans
    extra = ((k_detect,) + angular_gaps(P, dist[:, :k_detect], near[:, :k_detect], frame=(e1, e2))
             if k_detect else (0, None, None))
    return PointGraph(indptr, indices, gap, normal, spacing, *extra)


def _check_degree(indptr: np.ndarray, names: np.ndarray, least: int) -> None:
    lonely = np.sort(names[np.diff(indptr) < least])
    if lonely.size:
        raise PointCloudError(f"meshless_map: points {first_few(lonely)} have fewer than {least} "
                              "neighbours; increase k or radius.")


def tangent_frames(P: np.ndarray, indptr: np.ndarray, indices: np.ndarray):
    """Tangent frames ``(normal, e1, e2)``, each ``(N, 3)``: PCA of each point's neighbours
    (CSR rows, at least two each), normals turned towards the global best-fit plane's
    normal, right-handed."""
    N = P.shape[0]
    deg = np.diff(indptr)
    g = global_frame(P)[2]
    normal, e1 = np.empty((N, 3)), np.empty((N, 3))

    def block(r0, r1):
        lo, hi = indptr[r0], indptr[r1]
        D = P[indices[lo:hi]] - np.repeat(P[r0:r1], deg[r0:r1], axis=0)
        # Rows are contiguous and every point has >= 2 neighbours: reduceat sums them.
        starts = indptr[r0:r1] - lo
        C = np.empty((r1 - r0, 3, 3))
        for a in range(3):
            for b in range(a, 3):
                C[:, a, b] = C[:, b, a] = np.add.reduceat(D[:, a] * D[:, b], starts)
        _, vecs = np.linalg.eigh(C)
        normal[r0:r1] = vecs[:, :, 0] * np.where(vecs[:, :, 0] @ g < 0, -1.0, 1.0)[:, None]
        e1[r0:r1] = vecs[:, :, 2]

    for_blocks(block, N, BLOCK)                    # blocks of rows: temporaries stay in cache
    return normal, e1, np.cross(normal, e1)


@dataclass(frozen=True, eq=False)
class Frames:
    """Robust tangent frames of a point set (:func:`robust_frames`), ``N`` points.

    - ``normal (N, 3)``, ``e1 (N, 3)``, ``e2 (N, 3)``: right-handed orthonormal frames, the
      normal turned towards the global best-fit plane's normal;
    - ``height (N,)``: each point's distance to the plane fitted to its neighbours (the point
      itself left out: an outlier's is large; same units as the points);
    - ``noise (N,)``: the robust scale of the neighbours' own distances to that plane
      (1.4826 times their median: noise and curvature; units of the points);
    - ``radius (N,)``: the RMS distance of the neighbours from the point within that plane
      (the neighbourhood's size, from a point off the surface too).
    """

    normal: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    height: np.ndarray
    noise: np.ndarray
    radius: np.ndarray


def refresh_frames(P: np.ndarray, near: np.ndarray, frames: Frames, rows: np.ndarray, *,
                   towards: np.ndarray | None = None) -> Frames:
    """``frames`` with the rows ``rows`` recomputed by :func:`robust_frames` from the
    neighbours ``near (N, k)`` of ``P (N, 3)`` (after some neighbours were removed);
    ``towards`` as for :func:`robust_frames`."""
    if rows.size == 0:
        return frames
    new = robust_frames(P, near[rows], centres=rows, towards=towards)
    fields = {}
    for name in ("normal", "e1", "e2", "height", "noise", "radius"):
        a = getattr(frames, name).copy()
        a[rows] = getattr(new, name)
        fields[name] = a
    return Frames(**fields)


def robust_frames(P: np.ndarray, near: np.ndarray, *, rounds: int = 1,
                  centres: np.ndarray | None = None, towards: np.ndarray | None = None) -> Frames:
    """Tangent frames of points ``P (N, 3)`` from their nearest neighbours ``near (N, k)``
    (self excluded): a weighted PCA, Gaussian in the distance (bandwidth: the mean squared
    neighbour distance) and centred at the neighbours' weighted mean, not at the point (a
    noisy point does not tilt its own plane), then ``rounds`` reweightings that turn down
    neighbours far from the current plane (Cauchy weights at twice their robust scale).

    On samples of a surface with noise of 0.1-0.3 % of the diagonal the plain PCA of the
    fan's ~12 neighbours tilts normals by several degrees; 24 neighbours weighted this way
    cut that error 2-3x.  ``e1`` is a fixed direction of the plane (from the normal alone),
    since the fans and gaps only need some frame.  ``centres (M,)``: compute only the frames
    of these points, ``near`` then being their ``(M, k)`` neighbours.  ``towards (3,)``: the
    direction the normals are turned to (default: the best-fit plane's normal,
    :func:`global_frame`, an SVD of all of ``P``: pass it when calling again on the same
    points or a few rows).
    **Returns:** :class:`Frames` (of all points, or of ``centres``)."""
    g = global_frame(P)[2] if towards is None else np.asarray(towards, np.float64)
    C = P if centres is None else P[centres]
    N = C.shape[0]
    normal, e1 = np.empty((N, 3)), np.empty((N, 3))
    height, noise, radius = np.empty(N), np.empty(N), np.empty(N)

    def block(r0, r1):
        # np.take: 2x faster than P[...] with a column slice of ``near`` as the index.
        D = np.take(P, near[r0:r1], axis=0) - C[r0:r1, None, :]    # (block, k, 3)
        r2 = np.einsum("bkd,bkd->bk", D, D)
        w0 = np.exp(-r2 / (r2.mean(1, keepdims=True) + 1e-300))
        w = w0
        Dt = D.transpose(0, 2, 1)
        for it in range(rounds + 1):
            W = w / w.sum(1, keepdims=True)
            c = np.einsum("bk,bkd->bd", W, D)
            # The weighted covariance about c, sum_k W_k D_k D_k^T - c c^T (the weights sum to
            # one), and the residuals D_k . n - c . n: no centred (block, k, 3) copies.
            M = np.matmul(Dt * W[:, None, :], D) - c[:, :, None] * c[:, None, :]
            n = smallest_eigenvector(M)
            z = np.matmul(D, n[:, :, None])[..., 0]
            res = np.abs(z - np.einsum("bd,bd->b", c, n)[:, None])
            if it < rounds:       # the middle two of 24 (or the median): a partition, not a sort
                k = res.shape[1]
                mid = np.partition(res, [(k - 1) // 2, k // 2], axis=1)[:, [(k - 1) // 2, k // 2]]
                s = 1.4826 * mid.mean(1) + 1e-12 * np.sqrt(r2.mean(1))
                w = w0 / (1.0 + (res / (2.0 * s[:, None])) ** 2)
        k = res.shape[1]
        mid = np.partition(res, [(k - 1) // 2, k // 2], axis=1)[:, [(k - 1) // 2, k // 2]]
        s = 1.4826 * mid.mean(1) + 1e-12 * np.sqrt(r2.mean(1))
        n = n * np.where(n @ g < 0, -1.0, 1.0)[:, None]
        normal[r0:r1] = n
        ref = np.where(np.abs(n[:, :1]) < 0.6, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
        t = np.cross(n, ref)
        e1[r0:r1] = t / np.linalg.norm(t, axis=1, keepdims=True)
        height[r0:r1] = np.abs(np.einsum("bd,bd->b", c, n))
        noise[r0:r1] = s
        radius[r0:r1] = np.sqrt(np.maximum((r2 - z * z).mean(1), 0.0))

    for_blocks(block, N, DENSE_BLOCK)              # blocks of rows: temporaries stay in cache
    return Frames(normal, e1, np.cross(normal, e1), height, noise, radius)


def smallest_eigenvector(C: np.ndarray) -> np.ndarray:
    """Unit eigenvectors ``(B, 3)`` of the smallest eigenvalues of symmetric ``C (B, 3, 3)``,
    in closed form (the trigonometric eigenvalues, then the largest cross product of two rows
    of ``C - lambda I``): 10x faster than ``np.linalg.eigh`` on many small matrices; sign
    arbitrary.  Exact when the smallest eigenvalue is simple (a plane-like neighbourhood);
    for a repeated one, some unit vector of its eigenspace's span is returned."""
    a, b, c = C[:, 0, 0], C[:, 1, 1], C[:, 2, 2]
    d, e, f = C[:, 0, 1], C[:, 1, 2], C[:, 0, 2]
    q = (a + b + c) / 3
    p1 = d * d + e * e + f * f
    p = np.sqrt(((a - q) ** 2 + (b - q) ** 2 + (c - q) ** 2 + 2 * p1) / 6)
    ps = np.where(p > 0, p, 1.0)
    A, B_, Cc = (a - q) / ps, (b - q) / ps, (c - q) / ps
    D_, E, F = d / ps, e / ps, f / ps
    det = A * (B_ * Cc - E * E) - D_ * (D_ * Cc - E * F) + F * (D_ * E - B_ * F)
    phi = np.arccos(np.clip(det / 2, -1.0, 1.0)) / 3
    lam = q + 2 * p * np.cos(phi + 2 * np.pi / 3)
    M = C - lam[:, None, None] * np.eye(3)
    cands = np.stack([np.cross(M[:, 0], M[:, 1]), np.cross(M[:, 0], M[:, 2]),
                      np.cross(M[:, 1], M[:, 2])], 1)                         # (B, 3, 3)
    norms = np.einsum("bcd,bcd->bc", cands, cands)
    best = np.argmax(norms, axis=1)
    v = cands[np.arange(len(C)), best]
    nv = np.sqrt(norms[np.arange(len(C)), best])
    fallback = nv <= 1e-300                     # C = lambda I: any direction
    v[fallback] = [0.0, 0.0, 1.0]
    nv[fallback] = 1.0
    return v / nv[:, None]


def drop_steep_pairs(P, indptr, indices, normal, max_slope: float, exempt: np.ndarray | None = None,
                     *, min_dot: float = -1.0, counts: dict | None = None):
    """Remove the neighbour pairs ``v, w`` whose direction leaves either tangent plane by more
    than ``|n . (w - v)| / |w - v| > max_slope``, and those whose consistently oriented
    normals are opposed, ``n_v . n_w < min_dot`` (default ``-1``: none): on a thin part of
    the surface (an ear) they join its two sides, and the map would fold that part onto
    itself.  Points that
    would keep fewer than three neighbours keep all of theirs (pairs stay symmetric), and so
    do the points ``exempt (N,) bool`` (default: none).  With ``counts`` (a dict), its
    ``"opposed"`` is set to the number of (directed) pairs in each other's tangent planes
    (slope below 0.1) whose normals are opposed (``n_v . n_w < -0.9``): the seam of a
    non-orientable set (:data:`~jaxparam.points.orientation.NonOrientableWarning`).

    **Returns:** the pruned CSR ``(indptr, indices)``."""
    N = P.shape[0]
    deg = np.diff(indptr)
    keep = np.empty(indices.size, bool)

    def block(r0, r1):
        lo, hi = indptr[r0], indptr[r1]
        idx = indices[lo:hi]
        d = P[idx] - np.repeat(P[r0:r1], deg[r0:r1], axis=0)
        nv, nw = np.repeat(normal[r0:r1], deg[r0:r1], axis=0), normal[idx]
        tilt = np.maximum(np.abs(np.einsum("ij,ij->i", d, nv)), np.abs(np.einsum("ij,ij->i", d, nw)))
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        keep[lo:hi] = tilt <= max_slope * length
        if min_dot > -1 or counts is not None:
            dot = np.einsum("ij,ij->i", nv, nw)
            if min_dot > -1:
                keep[lo:hi] &= dot >= min_dot
            if counts is not None:
                opposed[r0] = int(np.sum((dot < -0.9) & (tilt < 0.1 * length)))

    opposed = {}
    for_blocks(block, N, DENSE_BLOCK)              # blocks of rows: temporaries stay in cache
    if counts is not None:
        counts["opposed"] = sum(opposed.values())
    rows = np.repeat(np.arange(N), deg)
    weak = np.add.reduceat(keep.astype(np.int64), indptr[:-1]) < 3
    if exempt is not None:
        weak = weak | exempt
    keep |= weak[rows] | weak[indices]
    ptr = np.zeros(N + 1, np.int64)
    np.cumsum(np.add.reduceat(keep.astype(np.int64), indptr[:-1]), out=ptr[1:])
    return ptr, indices[keep]


def global_frame(P: np.ndarray) -> np.ndarray:
    """``(3, 3)`` rows: the best-fit plane's axes and its normal, a right-handed frame whose
    normal's largest component is positive (so it does not depend on the points' order)."""
    V = np.linalg.svd(P - P.mean(0), full_matrices=False)[2]
    if V[2][np.argmax(np.abs(V[2]))] < 0:
        V[2] = -V[2]
    V[1] = np.cross(V[2], V[0])
    return V


def spatial_order(P: np.ndarray) -> np.ndarray:
    """A permutation putting points ``(N, 3)`` in Morton (Z-curve) order of a 2^21 grid."""
    return np.argsort(morton_keys(P), kind="stable")


def morton_keys(P: np.ndarray) -> np.ndarray:
    """``(N,) uint64`` Morton (Z-curve) codes of points ``(N, 3)`` on a 2^21 grid over their
    box (equal points have equal codes)."""
    def spread(x):                      # the 21 low bits of x moved to every third bit
        x = x.astype(np.uint64)
        for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                            (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
            x = (x | (x << np.uint64(shift))) & np.uint64(mask)
        return x

    lo, span = P.min(0), float(np.ptp(P, axis=0).max())
    q = ((P - lo) * ((2**21 - 1) / (span if span > 0 else 1.0))).astype(np.int64)
    return spread(q[:, 0]) | (spread(q[:, 1]) << np.uint64(1)) | (spread(q[:, 2]) << np.uint64(2))


def knn_gaps(P: np.ndarray, k: int):
    """Largest angular gap (radians) of each point's ``k`` nearest neighbours projected on
    their PCA plane, and the mean neighbour distance; ``(N,), (N,)``."""
    return angular_gaps(P, *nearest_neighbours(P, k))


def angular_gaps(P: np.ndarray, dist: np.ndarray, idx: np.ndarray, frame=None):
    """:func:`knn_gaps` from the neighbours ``idx (N, k)`` at distances ``dist (N, k)``, in
    the tangent frames ``frame = (e1, e2)`` (each ``(N, 3)``; default: PCA of these
    neighbours).  Dense arrays: every point has exactly ``k`` neighbours.

    **Returns:** ``(gap (N,), spacing (N,))``, the largest gap and the mean distance."""
    N = P.shape[0]
    gap = np.empty(N)

    def block(r0, r1):
        b = slice(r0, r1)
        D = np.take(P, idx[b], axis=0) - P[b, None, :]      # (block, k, 3)
        if frame is None:
            _, vecs = np.linalg.eigh(np.matmul(D.transpose(0, 2, 1), D))
            e1, e2 = vecs[:, :, 2], np.cross(vecs[:, :, 0], vecs[:, :, 2])
        else:
            e1, e2 = frame[0][b], frame[1][b]
        ang = np.arctan2(np.matmul(D, e2[:, :, None])[..., 0], np.matmul(D, e1[:, :, None])[..., 0])
        ang.sort(axis=1)
        inner = (ang[:, 1:] - ang[:, :-1]).max(axis=1)
        gap[b] = np.maximum(inner, ang[:, 0] + 2 * np.pi - ang[:, -1])

    for_blocks(block, N, DENSE_BLOCK)
    return gap, dist.mean(1)


def unreachable(graph: PointGraph, boundary: np.ndarray) -> np.ndarray:
    """``(N,) bool``: the points in no component of the (symmetrized) neighbour graph that
    holds a point of ``boundary`` (eq. (4) is singular for them)."""
    N = graph.n_points
    G = sp.csr_matrix((np.ones(graph.indices.size, np.int8), graph.indices, graph.indptr), shape=(N, N))
    _, lab = connected_components(G, directed=True, connection="weak")
    return ~np.isin(lab, np.unique(lab[boundary]))
