"""Merging flattened charts: fewer charts for a bounded rise in distortion (issue 18).

The cone-grown charts are merged before flattening on normals alone (:mod:`.charts`), which
cannot tell a union that flattens well from one that does not: a wider cone there gives
fewer charts but raised decimated-knight's symmetric Dirichlet past xatlas's.  Here the
charts are already flattened, so a merge is judged by its map:

1. every chart under ``max_share`` of the 3D area (smallest first) pairs with its largest
   neighbour not yet paired whose union is a disk within ``cone`` degrees of the union's
   mean normal;
2. all unions are flattened in one batched problem (the ``flatten`` callable);
3. a union is kept when its map has no flip and no boundary self-crossing, its largest
   ``s1/s2`` is within ``max_aspect``, and the rise of the atlas's area-weighted symmetric
   Dirichlet (isometry = 2) it causes, added to those kept before (smallest rise first; a
   union that lowers it gives room to others), stays within ``budget`` times the atlas's
   distortion before merging (its area-weighted symmetric Dirichlet minus 2).  A share
   rather than an amount: meshes that flatten almost isometrically (3holes: 2.0034, xatlas
   2.0035) keep almost their distortion, coarse ones (decimated-knight: 2.038) may trade
   more of it for fewer charts.

Rounds repeat while some union is kept.  All numpy apart from the flattening; a discrete
choice, no gradient goes through it.
"""
from __future__ import annotations

import numpy as np

from . import charts as ch

__all__ = ["face_sym_dirichlet", "merge_pairs", "merge_flattened"]


def face_sym_dirichlet(V: np.ndarray, F: np.ndarray, corner_uv: np.ndarray):
    """``(sd (m,), aspect (m,), area3d (m,))`` of the per-corner UVs ``corner_uv (m, 3, 2)``
    of the 3D faces ``F (m, 3)`` into ``V (n, 3)``: ``sd = (s1^2 + s2^2 + s1^-2 + s2^-2) / 2``
    (isometry = 2) and ``aspect = s1 / s2`` of each face's map, at the UVs' own scale."""
    P = V[F]
    x, y = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    l1 = np.linalg.norm(x, axis=1)
    ex = x / np.maximum(l1, 1e-300)[:, None]
    yx = np.einsum("ij,ij->i", y, ex)
    yy = np.linalg.norm(y - yx[:, None] * ex, axis=1)
    D = np.stack([np.stack([l1, yx], -1), np.stack([np.zeros_like(l1), yy], -1)], -2)
    U = np.stack([corner_uv[:, 1] - corner_uv[:, 0], corner_uv[:, 2] - corner_uv[:, 0]], -1)
    sv = np.linalg.svd(U @ np.linalg.inv(D), compute_uv=False)
    with np.errstate(divide="ignore"):
        sd = (sv[:, 0] ** 2 + sv[:, 1] ** 2 + sv[:, 0] ** -2.0 + sv[:, 1] ** -2.0) / 2
        aspect = sv[:, 0] / sv[:, 1]
    return sd, aspect, 0.5 * np.linalg.norm(np.cross(x, y), axis=1)


def merge_pairs(chart, normals, areas, adj, faces, *, cone: float, max_share: float) -> list:
    """Step 1 of the module docstring: ``[(small, into), ...]`` chart pairs, each chart in
    at most one.  ``chart (m,)``, ``normals (m, 3)``, ``areas (m,)``, ``adj (2, k)`` face
    pairs, ``faces (m, 3)``.  Loops over charts, not faces."""
    c = int(chart.max()) + 1
    area_c = np.bincount(chart, weights=areas, minlength=c)
    N = np.zeros((c, 3))
    np.add.at(N, chart, normals * areas[:, None])
    order = np.argsort(chart, kind="stable")
    bounds = np.searchsorted(chart[order], np.arange(c + 1))
    members = [order[bounds[k]:bounds[k + 1]] for k in range(c)]
    a, b = chart[adj[0]], chart[adj[1]]
    cross = a != b
    pair = np.unique(np.sort(np.stack([a[cross], b[cross]], 1), axis=1), axis=0)
    nbrs = [[] for _ in range(c)]
    for p, q in pair.tolist():
        nbrs[p].append(q)
        nbrs[q].append(p)
    cos_t = np.cos(np.radians(cone))
    limit = max_share * float(areas.sum())
    used = np.zeros(c, bool)
    out = []
    for s in np.argsort(area_c, kind="stable").tolist():
        if area_c[s] > limit:
            break
        if used[s]:
            continue
        for q in sorted(nbrs[s], key=lambda r: -area_c[r]):
            if used[q]:
                continue
            n = N[s] + N[q]
            fs = np.concatenate([members[s], members[q]])
            if np.min(normals[fs] @ (n / max(np.linalg.norm(n), 1e-300))) < cos_t:
                continue
            if not ch.faces_are_disk(faces[fs]):
                continue
            out.append((s, q))
            used[s] = used[q] = True
            break
    return out


