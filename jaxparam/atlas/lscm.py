"""Every chart's least-squares conformal map at once: the start of the atlas's minimization.

A convex-combination start puts each chart's boundary on a circle, far from the free
boundary's optimum: on cow refined once (22k faces, 161 charts) its symmetric Dirichlet
energy is 319 (4 at an isometry) and Newton takes 19 steps.  The least-squares conformal map
(Lévy et al. 2002; the conformal energy of the survey's §6, quadratic in the UVs) lets the
boundary go where the chart's shape wants it: 4.03 there, and 10 steps.  Where a chart's
conformal map folds, the chart keeps the circle, and such charts then set the step count
(the atlas's charts of cow refined 3 times: 2549 -> 1025, 18 -> 17 steps;
benchmarks/README.md).

Per triangle, in its own frame (corners ``(x_j, y_j)``, area ``A``), conformality is one
complex equation ``sum_j W_j (u_j + i v_j) = 0`` with ``W_j = ((x_{j+2} - x_{j+1}) + i
(y_{j+2} - y_{j+1})) / sqrt(2 A)``; its real and imaginary parts are two rows ``r1, r2``
over the corners' interleaved ``(u, v)``, and the map minimizes ``sum_T |r1 q|^2 + |r2 q|^2``
with two boundary vertices of each chart pinned (a chart's conformal energy is zero on
every similarity, so two points fix one).  The normal matrix ``sum_T r1 r1^T + r2 r2^T``
is assembled on the minimization's own Hessian pattern
(:func:`jaxparam.optimize.problem.hessian_pattern`, every vertex free) with the pins held by
a diagonal penalty, so the Newton iterations that follow reuse the pattern and PARDISO's
symbolic analysis.  A chart whose map inverts a triangle or crosses its own boundary keeps
its convex start (Theorem 1: one-to-one), so the start is flip-free and one-to-one chart by
chart either way.
"""
from __future__ import annotations

import numpy as np

from .. import host
from .. import sparse
from ..optimize.problem import free_vertices, hessian_pattern
from .flatten import ChartMesh, convex_start, rescale, self_overlaps

__all__ = ["conformal_start", "conformal_map", "pinned_pairs"]

#: The pins' diagonal penalty, relative to the mean diagonal: the pinned UVs are met to
#: about its inverse (relative), far below what the rescaling and the minimization see.
PIN_PENALTY = 1e8


def pinned_pairs(cm: ChartMesh) -> tuple[np.ndarray, np.ndarray]:
    """Two boundary vertices of each chart, far apart: the boundary vertex farthest (in 3D)
    from the chart's first boundary vertex, and the one farthest from that.
    **Returns:** ``(a, b)``, ``(c,)`` UV-vertex ids each."""
    V = np.asarray(cm.mesh.vertices, np.float64)
    B = np.concatenate(cm.mesh.topology.boundary_loops)
    c = cm.uv_chart[B]
    order = np.argsort(c, kind="stable")
    B, c = B[order], c[order]
    k = np.arange(cm.n_charts)

    def farthest(src):
        d = np.linalg.norm(V[B] - V[src[c]], axis=1)
        o = np.lexsort((-d, c))
        return B[o[np.searchsorted(c[o], k)]]

    b = farthest(B[np.searchsorted(c, k)])
    return farthest(b), b


def conformal_map(cm: ChartMesh) -> np.ndarray:
    """Every chart's least-squares conformal map, one sparse solve: ``uv (n_uv, 2)``, each
    chart's pins at ``(0, 0)`` and ``(|p_a - p_b|, 0)`` (its 3D scale)."""
    V = np.asarray(cm.mesh.vertices, np.float64)
    t = cm.mesh.topology
    F = t.faces
    m = F.shape[0]
    l1, x2, y2, _ = host.frame_coordinates(V, F)
    X = np.stack([np.zeros(m), l1, x2], 1)
    Y = np.stack([np.zeros(m), np.zeros(m), y2], 1)
    s = 1.0 / np.sqrt(l1 * y2)                                  # 1 / sqrt(2 A)
    a = (np.roll(X, -2, 1) - np.roll(X, -1, 1)) * s[:, None]    # Re W_j
    b = (np.roll(Y, -2, 1) - np.roll(Y, -1, 1)) * s[:, None]    # Im W_j
    r1 = np.stack([a, -b], 2).reshape(m, 6)                     # Re: a u - b v
    r2 = np.stack([b, a], 2).reshape(m, 6)                      # Im: b u + a v
    H = r1[:, :, None] * r1[:, None, :] + r2[:, :, None] * r2[:, None, :]
    free = free_vertices(t, True)
    hp = hessian_pattern(t, np.asarray(free, np.int64).tobytes())
    vals = np.bincount(hp.pos, weights=H.reshape(-1), minlength=hp.pattern.nnz)
    slot = np.full(t.n_vertices, -1, np.int64)
    slot[free] = np.arange(free.size)
    pa, pb = pinned_pairs(cm)
    target = np.zeros((t.n_vertices, 2))
    target[pb, 0] = np.linalg.norm(V[pa] - V[pb], axis=1)
    dofs = (2 * slot[np.r_[pa, pb]][:, None] + np.arange(2)).reshape(-1)
    w = PIN_PENALTY * float(np.mean(vals[hp.diag]))
    vals[hp.diag[dofs]] += w
    rhs = np.zeros(2 * free.size)
    rhs[dofs] = w * target[np.r_[pa, pb]].reshape(-1)
    x = sparse.factorize(hp.pattern, vals, symmetric=True).solve(rhs)
    uv = np.zeros((t.n_vertices, 2))
    uv[free] = x.reshape(-1, 2)
    return uv


def conformal_start(cm: ChartMesh, *, weights: str = "shape_preserving") -> np.ndarray:
    """The atlas's start: each chart's :func:`conformal_map`, mirrored when it came out
    clockwise, or its :func:`~jaxparam.atlas.flatten.convex_start` (``weights``) where the
    conformal map inverts or flattens a triangle or crosses its own boundary; every chart
    recentred and scaled to its 3D area (:func:`~jaxparam.atlas.flatten.rescale`).
    **Returns:** ``uv (n_uv, 2)``, flip-free chart by chart."""
    uv = conformal_map(cm)
    F = cm.mesh.faces
    area = host.signed_areas(uv, F)
    neg = np.bincount(cm.chart, weights=(area < 0), minlength=cm.n_charts)
    zero = np.bincount(cm.chart, weights=~(np.abs(area) > 0), minlength=cm.n_charts)   # NaN too
    size = np.bincount(cm.chart, minlength=cm.n_charts)
    mirror = (neg == size) & (zero == 0)
    uv[mirror[cm.uv_chart], 1] *= -1.0
    bad = ~mirror & ((neg > 0) | (zero > 0)) | ~np.isfinite(
        np.bincount(cm.uv_chart, weights=uv.sum(1), minlength=cm.n_charts))
    # A conformal map can cross its own boundary; the minimization would keep the fold
    # (its energy does not see it) and the chart would be split: start those on a circle.
    bad |= self_overlaps(cm, np.where(bad[cm.uv_chart, None], 0.0, uv)) > 0
    if bad.any():
        on = bad[cm.uv_chart]
        uv[on] = convex_start(cm, weights=weights)[on]
    return rescale(cm, uv)
