"""Unorganized points (survey §8): meshless parameterization, boundary detection, reconstruction.

Pipeline (numpy for the combinatorics, JAX for what depends on coordinates):

1. :func:`knn_graph`: the ``k`` nearest neighbours of every point (cKDTree),
   made symmetric by default (``w`` is ``v``'s neighbour when either lists the
   other).  Directed kNN graphs are often singular in practice: a cluster whose
   neighbours only point at each other never reaches the boundary (the
   solvability condition at the end of §8).
2. Tangent planes by PCA of each neighbourhood; neighbours sorted by angle
   around the point in that plane (a star-shaped fan, so the point lies in the
   fan's kernel).
3. :func:`detect_boundary`: a point is a boundary candidate when the largest
   angular gap between its 24 nearest neighbours, projected, exceeds ``gap``
   (default ``0.7 pi``).  The candidates are ordered into one closed polygon by the
   longest path of their minimum spanning tree (a loop of points has a nearly
   path-shaped spanning tree; points on short branches are left interior).
   The survey leaves this step to [13]; users can pass ``boundary`` indices.
4. Weights on the fans: ``uniform`` and ``inverse_distance`` (spring weights,
   symmetric: a Cholesky solve), ``mean_value`` and ``shape_preserving``
   (Floater's, on the fan of triangles ``(v, w_j, w_{j+1})``, 3D angles and
   lengths, so that everything is differentiable in the points).
5. The boundary on a circle or square (chord length), the interior by the same
   differentiable sparse solve as meshes (:func:`jaxparam.sparse.solve`).

Step 2 also drops neighbour pairs that leave a tangent plane steeply (they
join the two sides of parts thinner than the spacing).  Large clouds are
processed in Morton (Z-curve) order and in blocks of points, for memory
locality; results come back in the input's order.

:func:`reconstruct_surface` triangulates the parameter points (Delaunay),
lifts the triangles to 3D, flips edges towards 3D Delaunay where the
parameter plane allows, peels off the hull triangles that bridge concave
parts of the boundary and the ears over boundary points the detector missed.
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree, shortest_path
from scipy.spatial import Delaunay, cKDTree

from . import boundary as bmap
from . import sparse
from .errors import MeshFileError, PointCloudError, first_few
from .geometry import safe_norm
from .memory import reuse_freed_memory
from .mesh import TriMesh
from .topology import half_edge_twins, permute_rows, renumber
from .triangles import corner_angle, face_angles, orient

__all__ = ["load_points", "check_points", "knn_graph", "PointGraph", "point_graph",
           "detect_boundary", "meshless_map", "reconstruct_surface", "WEIGHTS"]

WEIGHTS = ("uniform", "inverse_distance", "shape_preserving", "mean_value")


# ------------------------------------------------------------------------------------------
# Input
# ------------------------------------------------------------------------------------------

def load_points(path) -> np.ndarray:
    """Read points: ``.xyz``/``.txt`` (x y z per line), ``.npy``, ``.ply``; ``(N, 3) float``.

    Example::

        P = jp.load_points("camelhead.xyz")
    """
    p = Path(path)
    if not p.exists():
        raise MeshFileError(f"{path}: no such file.")
    ext = p.suffix.lower()
    if ext == ".npy":
        try:
            P = np.load(p, allow_pickle=False)
        except Exception as exc:
            raise MeshFileError(f"{path}: not a readable .npy array ({exc}).") from None
    elif ext == ".ply":
        try:
            import trimesh
            P = np.asarray(trimesh.load(str(p), process=False).vertices)
        except Exception as exc:
            raise MeshFileError(f"{path}: cannot read the PLY file ({type(exc).__name__}: {exc}).") from None
    else:
        rows = []
        for line_no, raw in enumerate(p.read_text(errors="replace").splitlines(), 1):
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            parts = line.replace(",", " ").split()
            if len(parts) < 3:
                raise MeshFileError(f"{path}, line {line_no}: expected 'x y z', got {line!r}.")
            try:
                rows.append([float(t) for t in parts[:3]])
            except ValueError:
                raise MeshFileError(f"{path}, line {line_no}: cannot read numbers from {line!r}.") from None
        P = np.asarray(rows, np.float64).reshape(-1, 3)
    P = np.asarray(P, np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise MeshFileError(f"{path}: expected an (N, 3) array of points, got shape {P.shape}.")
    return P


def check_points(points, *, k: int = 10, merge_duplicates: bool = False):
    """Validate a point set; returns ``(points (N, 3), kept)`` where ``kept`` maps back.

    Raises :class:`PointCloudError` for a wrong shape, non-finite coordinates,
    too few points, ``k >= N``, duplicates (unless ``merge_duplicates``: then
    the later copies are dropped and ``kept`` says which points remain) and
    point sets that are collinear or coincident.
    """
    P = np.asarray(points, np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise PointCloudError(f"meshless_map: points must have shape (N, 3), got {P.shape}.")
    bad = np.flatnonzero(~np.all(np.isfinite(P), axis=1))
    if bad.size:
        raise PointCloudError(f"meshless_map: points {first_few(bad)} have non-finite coordinates; "
                              "remove them.")
    kept = np.arange(P.shape[0])
    # Equal points share a Morton key: only points whose key repeats need the exact (and, over
    # all points, 3x slower) row-wise np.unique.
    codes = _morton_keys(P)
    key = np.sort(codes)
    rep = key[1:][key[1:] == key[:-1]]
    maybe = np.flatnonzero(np.isin(codes, rep)) if rep.size else np.zeros(0, np.int64)
    dup = np.zeros(0, np.int64)
    if maybe.size:
        _, first, inv = np.unique(P[maybe], axis=0, return_index=True, return_inverse=True)
        first = maybe[first][inv.reshape(-1)]             # each point's first equal point
        dup = maybe[first != maybe]
    if dup.size:
        if not merge_duplicates:
            raise PointCloudError(
                f"meshless_map: points {first_few(dup)} duplicate earlier points (point {int(dup[0])} "
                f"equals point {int(first[maybe == dup[0]][0])}); remove them or pass "
                "merge_duplicates=True.")
        kept = np.setdiff1d(kept, dup)
        P = P[kept]
    if P.shape[0] < 4:
        raise PointCloudError(f"meshless_map: {P.shape[0]} points are too few; at least 4 are needed.")
    if k >= P.shape[0]:
        raise PointCloudError(f"meshless_map: k = {k} neighbours needs more than {k} points, "
                              f"got {P.shape[0]}; lower k.")
    s = np.linalg.svd(P - P.mean(0), compute_uv=False)
    if s[0] == 0 or s[1] <= 1e-9 * s[0]:
        what = "coincident" if s[0] == 0 else "collinear"
        raise PointCloudError(f"meshless_map: the points are {what}; a surface needs points "
                              "spread in two directions.")
    return P, kept


# ------------------------------------------------------------------------------------------
# Neighbourhoods, fans and boundary
# ------------------------------------------------------------------------------------------

def _nearest(P: np.ndarray, k: int):
    """``(dist (N, k), idx (N, k))``: each point's ``k`` nearest other points, nearest first."""
    dist, idx = cKDTree(P).query(P, k + 1, workers=-1)
    return dist[:, 1:], idx[:, 1:]