def merge_flattened(V, F, adj, chart, corner_uv, flatten, *, cone: float, budget: float,
                    max_aspect: float, max_share: float = 0.01, rounds: int = 4):
    """Merge flattened charts (module docstring).

    **Arguments:** ``V (n, 3)``, ``F (m, 3)``, ``adj (2, k)`` face pairs (interior edges),
    ``chart (m,)``, ``corner_uv (m, 3, 2)`` the
    charts' maps; ``flatten(chart, faces_idx)`` returns ``(corner_uv (k, 3, 2), labels,
    quality)`` for the charts of the faces ``faces_idx`` (``quality`` as
    :func:`.flatten.chart_quality`, indexed like ``labels``); ``cone`` (degrees),
    ``budget`` (largest total rise of the area-weighted symmetric Dirichlet, isometry 2, as
    a share of its excess over 2 before merging),
    ``max_aspect``, ``max_share`` (charts under this share of the area merge), ``rounds``.
    **Returns:** ``(chart (m,) relabelled, corner_uv (m, 3, 2), merges)``.
    """
    chart, corner_uv = chart.copy(), corner_uv.copy()
    normals, areas = ch.face_normals(V, F)
    total = float(areas.sum())
    sd0, _, _ = face_sym_dirichlet(V, F, corner_uv)
    allowed = float(budget) * max(float(np.sum(sd0 * areas)) / total - 2.0, 0.0)
    used, merges = 0.0, 0
    for _ in range(int(rounds)):
        pairs = merge_pairs(chart, normals, areas, adj, F, cone=cone, max_share=max_share)
        if not pairs:
            break
        sd, _, _ = face_sym_dirichlet(V, F, corner_uv)
        sd_c = np.bincount(chart, weights=sd * areas, minlength=int(chart.max()) + 1)
        small = np.zeros(int(chart.max()) + 1, np.int64) - 1
        for s, q in pairs:
            small[q] = s
        lut = np.arange(small.size)
        lut[[s for s, _ in pairs]] = [q for _, q in pairs]
        trial = lut[chart]
        into = np.array([q for _, q in pairs])
        fidx = np.flatnonzero(np.isin(trial, into))
        cuv, labels, qual = flatten(trial, fidx)
        sd_new, _, _ = face_sym_dirichlet(V, F[fidx], cuv)
        sd_u = np.bincount(np.searchsorted(labels, trial[fidx]), weights=sd_new * areas[fidx],
                           minlength=labels.size)
        k = np.searchsorted(labels, into)
        ok = (qual["flips"][k] == 0) & (qual["overlaps"][k] == 0) & (qual["max_aspect"][k] <= max_aspect)
        rise = (sd_u[k] - sd_c[into] - sd_c[small[into]]) / total
        kept = []
        for j in np.argsort(rise, kind="stable"):
            if ok[j] and used + rise[j] <= allowed:
                used += rise[j]
                kept.append(into[j])
        if not kept:
            break
        keep_face = np.isin(trial[fidx], kept)
        sel = fidx[keep_face]
        chart[sel] = trial[sel]
        corner_uv[sel] = cuv[keep_face]
        merges += len(kept)
    return ch.relabel(chart), corner_uv, merges
