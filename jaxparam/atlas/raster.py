"""The packing raster: charts as conservative cell masks, their four proper turns, and
where a mask fits among the cells already taken (the primitives of
:mod:`~jaxparam.atlas.pack` and :mod:`~jaxparam.atlas.fill`).

Masks are ``(rows, cols)`` bool arrays indexed ``[j (v), i (u)]`` in cells; an occupancy is
the same over the whole square, holding every placed chart grown by the margin.
"""
from __future__ import annotations

import numpy as np

__all__ = ["rasterize", "proper_turns", "correlations", "lowest_inside", "grown", "paint"]


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



#: The four proper turns of a mask: (mask of M, linear part, translation in mask (h, w)).
def proper_turns(M):
    h, w = M.shape
    return ((M, np.eye(2), (0.0, 0.0)),
            (np.rot90(M, -1), np.array([[0.0, -1.0], [1.0, 0.0]]), (h, 0.0)),     # (h - v, u)
            (M[::-1, ::-1], -np.eye(2), (w, h)),                                 # (w - u, h - v)
            (np.rot90(M, 1), np.array([[0.0, 1.0], [-1.0, 0.0]]), (0.0, w)))     # (v, w - u)



def correlations(F_occ, masks, shape):
    """``corr[t][j, i] = sum_{y, x} occ[j + y, i + x] masks[t][y, x]`` for the four turns'
    masks (``None`` to skip one), from the occupancy's spectrum ``F_occ`` (an ``rfft2`` at
    ``shape``).  Turns 2 and 3 are turns 0 and 1 rotated by 180 degrees (:func:`proper_turns`), so
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



def lowest_inside(turns, occb, W, H, samples: int = 24, chunk: int = 512, chunks: int = 8):
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



def paint(occb, M, i, j, margin):
    """Mark the mask ``M`` placed at cell ``(i, j)``, grown by ``margin`` cells, in ``occb``;
    **returns** the rows and columns touched, ``(js, je, is_, ie)``."""
    cap_r, cap_c = occb.shape
    D = grown(M, margin)
    j0, i0 = j - margin, i - margin
    js, is_ = max(j0, 0), max(i0, 0)
    je, ie = min(j0 + D.shape[0], cap_r), min(i0 + D.shape[1], cap_c)
    occb[js:je, is_:ie] |= D[js - j0:je - j0, is_ - i0:ie - i0]
    return js, je, is_, ie
