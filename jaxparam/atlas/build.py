""":func:`atlas`: charts, one batched flattening, splits of failing charts, packing."""
from __future__ import annotations

import time

import jax
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .. import energies as en_mod
from .. import host, metrics
from ..disk import unstitched
from ..errors import MeshError, SolverError, TopologyError
from ..io import as_mesh
from ..mesh import TriMesh
from ..triangles import doubled_areas
from ..clock import StageClock
from ..progress import StageBar
from . import charts as ch
from . import compact as cp
from . import flatten as fl
from . import lscm
from . import merge as mg
from . import notches
from .pack import ORDER_CHARTS, layout_charts, min_area_rotation, texels_per_cell
from .result import Atlas, atlas_stats

__all__ = ["atlas"]


def _flatten_subset(V, F, chart, faces_idx, en, start, weights, solver, max_iters, prev=None):
    """Flatten the charts of the faces ``faces_idx``: per-corner UVs ``(k, 3, 2)`` and the
    per-chart quality (indexed by the subset's chart order).  ``prev``: ``(corner_uv (m, 3,
    2), chart (m,))`` of the round before; the large pieces of its charts start from its map
    (:func:`~jaxparam.atlas.flatten.warm_charts`), as a problem of their own: they take a few
    Newton steps where the new pieces take their usual course, and one problem takes as many
    steps as its slowest chart."""
    labels, sub_chart = np.unique(chart[faces_idx], return_inverse=True)
    warm = np.zeros(labels.size, bool)
    if prev is not None:
        warm = fl.warm_charts(sub_chart, prev[0][faces_idx], prev[1][faces_idx], np.bincount(prev[1]))
    cuv, q = np.zeros((faces_idx.size, 3, 2)), {}
    for group in (warm, ~warm):
        if not group.any():
            continue
        on = group[sub_chart]
        cm = fl.chart_mesh(V, F[faces_idx[on]], np.unique(sub_chart[on], return_inverse=True)[1])
        uv0 = (lscm.conformal_start(cm, weights=weights) if start == "conformal"
               else fl.convex_start(cm, weights=weights))
        cold = None
        if group is warm:
            uv0, cold = fl.uv_of_corners(cm, prev[0][faces_idx[on]]), uv0
        uv, _ = fl.minimize_charts(cm, en, uv0, solver=solver, max_iters=max_iters, cold=cold)
        cuv[on] = uv[cm.mesh.faces]
        for key, value in fl.chart_quality(cm, uv).items():
            q.setdefault(key, np.zeros(labels.size, value.dtype))[group] = value
    return cuv, labels, q


#: A chart whose map crosses its own boundary gives the faces at the crossing edges' ends, and
#: their neighbours, a chart of their own when they are at most this share of it (else it is
#: halved, :func:`~jaxparam.atlas.charts.split_chart`, as for a fold or a stretched triangle).
PEEL_SHARE = 0.4
#: ... and when it has at least this many faces.
PEEL_MIN_FACES = 8
#: Rounds after ``max_splits`` in which :func:`atlas` halves the charts that still fold (no
#: peeling, ``max_aspect`` no longer counts): halving reaches single triangles, which never fold.
FINAL_HALVINGS = 24


def _peeled_or_halved(V, F, faces_of, corner_uv, adj_csr, peel: bool = True) -> list:
    """The pieces of a failing chart (``faces_of``, its faces; ``corner_uv (m, 3, 2)`` its
    map): where the map's boundary crosses itself, the faces at the crossing edges' ends grown
    by one ring (session 32: a crossing is a local fold of the outline, and halving the chart
    left two halves that often crossed again; camelhead 76 -> 132 charts, 73.1 -> 77.6 %
    covered, camel_b 73.7 -> 74.6 %, cow 147 -> 135 charts, a noisy cow 254 -> 218 charts);
    else, or when those faces are more than :data:`PEEL_SHARE` of the chart, or with ``peel``
    false, its two halves."""
    if peel and faces_of.size >= PEEL_MIN_FACES:
        ids, inv = np.unique(F[faces_of], return_inverse=True)
        local = inv.reshape(-1, 3)
        uv = np.zeros((ids.size, 2))
        uv[local.reshape(-1)] = corner_uv[faces_of].reshape(-1, 2)
        seg, pairs = metrics.boundary_crossings(TriMesh(V[ids], local, validate=False), uv)
        if pairs.size:
            ends = np.zeros(ids.size, bool)
            ends[seg[pairs.reshape(-1)].reshape(-1)] = True
            peel = ends[local].any(1)
            peel |= adj_csr[faces_of][:, faces_of] @ peel.astype(np.int8) > 0
            if peel.sum() <= PEEL_SHARE * faces_of.size:
                return [faces_of[~peel], faces_of[peel]]
    return ch.split_chart(faces_of, adj_csr, merge_small=True)


