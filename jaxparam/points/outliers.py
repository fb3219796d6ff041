"""Outliers of a scanned point set: points far from the surface their neighbours define, found
from the robust tangent frames (:func:`~jaxparam.points.graph.robust_frames`) and taken out of
the neighbour lists without a second tree query.  Numpy on concrete points."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..blocks import for_blocks
from .defaults import GAP, OUTLIER_HEIGHT, OUTLIER_ISOLATION, OUTLIER_MIN_NEIGHBOURS, OUTLIER_SCALE
from .graph import DENSE_BLOCK, Frames

__all__ = ["find_outliers", "drop_points"]


def find_outliers(P: np.ndarray, frames: Frames, dist: np.ndarray, near: np.ndarray, *,
                  scale: float = OUTLIER_SCALE, height: float = OUTLIER_HEIGHT,
                  isolation: float = OUTLIER_ISOLATION, gap: float = GAP) -> np.ndarray:
    """``(N,) bool``: the points of ``P (N, 3)`` far from the surface their neighbours
    ``near (N, k)`` (at distances ``dist (N, k)``, nearest first, ``k >= 4``) define.  A point
    is an outlier when

    - its height above its neighbours' plane (``frames.height``, the point itself left out of
      that plane's fit) exceeds ``scale`` robust noise scales of the neighbours
      (``frames.noise``: adapts to the noise and curvature around it) and ``height`` times
      their in-plane RMS distance (``frames.radius``: adapts to the density); or
    - it is isolated: its mean distance to its 4 nearest exceeds ``isolation`` times the
      median of the same over its neighbours, and either its height exceeds two noise
      scales or its neighbours leave an angular gap above ``gap`` around it in its plane
      (a point beyond the boundary).  Isolation alone would also flag the vertices of large
      triangles next to small ones in an adaptive mesh's vertex set (40 of camelhead.xyz's
      11381); those have neighbours all around.

    Measured on samples of four shared disk meshes (20k points with noise 0.2 %, eightfold
    density variation and 1 % outliers 1.5-10 % of the diagonal off): a few of 200 outliers
    missed (the reconstruction finds most of them later, as points whose every Delaunay face
    is a bridge), at most 5 of 19800 inliers flagged.  On camelhead.xyz (an adaptive
    mesh's vertices, no outlier) the isolation test flags clean points next to large
    boundary triangles (angular gap near pi, height under 1.5 noise scales): indistinguishable
    here from a planted outlier lying in the tangent plane beyond the boundary.  With the
    points the reconstruction drops later, :func:`~jaxparam.points.reconstruct_surface`
    reports 32 of its 11381 points as outliers (0.28 %; measured in session 10).

    With fewer than ``OUTLIER_MIN_NEIGHBOURS`` (8) neighbours per point (a set of at most 8
    points) nothing is flagged: the neighbours' plane and noise scale mean nothing there."""
    if near.shape[1] < OUTLIER_MIN_NEIGHBOURS:
        return np.zeros(P.shape[0], bool)
    d4 = dist[:, :4].mean(1)
    high = (frames.height > scale * frames.noise) & (frames.height > height * frames.radius)
    iso = np.flatnonzero((d4 > isolation * _row_median(np.take(d4, near))) & ~high)
    if iso.size:
        D = P[near[iso]] - P[iso, None, :]
        ang = np.sort(np.arctan2(np.einsum("ckd,cd->ck", D, frames.e2[iso]),
                                 np.einsum("ckd,cd->ck", D, frames.e1[iso])), axis=1)
        wide = np.maximum((ang[:, 1:] - ang[:, :-1]).max(1), ang[:, 0] + 2 * np.pi - ang[:, -1])
        high[iso] = (wide > gap) | (frames.height[iso] > 2.0 * frames.noise[iso])
    return high


def _row_median(v: np.ndarray) -> np.ndarray:
    """``np.median(v, axis=1)`` of ``v (N, k)`` without NaNs, bitwise, by one partition for the
    middle one or two (np.median's own checks and copies cost as much again at 1M points)."""
    k = v.shape[1]
    mid = [(k - 1) // 2, k // 2]
    out = np.empty(v.shape[0])

    def block(r0, r1):
        out[r0:r1] = np.partition(v[r0:r1], mid, axis=1)[:, mid].mean(1)

    for_blocks(block, v.shape[0], DENSE_BLOCK)
    return out


def drop_points(P: np.ndarray, dist: np.ndarray, near: np.ndarray, drop: np.ndarray, k: int):
    """Remove the points ``drop (N,) bool`` from ``P (N, 3)`` and from the neighbour lists
    ``dist, near (N, q)`` (nearest first), keeping each remaining point's ``k <= q`` nearest
    remaining neighbours; the few rows that lose more than ``q - k`` are queried again.

    **Returns:** ``(keep (M,) int, P[keep], dist (M, k), near (M, k), changed (c,) int)``,
    indices into ``P[keep]``; ``changed`` the rows whose ``k`` nearest changed."""
    keep = np.flatnonzero(~drop)
    new = np.full(P.shape[0], -1, np.int64)
    new[keep] = np.arange(keep.size)
    nk, dk = near[keep], dist[keep]
    good = ~drop[nk]
    hit = np.flatnonzero(~good.all(1))         # the few rows that lost a neighbour
    order = np.argsort(~good[hit], axis=1, kind="stable")      # kept neighbours first, in order
    nk[hit] = np.take_along_axis(nk[hit], order, 1)
    dk[hit] = np.take_along_axis(dk[hit], order, 1)
    nk, dk = nk[:, :k], dk[:, :k]
    Q = P[keep]
    short = np.flatnonzero(good.sum(1) < k)
    if short.size:
        d2, i2 = cKDTree(Q).query(Q[short], k + 1, workers=-1)
        dk[short], nk[short] = d2[:, 1:], keep[i2[:, 1:]]
    changed = np.flatnonzero(~good[:, :k].all(1))
    return keep, Q, dk, new[nk], changed
