"""Packing flattened charts into the unit square: proper rotations, a margin in texels.

Each chart is first turned (a proper rotation, never a mirror) so that its minimal-area
bounding rectangle is axis-aligned (rotating calipers on the convex hull).  The packer
then works on a raster of ``texture_size`` cells a side: each chart is rasterized
conservatively (every cell its triangles touch, by the separating-axis test), charts are
placed largest first at the lowest, then leftmost, free position (found for all
positions at once by an FFT correlation of the chart's mask with the occupancy), trying
the chart in its four proper turns (0, 90, 180, 270 degrees).  The occupancy holds every placed chart
dilated by the margin, so two charts are at least ``margin_texels`` texels apart.  The
scale (UV units per 3D unit, one for all charts, so texel density is uniform) is found by
bisection on a coarse raster whose cells are ``f x f`` texels (a coarse placement is valid
at full size too), then tried at full size 3 % larger, then 6 % or 1.5 % (the coarse
placement is the fallback).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SolverError

__all__ = ["Packing", "min_area_rotation", "rasterize", "pack_charts"]


@dataclass(frozen=True)
class Packing:
    """Where each chart goes: ``uv = scale * (R[c] @ (uv_chart - origin[c])) + offset[c]``.

    **Fields:** ``rotation (c, 2, 2)`` (proper rotations: det +1), ``origin (c, 2)``,
    ``offset (c, 2)``, ``scale`` (UV units per 3D length unit), ``texture_size``,
    ``margin_texels``, ``attempts`` (scales tried).
    """

    rotation: np.ndarray
    origin: np.ndarray
    offset: np.ndarray
    scale: float
    texture_size: int
    margin_texels: int
    attempts: int

    def apply(self, uv: np.ndarray, uv_chart: np.ndarray) -> np.ndarray:
        """The packed ``(n_uv, 2)`` UVs of the chart UVs ``uv (n_uv, 2)``."""
        R = self.rotation[uv_chart]
        local = np.einsum("nij,nj->ni", R, uv - self.origin[uv_chart])
        return self.scale * local + self.offset[uv_chart]


def _hull(P: np.ndarray) -> np.ndarray:
    """Convex hull vertices of ``P (k, 2)``, counter-clockwise, ``(h, 2)`` (Qhull)."""
    from scipy.spatial import ConvexHull, QhullError
    try:
        return P[ConvexHull(P).vertices]
    except (QhullError, ValueError):
        return P[:0]


def min_area_rotation(P: np.ndarray) -> np.ndarray:
    """The proper rotation ``(2, 2)`` that makes the minimal-area bounding rectangle of the
    points ``P (k, 2)`` axis-aligned (wider than tall)."""
    H = _hull(P)
    if len(H) < 3:
        return np.eye(2)
    e = np.roll(H, -1, axis=0) - H
    ang = np.arctan2(e[:, 1], e[:, 0])
    c, s = np.cos(-ang), np.sin(-ang)
    R = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)       # (h, 2, 2)
    Q = np.einsum("hij,kj->hki", R, H)
    ext = Q.max(1) - Q.min(1)
    best = int(np.argmin(ext[:, 0] * ext[:, 1]))
    Rb = R[best]
    if ext[best, 1] > ext[best, 0]:
        Rb = np.array([[0.0, 1.0], [-1.0, 0.0]]) @ Rb
    return Rb


def rasterize(S: np.ndarray, shape) -> np.ndarray:
    """Conservative raster of a region bounded by the segments ``S (k, 2, 2)`` (in cell
    units; the boundary edges of a chart, in any order): every cell ``[i, i+1] x [j, j+1]``
    that meets the closed region, as a ``shape = (rows, cols)`` bool mask indexed
    ``[j (v), i (u)]``.

    A cell meets the region when a boundary segment passes through it (all cells a segment
    touches: those around each of its crossings with the grid lines, and those holding its
    points between crossings) or when its centre is inside (even-odd rule along each row of
    centres)."""
    rows, cols = shape
    mask = np.zeros(shape, bool)
    A, B = S[:, 0], S[:, 1]
    # cells of the segments: the endpoints and both sides of every grid-line crossing
    pts = [A, B]
    for ax in (0, 1):
        lo, hi = np.minimum(A[:, ax], B[:, ax]), np.maximum(A[:, ax], B[:, ax])
        first, last = np.ceil(lo).astype(np.int64), np.floor(hi).astype(np.int64)
        cnt = np.maximum(last - first + 1, 0)
        e = np.repeat(np.arange(len(S)), cnt)
        line = (np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt) + first[e]).astype(float)
        d = B[e, ax] - A[e, ax]
        tt = np.where(d != 0, (line - A[e, ax]) / np.where(d != 0, d, 1.0), 0.0)
        P = A[e] + tt[:, None] * (B[e] - A[e])
        P[:, ax] = line
        for side in (-0.5, 0.5):
            Q = P.copy()
            Q[:, ax] += side
            pts.append(Q)
            # a crossing on a grid corner touches the diagonal cells too
            Q2 = Q.copy()
            Q2[:, 1 - ax] = np.where(np.floor(P[:, 1 - ax]) == P[:, 1 - ax], P[:, 1 - ax] - 0.5, Q[:, 1 - ax])
            pts.append(Q2)
    P = np.concatenate(pts)
    ci, cj = np.floor(P[:, 0]).astype(np.int64), np.floor(P[:, 1]).astype(np.int64)
    ok = (ci >= 0) & (cj >= 0) & (ci < cols) & (cj < rows)
    mask[cj[ok], ci[ok]] = True
    # centres inside: each segment toggles the cells right of where it crosses a centre row
    y0, y1 = A[:, 1], B[:, 1]
    lo, hi = np.minimum(y0, y1), np.maximum(y0, y1)
    first = np.ceil(lo - 0.5).astype(np.int64)          # rows j with lo <= j + 0.5 < hi
    last = np.ceil(hi - 0.5).astype(np.int64) - 1
    cnt = np.maximum(last - first + 1, 0)
    e = np.repeat(np.arange(len(S)), cnt)
    j = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt) + first[e]
    yc = j + 0.5
    x = A[e, 0] + (yc - A[e, 1]) / (B[e, 1] - A[e, 1]) * (B[e, 0] - A[e, 0])
    i = np.clip(np.ceil(x - 0.5).astype(np.int64), 0, cols)
    keep = (j >= 0) & (j < rows)
    T = np.zeros((rows, cols + 1), np.int32)
    np.add.at(T, (j[keep], i[keep]), 1)
    inside = (np.cumsum(T, axis=1)[:, :cols] % 2).astype(bool)
    return mask | inside


def boundary_segments(uv_faces: np.ndarray, chart: np.ndarray):
    """``(edges (b, 2) UV-vertex pairs, owner (b,) chart)``: the boundary edges of every
    chart (half-edges of ``uv_faces`` without a twin)."""
    h = np.stack([uv_faces[:, [0, 1]], uv_faces[:, [1, 2]], uv_faces[:, [2, 0]]], 1).reshape(-1, 2)
    owner = np.repeat(chart, 3)
    n = int(uv_faces.max()) + 1
    key = h[:, 0] * np.int64(n) + h[:, 1]
    twin = h[:, 1] * np.int64(n) + h[:, 0]
    lone = ~np.isin(twin, key)
    return h[lone], owner[lone]


def _chart_masks(local, seg, seg_of, scale_cells):
    """Masks of every chart at a scale in cells per 3D unit."""
    out = []
    for k in seg_of:
        S = local[seg[k]] * scale_cells                      # (b, 2, 2) >= 0
        w, h = np.floor(S[..., 0].max()) + 1, np.floor(S[..., 1].max()) + 1
        out.append(rasterize(S, (int(h), int(w))))
    return out


#: The four proper turns of a mask: (mask of M, linear part, translation in mask (h, w)).
def _turns(M):
    h, w = M.shape
    return ((M, np.eye(2), (0.0, 0.0)),
            (np.rot90(M, -1), np.array([[0.0, -1.0], [1.0, 0.0]]), (h, 0.0)),     # (h - v, u)
            (M[::-1, ::-1], -np.eye(2), (w, h)),                                 # (w - u, h - v)
            (np.rot90(M, 1), np.array([[0.0, 1.0], [-1.0, 0.0]]), (0.0, w)))     # (v, w - u)


def _place(masks, size, margin):
    """Place masks (largest first) in a ``size x size`` grid at the lowest, then leftmost
    free position over the four proper turns; ``None`` if one does not fit, else
    ``(positions (c, 2) cells [u, v], turn (c,) int)``."""
    from scipy import fft, ndimage

    occ = np.zeros((size, size), np.float32)
    top = 0
    pos = np.zeros((len(masks), 2), np.int64)
    turn = np.zeros(len(masks), np.int64)
    st = np.ones((2 * margin + 1, 2 * margin + 1), bool) if margin else None
    order = np.argsort([-m.sum() for m in masks], kind="stable")
    for c in order:
        best = None
        h0, w0 = masks[c].shape
        L = max(h0, w0)
        rows = min(size, top + L)
        shape = (fft.next_fast_len(rows + L, True), fft.next_fast_len(size + L, True))
        F_occ = fft.rfft2(occ[:rows], shape)
        for t, (M, _, _) in enumerate(_turns(masks[c])):
            h, w = M.shape
            if h > size or w > size or not M.any():
                continue
            ov = fft.irfft2(F_occ * np.conj(fft.rfft2(M.astype(np.float32), shape)), shape)
            nrow = size - h + 1
            free = np.ones((nrow, size - w + 1), bool)
            k = min(nrow, max(rows - h + 1, 0))
            free[:k] = ov[:k, : size - w + 1] < 0.5
            if not free.any():
                continue
            j = int(np.argmax(free.any(1)))
            i = int(np.argmax(free[j]))
            score = (j, j + h, i)
            if best is None or score < best[0]:
                best = (score, t, i, j, M)
        if best is None:
            return None
        _, t, i, j, M = best
        h, w = M.shape
        # the occupancy keeps the mask grown by `margin` cells on each side
        pad = np.pad(M, margin) if margin else M
        D = ndimage.binary_dilation(pad, st) if margin else pad
        j0, i0 = j - margin, i - margin
        js, is_ = max(j0, 0), max(i0, 0)
        je, ie = min(j0 + D.shape[0], size), min(i0 + D.shape[1], size)
        occ[js:je, is_:ie] = np.maximum(occ[js:je, is_:ie], D[js - j0:je - j0, is_ - i0:ie - i0])
        top = max(top, min(size, j + h + margin))
        pos[c] = (i, j)
        turn[c] = t
    return pos, turn


def _try(local, seg, seg_of, scale, size, margin):
    """``(masks, placement or None)`` at ``scale`` (UV units per 3D unit) on a raster of
    ``size`` cells."""
    masks = _chart_masks(local, seg, seg_of, scale * size)
    if sum(int(M.sum()) for M in masks) > 0.97 * size ** 2:      # cannot fit
        return masks, None
    return masks, _place(masks, size, margin)


def pack_charts(uv, uv_faces, chart, uv_chart, area3d, *, texture_size: int = 1024,
                margin_texels: int = 2, fill: float = 0.9, max_attempts: int = 14) -> Packing:
    """Pack the charts' UVs (``uv (n_uv, 2)`` at 3D scale) into ``[0, 1]^2``.

    **Arguments:** ``uv_faces (m, 3)``, ``chart (m,)`` face charts, ``uv_chart (n_uv,)``,
    ``area3d`` (total UV area of the charts at their own scale); ``texture_size`` (cells a side),
    ``margin_texels``; ``fill``: the share of the square the first scale tries to cover.
    **Returns:** a :class:`Packing`.
    """
    k = int(chart.max()) + 1
    rot = np.zeros((k, 2, 2))
    origin = np.zeros((k, 2))
    order = np.argsort(uv_chart, kind="stable")
    bounds = np.searchsorted(uv_chart[order], np.arange(k + 1))
    seg, owner = boundary_segments(uv_faces, chart)
    so = np.argsort(owner, kind="stable")
    sb = np.searchsorted(owner[so], np.arange(k + 1))
    seg_of = [so[sb[c]:sb[c + 1]] for c in range(k)]
    local = np.zeros_like(uv)
    for c in range(k):
        ids = order[bounds[c]:bounds[c + 1]]
        R = min_area_rotation(uv[ids])
        Q = uv[ids] @ R.T
        rot[c], origin[c] = R, np.linalg.solve(R, Q.min(0))
        local[ids] = Q - Q.min(0)
    # the scale: bisection on a coarse raster (its cells are f x f texels, so a coarse
    # placement is also valid at full size), then one or two tries at full size
    f = 1
    while texture_size // (2 * f) >= 192 and texture_size % (2 * f) == 0:
        f *= 2
    cs, cm = texture_size // f, int(np.ceil(margin_texels / f))
    scale = np.sqrt(fill / area3d)
    lo, hi, best = None, None, None
    attempt = 0
    while attempt < max_attempts and (lo is None or hi is None or hi / lo > 1.01):
        attempt += 1
        s_try = scale if lo is None and hi is None else (
            np.sqrt(lo * hi) if lo is not None and hi is not None else (lo * 1.1 if hi is None else hi * 0.85))
        masks, placed = _try(local, seg, seg_of, s_try, cs, cm)
        if placed is None:
            hi = s_try
        else:
            lo, best = s_try, (masks, placed, cs)
    if best is None:
        raise SolverError(f"pack_charts: the {k} charts did not fit into the unit square after "
                          f"{attempt} scales; lower margin_texels or raise texture_size.",
                          stage="pack")
    scale = lo
    if f > 1:
        # the coarse placement at lo is valid at full size already; two full-size tries
        # above it: 3 % larger, then 6 % if that fits, else 1.5 %
        for step in (1.03, None):
            step = step or (1.06 if scale > lo else 1.015)
            attempt += 1
            masks, placed = _try(local, seg, seg_of, lo * step, texture_size, margin_texels)
            if placed is not None:
                scale, best = lo * step, (masks, placed, texture_size)
    masks, (pos, turn), size = best
    cell = 1.0 / size
    offset = np.zeros((k, 2))
    for c in range(k):
        _, Rt, tr = _turns(masks[c])[turn[c]]
        rot[c] = Rt @ rot[c]
        offset[c] = (pos[c] + np.asarray(tr, float)) * cell
    return Packing(rot, origin, offset, float(scale), texture_size, margin_texels, attempt)