def _compact(V, F, chart, corner_uv, adj_csr, en, solver, max_iters, *, max_new, accept):
    """Cut charts into more convex pieces (:func:`~jaxparam.atlas.compact.plan_splits`) and
    minimize every piece again from its parent's map (:func:`_pieces_minimized`).
    **Returns:** ``(chart, corner_uv, new charts)``."""
    new, parent = cp.plan_splits(corner_uv, F, chart, adj_csr, max_new=max_new, accept=accept)
    return _pieces_minimized(V, F, chart, corner_uv, new, parent, en, solver, max_iters)


#: :func:`_long_charts_cut` tries long charts cut into pieces no longer than each of these
#: shares of the side of the square the atlas fills at 75 % (``plan_strips``' ``share``) and
#: keeps the layout that covers most.  Held out (session 33; charts, covered, before -> after):
#: a flat 4 x 1 strip 1 -> 2, 32 -> 98.6 % at 1.0 (4 charts at 0.5); a torus of tube radius
#: 0.06 7 -> 19, 22.7 -> 63.4 % at 0.5 (12, 61.1 % at 1.0); a 1 : 0.25 : 0.06 ellipsoid 6 ->
#: 9, 41.5 -> 74.9 % at 1.0; a capsule 8 x 0.3 (34,560 faces) 3 -> 13, 19.3 -> 77.0 % at 0.5.
STRIP_SHARES = (1.0, 0.5)
#: How far the pieces may raise the atlas's largest ``s1/s2`` (a factor): a piece's free
#: boundary may stretch its worst triangle a little (a thin torus's strip 1.074 -> 1.075
#: undid its parent's cuts at a factor of 1).
STRIP_ASPECT_SLACK = 1.05


def _long_charts_cut(V, F, chart, corner_uv, adj_csr, en, solver, max_iters, layout, laid):
    """Long charts cut across their length (:func:`~jaxparam.atlas.compact.plan_strips`, at
    each of :data:`STRIP_SHARES`, the straight ones alone and then with the curved ones: one
    plan for all charts, so a curved chart whose cut packs worse would spoil a straight one's
    gain), the pieces minimized again from their parent's map;
    **returns** ``(chart, corner_uv, laid)``: the layout that covers most, the given one
    unless a cut packs tighter (``layout(chart, corner_uv)`` packs)."""
    best = (chart, corner_uv, laid)
    ceiling = STRIP_ASPECT_SLACK * _largest_aspect(V, F, corner_uv)
    tried = []
    for curved, share in [(c, s) for c in (False, True) for s in STRIP_SHARES]:
        new, parent = cp.plan_strips(corner_uv, F, chart, adj_csr, share=share, curved=curved)
        if any(np.array_equal(new, t) for t in tried):
            continue
        tried.append(new)
        cut, cuv, made = _pieces_minimized(V, F, chart, corner_uv, new, parent, en, solver,
                                           max_iters, ceiling=ceiling)
        if not made:
            continue
        try:
            laid2 = layout(cut, cuv)
        except SolverError:                   # the pieces do not fit at full size
            continue
        if laid2[-1] > best[2][-1]:
            best = (cut, cuv, laid2)
    return best


