"""Boundary detection for unorganized points: the points with a wide angular gap in their
neighbourhood, ordered into one closed polygon (the survey leaves this step to [13])."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree, shortest_path
from scipy.spatial import cKDTree

from ..errors import PointCloudError
from ..triangles import polygon_area
from .defaults import GAP, K_DETECT
from .graph import PointGraph, global_frame, knn_gaps

__all__ = ["detect_boundary"]


def detect_boundary(points, graph: PointGraph | None = None, *, gap: float = GAP,
                    k_detect: int = K_DETECT) -> np.ndarray:
    """Boundary points as one closed polygon (indices into ``points``, in order, anticlockwise
    about the global normal).

    Candidates: points whose ``k_detect`` nearest neighbours, projected on the
    tangent plane (the robust frames of :func:`~jaxparam.points.graph.robust_frames` when
    ``graph`` is given), leave an angular gap larger than ``gap`` (a larger
    neighbourhood than the map's: random samplings leave wide gaps in small
    ones).  Candidates within three local spacings of each other (the smaller of the
    two points' mean neighbour distances) are linked; the
    linked group with the longest spanning tree is kept (stray interior
    candidates drop out) and ordered along the longest path of that tree.
    ``graph`` (from :func:`~jaxparam.points.point_graph` with the same ``k_detect``)
    supplies the gaps already computed.
    """
    P = np.asarray(points, np.float64)
    k_detect = min(k_detect, P.shape[0] - 1)
    if graph is not None and graph.detect_k == k_detect:
        det_gap, det_spacing = graph.detect_gap, graph.detect_spacing
    else:
        det_gap, det_spacing = knn_gaps(P, k_detect)
    cand = np.flatnonzero(det_gap > gap)
    n_cand = cand.size
    if cand.size < 3:
        raise PointCloudError(f"meshless_map: found {cand.size} boundary points (largest angular gap "
                              f"> {gap:.2f} rad); the points may sample a closed surface. Pass "
                              "boundary=indices, or lower gap.")
    Q = P[cand]
    kk = min(8, cand.size - 1)
    dist, idx = cKDTree(Q).query(Q, kk + 1)
    # Linked within three local spacings (the smaller of the pair's): the threshold follows
    # the density, so an unevenly sampled boundary stays one chain, and a stray point off the
    # surface (whose own spacing is large) links no further than its partner's spacing allows:
    # with the larger one, two outliers 5-6 % of the diagonal off a 50k-point noisy scan
    # linked a handful of candidates 0.2 apart into a chain longer than the true boundary.
    sp_c = det_spacing[cand]
    rows = np.repeat(np.arange(cand.size), kk)
    d = dist[:, 1:].reshape(-1)
    ok = d <= 3.0 * np.minimum(sp_c[rows], sp_c[idx[:, 1:].reshape(-1)])
    W = sp.csr_matrix((d[ok] + 1e-300, (rows[ok], idx[:, 1:].reshape(-1)[ok])), shape=(cand.size,) * 2)
    W = W.maximum(W.T)
    nc, lab = connected_components(W, directed=False)
    # The boundary is the longest chain: largest total spanning-tree length, not the most points
    # (clusters of stray candidates in sparsely sampled regions can be as numerous).
    Tall = minimum_spanning_tree(W)
    length = np.bincount(lab[Tall.nonzero()[0]], weights=Tall.data, minlength=nc)
    big = np.flatnonzero(lab == np.argmax(length))
    cand, W = cand[big], W[big][:, big]
    if cand.size < 3:
        raise PointCloudError(f"meshless_map: the {n_cand} "
                              "boundary candidates (points with an angular gap > "
                              f"{gap:.2f} rad) form no chain of 3 or more: the points may sample a "
                              "closed surface, which a meshless map cannot flatten; cut it open, "
                              "or pass boundary=indices (a closed loop), or change k_detect/gap.")
    loop = cand[_longest_path(W)]
    if loop.size < 3:
        raise PointCloudError("meshless_map: could not order the boundary points into a polygon; "
                              "pass boundary=indices.")
    # Anticlockwise about the global normal.
    g = global_frame(P)
    uv = (P[loop] - P[loop].mean(0)) @ g[:2].T
    area = polygon_area(uv)
    return loop if area > 0 else loop[::-1]


def _longest_path(W) -> np.ndarray:
    """The nodes, in order, of the longest path in the minimum spanning tree of the weighted
    graph ``W`` (its largest tree when ``W`` is not connected): two sweeps of shortest paths."""
    T = minimum_spanning_tree(W)
    T = T + T.T
    d0 = shortest_path(T, directed=False, indices=0)
    far = np.where(np.isfinite(d0), d0, -1)
    a = int(np.argmax(far))
    da, pred = shortest_path(T, directed=False, indices=a, return_predecessors=True)
    da = np.where(np.isfinite(da), da, -1)
    b = int(np.argmax(da))
    path = [b]
    while path[-1] != a:
        path.append(int(pred[path[-1]]))
    return np.asarray(path[::-1])