def knn_graph(points, k: int = 10, *, radius: float | None = None, symmetric: bool = True,
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
        idx = _nearest(P, k)[1] if nearest is None else np.asarray(nearest)[:, :k]
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

    ``indptr, indices``: each point's neighbours sorted anticlockwise around
    it in its PCA tangent plane; ``gap (N,)`` the largest angular gap (radians);
    ``normal (N, 3)``; ``spacing (N,)`` the mean distance to the neighbours.
    ``detect_k``, ``detect_gap``, ``detect_spacing``: the same gap and spacing for
    the ``detect_k`` nearest neighbours (boundary detection), when computed.
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
    def rows(self) -> np.ndarray:
        return np.repeat(np.arange(self.indptr.size - 1), np.diff(self.indptr))


def point_graph(points, k: int = 10, *, radius: float | None = None, symmetric: bool = True,
                k_detect: int = 24, max_slope: float = 0.6) -> PointGraph:
    """Neighbours, tangent planes and angularly sorted fans of every point; with ``k`` nearest
    neighbours, also the angular gaps of the ``k_detect`` nearest (for
    :func:`detect_boundary`) from the same tree query (0 skips them).

    Neighbour pairs that leave either point's tangent plane steeply (``|n . d| / |d| >
    max_slope``, about 37 degrees by default) are dropped: on a part of the surface
    thinner than the point spacing they join its two sides (a thin part of
    camelhead.xyz's head), and the map folds that part onto itself.  ``max_slope=1`` keeps every pair."""
    P0 = np.asarray(points, np.float64)
    N = P0.shape[0]
    # Work in a space-filling-curve order, so that neighbours sit close in memory (the tree
    # query and the gathers run 1.3-2x faster on a large shuffled cloud); every result is
    # mapped back to the input's order at the end.
    perm = _spatial_order(P0)
    G = _point_graph_in_order(P0[perm], k, radius, symmetric, k_detect, names=perm,
                              max_slope=max_slope)
    # Back to the input's order: row v of the result is row inv[v] here, neighbours renamed.
    inv = np.empty(N, np.int64)
    inv[perm] = np.arange(N)
    ptr, src = permute_rows(G.indptr, inv)
    back = lambda x: None if x is None else x[inv]      # noqa: E731
    return PointGraph(ptr, perm[G.indices[src]], G.gap[inv], G.normal[inv], G.spacing[inv],
                      G.detect_k, back(G.detect_gap), back(G.detect_spacing))


def _point_graph_in_order(P: np.ndarray, k: int, radius, symmetric: bool, k_detect: int,
                          names: np.ndarray, max_slope: float = 0.6) -> PointGraph:
    """:func:`point_graph` computed in the points' own order (fast when it is spatially
    coherent); ``names[i]`` is point ``i``'s index in the user's order (for messages)."""
    N = P.shape[0]
    k_detect = min(k_detect, N - 1) if radius is None else 0
    dist, near = _nearest(P, max(k, k_detect)) if radius is None else (None, None)
    indptr, indices = knn_graph(P, k, radius=radius, symmetric=symmetric, nearest=near)
    _check_degree(indptr, names, 2)
    normal, e1, e2 = _frames(P, indptr, indices)
    if max_slope < 1:
        indptr, indices = _drop_steep(P, indptr, indices, normal, max_slope)
        _check_degree(indptr, names, 2)
    deg = np.diff(indptr)
    gap, spacing = np.empty(N), np.empty(N)
    fans = np.empty_like(indices)
    for r0 in range(0, N, _BLOCK):                 # blocks of rows: temporaries stay in cache
        r1 = min(r0 + _BLOCK, N)
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
    indices = fans
    extra = ((k_detect,) + _gaps_of(P, dist[:, :k_detect], near[:, :k_detect], frame=(e1, e2))
             if k_detect else (0, None, None))
    return PointGraph(indptr, indices, gap, normal, spacing, *extra)


def _check_degree(indptr: np.ndarray, names: np.ndarray, least: int) -> None:
    lonely = np.sort(names[np.diff(indptr) < least])
    if lonely.size:
        raise PointCloudError(f"meshless_map: points {first_few(lonely)} have fewer than {least} "
                              "neighbours; increase k or radius.")


def _frames(P: np.ndarray, indptr: np.ndarray, indices: np.ndarray):
    """Tangent frames ``(normal, e1, e2)``, each ``(N, 3)``: PCA of each point's neighbours
    (CSR rows), normals turned towards the global best-fit plane's normal, right-handed."""
    N = P.shape[0]
    deg = np.diff(indptr)
    g = _global_frame(P)[2]
    normal, e1 = np.empty((N, 3)), np.empty((N, 3))
    for r0 in range(0, N, _BLOCK):                 # blocks of rows: temporaries stay in cache
        r1 = min(r0 + _BLOCK, N)
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
    return normal, e1, np.cross(normal, e1)


def _drop_steep(P, indptr, indices, normal, max_slope: float):
    """Remove the neighbour pairs ``v, w`` whose direction leaves either tangent plane by more
    than ``|n . (w - v)| / |w - v| > max_slope``: on a thin part of the surface (an ear)
    they join its two sides, and the map would fold that part onto itself.  Points that
    would keep fewer than three neighbours keep all of theirs (pairs stay symmetric)."""
    N = P.shape[0]
    deg = np.diff(indptr)
    keep = np.empty(indices.size, bool)
    for r0 in range(0, N, _BLOCK):                 # blocks of rows: temporaries stay in cache
        r1 = min(r0 + _BLOCK, N)
        lo, hi = indptr[r0], indptr[r1]
        idx = indices[lo:hi]
        d = P[idx] - np.repeat(P[r0:r1], deg[r0:r1], axis=0)
        tilt = np.maximum(np.abs(np.einsum("ij,ij->i", d, np.repeat(normal[r0:r1], deg[r0:r1], axis=0))),
                          np.abs(np.einsum("ij,ij->i", d, normal[idx])))
        keep[lo:hi] = tilt <= max_slope * np.sqrt(np.einsum("ij,ij->i", d, d))
    rows = np.repeat(np.arange(N), deg)
    weak = np.add.reduceat(keep.astype(np.int64), indptr[:-1]) < 3
    keep |= weak[rows] | weak[indices]
    ptr = np.zeros(N + 1, np.int64)
    np.cumsum(np.add.reduceat(keep.astype(np.int64), indptr[:-1]), out=ptr[1:])
    return ptr, indices[keep]


def _global_frame(P: np.ndarray) -> np.ndarray:
    """``(3, 3)`` rows: the best-fit plane's axes and its normal, a right-handed frame whose
    normal's largest component is positive (so it does not depend on the points' order)."""
    V = np.linalg.svd(P - P.mean(0), full_matrices=False)[2]
    if V[2][np.argmax(np.abs(V[2]))] < 0:
        V[2] = -V[2]
    V[1] = np.cross(V[2], V[0])
    return V


def _spatial_order(P: np.ndarray) -> np.ndarray:
    """A permutation putting points ``(N, 3)`` in Morton (Z-curve) order of a 2^21 grid."""
    return np.argsort(_morton_keys(P), kind="stable")


def _morton_keys(P: np.ndarray) -> np.ndarray:
    """``(N,) uint64`` Morton (Z-curve) codes of points ``(N, 3)`` on a 2^21 grid over their box."""
    def spread(x):                      # the 21 low bits of x moved to every third bit
        x = x.astype(np.uint64)
        for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                            (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
            x = (x | (x << np.uint64(shift))) & np.uint64(mask)
        return x

    lo, span = P.min(0), float(np.ptp(P, axis=0).max())
    q = ((P - lo) * ((2**21 - 1) / (span if span > 0 else 1.0))).astype(np.int64)
    return spread(q[:, 0]) | (spread(q[:, 1]) << np.uint64(1)) | (spread(q[:, 2]) << np.uint64(2))


def _knn_gaps(P: np.ndarray, k: int):
    """Largest angular gap (radians) of each point's ``k`` nearest neighbours projected on
    their PCA plane, and the mean neighbour distance; ``(N,), (N,)``."""
    return _gaps_of(P, *_nearest(P, k))


#: Points per block in the dense neighbourhood computations: the (block, k, 3) temporaries
#: stay in cache instead of streaming (N, k, 3) arrays through memory (1M points: 4 s -> ~1 s).
_BLOCK = 1 << 15


def _gaps_of(P: np.ndarray, dist: np.ndarray, idx: np.ndarray, frame=None):
    """:func:`_knn_gaps` from the neighbours ``idx (N, k)`` at distances ``dist (N, k)``, in
    the tangent frames ``frame = (e1, e2)`` (each ``(N, 3)``; default: PCA of these
    neighbours).  Dense arrays: every point has exactly ``k`` neighbours."""
    N = P.shape[0]
    gap = np.empty(N)
    for s in range(0, N, _BLOCK):
        b = slice(s, min(s + _BLOCK, N))
        D = P[idx[b]] - P[b, None, :]                       # (block, k, 3)
        if frame is None:
            _, vecs = np.linalg.eigh(np.matmul(D.transpose(0, 2, 1), D))
            e1, e2 = vecs[:, :, 2], np.cross(vecs[:, :, 0], vecs[:, :, 2])
        else:
            e1, e2 = frame[0][b], frame[1][b]
        ang = np.arctan2(np.matmul(D, e2[:, :, None])[..., 0], np.matmul(D, e1[:, :, None])[..., 0])
        ang.sort(axis=1)
        inner = (ang[:, 1:] - ang[:, :-1]).max(axis=1)
        gap[b] = np.maximum(inner, ang[:, 0] + 2 * np.pi - ang[:, -1])
    return gap, dist.mean(1)


def detect_boundary(points, graph: PointGraph | None = None, *, gap: float = 0.7 * np.pi,
                    k_detect: int = 24) -> np.ndarray:
    """Boundary points as one closed polygon (indices in order, anticlockwise about the
    global normal).

    Candidates: points whose ``k_detect`` nearest neighbours, projected on the
    tangent plane, leave an angular gap larger than ``gap`` (a larger
    neighbourhood than the map's: random samplings leave wide gaps in small
    ones).  Candidates within three spacings of each other are linked; the
    linked group with the longest spanning tree is kept (stray interior
    candidates drop out) and ordered along the longest path of that tree.
    """
    P = np.asarray(points, np.float64)
    k_detect = min(k_detect, P.shape[0] - 1)
    if graph is not None and graph.detect_k == k_detect:
        det_gap, det_spacing = graph.detect_gap, graph.detect_spacing
    else:
        det_gap, det_spacing = _knn_gaps(P, k_detect)
    cand = np.flatnonzero(det_gap > gap)
    if cand.size < 3:
        raise PointCloudError(f"meshless_map: found {cand.size} boundary points (largest angular gap "
                              f"> {gap:.2f} rad); the points may sample a closed surface. Pass "
                              "boundary=indices, or lower gap.")
    Q = P[cand]
    kk = min(8, cand.size - 1)
    dist, idx = cKDTree(Q).query(Q, kk + 1)
    link = 3.0 * np.median(det_spacing[cand])
    rows = np.repeat(np.arange(cand.size), kk)
    d = dist[:, 1:].reshape(-1)
    ok = d <= link
    W = sp.csr_matrix((d[ok] + 1e-300, (rows[ok], idx[:, 1:].reshape(-1)[ok])), shape=(cand.size,) * 2)
    W = W.maximum(W.T)
    from scipy.sparse.csgraph import connected_components
    nc, lab = connected_components(W, directed=False)
    # The boundary is the longest chain: largest total spanning-tree length, not the most points
    # (clusters of stray candidates in sparsely sampled regions can be as numerous).
    Tall = minimum_spanning_tree(W)
    length = np.bincount(lab[Tall.nonzero()[0]], weights=Tall.data, minlength=nc)
    big = np.flatnonzero(lab == np.argmax(length))
    cand, W = cand[big], W[big][:, big]
    if cand.size < 3:
        raise PointCloudError("meshless_map: the boundary candidates do not form a chain; pass "
                              "boundary=indices, or change k_detect/gap.")
    T = minimum_spanning_tree(W)
    T = T + T.T
    # Longest path in the spanning forest's largest tree: two sweeps of shortest paths.
    d0 = shortest_path(T, directed=False, indices=0)
    far = np.where(np.isfinite(d0), d0, -1)
    a = int(np.argmax(far))
    da, pred = shortest_path(T, directed=False, indices=a, return_predecessors=True)
    da = np.where(np.isfinite(da), da, -1)
    b = int(np.argmax(da))
    path = [b]
    while path[-1] != a:
        path.append(int(pred[path[-1]]))
    loop = cand[np.asarray(path[::-1])]
    if loop.size < 3:
        raise PointCloudError("meshless_map: could not order the boundary points into a polygon; "
                              "pass boundary=indices.")
    # Anticlockwise about the global normal.
    g = _global_frame(P)
    uv = (P[loop] - P[loop].mean(0)) @ g[:2].T
    area = 0.5 * np.sum(uv[:, 0] * np.roll(uv[:, 1], -1) - np.roll(uv[:, 0], -1) * uv[:, 1])
    return loop if area > 0 else loop[::-1]


# ------------------------------------------------------------------------------------------
# Weights and the solve
# ------------------------------------------------------------------------------------------

def _angle(a, b):
    return jnp.arctan2(safe_norm(jnp.cross(a, b)), jnp.sum(a * b, -1))


@functools.partial(jax.jit, static_argnames=("kind", "n_rows", "max_degree"))
def _fan_weights(P, center, nbr, nxt, prev, row, row_start, row_end, degree, *, kind, n_rows,
                 max_degree):
    """Weights on the fan entries ``(v, w_j)`` with ``w_{j+1} = nxt``, ``w_{j-1} = prev``."""
    from .weights import _shape_preserving

    x = P[center]
    d = P[nbr] - x
    r = safe_norm(d)
    if kind == "uniform":
        return jnp.ones_like(r)
    if kind == "inverse_distance":
        return 1.0 / r
    delta = _angle(d, P[nxt] - x)
    if kind == "mean_value":
        return (jnp.tan(0.5 * _angle(P[prev] - x, d)) + jnp.tan(0.5 * delta)) / r
    return _shape_preserving(delta, r, row, row_start, row_end, degree, n_rows, max_degree)


@dataclass(frozen=True, eq=False)
class _System:
    pattern: sparse.Pattern
    rows_e: np.ndarray
    center: np.ndarray
    nbr: np.ndarray
    nxt: np.ndarray
    prev: np.ndarray
    row_start: np.ndarray
    row_end: np.ndarray
    degree: np.ndarray
    diag_pos: np.ndarray
    off_pos: np.ndarray
    ii: np.ndarray
    ib: np.ndarray
    ib_slot: np.ndarray
    interior: np.ndarray
    n_rows: int


def _system(graph: PointGraph, boundary: np.ndarray, N: int) -> _System:
    is_b = np.zeros(N, bool)
    is_b[boundary] = True
    interior = np.flatnonzero(~is_b)
    slot = np.full(N, -1, np.int64)
    slot[interior] = np.arange(interior.size)
    bslot = np.full(N, -1, np.int64)
    bslot[boundary] = np.arange(boundary.size)
    rows_all = graph.rows
    keep = ~is_b[rows_all]
    ent = np.flatnonzero(keep)
    center = rows_all[ent]
    nbr = graph.indices[ent]
    # The entry after / before each one in its (cyclic) fan: the next / previous entry, but
    # the first / last of the row at its ends (every row has at least two entries).
    nxt_all = np.arange(1, graph.indices.size + 1)
    nxt_all[graph.indptr[1:] - 1] = graph.indptr[:-1]
    prv_all = np.arange(-1, graph.indices.size - 1)
    prv_all[graph.indptr[:-1]] = graph.indptr[1:] - 1
    nxt = graph.indices[nxt_all[ent]]
    prev = graph.indices[prv_all[ent]]
    row = slot[center]
    degree = np.bincount(row, minlength=interior.size)
    starts = np.zeros(interior.size + 1, np.int64)
    np.cumsum(degree, out=starts[1:])
    ii = np.flatnonzero(~is_b[nbr])
    ib = np.flatnonzero(is_b[nbr])
    ni = interior.size
    r = np.concatenate([np.arange(ni), row[ii]])
    c = np.concatenate([np.arange(ni), slot[nbr[ii]]])
    # CSR order by one stable (radix) sort of (row, column) keys: 6x faster than a COO build
    # plus a per-row column sort on 12M entries.
    order = np.argsort(r * np.int64(ni) + c, kind="stable")
    indptr = np.zeros(ni + 1, np.int64)
    np.cumsum(np.bincount(r, minlength=ni), out=indptr[1:])
    pos = np.empty(r.size, np.int64)
    pos[order] = np.arange(r.size)
    return _System(sparse.Pattern(indptr, c[order], ni), row, center, nbr, nxt, prev,
                   starts[row], starts[row + 1], degree, pos[:interior.size], pos[interior.size:],
                   ii, ib, bslot[nbr[ib]], interior, int(interior.size))


def _check_solvable(S: _System, N: int, boundary: np.ndarray) -> None:
    """Every interior point must reach a boundary point along G (end of §8)."""
    src = S.interior[S.rows_e]
    G = sp.csr_matrix((np.ones(src.size), (S.nbr, src)), shape=(N + 1, N + 1))   # reversed edges
    G = G + sp.csr_matrix((np.ones(boundary.size), (np.full(boundary.size, N), boundary)),
                          shape=(N + 1, N + 1))
    reached = breadth_first_order(G, N, directed=True, return_predecessors=False)
    ok = np.zeros(N + 1, bool)
    ok[reached] = True
    bad = S.interior[~ok[S.interior]]
    if bad.size:
        raise PointCloudError(
            f"meshless_map: {bad.size} points cannot reach the boundary through their neighbours "
            f"(e.g. point {int(bad[0])}); the system (3) would be singular: increase k, use "
            "symmetric neighbourhoods, or remove the isolated cluster.")


def meshless_map(points, *, k: int = 10, weights: str = "inverse_distance", boundary="circle",
                 spacing: str = "chord", boundary_indices=None, radius: float | None = None,
                 symmetric: bool = True, gap: float = 0.7 * np.pi, graph: PointGraph | None = None,
                 merge_duplicates: bool = False, max_slope: float = 0.6):
    """Meshless parameterization of unorganized points (survey §8).

    **Arguments:** ``points: (N, 3)`` (numpy, JAX or a tracer with ``graph`` given);
    ``k`` neighbours (or ``radius``); ``weights`` one of :data:`WEIGHTS`;
    ``boundary`` ``"circle"`` or ``"square"``; ``boundary_indices`` the ordered
    boundary points (default: detected); ``graph`` a precomputed
    :func:`point_graph` (needed under ``jax.grad``: neighbourhoods are topology,
    computed from concrete points); ``max_slope`` drops neighbour pairs that leave
    the tangent planes steeply (see :func:`point_graph`).

    **Returns:** ``(uv (N, 2), boundary (b,) int)``.

    Differentiable in the points: ``jax.grad`` flows through the weights,
    the boundary map and the sparse solve.

    Example::

        uv, bnd = jp.meshless_map(points, k=10, weights="inverse_distance")
    """
    _check_map_options("meshless_map", weights, boundary, spacing)
    traced = isinstance(points, jax.core.Tracer)
    if traced:
        if graph is None or boundary_indices is None:
            raise PointCloudError("meshless_map: under jax.grad/jit pass graph=jp.points.point_graph("
                                  "concrete_points) and boundary_indices=... computed from concrete points.")
        N = points.shape[0]
        P = points
    else:
        Pc, kept = check_points(points, k=k, merge_duplicates=merge_duplicates)
        if kept.size != np.asarray(points).shape[0]:
            uv, bnd = meshless_map(Pc, k=k, weights=weights, boundary=boundary, spacing=spacing,
                                   radius=radius, symmetric=symmetric, gap=gap, max_slope=max_slope)
            return uv, kept[bnd]
        N = Pc.shape[0]
        P = points if isinstance(points, jax.Array) else Pc
        if graph is None:
            graph = point_graph(Pc, k, radius=radius, symmetric=symmetric, max_slope=max_slope)
    if boundary_indices is None:
        bnd = detect_boundary(np.asarray(P), graph, gap=gap)
    else:
        bnd = _check_boundary_indices("meshless_map", boundary_indices, N)
    sym = weights in ("uniform", "inverse_distance") and symmetric and radius is None
    return _map_points(P, graph, bnd, weights=weights, boundary=boundary, spacing=spacing,
                       symmetric=sym), bnd


def _check_map_options(where: str, weights, boundary, spacing) -> None:
    if weights not in WEIGHTS:
        raise PointCloudError(f"{where}: unknown weights {weights!r}; use one of {WEIGHTS}.")
    if not isinstance(boundary, str) or boundary not in ("circle", "square"):
        raise PointCloudError(f"{where}: boundary must be 'circle' or 'square', got {boundary!r}; "
                              "to choose the boundary points pass boundary_indices.")
    if spacing not in bmap.SPACINGS:
        raise PointCloudError(f"{where}: unknown spacing {spacing!r}; use one of {bmap.SPACINGS}.")


def _check_boundary_indices(where: str, indices, n: int) -> np.ndarray:
    """User boundary indices as ``(b,) int64``, or a :class:`PointCloudError`."""
    bnd = np.asarray(indices, np.int64)
    if bnd.ndim != 1 or bnd.size < 3 or bnd.min() < 0 or bnd.max() >= n or np.unique(bnd).size != bnd.size:
        raise PointCloudError(f"{where}: boundary_indices must be >= 3 distinct point indices "
                              f"in [0, {n}), in order; got {bnd.size} values.")
    return bnd


def _map_points(P, graph: PointGraph, bnd: np.ndarray, *, weights: str, boundary: str, spacing: str,
                symmetric: bool):
    """The meshless map of checked points ``P (N, 3)`` (array or tracer) with their graph and
    boundary polygon: weights, boundary map, the sparse solve; ``(N, 2)`` UVs."""
    N = P.shape[0]
    S = _system(graph, bnd, N)
    _check_solvable(S, N, bnd)
    Pj = P if isinstance(P, jax.core.Tracer) else jnp.asarray(P, dtype=jnp.float64)
    max_deg = 1 << max(3, (int(S.degree.max()) - 1).bit_length())
    w = _fan_weights(Pj, S.center, S.nbr, S.nxt, S.prev, S.rows_e, S.row_start, S.row_end, S.degree,
                     kind=weights, n_rows=S.n_rows, max_degree=max_deg)
    uv_b = _boundary_map(Pj, jnp.asarray(bnd), boundary=boundary, spacing=spacing)
    from .linear import _assemble_jit

    vals, rhs = _assemble_jit(w, uv_b, S.rows_e, S.ii, S.ib, S.ib_slot, S.rows_e[S.ib], S.diag_pos,
                              S.off_pos, ni=S.n_rows, nnz=S.pattern.nnz)
    from .linear import _solve       # eager factorization when nothing is traced

    x = _solve(S.pattern, vals, rhs, symmetric, "auto")
    return _scatter(x, uv_b, jnp.asarray(S.interior), jnp.asarray(bnd), n=N)


# One compiled kernel each instead of a dozen eager operations (each compiled on its own
# for every new point count).
@functools.partial(jax.jit, static_argnames=("boundary", "spacing"))
def _boundary_map(P, bnd, *, boundary, spacing):
    return bmap.boundary_uv(P[bnd], boundary, spacing=spacing)


@functools.partial(jax.jit, static_argnames=("n",))
def _scatter(x, uv_b, interior, bnd, *, n):
    return jnp.zeros((n, 2), x.dtype).at[interior].set(x).at[bnd].set(uv_b)


# ------------------------------------------------------------------------------------------
# Reconstruction
# ------------------------------------------------------------------------------------------

def reconstruct_surface(points, *, bridge_factor: float = 3.0, flip_rounds: int = 100,
                        **options) -> TriMesh:
    """Triangulate unorganized points through their meshless parameterization (§8).

    The meshless map uses shape-preserving weights unless ``weights`` says
    otherwise (on camelhead.xyz they recover 80 % of the source mesh's edges,
    inverse distance 68 %).  Delaunay triangulation of the parameter points,
    lifted to 3D, then made closer to a Delaunay triangulation *in 3D*: an
    interior edge whose two opposite 3D angles sum to more than pi is flipped
    when both new triangles keep a positive area in the parameter plane (so the
    UVs stay one-to-one), for at most ``flip_rounds`` rounds of independent
    flips (0 turns this off).  Triangles on
    the outside whose longest 3D edge exceeds ``bridge_factor`` times the local
    point spacing (they bridge concave parts of the boundary) are peeled off
    repeatedly, and the largest manifold disk is kept.

    **Returns:** a :class:`TriMesh` over all input points (in their order;
    unused points are unreferenced) with ``.uv``, ``.boundary_points`` and
    ``.stage_seconds`` (wall-clock seconds of each stage, a dict).

    Example::

        rec = jp.reconstruct_surface(points)
        rec.uv, rec.faces
    """
    weights = options.pop("weights", "shape_preserving")
    k, radius = options.pop("k", 10), options.pop("radius", None)
    symmetric = options.pop("symmetric", True)
    boundary, spacing = options.pop("boundary", "circle"), options.pop("spacing", "chord")
    gap, user_bnd = options.pop("gap", 0.7 * np.pi), options.pop("boundary_indices", None)
    merge = options.pop("merge_duplicates", False)
    max_slope = options.pop("max_slope", 0.6)
    if options:
        raise PointCloudError(f"reconstruct_surface: unknown options {sorted(options)}.")
    _check_map_options("reconstruct_surface", weights, boundary, spacing)
    with reuse_freed_memory(np.shape(points)[0] if np.ndim(points) == 2 else 0):
        return _reconstruct(points, k=k, radius=radius, symmetric=symmetric, weights=weights,
                            boundary=boundary, spacing=spacing, gap=gap, user_bnd=user_bnd,
                            merge=merge, max_slope=max_slope, bridge_factor=bridge_factor,
                            flip_rounds=flip_rounds)


def _reconstruct(points, *, k, radius, symmetric, weights, boundary, spacing, gap, user_bnd, merge,
                 max_slope, bridge_factor, flip_rounds) -> TriMesh:
    clock = _StageClock()
    P0, kept = check_points(points, k=k, merge_duplicates=merge)
    # Everything below runs on the points in Morton order (neighbours close in memory: the
    # weights, the triangulation and the flips run 1.3-2x faster on a large shuffled cloud);
    # the result is renumbered to the input's order at the end.
    perm = _spatial_order(P0)
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.size)
    P = P0[perm]
    graph = _point_graph_in_order(P, k, radius, symmetric, 24, names=perm, max_slope=max_slope)
    clock("neighbours")
    if user_bnd is None:
        bnd = detect_boundary(P, graph, gap=gap)
        clock("boundary")
    else:
        bnd = inv[_check_boundary_indices("reconstruct_surface", user_bnd, P.shape[0])]
    U = np.asarray(_map_points(P, graph, bnd, weights=weights, boundary=boundary, spacing=spacing,
                               symmetric=weights in ("uniform", "inverse_distance") and symmetric
                               and radius is None))
    clock("weights_and_solve")
    F = _delaunay(U)
    F = F[np.argsort(F.min(axis=1), kind="stable")]     # faces in the points' (Morton) order too
    clock("delaunay")
    if flip_rounds:
        F = _flip_towards_3d_delaunay(F, P, U, flip_rounds)
        clock("flips")
    L = np.stack([np.linalg.norm(P[F[:, i]] - P[F[:, (i + 1) % 3]], axis=1) for i in range(3)], 1)
    local = graph.spacing[F].mean(1)
    too_long = L.max(1) > bridge_factor * local
    # Peel in one pass: the too-long faces connected to the outside through too-long faces.
    keep = ~_outside_bridges(F, too_long, len(P))
    F = _peel_ears(F[keep], P, graph)
    F, topology = _largest_manifold_disk(F, len(P))
    n_in = np.asarray(points).shape[0]
    V = np.asarray(points, np.float64) if kept.size == n_in else P0
    mesh = TriMesh(V, None, renumber(topology, perm), uv=U[inv], validate=False,
                   name="reconstruction")
    clock("peel_and_topology")
    mesh.boundary_points = perm[bnd]
    mesh.stage_seconds = clock.seconds
    return mesh


class _StageClock:
    """Wall-clock seconds per named stage: ``clock("name")`` closes the stage that ran since
    the previous call."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self._t = time.perf_counter()

    def __call__(self, name: str) -> None:
        now = time.perf_counter()
        self.seconds[name] = now - self._t
        self._t = now


def _delaunay(U: np.ndarray) -> np.ndarray:
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


def _flip_towards_3d_delaunay(F: np.ndarray, P: np.ndarray, U: np.ndarray, rounds: int) -> np.ndarray:
    """Flip interior edges ``a-b`` (faces ``(a, b, c)``, ``(b, a, d)``) whose opposite 3D angles
    at ``c`` and ``d`` sum to more than pi, and to more than the new diagonal's, into
    ``(a, d, c)``, ``(d, b, c)``, when both new faces keep a positive parameter-plane area.
    The planar embedding is kept, so the result still triangulates the same points one-to-one
    in the plane.

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

    def nxt(h):
        return h - h % 3 + (h + 1) % 3

    def prv(h):
        return h - h % 3 + (h + 2) % 3

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
    return F


def _peel_ears(F: np.ndarray, P: np.ndarray, graph: PointGraph, *, min_angle: float = 0.45 * np.pi,
               rounds: int = 3) -> np.ndarray:
    """Remove boundary "ears" that cover empty space: a face ``(b1, b2, p)`` whose edge
    ``b1-b2`` is on the boundary and whose third vertex ``p`` is not, when none of ``p``'s
    neighbours in ``graph`` lies inside the face's angle at ``p`` (seen in ``p``'s tangent
    plane) and that angle is at least ``min_angle`` (regular boundary faces have apex
    angles near 45 or 60 degrees; on camelhead.xyz exactly the three ears reach 81).  Such
    a face spans a concave notch of the boundary whose point ``p`` the boundary detection
    missed; peeling it puts ``p`` on the boundary.  Each round peels faces with no vertex in common, so the result stays a
    manifold disk."""
    n, m = len(P), len(F)
    deg = np.diff(graph.indptr)
    src, dst, opp = F.reshape(-1), F[:, [1, 2, 0]].reshape(-1), F[:, [2, 0, 1]].reshape(-1)
    twin = half_edge_twins(F, n)
    alive = np.ones(m, bool)
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
        ear = np.flatnonzero((width >= min_angle) & ~inside.any(axis=1))
        if ear.size == 0:
            break
        # Independent: no two peeled faces share a vertex in this round.
        verts = np.stack([b1[ear], b2[ear], p[ear]], 1)
        first = np.full(n, ear.size)
        np.minimum.at(first, verts.reshape(-1), np.repeat(np.arange(ear.size), 3))
        ok = np.all(first[verts] == np.arange(ear.size)[:, None], axis=1)
        alive[h[ear[ok]] // 3] = False
    return F[alive]


def _outside_bridges(F: np.ndarray, bad: np.ndarray, n: int) -> np.ndarray:
    """Faces flagged ``bad`` that reach the triangulation's outside through bad faces only."""
    m = len(F)
    twin = half_edge_twins(F, n)
    h = np.flatnonzero(twin > np.arange(3 * m))          # each interior edge once
    a, b = h // 3, twin[h] // 3
    both = bad[a] & bad[b]
    hull_faces = np.unique(np.flatnonzero(twin < 0) // 3)
    hull_faces = hull_faces[bad[hull_faces]]
    out = m
    rows = np.concatenate([a[both], b[both], np.full(hull_faces.size, out)])
    cols = np.concatenate([b[both], a[both], hull_faces])
    G = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(m + 1, m + 1))
    reached = breadth_first_order(G, out, directed=False, return_predecessors=False)
    mask = np.zeros(m + 1, bool)
    mask[reached] = True
    return mask[:m]


def _largest_manifold_disk(F: np.ndarray, n: int):
    """Make a subset of a planar triangulation a manifold disk: drop the faces at vertices
    where the boundary touches itself (more than two boundary edges: a bowtie left by the
    peeling), then keep the largest edge-connected component.  **Returns:** ``(faces,
    topology)``."""
    from . import topology as topo
    from .errors import NonManifoldError

    for _ in range(50):
        try:
            t = topo.build(F, n, where="reconstruct_surface")
        except NonManifoldError:
            e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
            key = e[:, 0] * np.int64(n) + e[:, 1]
            _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
            touches = np.bincount(e[cnt[inv] == 1].reshape(-1), minlength=n)
            F = F[~np.isin(F, np.flatnonzero(touches > 2)).any(1)]
            continue
        if t.n_components > 1:
            big = int(np.argmax(np.bincount(t.components[t.components >= 0])))
            F = F[t.components[F[:, 0]] == big]
            continue
        return F, t
    raise PointCloudError("reconstruct_surface: could not extract a manifold disk from the "
                          "triangulation; try a larger k or bridge_factor.")
