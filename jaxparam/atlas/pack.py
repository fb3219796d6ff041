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
whole mask (:func:`lowest_inside`); when none is free there, all positions are tested at once by
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
from .fill import fill_contact, fill_square, jittered_orders
from .raster import correlations, grown, lowest_inside, paint, proper_turns, rasterize

__all__ = ["Packing", "texels_per_cell", "MANY_CHARTS", "MANY_CHARTS_STEPS", "jittered_orders", "min_area_rotation",
           "min_square_rotation", "rasterize", "pack_charts",
           "place_square", "fill_square", "fill_contact", "grown", "reorder", "ORDER_GAIN", "ORDER_STEPS", "layout_charts",
           "FINAL_ORDERS", "ORDER_CHARTS"]


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
    for t, ov in enumerate(correlations(F_occ, masks, shape)):
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
        turns = proper_turns(masks[c])
        best = lowest_inside(turns, occb, W, H)
        if best is None:
            best = _anywhere(turns, occ, W, H, cap, margin)
        if best is None:
            return None
        _, t, i, j, M = best
        h, w = M.shape
        # the occupancy keeps the mask grown by `margin` cells on each side
        js, je, is_, ie = paint(occb, M, i, j, margin)
        occ[js:je, is_:ie] = occb[js:je, is_:ie]
        W, H = max(W, i + w), max(H, j + h)
        pos[c] = (i, j)
        turn[c] = t
    return pos, turn, max(W, H, 1)


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


def _frames(uv, uv_faces, chart, uv_chart):
    """Each chart turned to its minimal-area rectangle (the smallest square for a lone chart)
    and moved to the origin: ``(rot (k, 2, 2), origin (k, 2), local (n_uv, 2), seg, seg_of)``,
    ``seg`` the charts' boundary segments and ``seg_of[c]`` chart ``c``'s among them."""
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
    return rot, origin, local, seg, seg_of


def _packing(rot, origin, masks, placed, scale, m, texture_size, margin_texels, attempts) -> Packing:
    """The :class:`Packing` of charts turned by ``rot`` whose ``masks`` were ``placed``
    (``(pos, turn, side)``, in cells) with ``m`` cells of margin at the square's border."""
    pos, turn, side = placed
    rot = rot.copy()
    offset = np.zeros((len(masks), 2))
    for c in range(len(masks)):
        _, Rt, tr = proper_turns(masks[c])[turn[c]]
        rot[c] = Rt @ rot[c]
        offset[c] = (pos[c] + m + np.asarray(tr, float)) / (side + 2 * m)
    return Packing(rot, origin, offset, float(scale), texture_size, margin_texels, attempts)


def _cells(texture_size: int, margin_texels: int):
    """``(size, m, inner)``: the raster's cells a side, the margin in cells, and the side of
    the square inside the border's margin."""
    f = texels_per_cell(texture_size)
    size, m = texture_size // f, int(np.ceil(margin_texels / f))
    return size, m, size - 2 * m


#: :func:`reorder`'s reach above the packing it starts from (covered area) and its steps.
ORDER_GAIN = 1.04
ORDER_STEPS = 5


def reorder(uv, uv_faces, chart, uv_chart, packing: Packing, orders: int) -> Packing:
    """:func:`pack_charts`'s ``packing`` of these charts, or one at a larger scale that places
    them in another order: a bisection on the scale between the packing's and
    :data:`ORDER_GAIN` times its covered area (:data:`ORDER_STEPS` steps), each scale tried
    with the bottom-left fill in ``orders`` orders near largest first
    (:func:`~jaxparam.atlas.fill.jittered_orders`).  Where largest first leaves a gap that
    no later chart fits, another order often does not (session 36: halftunnel 68.3 -> 70.5 %
    covered).  It never covers less than ``packing``.  Arguments as :func:`pack_charts`'s."""
    rot, origin, local, seg, seg_of = _frames(uv, uv_faces, chart, uv_chart)
    size, m, inner = _cells(packing.texture_size, packing.margin_texels)
    lo, hi = packing.scale * size, packing.scale * size * np.sqrt(ORDER_GAIN)
    best, attempts = None, packing.attempts
    for _ in range(ORDER_STEPS):
        s = 0.5 * (lo + hi)
        masks = _chart_masks(local, seg, seg_of, s)
        placed = None
        for order in jittered_orders(masks, orders):
            placed = fill_square(masks, inner, m, order)
            attempts += 1
            if placed is not None:
                break
        if placed is None:
            hi = s
        else:
            lo, best = s, (masks, placed)
    if best is None:
        return packing
    return _packing(rot, origin, best[0], best[1], lo / size, m, packing.texture_size,
                    packing.margin_texels, attempts)


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
    rot, origin, local, seg, seg_of = _frames(uv, uv_faces, chart, uv_chart)
    # a packing of side S <= size cells maps a cell onto texture_size / S >= f texels, so m
    # cells keep the margin
    f = texels_per_cell(texture_size)
    # the charts go into the inner square: m cells of margin at each side of [0, 1]^2 too
    size, m, inner = _cells(texture_size, margin_texels)
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
        order = np.argsort(uv_chart, kind="stable")
        bounds = np.searchsorted(uv_chart[order], np.arange(k + 1))
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
    scale, _, masks, placed = best
    return _packing(rot, origin, masks, placed, scale, m, texture_size, margin_texels, attempt)


#: The atlas's last packing of at most :data:`ORDER_CHARTS` charts is tried again at larger
#: scales in this many orders of placement near largest first (:func:`reorder`); the charts
#: are chosen on packings without them.  Each order is a fill of every chart, so
#: the many charts of a noisy or refined mesh would take tens of seconds.
FINAL_ORDERS = 4
ORDER_CHARTS = 200


def layout_charts(chart, corner_uv, F, n, texture_size, margin_texels, refine_steps: int = 6,
                  reordered=None):
    """The atlas of flattened charts (``chart (m,)``, ``corner_uv (m, 3, 2)`` at 3D scale, of
    the faces ``F (m, 3)`` of ``n`` vertices): one UV vertex per (chart, vertex), the charts
    packed (``refine_steps``: the bisection steps of :func:`pack_charts`; ``reordered``:
    instead, a packing of these charts that :func:`reorder` improves in
    :data:`FINAL_ORDERS` orders).  **Returns:** ``(uv_faces, vertex, uv_chart, chart_uv,
    packing, uv, coverage)``."""
    key = np.repeat(chart, 3) * np.int64(n) + F.reshape(-1)
    uniq, first, inv = np.unique(key, return_index=True, return_inverse=True)
    uv_faces = inv.reshape(-1, 3).astype(np.int64)
    vertex = uniq % n
    uv_chart = uniq // n
    chart_uv = corner_uv.reshape(-1, 2)[first]
    T = chart_uv[uv_faces]
    e1, e2 = T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]
    a_uv = 0.5 * float(np.sum(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]))
    if reordered is not None:
        packing = reorder(chart_uv, uv_faces, chart, uv_chart, reordered, FINAL_ORDERS)
    else:
        packing = pack_charts(chart_uv, uv_faces, chart, uv_chart, a_uv, texture_size=texture_size,
                              margin_texels=margin_texels, refine_steps=refine_steps)
    uv = np.clip(packing.apply(chart_uv, uv_chart), 0.0, 1.0)    # rounding at the borders
    return uv_faces, vertex, uv_chart, chart_uv, packing, uv, a_uv * packing.scale ** 2
