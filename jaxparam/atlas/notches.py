"""Flattened charts' spikes moved into the notches beside them, with no new minimization.

A face with one edge in its own chart and its two other edges on one neighbouring chart
(an *ear*) sticks out of its chart's UV outline as a spike, and leaves a notch in the
neighbour's.  The cone growth, the splits along level sets and the compaction's straight cuts
all leave such faces along the seams (cow's atlas: 256 of its 5,520 faces, session 26), and
spikes pack badly.  Moved into the neighbouring chart, the face needs no new UVs: its three
corners are already vertices of that chart (two consecutive boundary edges there), so its UV
triangle is the notch's.  The donor loses an ear and the receiver fills a notch; both stay
disks (an ear's apex is in no other face of its chart, and the receiver's boundary passes
through the apex once), so both outlines get straighter and the seams shorter.

A move is kept where the notch's triangle is positive (then it lies on the far side of both
boundary edges, outside the receiver near the apex), no more stretched than ``max_aspect``
and, in symmetric Dirichlet, within :data:`SD_GROWTH` of the face's map in its own chart, and
where the receiver's boundary does not cross itself afterwards (checked chart by chart, the
moves into a chart that crosses undone).  Moves in one round touch no common face.  All numpy;
like the charts, a discrete choice made on concrete positions.
"""
from __future__ import annotations

import numpy as np

from .. import host
from . import flatten as fl

__all__ = ["ear_targets", "fill_notches", "SD_GROWTH", "ROUNDS"]

#: A moved face's symmetric Dirichlet (``s1^2 + s2^2 + s1^-2 + s2^-2``, 4 for an isometry) in
#: the receiving chart may exceed its value in its own chart by at most this share (the
#: charts a move changes are then minimized again, :func:`jaxparam.atlas.build.atlas`).
SD_GROWTH = 0.25
#: Rounds of moves (a move can leave a new ear beside it).
ROUNDS = 4


def ear_targets(nbr: np.ndarray, chart: np.ndarray) -> np.ndarray:
    """``(m,) int``: for each face with at most one neighbour in its own chart and two in
    one other chart, that chart; ``-1`` for every other face.  ``nbr (m, 3)`` the face across
    each edge (``-1`` across the mesh's boundary), ``chart (m,)`` the labels."""
    nc = np.where(nbr >= 0, chart[np.maximum(nbr, 0)], -1)
    own = (nc == chart[:, None]).sum(1)
    pair = np.full(chart.size, -1, np.int64)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        same = (nc[:, i] == nc[:, j]) & (nc[:, i] >= 0) & (nc[:, i] != chart)
        pair = np.where(same & (pair < 0), nc[:, i], pair)
    return np.where(own <= 1, pair, -1)


def _symmetric_dirichlet(q: dict) -> np.ndarray:
    s1, s2 = np.abs(q["s1"]), np.abs(q["s2"])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        sd = s1 ** 2 + s2 ** 2 + s1 ** -2.0 + s2 ** -2.0
    return np.where(np.isfinite(sd), sd, np.inf)


def _triangle_quantities(V: np.ndarray, F: np.ndarray, faces: np.ndarray, T: np.ndarray) -> dict:
    """:func:`jaxparam.host.face_quantities` of ``faces (k,)`` with UV triangles ``T (k, 3, 2)``."""
    k = faces.size
    tri = np.arange(3 * k).reshape(k, 3)
    return host.face_quantities(V[F[faces]].reshape(-1, 3), tri, T.reshape(-1, 2))


def fill_notches(V: np.ndarray, F: np.ndarray, nbr: np.ndarray, chart: np.ndarray,
                 corner_uv: np.ndarray, *, max_aspect: float, rounds: int = ROUNDS):
    """Ears moved into the notches of their neighbouring charts (see the module's notes).

    **Arguments:** ``V (n, 3)``, ``F (m, 3)`` the mesh; ``nbr (m, 3)`` the face across each
    edge (:func:`jaxparam.atlas.charts.face_neighbours`); ``chart (m,)`` labels ``0..c-1``,
    every chart a disk; ``corner_uv (m, 3, 2)`` each face's corners in its chart's plane;
    ``max_aspect`` the largest ``s1/s2`` a moved face may have.

    **Returns:** ``(chart, corner_uv, moved)``: new arrays (the labels as given: a chart of
    one face that moved whole leaves its label unused) and the number of faces moved."""
    chart = np.asarray(chart, np.int64).copy()
    corner_uv = np.array(corner_uv, np.float64)
    n = int(F.max()) + 1
    m = F.shape[0]
    moved = 0
    for _ in range(rounds):
        target = ear_targets(nbr, chart)
        cand = np.flatnonzero(target >= 0)
        if not cand.size:
            break
        # no two moves in a round touch: a candidate gives way to a neighbouring one of lower index
        is_cand = np.zeros(m, bool)
        is_cand[cand] = True
        blocked = (is_cand[np.maximum(nbr[cand], 0)] & (nbr[cand] >= 0) & (nbr[cand] < cand[:, None])).any(1)
        cand = cand[~blocked]
        recv = target[cand]
        # the receiver's UV of each corner: one UV per (chart, vertex) in a disk chart
        key = np.repeat(chart, 3) * np.int64(n) + F.reshape(-1)
        order = np.argsort(key, kind="stable")
        skey = key[order]
        want = recv[:, None] * np.int64(n) + F[cand]
        pos = np.minimum(np.searchsorted(skey, want), skey.size - 1)
        found = (skey[pos] == want).all(1)
        cand, recv, pos = cand[found], recv[found], pos[found]
        T = corner_uv.reshape(-1, 2)[order[pos]]                                   # (k, 3, 2)
        q_new = _triangle_quantities(V, F, cand, T)
        q_old = _triangle_quantities(V, F, cand, corner_uv[cand])
        sd_new, sd_old = _symmetric_dirichlet(q_new), _symmetric_dirichlet(q_old)
        aspect = host.map_aspects(q_new)
        ok = ((q_new["area_uv"] > 0) & (aspect <= max_aspect)
              & (sd_new <= (1.0 + SD_GROWTH) * sd_old))
        cand, recv, T = cand[ok], recv[ok], T[ok]
        if not cand.size:
            break
        before_chart, before_uv = chart[cand].copy(), corner_uv[cand].copy()
        chart[cand], corner_uv[cand] = recv, T
        # undo the moves into receivers whose boundary now crosses itself
        touched = np.unique(recv)
        faces = np.flatnonzero(np.isin(chart, touched))
        labels, sub = np.unique(chart[faces], return_inverse=True)
        cm = fl.chart_mesh(V, F[faces], sub)
        crossing = labels[fl.self_overlaps(cm, fl.uv_of_corners(cm, corner_uv[faces])) > 0]
        undo = np.isin(recv, crossing)
        chart[cand[undo]], corner_uv[cand[undo]] = before_chart[undo], before_uv[undo]
        moved += int((~undo).sum())
        if undo.all():
            break
    return chart, corner_uv, moved
