"""Optional smoothing of scanned points before their reconstruction: each point moved along its
robust normal onto a surface fitted to its neighbours (a moving-least-squares projection).
Numpy on concrete points."""
from __future__ import annotations

import numpy as np

from .graph import BLOCK, Frames

__all__ = ["SMOOTHING", "smooth_points"]

#: The values of ``reconstruct_surface(smooth=...)``: ``None`` keeps the input points.
SMOOTHING = (None, "mls", "plane")


def smooth_points(P: np.ndarray, near: np.ndarray, frames: Frames, how: str) -> np.ndarray:
    """Points ``P (N, 3)`` moved along ``frames.normal`` onto a surface fitted to their
    neighbours ``near (N, k)`` (self excluded, ``k >= 6``), Gaussian-weighted by distance:

    - ``"mls"``: the weighted least-squares quadratic height field ``z(x, y)`` over the
      tangent plane ``(e1, e2)``, evaluated at the point (curved parts are not flattened);
    - ``"plane"``: the plane of :func:`~jaxparam.points.graph.robust_frames` (shrinks curved
      parts by about ``curvature * spacing^2``).

    Heights are the neighbours' own, so the point's noise drops out; the neighbours' averages
    out by their number.  **Returns:** the moved points ``(N, 3)`` (a new array)."""
    if how == "plane":
        # The plane passes through the neighbours' weighted mean c: the point's signed height
        # is n . (0 - c) in the point's own coordinates.
        out = np.empty_like(P)
        for r0 in range(0, P.shape[0], BLOCK):
            r1 = min(r0 + BLOCK, P.shape[0])
            D = P[near[r0:r1]] - P[r0:r1, None, :]
            n = frames.normal[r0:r1]
            r2 = np.einsum("bkd,bkd->bk", D, D)
            w = np.exp(-r2 / (r2.mean(1, keepdims=True) + 1e-300))
            h = np.einsum("bk,bk->b", w, np.einsum("bkd,bd->bk", D, n)) / w.sum(1)
            out[r0:r1] = P[r0:r1] + h[:, None] * n
        return out
    out = np.empty_like(P)
    for r0 in range(0, P.shape[0], BLOCK):
        r1 = min(r0 + BLOCK, P.shape[0])
        D = P[near[r0:r1]] - P[r0:r1, None, :]                       # (b, k, 3)
        n, e1, e2 = frames.normal[r0:r1], frames.e1[r0:r1], frames.e2[r0:r1]
        x = np.einsum("bkd,bd->bk", D, e1)
        y = np.einsum("bkd,bd->bk", D, e2)
        z = np.einsum("bkd,bd->bk", D, n)
        r2 = x * x + y * y
        h2 = r2.mean(1, keepdims=True) + 1e-300
        w = np.exp(-r2 / h2)
        # Scaled monomials (units cancel; the system stays well conditioned).
        s = np.sqrt(h2)
        xs, ys = x / s, y / s
        A = np.stack([np.ones_like(xs), xs, ys, xs * xs, xs * ys, ys * ys], -1)   # (b, k, 6)
        Aw = A * w[:, :, None]
        M = np.matmul(Aw.transpose(0, 2, 1), A) + 1e-9 * np.eye(6)
        rhs = np.einsum("bkc,bk->bc", Aw, z)
        a0 = np.linalg.solve(M, rhs[:, :, None])[:, 0, 0]
        out[r0:r1] = P[r0:r1] + a0[:, None] * n
    return out
