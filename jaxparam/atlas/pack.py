"""Packing flattened charts into the unit square: proper rotations, a margin in texels.

Each chart is first turned (a proper rotation, never a mirror) so that its minimal-area
bounding rectangle is axis-aligned (rotating calipers on the convex hull).  The packer
then works on a raster whose cells are ``f x f`` texels (``f`` the largest power of two
that divides the texture size and leaves at least 512 cells a side; 512 cells for a 1024
or 2048 texture): each chart is rasterized conservatively
(every cell its boundary touches, and the cells inside), and charts are placed largest
first, each at the free position that keeps the bounding square of the charts placed so
far smallest (then the smallest bounding rectangle, then the lowest, then the leftmost),
over its four proper turns (0, 90, 180, 270 degrees).  The occupancy holds every placed
chart dilated by the margin.  Inside the current bounding rectangle, free positions are
sifted with a few of the mask's boundary cells and checked with all of them, then with the
whole mask (:func:`_inside`); when none is free there, all positions are tested at once by
an FFT correlation of the mask with the occupancy (:func:`_anywhere`).  The bounding
square (side ``S`` cells), framed by ``m = ceil(margin_texels / f)`` free cells on each
side, is then scaled onto ``[0, 1]^2``: a cell becomes ``texture_size / (S + 2 m) >= f``
texels, so two charts stay at least ``margin_texels`` texels apart, and every chart at
least ``margin_texels`` texels from the square's border (for bilinear filtering and
mip-maps at the texture's edge).  The scale (UV units per 3D unit, one for all charts, so
texel density is uniform) starts from the charts' area and is corrected from each
packing's side, so that ``S + 2 m`` comes close to (and not above) the raster's size: a
few packings in all; it starts no larger than the longest chart allows, and where wide
margins would take much of the square, from the scale at which the charts and their margins
take the share ``fill`` (a texture too small for one cell per chart and its margins is refused
before any packing).  A short bisection on the scale then packs into the fixed square of
the raster's size less the frame (:func:`fill_square`: largest first, each chart at its
lowest, then leftmost free position over its four turns) at scales up to 12 % more area,
and keeps the largest scale that fits: bottom-left filling of a fixed square nests the
last charts into the gaps the growing square leaves (session 8, on the same charts: 3holes
59.6 -> 61.9 %, rocker-arm 60.8 -> 63.0 %, decimated-knight 64.8 -> 65.8 %, bunny 65.1 ->
66.0 %, cow and halftunnel unchanged).  Each scale of that bisection is tried first by the
bottom-left fill, and when that fails by the most-contact fill (:func:`fill_contact`: each
chart, over its four proper turns, at the free position whose ring of neighbouring cells
touches the most placed charts' margins and the square's border; FFT correlations, two to
four times the bottom-left fill's time): neither wins on every set of charts, and the
coverage depends only on the scale that fits (session 10, same charts: bunny 66.0 -> 70.3 %,
decimated-knight 70.3 -> 71.3 %, 3holes 69.5 -> 70.0 %; cow, camel_b, camelhead, rocker-arm
and halftunnel unchanged).  The most-contact fill places the :data:`CONTACT_CHARTS` largest
charts, the rest bottom-left: a noisy mesh's thousands of small charts would cost 15 ms each
in FFTs (session 18).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SolverError

__all__ = ["Packing", "texels_per_cell", "MANY_CHARTS", "MANY_CHARTS_STEPS", "min_area_rotation",
           "min_square_rotation", "rasterize", "pack_charts",
           "place_square", "fill_square", "fill_contact", "grown"]


@dataclass(frozen=True)
class Packing:
    """Where each chart goes: ``uv = scale * (R[c] @ (uv_chart - origin[c])) + offset[c]``.

    **Fields:** ``rotation (c, 2, 2)`` (proper rotations: det +1), ``origin (c, 2)``,
    ``offset (c, 2)``, ``scale`` (UV units per 3D length unit), ``texture_size``,
    ``margin_texels``, ``attempts`` (packings tried).
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