def _largest_aspect(V, F, corner_uv) -> float:
    """The atlas's largest ``s1/s2`` over its faces (``corner_uv (m, 3, 2)``)."""
    corners = np.arange(3 * F.shape[0]).reshape(-1, 3)
    q = host.face_quantities(V[F].reshape(-1, 3), corners, corner_uv.reshape(-1, 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(np.max(np.abs(q["s1"]) / np.abs(q["s2"])))


def _pieces_minimized(V, F, chart, corner_uv, new, parent, en, solver, max_iters, *,
                      ceiling: float = 0.0):
    """The cut charts' pieces (``new (m,)`` labels, ``parent`` each label's chart before the
    cuts) minimized again from their parent's map, in one problem.  A piece whose map then
    flips, crosses itself, raises the energy, or raises the largest ``s1/s2`` above both the
    parent's and ``ceiling`` keeps its start, the parent's map on it (until session 36 the
    parent's cuts were undone: a 20x stretched camelhead's longest chart stayed whole, and
    the atlas covered 18 %).
    **Returns:** ``(chart, corner_uv, new charts)``."""
    k0 = int(chart.max()) + 1
    if parent.size == k0:
        return chart, corner_uv, 0
    todo = np.flatnonzero(np.isin(chart, parent[k0:]))
    labels, sub = np.unique(new[todo], return_inverse=True)
    cm = fl.chart_mesh(V, F[todo], sub)
    uv0 = fl.uv_of_corners(cm, corner_uv[todo])
    q0 = fl.chart_quality(cm, uv0)
    uv, _ = fl.minimize_charts(cm, en, uv0, solver=solver, max_iters=max_iters)
    q = fl.chart_quality(cm, uv)
    fam = parent[labels]                                   # each piece's parent label
    worst = np.zeros(k0)
    np.maximum.at(worst, fam, q0["max_aspect"])
    worst = np.maximum(worst, float(ceiling))
    bad = ((q["flips"] > 0) | (q["overlaps"] > 0) | (q["max_aspect"] > worst[fam] * (1 + 1e-9))
           | (q["sym_dirichlet"] > q0["sym_dirichlet"] * (1 + 1e-12)))
    # such a piece keeps its start, the parent's map on it: one-to-one, as the parent's is
    back = np.unique(cm.mesh.faces[bad[sub]])
    uv[back] = uv0[back]
    chart = chart.copy()
    corner_uv = corner_uv.copy()
    chart[todo] = new[todo]
    corner_uv[todo] = uv[cm.mesh.faces]
    made = int(np.unique(chart).size) - k0
    return ch.relabel(chart), corner_uv, made


#: An atlas of at most ``PACKING_CUT_CHARTS`` charts covering under ``PACKING_CUT_BELOW`` of
#: the square also tries its widest chart (the largest minimal-area rectangle, the one that
#: bounds the packing's scale) cut in two by a straight line
#: (:func:`~jaxparam.atlas.compact.straight_cuts`): the ``PACKING_CUT_TRIED`` cuts into two
#: disks whose pieces' rectangles fill a square best are packed with the other charts at
#: ``PACKING_CUT_TEXELS`` texels a side (``PACKING_CUT_STEPS`` bisection steps), the best is
#: minimized again and kept when it packs tighter.  A lone chart's outline cannot fill a
#: square (snail's, convex to 1.3 %, filled 62.6 %; xatlas makes two charts of it), nor can
#: a wide arc among a few (session 31).  Up to 16 charts since session 32 (bumpy: 16 charts,
#: 64.3 -> 18 charts, 70.5 %, 3.6 -> 10.8 s; halftunnel 15, 66.9 % -> 16, 68.2 %; the other
#: shared meshes have more charts or cover more), with 3 bisection steps for the candidates
#: instead of 6 (bumpy 14.4 -> 10.8 s for the same atlas; halftunnel 69.2 -> 68.2 %).
PACKING_CUT_BELOW = 0.75
PACKING_CUT_CHARTS = 16
#: ... counting the charts that hold at least this share of the UV area: a noisy snail's
#: three large charts came with 14 of a few faces each (splits of crumpled triangles), and
#: its arc-shaped chart, uncut, left 43.6 % covered.
PACKING_CUT_SHARE = 0.01
PACKING_CUT_TEXELS = 128
PACKING_CUT_TRIED = 24
PACKING_CUT_ROUNDS = 2
PACKING_CUT_STEPS = 3


def _large_charts(chart, corner_uv) -> int:
    """How many charts hold at least :data:`PACKING_CUT_SHARE` of the UV area."""
    area = np.bincount(chart, weights=np.abs(doubled_areas(corner_uv)))
    return int(np.sum(area >= PACKING_CUT_SHARE * area.sum()))


def _two_rectangles_fill(corner_uv, sides) -> np.ndarray:
    """``(c,)``: for each cut ``sides (c, f)``, the share of the smallest square holding its
    two pieces' bounding rectangles (the least-area of 16 directions, 11.25 degrees apart;
    side by side or one above the other, each turned or not) that the pieces' UV area fills."""
    th = np.arange(16) * np.pi / 16
    D = np.stack([np.cos(th), np.sin(th)])                             # (2, 16)
    proj = corner_uv @ D                                               # (f, 3, 16)
    hi, lo = proj.max(1), proj.min(1)                                  # (f, 16)
    fa = 0.5 * np.abs(doubled_areas(corner_uv))
    out = np.zeros(len(sides))
    for i, side in enumerate(sides):
        dims = []
        for piece in (side, ~side):
            ext = hi[piece].max(0) - lo[piece].min(0)                  # (16,) widths
            other = np.roll(ext, -8)                                   # the perpendicular's
            j = int(np.argmin(ext * other))
            dims.append((ext[j], other[j]))
        (w1, h1), (w2, h2) = dims
        side_len = min(min(max(a + c, max(b, d)), max(max(a, c), b + d))
                       for a, b in ((w1, h1), (h1, w1)) for c, d in ((w2, h2), (h2, w2)))
        out[i] = fa.sum() / max(side_len * side_len, 1e-300)
    return out


def _widest_cut(V, F, chart, corner_uv, adj_csr, en, solver, max_iters):
    """The atlas's widest chart cut in two (:data:`PACKING_CUT_BELOW`): ``(chart,
    corner_uv)``, or ``None`` when no cut is a pair of disks or the pieces' maps fail."""
    k, n = int(chart.max()) + 1, int(F.max()) + 1
    rect = []
    for c in range(k):
        P = corner_uv[chart == c].reshape(-1, 2)
        rect.append(float(np.prod(np.ptp(P @ min_area_rotation(P).T, axis=0))))
    fk = np.flatnonzero(chart == int(np.argmax(rect)))
    sub = adj_csr[fk][:, fk]
    sides = cp.straight_cuts(corner_uv[fk])
    best, packed = None, 0
    # the first few cuts into two disks, by how well their pieces' bounding rectangles fill
    # a square, go to a packing with the other charts
    for i in np.argsort(-_two_rectangles_fill(corner_uv[fk], sides), kind="stable"):
        if packed == PACKING_CUT_TRIED:
            break
        if not cp.two_disks(sides[i], F[fk], sub):
            continue
        packed += 1
        new = chart.copy()
        new[fk[sides[i]]] = k
        try:
            score = layout_charts(new, corner_uv, F, n, PACKING_CUT_TEXELS, 1, PACKING_CUT_STEPS)[-1]
        except SolverError:
            continue
        if best is None or score > best[0]:
            best = (score, new)
    if best is None:
        return None
    parent = np.r_[np.arange(k), chart[fk[0]]]
    # a piece's free boundary may stretch a triangle a little more than its parent did, as
    # long as the atlas's largest s1/s2 stays (a noisy snail's arc 1.370 -> 1.371 among 3.38)
    cut, cuv, made = _pieces_minimized(V, F, chart, corner_uv, best[1], parent, en, solver, max_iters,
                                       ceiling=_largest_aspect(V, F, corner_uv))
    return (cut, cuv) if made else None


def _notches_filled(V, F, nbr, chart, corner_uv, en, solver, max_iters, max_aspect):
    """Ears moved into their neighbours' notches (:func:`~jaxparam.atlas.notches.fill_notches`),
    then every chart a move changed minimized again from there, in one problem, so that each
    chart stays its own free-boundary optimum (what :func:`~jaxparam.atlas.atlas_uv`
    re-solves).  The charts joined by moves go back as they were, moves and maps, wherever
    one of them then flips, crosses itself or passes ``max_aspect``.
    **Returns:** ``(chart, corner_uv)``, labels ``0..c-1``."""
    new, cuv, moved = notches.fill_notches(V, F, nbr, chart, corner_uv, max_aspect=max_aspect)
    if not moved:
        return chart, corner_uv
    changed = np.flatnonzero(new != chart)
    k = int(chart.max()) + 1
    # charts joined by a move (donor and receiver) stand or fall together
    link = sp.coo_matrix((np.ones(changed.size), (chart[changed], new[changed])), shape=(k, k))
    group = connected_components(link, directed=False)[1]
    touched = np.unique(np.r_[chart[changed], new[changed]])
    todo = np.flatnonzero(np.isin(new, touched))
    labels, sub = np.unique(new[todo], return_inverse=True)
    cm = fl.chart_mesh(V, F[todo], sub)
    uv0 = fl.uv_of_corners(cm, cuv[todo])
    uv, _ = fl.minimize_charts(cm, en, uv0, solver=solver, max_iters=max_iters)
    q = fl.chart_quality(cm, uv)
    bad = labels[(q["flips"] > 0) | (q["overlaps"] > 0) | (q["max_aspect"] > max_aspect)]
    keep = ~np.isin(group[new[todo]], group[bad])
    out_chart, out_uv = chart.copy(), corner_uv.copy()
    back = np.isin(group[chart], group[bad])        # faces of the charts that go back
    out_chart[~back] = new[~back]
    out_uv[todo[keep]] = uv[cm.mesh.faces[keep]]
    return ch.relabel(out_chart), out_uv


#: Up to this many charts, the charts are packed with and without the ears moved into the
#: neighbours' notches, and the layout that covers more is kept: a few large pieces pack by
#: luck, and the moves cost halftunnel coverage (session 26: 66.8 -> 63.1 %; kept now: 66.9 %
#: for 2.2 s more).  At 64, 3holes and bunny (39 and 37 charts) packed a second time for the
#: same coverage (+4-5 s), bumpy (16) too (+1 s).
NOTCH_CHOICE_CHARTS = 20


#: Ears move into their neighbours' notches only while a face covers at least this many cells
#: of the packing raster (at 75 % of it, on average): a finer face's ear bends the outline by
#: less than a cell.  On cow refined 1-to-16 and 1-to-64 (88k, 353k faces: 2.2 and 0.56 cells
#: a face) the atlas covered 76.08 % with or without the moves, and at 1-to-256 (1.41M faces)
#: re-minimizing the charts the moves touched took 668 of 1,153 s (session 34, issue 18).
NOTCH_MIN_CELLS = 4.0


def _ears_show(n_faces: int, texture_size: int) -> bool:
    """Whether a face is large enough on the packing raster for :func:`_notches_filled`
    (:data:`NOTCH_MIN_CELLS`)."""
    side = texture_size // texels_per_cell(texture_size)
    return 0.75 * side * side >= NOTCH_MIN_CELLS * n_faces


#: The most charts :func:`atlas` compacts.  Above, the many small charts of a noisy mesh
#: gain nothing from the cuts, whose second packing is as long as the first: noisy
#: rocker-arm (1,537 charts) 62.06 -> 62.2 % covered for 109 s, noisy camelhead (1,775) no
#: gain for 112 s; at 618 charts (noisy camel_b refined once) 68.2 -> 71.8 % for 15 s, at
#: 268 (noisy cow) 69.6 -> 74.0 % (session 18, issue 18).
COMPACT_CHARTS = 1000
#: Nor when its charts hold fewer faces than this on average: a noisy cow (0.5 % noise, 852
#: charts of 6.5 faces) spent 132 s compacting for the same coverage (session 27); the
#: compactions that paid had 20-23 faces a chart (noisy cow at 268 charts, noisy camel_b
#: refined once at 618).
COMPACT_MIN_FACES = 12


def atlas(mesh: TriMesh, *, energy="symmetric_dirichlet", texture_size: int = 1024,
          margin_texels: int = 2, cone: float = 88.0, max_aspect: float = 3.5,
          start: str = "conformal", weights: str = "shape_preserving", solver="newton",
          max_iters: int = 200,
          max_splits: int = 16, merge_cone: float | None = None,
          small_merge_cone: float | None = None, post_merge_budget: float = 0.0,
          post_merge_cone: float = 100.0, post_merge_share: float = 0.05,
          compact: float = 0.5, compact_accept: float = 0.9, normals: str = "auto",
          verbose: bool | None = None) -> Atlas:
    """A UV atlas of any manifold mesh: closed or open, any genus, several components.

    **Arguments:**

    - ``mesh``: a :class:`~jaxparam.TriMesh` (or a ``trimesh.Trimesh``, or a ``(V, F)`` pair)
      with concrete vertices.
    - ``energy``: the distortion each chart's map minimizes (a name or ``jp.energy(f)``).
    - ``texture_size``: texels a side of the texture the atlas is packed for;
      ``margin_texels``: the least gap between two charts, and between a chart and the
      border of ``[0, 1]^2``, in texels (for bilinear filtering and mip-maps).
    - ``cone``: the largest angle (degrees) between a face normal and its chart's mean
      normal while charts grow; ``merge_cone``: the same while charts merge (default
      ``cone``); ``small_merge_cone``: a second merge in which only charts under 1 % of
      the area merge into a neighbour, within this wider cone (``None``: none).
    - ``normals``: the face normals the cones test: ``"raw"`` (each face's own),
      ``"smoothed"`` (averaged with the neighbours', :func:`~jaxparam.atlas.charts.smoothed_normals`,
      for a noisy mesh, whose tilted triangles would each start a chart) or ``"auto"`` (the
      default: smoothed where the mesh is noisy, :func:`~jaxparam.atlas.charts.segment`;
      every clean mesh of ``../shared/data`` keeps its own normals).
    - ``max_aspect``: a chart whose map has a triangle with ``s1/s2`` above this, or whose
      boundary crosses itself, is split in two and flattened again (at most ``max_splits``
      rounds; camel_b needs 10; then up to :data:`FINAL_HALVINGS` rounds halve the charts
      that still fold or cross themselves, whatever their ``s1/s2``).  The default 3.5 splits only where the cone's charts
      stretch some triangles (decimated-knight: 72 charts, max ``s1/s2`` 3.37, E_sd 2.038,
      where 8.0 gave 60, 4.92 and 2.064; the other meshes of ``../shared/data`` stay
      under 2.4).
    - ``post_merge_budget``: after flattening, neighbouring charts (the smaller under
      ``post_merge_share`` of the area, the union within ``post_merge_cone`` degrees) are
      merged and flattened again, and a union is kept when its map is flip-free, does not
      cross itself, stays within ``max_aspect``, and the atlas's area-weighted symmetric
      Dirichlet (isometry 2) rises by at most ``post_merge_budget`` times its excess over 2
      in all (:mod:`~jaxparam.atlas.merge`; 0, the default: no merging).  At 0.04
      (session 8, load 16-18): 3holes 34 -> 29 charts (xatlas 29), E_sd 2.0035 (2.0035);
      rocker-arm 57 -> 39 (43), 2.0027 (2.0065); cow 110 -> 73 (107), 2.0060 (2.0401);
      decimated-knight 72 -> 46 (75), 2.0394 (2.0417); max ``s1/s2`` unchanged; but
      coverage falls 2.7-3.7 points (cow 64.1 %, xatlas 64.3 %) and rocker-arm's merge
      rounds took 473 s, so it is not the default yet.
    - ``compact``: after flattening, charts whose UV outline is far from convex are cut by
      straight lines into pieces whose convex hulls hold at most ``compact_accept`` of the
      chart's hull area, the largest gain first, at most ``compact`` times the number of
      charts new ones (:mod:`~jaxparam.atlas.compact`); each piece is minimized again from
      its parent's map (its energy can only fall), and the cuts are kept when the pieces
      pack tighter than the whole charts (0: no cuts).  At 0.5 (session 9, margin kept at
      the border too): camel_b 80 -> 113 charts, 63.2 -> 72.0 % covered; camelhead 67 ->
      88, 61.6 -> 72.1 %; cow 110 -> 146 (xatlas 107), 67.6 -> 71.7 %; E_sd and max
      ``s1/s2`` never higher; the atlas takes 1.1-3x the time.  Not above
      :data:`COMPACT_CHARTS` charts, nor under :data:`COMPACT_MIN_FACES` faces a chart (a
      noisy mesh's), where the cuts gain nothing.  An atlas of at most
      :data:`PACKING_CUT_CHARTS` charts of :data:`PACKING_CUT_SHARE` of the UV area or more
      (and any number of smaller ones), covering under :data:`PACKING_CUT_BELOW` of the
      square, then tries its widest chart cut in two by a straight line, the cut ranked by a
      packing, and keeps it when the charts pack tighter (snail: one chart 62.6 -> two 75.2 %
      covered, as xatlas makes two; a flat 4 x 1 strip 32 -> 99 %).  Before that, charts
      longer than the square's side (or half of it) and twice as long as wide are cut
      across their length into equal pieces, kept when they pack tighter
      (:data:`STRIP_SHARES`: a thin torus 22.7 -> 63.4 %, a capsule 19.3 -> 77.0 %).
    - ``start``: each chart's start, ``"conformal"`` (the default: its least-squares
      conformal map, :mod:`~jaxparam.atlas.lscm`, or its convex-combination map where that
      inverts a triangle) or ``"convex"`` (the convex-combination map, boundary on a
      circle).  Both are flip-free.  The conformal start is far closer to the optimum
      (cow refined once: energy 4.03 against 319, 10 Newton steps against 19); at 1.41M
      faces the atlas took 310 s against 390 s, with 238 charts against 296.
    - ``weights``, ``solver``, ``max_iters``: the convex-combination start's weights and
      the minimization's solver and iteration cap.
    - ``verbose``: a progress bar over the stages (charts, flatten and its split rounds,
      merge, pack, compact, orders); ``None``: as ``jp.config.progress`` says (it shows for runs
      longer than a second).

    **Returns:** an :class:`~jaxparam.atlas.Atlas` (``uv (n_uv, 2)``, ``uv_faces (m, 3)``,
    ``chart (m,)``, ``seams``, ``stats``).  The mesh's vertices are never duplicated or
    reordered: seams live in ``uv_faces`` only.

    Each chart is a topological disk, mapped by a conformal (or convex-combination) start and a flip-free,
    free-boundary minimization (all charts in one problem), then turned by a proper
    rotation (never mirrored) and packed into ``[0, 1]^2``.  Before each packing, faces that
    stick out of their chart as spikes move into the neighbouring chart's notch, and the
    charts that changed are minimized again (:mod:`~jaxparam.atlas.notches`: cow 72.6 ->
    76.5 % covered, seams 17 % shorter).

    *Differentiability:* the charts and the packing are discrete choices and carry no
    gradient; the packed UVs for new vertex positions with the layout held fixed
    come from :func:`jaxparam.atlas.atlas_uv` (``jp.atlas_uv``) (implicit gradients through each chart's
    minimization).

    Raises :class:`~jaxparam.MeshError` for traced vertices or bad arguments (a
    non-manifold mesh is refused when the :class:`TriMesh` is made), and
    :class:`~jaxparam.SolverError` (stage ``"atlas"``) when a chart still fails after the
    splits.

    Example::

        a = jp.atlas(jp.load("bunny.off"))
        jp.save("bunny_atlas.obj", mesh, a.uv, uv_faces=a.uv_faces)
    """
    mesh = as_mesh(mesh, "atlas")
    if isinstance(mesh.vertices, jax.core.Tracer):
        raise MeshError("atlas: the vertices are JAX tracers; the charts and the packing are "
                        "discrete choices made on concrete positions. Build the atlas from concrete "
                        "vertices, then differentiate jp.atlas_uv(vertices, atlas).")
    soup = unstitched(mesh) if mesh.topology.n_components > 0.5 * mesh.topology.n_faces else None
    if soup:
        # one chart per triangle, and a packing of thousands of charts (a 1,653-triangle soup
        # took 177 s): refused, as flatten refuses it
        raise TopologyError(f"atlas: {soup}; unstitched, every triangle would be a chart of its own.")
    if int(texture_size) < 8:
        raise MeshError(f"atlas: texture_size must be at least 8 texels, got {texture_size}.")
    if not 0 <= 2 * int(margin_texels) < int(texture_size):
        raise MeshError(f"atlas: margin_texels must be >= 0 and leave room inside the "
                        f"{texture_size}-texel texture (below {int(texture_size) / 2:g}), "
                        f"got {margin_texels}.")
    if start not in ("conformal", "convex"):
        raise MeshError(f"atlas: start must be 'conformal' or 'convex', got {start!r}.")
    if not 0 < cone < 180:
        raise MeshError(f"atlas: cone must be an angle in (0, 180) degrees, got {cone}.")
    if not max_aspect > 1:      # s1/s2 >= 1: at 1 or below every chart splits to single triangles
        raise MeshError(f"atlas: max_aspect bounds s1/s2 >= 1 and must be above 1 (default 3.5), got {max_aspect}.")
    if merge_cone is not None and not 0 < merge_cone < 180:
        raise MeshError(f"atlas: merge_cone must be an angle in (0, 180) degrees or None, got {merge_cone}.")
    if small_merge_cone is not None and not 0 < small_merge_cone < 180:
        raise MeshError("atlas: small_merge_cone must be an angle in (0, 180) degrees or None, "
                        f"got {small_merge_cone}.")
    if normals not in ("auto", "raw", "smoothed"):
        raise MeshError(f"atlas: normals must be 'auto', 'raw' or 'smoothed', got {normals!r}.")
    if not (compact >= 0 and 0 < compact_accept < 1):
        raise MeshError(f"atlas: compact must be >= 0 and compact_accept in (0, 1); got {compact}, "
                        f"{compact_accept}.")
    if not (post_merge_budget >= 0 and 0 < post_merge_cone < 180 and 0 < post_merge_share <= 1):
        raise MeshError("atlas: post_merge_budget must be >= 0, post_merge_cone in (0, 180) degrees "
                        f"and post_merge_share in (0, 1]; got {post_merge_budget}, {post_merge_cone}, "
                        f"{post_merge_share}.")
    en = en_mod.get(energy)
    if en.scale_invariant:
        # Unchanged when one triangle is scaled, so nothing stops a free chart's triangles from
        # shrinking: on a knight (1000 faces) 'mips' left 43 faces under 1e-18 texels.
        raise MeshError(f"atlas: the energy {en.name!r} is scale-invariant, so a chart's free "
                        "boundary lets its triangles shrink to nothing (no texels); use one that "
                        "penalizes area change: symmetric_dirichlet (the default) or arap.")
    if en_mod.ENERGIES.get(en.name) is en and en.name in en_mod.NO_FREE_MINIMUM:
        raise MeshError(f"atlas: the energy {en.name!r} with a chart's free boundary "
                        f"{en_mod.NO_FREE_MINIMUM[en.name]}; use symmetric_dirichlet (the "
                        "default) or arap.")
    t0 = time.perf_counter()
    clock = StageClock()
    mark = StageBar(clock, total=4 + (post_merge_budget > 0) + (compact > 0), desc="atlas",
                    verbose=verbose)
    try:
        V = np.asarray(mesh.vertices, np.float64)
        t = mesh.topology
        F = t.faces
        chart = ch.segment(mesh, cone=cone, merge_cone=merge_cone, small_cone=small_merge_cone,
                           normals=normals)
        mark("charts")
        adj_csr = ch.face_csr(t)
        corner_uv = np.zeros((F.shape[0], 3, 2))
        todo = np.arange(F.shape[0])
        prev = None
        splits = 0
        overlaps = 0
        last = max_splits + FINAL_HALVINGS
        for round_ in range(last + 1):
            if round_:
                mark.note(f"flatten, split round {round_}")
            cuv, labels, q = _flatten_subset(V, F, chart, todo, en, start, weights, solver, max_iters,
                                             prev)
            corner_uv[todo] = cuv
            bad = (q["flips"] > 0) | (q["overlaps"] > 0)
            if round_ < max_splits:
                bad |= q["max_aspect"] > max_aspect
            if not bad.any():
                break
            if round_ == last:
                raise SolverError(
                    f"atlas: {int(bad.sum())} charts still fold over after {last} rounds of "
                    "splits; raise max_splits or lower cone.", stage="atlas")
            prev = (corner_uv, chart.copy())   # corner_uv is not written before the next flatten
            nxt = int(chart.max()) + 1
            redo = []
            for c in labels[bad]:
                # past max_splits rounds only folds count, and they are halved: peeling a big
                # chart's crossings round after round left 2 charts folded after 16 rounds on
                # cow x256 (1.41M faces, 375 s); halving ends at single triangles
                pieces = _peeled_or_halved(V, F, np.flatnonzero(chart == c), corner_uv, adj_csr,
                                           peel=round_ < max_splits)
                for k, piece in enumerate(pieces):
                    if k:
                        chart[piece] = nxt
                        nxt += 1
                redo.append(np.flatnonzero(chart == c))
                redo.extend(pieces[1:])
            splits += int(bad.sum())
            chart = ch.relabel(chart)
            chart = ch.make_disks(t, chart, adj_csr)
            # redo every chart that now holds a face of a split chart
            touched = np.unique(chart[np.concatenate(redo)])
            todo = np.flatnonzero(np.isin(chart, touched))
        mark("flatten")
        if post_merge_budget > 0:
            chart, corner_uv, _ = mg.merge_flattened(
                V, F, ch.face_adjacency(t), chart, corner_uv,
                lambda c, idx: _flatten_subset(V, F, c, idx, en, start, weights, solver, max_iters),
                cone=float(post_merge_cone), budget=float(post_merge_budget),
                max_aspect=float(max_aspect), max_share=float(post_merge_share))
            mark("merge")
        ears = _ears_show(F.shape[0], int(texture_size))
        nbr = ch.face_neighbours(t) if ears else None

        def layout(c, cuv, reordered=None):
            return layout_charts(c, cuv, F, t.n_vertices, int(texture_size), int(margin_texels),
                                 reordered=reordered)

        def notched(c, cuv):
            if not ears:
                return c, cuv
            return _notches_filled(V, F, nbr, c, cuv, en, solver, max_iters, float(max_aspect))

        filled, filled_uv = notched(chart, corner_uv)
        laid = layout(filled, filled_uv)
        if filled is not chart and int(chart.max()) + 1 <= NOTCH_CHOICE_CHARTS:
            plain = layout(chart, corner_uv)
            if plain[-1] > laid[-1]:
                filled, filled_uv, laid = chart, corner_uv, plain
        chart, corner_uv = filled, filled_uv
        mark("pack")
        if compact > 0:
            k = int(chart.max()) + 1
            made = False
            if k <= COMPACT_CHARTS and F.shape[0] >= COMPACT_MIN_FACES * k:
                chart2, corner_uv2, made = _compact(V, F, chart, corner_uv, adj_csr, en, solver,
                                                    max_iters, max_new=int(compact * k),
                                                    accept=float(compact_accept))
            if made:
                chart2, corner_uv2 = notched(chart2, corner_uv2)
                try:
                    laid2 = layout(chart2, corner_uv2)
                except SolverError:               # the cuts' charts do not fit: keep the
                    laid2 = None                  # layout that does (a held-out torus: 8
                if laid2 is not None and laid2[-1] > laid[-1]:   # charts fit, 12 did not)
                    chart, corner_uv, laid = chart2, corner_uv2, laid2
            k = int(chart.max()) + 1
            if k <= COMPACT_CHARTS and F.shape[0] >= COMPACT_MIN_FACES * k:   # as the compaction
                chart, corner_uv, laid = _long_charts_cut(V, F, chart, corner_uv, adj_csr, en,
                                                          solver, max_iters, layout, laid)
            for _ in range(PACKING_CUT_ROUNDS):
                k = int(chart.max()) + 1
                if not (_large_charts(chart, corner_uv) <= PACKING_CUT_CHARTS and k <= COMPACT_CHARTS
                        and laid[-1] < PACKING_CUT_BELOW and F.shape[0] >= (k + 1) * COMPACT_MIN_FACES):
                    break
                cut = _widest_cut(V, F, chart, corner_uv, adj_csr, en, solver, max_iters)
                try:
                    laid2 = None if cut is None else layout(*cut)
                except SolverError:               # the pieces do not fit at full size
                    laid2 = None
                if laid2 is None or laid2[-1] <= laid[-1]:
                    break
                chart, corner_uv, laid = cut[0], cut[1], laid2
            mark("compact")
        if int(chart.max()) + 1 <= ORDER_CHARTS:   # the same charts: it never covers less
            laid = max(laid, layout(chart, corner_uv, laid[4]), key=lambda lay: lay[-1])
        mark("orders")
    finally:
        mark.close()
    uv_faces, vertex, uv_chart, chart_uv, packing, uv, _ = laid
    seconds = {**clock.seconds, "total": time.perf_counter() - t0}
    seam_ids = ch.chart_edges(t, chart)
    ef = t.edge_faces[seam_ids]
    seams = t.edges[seam_ids[(ef[:, 0] >= 0) & (ef[:, 1] >= 0)]]
    stats = atlas_stats(V, F, uv, uv_faces, chart, seams, overlaps, splits, seconds)
    return Atlas(uv=uv, uv_faces=uv_faces, vertex=vertex, uv_chart=uv_chart, chart=chart,
                 seams=seams, chart_uv=chart_uv, packing=packing, energy=en, stats=stats)
