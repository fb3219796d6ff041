"""Least-squares conformal maps (Lévy et al. 2002) of one or several disks, one sparse solve.

The start of a free-boundary minimization: :func:`jaxparam.minimize`'s default with
``free_boundary=True``, and every chart of :func:`jaxparam.atlas`
(:mod:`jaxparam.atlas.lscm`).  A convex-combination start puts the boundary on a circle,
far from where a free boundary's optimum puts it; the conformal map lets the boundary go
where the surface's shape wants it (Newton from it, symmetric Dirichlet, against the convex
map: camelhead 25 -> 19 steps, snail x16 12 -> 5, bump-domain x4 19 -> 1; benchmarks/README.md,
session 14).

Per triangle, in its own frame (corners ``(x_j, y_j)``, area ``A``), conformality is one
complex equation ``sum_j W_j (u_j + i v_j) = 0`` with ``W_j = ((x_{j+2} - x_{j+1}) + i
(y_{j+2} - y_{j+1})) / sqrt(2 A)``; its real and imaginary parts are two rows ``r1, r2``
over the corners' interleaved ``(u, v)``, and the map minimizes ``sum_T |r1 q|^2 + |r2 q|^2``
with two boundary vertices of each disk pinned (a disk's conformal energy is zero on every
similarity, so two points fix one).  The normal matrix ``sum_T r1 r1^T + r2 r2^T`` is
assembled on the minimization's own Hessian pattern
(:func:`jaxparam.optimize.problem.hessian_pattern`, every vertex free) with the pins held by
a diagonal penalty, so the Newton iterations that follow reuse the pattern and PARDISO's
symbolic analysis.  The map is not one-to-one in general (it can fold a triangle or cross
its own boundary): the callers check it and fall back to a convex-combination map.
"""
from __future__ import annotations

import numpy as np

from .. import host
from .. import sparse
from .problem import free_vertices, hessian_pattern

__all__ = ["conformal_map", "pinned_pairs", "orient_disks", "PIN_PENALTY"]

#: The pins' diagonal penalty, relative to the mean diagonal: the pinned UVs are met to
#: about its inverse (relative), far below what the rescaling and the minimization see.
PIN_PENALTY = 1e8


def pinned_pairs(vertices, topology, label: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Two boundary vertices of each of the ``n`` disks (``label (n_vertices,)`` each
    vertex's disk), far apart: the boundary vertex farthest (in 3D) from the disk's first
    boundary vertex, and the one farthest from that.  **Returns:** ``(a, b)``, ``(n,)``
    vertex ids each."""
    V = np.asarray(vertices, np.float64)
    B = np.concatenate(topology.boundary_loops)
    c = label[B]
    order = np.argsort(c, kind="stable")
    B, c = B[order], c[order]
    k = np.arange(n)

    def farthest(src):
        d = np.linalg.norm(V[B] - V[src[c]], axis=1)
        o = np.lexsort((-d, c))
        return B[o[np.searchsorted(c[o], k)]]

    b = farthest(B[np.searchsorted(c, k)])
    return farthest(b), b


def conformal_map(vertices, topology, label: np.ndarray, n: int) -> np.ndarray:
    """Every disk's least-squares conformal map, one sparse solve: ``uv (n_vertices, 2)``,
    each disk's pins (:func:`pinned_pairs`) at ``(0, 0)`` and ``(|p_a - p_b|, 0)`` (its 3D
    scale); vertices in no face get 0.  ``label (n_vertices,)``: each vertex's disk in
    ``0..n-1`` (the disks share no vertex); every disk needs a boundary."""
    V = np.asarray(vertices, np.float64)
    t = topology
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
    pa, pb = pinned_pairs(V, t, label, n)
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


def orient_disks(uv: np.ndarray, faces: np.ndarray, face_label: np.ndarray,
                 vertex_label: np.ndarray, n: int) -> np.ndarray:
    """Check :func:`conformal_map`'s disks one by one: a disk whose triangles all came out
    clockwise is mirrored in place (``v -> -v``: a proper map of the other orientation, not
    a fold).  **Returns:** ``bad (n,) bool``: the disks that still invert or flatten a
    triangle, or have a non-finite UV (``face_label (m,)``, ``vertex_label (n_vertices,)``
    the faces' and vertices' disks).  Boundary self-crossings are the caller's to check."""
    area = host.signed_areas(uv, faces)
    neg = np.bincount(face_label, weights=(area < 0), minlength=n)
    zero = np.bincount(face_label, weights=~(np.abs(area) > 0), minlength=n)    # NaN too
    size = np.bincount(face_label, minlength=n)
    mirror = (neg == size) & (zero == 0)
    uv[mirror[vertex_label], 1] *= -1.0
    return ~mirror & ((neg > 0) | (zero > 0)) | ~np.isfinite(
        np.bincount(vertex_label, weights=uv.sum(1), minlength=n))