def texels_per_cell(texture_size: int) -> int:
    """The side ``f`` of a packing raster cell in texels: the largest power of two that
    divides ``texture_size`` and leaves at least 512 cells a side (``texture_size // f``
    cells: 512 for a 1024 or 2048 texture)."""
    f = 1
    while texture_size // (2 * f) >= 512 and texture_size % (2 * f) == 0:
        f *= 2
    return f


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


def min_square_rotation(P: np.ndarray, steps: int = 720) -> np.ndarray:
    """The proper rotation ``(2, 2)`` that makes the bounding square of the points ``P (k, 2)``
    smallest (its side ``max(width, height)``; angles in steps of ``90 / steps`` degrees and
    the convex hull's edge directions): the turn for an atlas of one chart, which fills the
    square alone (snail: 49.6 -> 63.1 % bound at the min-area rectangle's turn)."""
    H = _hull(P)
    if len(H) < 3:
        return np.eye(2)
    e = np.roll(H, -1, axis=0) - H
    th = np.r_[np.linspace(0.0, np.pi / 2, steps, endpoint=False), -np.arctan2(e[:, 1], e[:, 0])]
    c, s = np.cos(th), np.sin(th)
    R = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)       # (t, 2, 2)
    Q = np.einsum("tij,kj->tki", R, H)
    ext = Q.max(1) - Q.min(1)
    return R[int(np.argmin(ext.max(1)))]


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


def _correlations(F_occ, masks, shape):
    """``corr[t][j, i] = sum_{y, x} occ[j + y, i + x] masks[t][y, x]`` for the four turns'
    masks (``None`` to skip one), from the occupancy's spectrum ``F_occ`` (an ``rfft2`` at
    ``shape``).  Turns 2 and 3 are turns 0 and 1 rotated by 180 degrees (:func:`_turns`), so
    their correlations are the unturned masks' convolutions, read ``(h - 1, w - 1)`` further
    on: two mask spectra instead of four (the FFTs are most of the packing's time).  Each
    result is valid where ``j <= shape[0] - h`` and ``i <= shape[1] - w``, which is every
    position the callers read (float32 sums of 0/1 cells: within 1e-2 of an integer)."""
    from scipy import fft

    spectra, out = {}, []
    for t, M in enumerate(masks):
        if M is None:
            out.append(None)
            continue
        base = t % 2
        if base not in spectra:
            src = M if t < 2 else M[::-1, ::-1]
            spectra[base] = fft.rfft2(src.astype(np.float32), shape)
        if t < 2:
            out.append(fft.irfft2(F_occ * np.conj(spectra[base]), shape))
        else:
            h, w = M.shape
            out.append(fft.irfft2(F_occ * spectra[base], shape)[h - 1:, w - 1:])
    return out


