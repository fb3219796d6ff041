"""Every chart's least-squares conformal map at once: the start of the atlas's minimization.

A convex-combination start puts each chart's boundary on a circle, far from the free
boundary's optimum: on cow refined once (22k faces, 161 charts) its symmetric Dirichlet
energy is 319 (4 at an isometry) and Newton takes 19 steps.  The least-squares conformal map
(:mod:`jaxparam.optimize.conformal`, all charts in one solve) lets the boundary go where the chart's shape
wants it: 4.03 there, and 10 steps.  Where a chart's conformal map folds, the chart keeps the
circle, and such charts then set the step count (the atlas's charts of cow refined 3 times:
2549 -> 1025, 18 -> 17 steps; benchmarks/README.md).  A chart whose map inverts a triangle or
crosses its own boundary keeps its convex start (Theorem 1: one-to-one), so the start is
flip-free and one-to-one chart by chart either way.
"""
from __future__ import annotations

import numpy as np

from ..optimize import conformal as _lscm
from .flatten import ChartMesh, convex_start, rescale, self_overlaps

__all__ = ["conformal_start", "conformal_map", "pinned_pairs"]

def pinned_pairs(cm: ChartMesh) -> tuple[np.ndarray, np.ndarray]:
    """:func:`jaxparam.optimize.conformal.pinned_pairs` of the charts: ``(a, b)``, ``(c,)`` UV-vertex ids."""
    return _lscm.pinned_pairs(cm.mesh.vertices, cm.mesh.topology, cm.uv_chart, cm.n_charts)


def conformal_map(cm: ChartMesh) -> np.ndarray:
    """Every chart's least-squares conformal map, one sparse solve
    (:func:`jaxparam.optimize.conformal.conformal_map`): ``uv (n_uv, 2)``, each chart's pins at ``(0, 0)``
    and ``(|p_a - p_b|, 0)`` (its 3D scale)."""
    return _lscm.conformal_map(cm.mesh.vertices, cm.mesh.topology, cm.uv_chart, cm.n_charts)


def conformal_start(cm: ChartMesh, *, weights: str = "shape_preserving") -> np.ndarray:
    """The atlas's start: each chart's :func:`conformal_map`, mirrored when it came out
    clockwise, or its :func:`~jaxparam.atlas.flatten.convex_start` (``weights``) where the
    conformal map inverts or flattens a triangle or crosses its own boundary; every chart
    recentred and scaled to its 3D area (:func:`~jaxparam.atlas.flatten.rescale`).
    **Returns:** ``uv (n_uv, 2)``, flip-free chart by chart."""
    uv = conformal_map(cm)
    bad = _lscm.orient_disks(uv, cm.mesh.faces, cm.chart, cm.uv_chart, cm.n_charts)
    # A conformal map can cross its own boundary; the minimization would keep the fold
    # (its energy does not see it) and the chart would be split: start those on a circle.
    bad |= self_overlaps(cm, np.where(bad[cm.uv_chart, None], 0.0, uv)) > 0
    if bad.any():
        on = bad[cm.uv_chart]
        uv[on] = convex_start(cm, weights=weights)[on]
    return rescale(cm, uv)
