"""NumPy twins of the weights and per-face geometry kernels, for concrete inputs (issue 17).

A first call of a JAX kernel traces, lowers and compiles (about 1 s for the shape-preserving
weights, even when the persistent cache holds the executable, since tracing and lowering come
first); the same formulas in NumPy cost a few milliseconds on a 20k-face mesh.  Each function
here is the line-by-line twin of the JAX one it names, so the results agree to rounding
(``tests/test_speed_paths.py`` asserts the bounds: 1e-14 relative for every kind but the
shape-preserving weights, whose global prefix sum of angles XLA and NumPy round differently,
about 1e-11 on a 23k-face mesh); they are not bitwise equal where XLA's ``arctan2``/``tan``/
``cos`` differ from libm in the last bit.  Not differentiable: callers use
them only when :func:`jaxparam.weights.is_concrete` says no value is traced.
"""
from __future__ import annotations

import numpy as np

from . import tol

__all__ = ["safe_norm", "corner_geometry",  "weights_from_angles", "shape_preserving_weights",
           "frame_coordinates", "face_quantities", "circle", "signed_areas", "face_areas",
           "vertex_normals", "map_aspects", "collapsed_faces"]


def safe_norm(x, axis=-1):
    """Twin of :func:`jaxparam.geometry.safe_norm` (0 below the squared floor)."""
    s = np.sum(x * x, axis=axis)
    pos = s > tol.SAFE_SQRT_FLOOR
    return np.where(pos, np.sqrt(np.where(pos, s, 1.0)), 0.0)


def corner_geometry(V, F):
    """Twin of ``weights._corner_geometry``: per corner ``3 f + c``, ``(angle, cot, length)``."""
    P = V[F]
    e = np.roll(P, -1, axis=1) - P
    f = np.roll(P, 1, axis=1) - P
    cr = safe_norm(np.cross(e, f))
    dot = np.sum(e * f, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cot = dot / cr
    return np.arctan2(cr, dot).reshape(-1), cot.reshape(-1), safe_norm(e).reshape(-1)


def weights_from_angles(kind, angle, prev_angle, length, row, row_start, row_end, degree, *,
                        n_rows, max_degree):
    """Twin of :func:`jaxparam.weights.weights_from_angles` (same arguments, ``(k,)`` out)."""
    if kind == "uniform":
        return np.ones_like(length)
    if kind == "inverse_distance":
        return 1.0 / length
    if kind == "mean_value":
        return (np.tan(0.5 * prev_angle) + np.tan(0.5 * angle)) / length
    if kind == "shape_preserving":
        return shape_preserving_weights(angle, length, row, row_start, row_end, degree,
                                        n_rows=n_rows, max_degree=max_degree)
    raise ValueError(kind)


def shape_preserving_weights(delta, r, row, row_start, row_end, degree, *, n_rows, max_degree):
    """Twin of :func:`jaxparam.weights.shape_preserving_weights` (Floater's eq. (7)).

    The edge opposite each ``p_k`` is found by the same bisection within its row as the JAX
    kernel (``log2`` of the largest degree vectorized steps), so the same edge is chosen.
    """
    total = np.bincount(row, delta, minlength=n_rows)
    scale = (2 * np.pi / total)[row]
    # The global prefix sum cancels in ``excl - excl[row_start]``: both this and the JAX
    # kernel (which sums in another order) round by ~1e-11 on 70k angles (camelhead).
    cum = np.cumsum(delta)
    excl = cum - delta
    phi = scale * (excl - excl[row_start])
    p = r[:, None] * np.stack([np.cos(phi), np.sin(phi)], -1)
    target = np.mod(phi + np.pi, 2 * np.pi)
    lo, hi = row_start.copy(), row_end.copy()
    for _ in range(max(1, int(max_degree).bit_length())):
        mid = (lo + hi) // 2
        up = (lo < hi) & (phi[np.minimum(mid, row_end - 1)] <= target)
        lo, hi = np.where(up, mid + 1, lo), np.where(up | (lo >= hi), hi, mid)
    upper = lo
    l = np.clip(upper - 1, row_start, row_end - 1)
    m = np.where(l + 1 < row_end, l + 1, row_start)
    pk, pl, pm = p, p[l], p[m]
    cross = lambda a, b: a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    ak, al, am = cross(pl, pm), cross(pm, pk), cross(pk, pl)
    tot = ak + al + am
    k_idx = np.arange(p.shape[0])
    on_l, on_m = l == k_idx, m == k_idx
    flat = on_l | on_m | (np.abs(tot) <= 1e-300)
    tot = np.where(flat, 1.0, tot)
    rk, rl, rm = r, r[l], r[m]
    other = np.where(on_l, rm, rl)
    share_k = other / (rk + other)
    ak = np.where(flat, share_k, ak / tot)
    al = np.where(on_l, 0.0, np.where(on_m, 1.0 - share_k, al / tot))
    am = np.where(on_m, 0.0, np.where(on_l, 1.0 - share_k, am / tot))
    idx = np.concatenate([k_idx, l, m])
    tau = np.concatenate([ak, al, am])
    lam = np.bincount(idx, tau, minlength=p.shape[0])
    return lam / degree[row]


def signed_areas(uv, F) -> np.ndarray:
    """Twin of :func:`jaxparam.geometry.signed_areas`: ``(m,)`` signed areas of the faces
    ``F (m, 3)`` of ``uv (n, 2)`` (positive: counter-clockwise)."""
    Q = np.asarray(uv)[F]
    d1, d2 = Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]
    return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])