def _inside(turns, occb, W, H, samples: int = 24, chunk: int = 512, chunks: int = 8):
    """The lowest, then leftmost free position inside the current bounding rectangle
    ``W x H`` over the turns, or ``None`` (then :func:`_anywhere` searches).

    The mask's boundary cells (those with a cell outside among their eight neighbours)
    are tested first: a few sift the positions (shifted ANDs), all of them check the
    survivors in row order, and the whole mask checks the first positions whose boundary
    is free (a placed mask could lie inside the new one's interior; when masks are placed
    largest first it cannot).  After ``chunks`` chunks of survivors the caller falls back
    to the FFT search.  **Returns:** ``(key, turn, i, j, mask)`` or ``None``.
    """
    from scipy import ndimage

    best = None
    for t, (M, _, _) in enumerate(turns):
        h, w = M.shape
        jn, in_ = H - h + 1, W - w + 1
        if jn <= 0 or in_ <= 0:
            continue
        rim = M & ~ndimage.binary_erosion(M, np.ones((3, 3), bool), border_value=0)
        by, bx = np.nonzero(rim)
        if by.size == 0:
            continue
        pick = np.unique(np.linspace(0, by.size - 1, min(samples, by.size)).astype(np.int64))
        hit = np.zeros((jn, in_), bool)       # in place: no temporary per sample
        for y, x in zip(by[pick], bx[pick]):
            hit |= occb[y:y + jn, x:x + in_]
        idx = np.flatnonzero(~hit)
        if best is not None:                  # only positions before the best so far
            idx = idx[idx // in_ * (1 << 12) + idx % in_ < best[0]]
        found = None
        for k in range(0, min(idx.size, chunk * chunks), chunk):
            jj, ii = np.divmod(idx[k:k + chunk], in_)
            hit = occb[jj[:, None] + by[None], ii[:, None] + bx[None]].any(1)
            for b in np.flatnonzero(~hit)[:4]:     # a free rim; the whole mask decides
                if not np.any(occb[jj[b]:jj[b] + h, ii[b]:ii[b] + w] & M):
                    found = (int(jj[b]), int(ii[b]))
                    break
            if found is not None:
                break
        if found is None:
            if idx.size > chunk * chunks:
                return None                   # too many to check: the exact search decides
            continue
        j, i = found
        key = (j << 12) + i
        if best is None or key < best[0]:
            best = (key, t, i, j, M)
    return best


def _anywhere(turns, occ, W, H, cap, margin):
    """The free position of least ``(square side, rectangle area, row, column)`` over the
    turns, all positions tested by an FFT correlation with the occupancy ``occ``.
    **Returns:** ``(key, turn, i, j, mask)`` or ``None``."""
    from scipy import fft

    L = max(turns[0][0].shape)
    # positions j <= H + margin, i <= W + margin suffice (beyond, the square only grows)
    R, C = min(cap, H + margin + L), min(cap, W + margin + L)
    shape = (fft.next_fast_len(R, True), fft.next_fast_len(C, True))
    F_occ = fft.rfft2(occ[:R, :C], shape)
    best = None
    masks = [M if M.any() else None for M, _, _ in turns]
    for t, ov in enumerate(_correlations(F_occ, masks, shape)):
        if ov is None:
            continue
        M = masks[t]
        h, w = M.shape
        jm, im = min(H + margin, cap - h), min(W + margin, cap - w)
        fj, fi = np.nonzero(ov[:jm + 1, :im + 1] < 0.5)
        if fj.size == 0:
            continue
        W2, H2 = np.maximum(W, fi + w), np.maximum(H, fj + h)
        key = ((np.maximum(W2, H2).astype(np.int64) << 24) + W2 * H2) * (1 << 24) + (fj << 12) + fi
        b = int(np.argmin(key))
        if best is None or key[b] < best[0]:
            best = (key[b], t, int(fi[b]), int(fj[b]), M)
    return best


def place_square(masks, cap: int, margin: int, order: np.ndarray | None = None):
    """Place masks (largest first) on a ``cap x cap`` raster, each at the free position
    (over its four proper turns) that keeps the bounding square of the masks placed so far
    smallest; ties go to the smaller bounding rectangle, then the lowest, then the
    leftmost position.  Masks are at least ``margin`` cells apart.  ``order``: the order of
    placement (default: decreasing mask area).

    **Returns:** ``None`` if one does not fit, else ``(positions (c, 2) cells [u, v],
    turn (c,) int, side)``, ``side`` the bounding square's in cells.
    """
    occ = np.zeros((cap, cap), np.float32)
    occb = np.zeros((cap, cap), bool)
    W = H = 0
    pos = np.zeros((len(masks), 2), np.int64)
    turn = np.zeros(len(masks), np.int64)
    if order is None:
        order = np.argsort([-m.sum() for m in masks], kind="stable")
    for c in order:
        L = max(masks[c].shape)
        if L > cap:
            return None
        turns = _turns(masks[c])
        best = _inside(turns, occb, W, H)
        if best is None:
            best = _anywhere(turns, occ, W, H, cap, margin)
        if best is None:
            return None
        _, t, i, j, M = best
        h, w = M.shape
        # the occupancy keeps the mask grown by `margin` cells on each side
        js, je, is_, ie = _paint(occb, M, i, j, margin)
        occ[js:je, is_:ie] = occb[js:je, is_:ie]
        W, H = max(W, i + w), max(H, j + h)
        pos[c] = (i, j)
        turn[c] = t
    return pos, turn, max(W, H, 1)


def grown(M: np.ndarray, margin: int) -> np.ndarray:
    """The mask ``M (h, w)`` padded by ``margin`` cells and dilated by the ``(2 margin + 1)``
    square, ``(h + 2 margin, w + 2 margin)`` bool: a running maximum along each axis (the
    square is separable; ``binary_dilation`` with it costs ``(2 margin + 1)^2`` per cell:
    283 of 302 s of cow's atlas with 64-texel margins)."""
    from scipy import ndimage

    if not margin:
        return M
    D = np.pad(M, margin).astype(np.uint8)
    for axis in (0, 1):
        D = ndimage.maximum_filter1d(D, 2 * margin + 1, axis=axis, mode="constant", cval=0)
    return D.astype(bool)


def _paint(occb, M, i, j, margin):
    """Mark the mask ``M`` placed at cell ``(i, j)``, grown by ``margin`` cells, in ``occb``;
    **returns** the rows and columns touched, ``(js, je, is_, ie)``."""
    cap_r, cap_c = occb.shape
    D = grown(M, margin)
    j0, i0 = j - margin, i - margin
    js, is_ = max(j0, 0), max(i0, 0)
    je, ie = min(j0 + D.shape[0], cap_r), min(i0 + D.shape[1], cap_c)
    occb[js:je, is_:ie] |= D[js - j0:je - j0, is_ - i0:ie - i0]
    return js, je, is_, ie


def _lowest_free(turns, occb, size):
    """The lowest, then leftmost free position of the mask over its turns inside the
    ``size x size`` square, all positions tested by an FFT correlation with ``occb``.
    **Returns:** ``(key, turn, i, j, mask)`` or ``None``."""
    from scipy import fft

    shape = (fft.next_fast_len(size, True),) * 2
    F_occ = fft.rfft2(occb[:size, :size].astype(np.float32), shape)
    best = None
    masks = [None if M.shape[0] > size or M.shape[1] > size or not M.any() else M
             for M, _, _ in turns]
    for t, ov in enumerate(_correlations(F_occ, masks, shape)):
        if ov is None:
            continue
        M = masks[t]
        h, w = M.shape
        free = ov[:size - h + 1, :size - w + 1] < 0.5
        if free.any():
            j, i = np.unravel_index(int(np.argmax(free)), free.shape)
            key = (int(j) << 12) + int(i)
            if best is None or key < best[0]:
                best = (key, t, int(i), int(j), M)
    return best


def fill_square(masks, size: int, margin: int, order: np.ndarray | None = None):
    """Place masks (largest first) in a fixed ``size x size`` raster, each at its lowest,
    then leftmost free position over its four proper turns (bottom-left fill), at least
    ``margin`` cells apart.  **Returns:** ``None`` if one does not fit, else
    ``(positions (c, 2) cells [u, v], turn (c,) int, size)``."""
    return _fill(masks, size, margin, order, _lowest)


def _lowest(turns, occb, size):
    """:func:`fill_square`'s placement: the lowest, then leftmost free position."""
    best = _inside(turns, occb, size, size)
    return best if best is not None else _lowest_free(turns, occb, size)


def _fill(masks, size: int, margin: int, order, place):
    """The placement loop of :func:`fill_square` and :func:`fill_contact`: masks in ``order``
    (default largest first), each where ``place(turns, occupied, size)`` puts it (``(key,
    turn, i, j, mask)`` or ``None``), then painted with its margin."""
    occb = np.zeros((size, size), bool)
    pos = np.zeros((len(masks), 2), np.int64)
    turn = np.zeros(len(masks), np.int64)
    if order is None:
        order = np.argsort([-m.sum() for m in masks], kind="stable")
    for c in order:
        if min(masks[c].shape) > size:
            return None
        best = place(_turns(masks[c]), occb, size)
        if best is None:
            return None
        _, t, i, j, M = best
        _paint(occb, M, i, j, margin)
        pos[c] = (i, j)
        turn[c] = t
    return pos, turn, size


def _most_contact(turns, occb, size, keep: int = 8):
    """The free position of the mask, over its turns, inside the ``size x size`` square whose
    ring (the cells next to the mask) meets the most occupied cells or the square's outside;
    ties go to the lowest, then leftmost position.  Occupancy and contact at every position
    come from FFT correlations (float32); the ``keep`` best of each turn are checked exactly
    against ``occb``, in order.  **Returns:** ``(key, turn, i, j, mask)`` or ``None``."""
    from scipy import fft, ndimage

    O = np.ones((size + 2, size + 2), np.float32)          # the outside counts as contact
    O[1:-1, 1:-1] = occb[:size, :size]
    shape = (fft.next_fast_len(size + 2, True),) * 2
    F_occ = fft.rfft2(O, shape)
    cands = []
    # at (j, i) in O: M at (j, i) in occb; the ring of a turn is the turned ring
    fits = [M.shape[0] <= size and M.shape[1] <= size and M.any() for M, _, _ in turns]
    pads = [np.pad(M, 1) if ok else None for (M, _, _), ok in zip(turns, fits)]
    ovs = _correlations(F_occ, pads, shape)
    rings = [None] * 4
    for t, ov in enumerate(ovs):
        if ov is None:
            continue
        M = turns[t][0]
        h, w = M.shape
        fj, fi = np.nonzero(ov[:size - h + 1, :size - w + 1] < 0.5)
        if fj.size == 0:
            continue
        rings[t] = (fj, fi, ndimage.binary_dilation(pads[t], np.ones((3, 3), bool)) & ~pads[t])
    cts = _correlations(F_occ, [r[2] if r is not None else None for r in rings], shape)
    for t, ct in enumerate(cts):
        if ct is None:
            continue
        fj, fi, _ = rings[t]
        M = turns[t][0]
        key = -np.rint(ct[fj, fi]).astype(np.int64) * (1 << 24) + (fj << 12) + fi
        for b in np.argsort(key, kind="stable")[:keep]:
            cands.append((int(key[b]), t, int(fi[b]), int(fj[b]), M))
    cands.sort(key=lambda c: c[0])
    for c in cands:
        _, _, i, j, M = c
        if not np.any(occb[j:j + M.shape[0], i:i + M.shape[1]] & M):
            return c
    return None


def fill_contact(masks, size: int, margin: int, order: np.ndarray | None = None,
                 lead: int | None = None):
    """Place masks (largest first) in a fixed ``size x size`` raster, each at the free
    position (over its four proper turns) where it touches the most placed masks' margins
    and the square's border (:func:`_most_contact`), at least ``margin`` cells apart;
    with ``lead``, only the first ``lead`` masks so, the rest as :func:`fill_square` places
    them (lowest, then leftmost).
    Tighter than :func:`fill_square` on some sets of ragged charts, looser on others
    (session 10, same charts, with both tried at each scale: bunny 66.0 -> 70.3 %,
    decimated-knight 70.3 -> 71.3 %, 3holes 69.5 -> 70.0 %).  **Returns:** ``None`` if one
    does not fit, else ``(positions (c, 2) cells [u, v], turn (c,) int, size)``."""
    if lead is None or lead >= len(masks):
        return _fill(masks, size, margin, order, _most_contact)
    placed = [0]

    def place(turns, occb, size):
        placed[0] += 1
        return (_most_contact if placed[0] <= lead else _lowest)(turns, occb, size)

    return _fill(masks, size, margin, order, place)


#: How many charts (the largest) :func:`pack_charts`'s most-contact fill places; the rest
#: go bottom-left.  Its FFT search costs about 15 ms a chart at 512 cells a side, at every
#: scale the bottom-left fill fails, and a noisy mesh's charts number in the thousands:
#: rocker-arm with Gaussian noise of 0.2 % of its diagonal has 1,537 charts, whose packing
#: took 148 s (63.2 % covered) with every chart placed by contact, 63 s (62.1 %) with 300,
#: 23 s (60.6 %) with none (session 18, issue 18).  The shared meshes have 11-160 charts.
CONTACT_CHARTS = 300
#: Above this many charts :func:`pack_charts` bisects the scale in :data:`MANY_CHARTS_STEPS`
#: steps instead of ``refine_steps``: each step packs every chart once or twice, and a noisy
#: cow (0.5 % noise, 852 charts of 6.5 faces each) spent 83 s in its 12 fills, 2.5-11 s each,
#: 237 s in all with its compaction (session 27's held-out sweep).
MANY_CHARTS = 300
#: The bisection steps above :data:`MANY_CHARTS` charts.
MANY_CHARTS_STEPS = 3


def pack_charts(uv, uv_faces, chart, uv_chart, area3d, *, texture_size: int = 1024,
                margin_texels: int = 2, fill: float = 0.72, max_attempts: int = 5,
                refine_steps: int = 6, refine_gain: float = 1.12,
                contact_charts: int = CONTACT_CHARTS) -> Packing:
    """Pack the charts' UVs (``uv (n_uv, 2)`` at 3D scale) into ``[0, 1]^2``.

    **Arguments:** ``uv_faces (m, 3)``, ``chart (m,)`` face charts, ``uv_chart (n_uv,)``,
    ``area3d`` (total UV area of the charts at their own scale); ``texture_size`` (texels a
    side), ``margin_texels`` (the least gap between two charts, and between a chart and the
    square's border); ``fill``: the share of the raster the first scale expects
    to cover; ``max_attempts``: packings tried at most; ``refine_steps``: bisection steps
    on the scale in the fixed square (:func:`fill_square`, else :func:`fill_contact` at each),
    between the growing-square packing's and ``refine_gain`` times its covered area (0: none;
    6 resolve the area to 0.2 %: against 4, session 10, same charts, 3holes 70.0 -> 70.4 %,
    camelhead 72.1 -> 72.4 %, cow 71.7 -> 71.9 %, rocker-arm 70.7 -> 71.0 %, none lower);
    ``contact_charts``: the most-contact fill places at most this many charts, the largest;
    the rest go bottom-left (:data:`CONTACT_CHARTS`).  Above :data:`MANY_CHARTS` charts the
    bisection takes at most :data:`MANY_CHARTS_STEPS` steps.
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
        R = min_area_rotation(uv[ids]) if k > 1 else min_square_rotation(uv[ids])
        Q = uv[ids] @ R.T
        rot[c], origin[c] = R, np.linalg.solve(R, Q.min(0))
        local[ids] = Q - Q.min(0)
    # a packing of side S <= size cells maps a cell onto texture_size / S >= f texels, so m
    # cells keep the margin
    f = texels_per_cell(texture_size)
    size, m = texture_size // f, int(np.ceil(margin_texels / f))
    # the charts go into the inner square: m cells of margin at each side of [0, 1]^2 too
    inner = size - 2 * m
    if inner < 1:
        raise SolverError(f"pack_charts: a margin of {margin_texels} texels leaves no room in a "
                          f"{texture_size}-texel texture; lower margin_texels or raise texture_size.",
                          stage="pack")
    cap = int(np.ceil(1.3 * inner))
    # cells per 3D unit: the share `fill` of the square by area, but never so large that the
    # longest chart (the longer side of its rectangle) would not fit in the square (needle
    # charts of a very anisotropic mesh: the area says nothing about their length)
    longest = float(local.max()) if local.size else 0.0
    s = inner * np.sqrt(fill / area3d)
    if longest > 0:
        s = min(s, 0.98 * inner / longest)
    # Wide margins: each chart takes about (w s + m)(h s + m) cells with its margin, so the
    # charts alone cannot have the share `fill` of the square (110 charts of cow with 64-texel
    # margins failed 19 packings, 10 s each, before one fit).  Where that bound is well below
    # the area's scale, start from it: area3d s^2 + m P s + k m^2 = fill inner^2, P the
    # charts' rectangles' half-perimeters (3D units).
    if k * (1 + m) ** 2 > inner * inner:
        raise SolverError(f"pack_charts: {k} charts, each at least one cell of {f} texel{'s' if f > 1 else ''} with a "
                          f"margin of {margin_texels} texels, need more than the {texture_size}-texel "
                          f"square holds; lower margin_texels or raise texture_size (to at least "
                          f"{int(np.ceil(np.sqrt(k) * (1 + m) * f + 2 * m * f))}).", stage="pack")
    if m > 0:
        ext = np.maximum.reduceat(local[order], bounds[:-1]) if local.size else np.zeros((k, 2))
        half_perimeter = float(ext.sum())
        c = k * m * m - fill * inner * inner
        if c >= 0:                       # the margins alone would fill that share: the square
            c = k * m * m - inner * inner
        b = m * half_perimeter
        s_margin = 2 * -c / (b + np.sqrt(b * b - 4 * area3d * c))         # the positive root
        if s_margin < 0.8 * s:
            s = s_margin
    best = None
    attempt = 0
    while attempt < max_attempts:
        attempt += 1
        masks = _chart_masks(local, seg, seg_of, s)
        placed = place_square(masks, cap, m)
        if placed is None:
            s *= 0.8
            continue
        side = placed[2]
        if side <= inner and (best is None or s / (side + 2 * m) > best[0]):
            best = (s / (side + 2 * m), s, masks, placed)
        if 0.97 * inner <= side <= inner:
            break
        s *= inner / side * (0.995 if side > inner else 1.0)
    if best is None:
        raise SolverError(f"pack_charts: the {k} charts did not fit into the unit square after "
                          f"{attempt} packings; lower margin_texels or raise texture_size.",
                          stage="pack")
    # bisection on the area covered, in the fixed square: lo fits (the packing above), hi may not;
    # a scale fits when the bottom-left fill or else the (slower) most-contact fill places all
    lo, hi = best[0] * size, best[0] * size * np.sqrt(refine_gain)       # cells per 3D unit
    steps = int(refine_steps) if k <= MANY_CHARTS else min(int(refine_steps), MANY_CHARTS_STEPS)
    for _ in range(steps):
        s = 0.5 * (lo + hi)
        masks = _chart_masks(local, seg, seg_of, s)
        placed = fill_square(masks, inner, m)
        attempt += 1
        if placed is None and int(contact_charts) > 0:      # (lead 0 is the same bottom-left fill)
            placed = fill_contact(masks, inner, m, lead=int(contact_charts))
            attempt += 1
        if placed is None:
            hi = s
        else:
            lo = s
            best = (s / size, s, masks, placed)
    scale, _, masks, (pos, turn, side) = best
    offset = np.zeros((k, 2))
    for c in range(k):
        _, Rt, tr = _turns(masks[c])[turn[c]]
        rot[c] = Rt @ rot[c]
        offset[c] = (pos[c] + m + np.asarray(tr, float)) / (side + 2 * m)
    return Packing(rot, origin, offset, float(scale), texture_size, margin_texels, attempt)