def face_areas(V, F) -> np.ndarray:
    """Twin of :func:`jaxparam.geometry.face_areas`: ``(m,)`` unsigned areas of the faces
    ``F (m, 3)`` of ``V (n, 3)`` (or ``(n, 2)``, lifted)."""
    V = np.asarray(V)
    if V.shape[-1] == 2:
        return np.abs(signed_areas(V, F))
    P = V[F]
    return 0.5 * safe_norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]))


def vertex_normals(V, F, N=None) -> np.ndarray:
    """``(n, 3)`` unit vertex normals of ``(V (n, 3), F (m, 3))``: the area-weighted sum of
    the face normals around each vertex (0 for unreferenced vertices); ``N (m, 3)``: the
    faces' unnormalized normals ``(v1 - v0) x (v2 - v0)``, when already at hand."""
    V, F = np.asarray(V), np.asarray(F)
    if N is None:
        N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    vn = np.stack([np.bincount(F.ravel(), weights=np.repeat(N[:, d], 3), minlength=V.shape[0])
                   for d in range(3)], 1)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)


def frame_coordinates(V, F):
    """Twin of :func:`jaxparam.geometry.local_frames`: each face of ``V (n, 3)``, ``F (m,
    3)`` in its own frame, corners ``(0, 0)``, ``(l1, 0)``, ``(x2, y2)``.  **Returns:**
    ``(l1, x2, y2, n)``: ``(m,)`` each, and the normals ``n = e1 x e2 (m, 3)`` (``|n|`` is
    twice the area)."""
    P = V[F]
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    l1 = safe_norm(e1)
    n = np.cross(e1, e2)
    return l1, np.sum(e1 * e2, -1) / l1, safe_norm(n) / l1, n


def face_quantities(V, F, uv) -> dict:
    """Twin of :func:`jaxparam.metrics.face_distortion`: ``J (m, 2, 2)``, signed ``s1``, ``s2``,
    ``area3d`` and signed ``area_uv`` (``(m,)`` each), from ``V (n, 3)``, ``F (m, 3)``,
    ``uv (n, 2)``, through the same local frames as :func:`jaxparam.geometry.jacobians`."""
    l1, x2, y2, n = frame_coordinates(V, F)
    Q = uv[F]
    q1, q2 = Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]
    det = l1 * y2                                   # frame columns (l1, 0) and (x2, y2)
    # J = [q1 q2] [[y2, -x2], [0, l1]] / det
    J = np.stack([q1 * y2[:, None], q2 * l1[:, None] - q1 * x2[:, None]], -1) / det[:, None, None]
    a, b, c, d = J[:, 0, 0], J[:, 0, 1], J[:, 1, 0], J[:, 1, 1]
    E, Fh, G, H = 0.5 * (a + d), 0.5 * (a - d), 0.5 * (c + b), 0.5 * (c - b)
    Qs = _safe_sqrt(E * E + H * H)
    R = _safe_sqrt(Fh * Fh + G * G)
    area_uv = 0.5 * (q1[:, 0] * q2[:, 1] - q1[:, 1] * q2[:, 0])
    return {"J": J, "s1": Qs + R, "s2": Qs - R, "area3d": 0.5 * safe_norm(n), "area_uv": area_uv}


def map_aspects(q: dict) -> np.ndarray:
    """``(m,)``: each face's map aspect ``s1 / s2`` from its :func:`face_quantities` ``q``, as
    ``s1^2 / det J`` (``s2 = s1 - 2R`` cancels at large aspects); ``nan`` where the UV triangle
    is not positive (flipped, degenerate or not finite: :func:`jaxparam.metrics.flips` counts
    those)."""
    J, s1 = q["J"], q["s1"]
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        return np.where(q["area_uv"] > 0, s1 * s1 / det, np.nan)


def collapsed_faces(q: dict) -> np.ndarray:
    """``(m,) bool``: the faces (their :func:`face_quantities` ``q``) whose UV triangle is
    positive but collapsed, its :func:`map_aspects` above :data:`jaxparam.tol.COLLAPSED_ASPECT`."""
    with np.errstate(invalid="ignore"):
        return map_aspects(q) > tol.COLLAPSED_ASPECT


def _safe_sqrt(x):
    pos = x > tol.SAFE_SQRT_FLOOR
    return np.where(pos, np.sqrt(np.where(pos, x, 1.0)), 0.0)


def circle(loop_xyz, spacing: str = "chord"):
    """Twin of :func:`jaxparam.boundary.circle` (unit radius): ``(k, 2)`` UVs of the loop
    ``loop_xyz (k, 3)`` on the unit circle, counter-clockwise, spaced by chord length
    (``"chord"``) or evenly (``"uniform"``)."""
    k = loop_xyz.shape[0]
    if spacing == "uniform":
        t = np.arange(k, dtype=np.float64) / k
    else:
        seg = safe_norm(np.roll(loop_xyz, -1, axis=0) - loop_xyz)
        t = np.concatenate([np.zeros(1), np.cumsum(seg)[:-1]]) / np.sum(seg)
    t = 2 * np.pi * t
    return np.stack([np.cos(t), np.sin(t)], axis=1)
