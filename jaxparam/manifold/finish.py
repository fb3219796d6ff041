"""The chosen samples of a closed remesh finished: the input's tips snapped to and the regions
of the base domain contracted, in the order whose remesh is estimated closer; and the guard
that drops samples which stretch the remesh.

Both steps move samples in the base domain only (the map and its exact inverse are untouched)
and are kept only where :func:`~jaxparam.manifold.relax.estimated_distance` finds the remesh
closer (manifold/snap.py, manifold/fans.py).  Everything runs on the positions the caller
gives (centred on their bounding box by :mod:`jaxparam.manifold.parameterization`).
"""
from __future__ import annotations

import numpy as np

from ..distance import point_triangle_distance
from ..host import face_areas
from .fans import chosen_contractions, contract_fans, regions
from .relax import estimated_distance
from .snap import SNAP_GAIN, bend, snap_tips

__all__ = ["finished", "lift_with", "stretches", "longest", "flattest", "RELAX_MAX_EDGE_GROWTH"]

#: The largest growth of the remesh's longest edge (over the plain samples') that relaxed,
#: snapped or contracted samples may bring (:func:`stretches`).
RELAX_MAX_EDGE_GROWTH = 1.25


def longest(X, faces) -> float:
    """The longest edge of the faces ``(m, 3)`` over points ``X``."""
    return float(np.max(np.linalg.norm(X[faces[:, [1, 2, 0]]] - X[faces], axis=-1)))


def stretches(X, X0, faces) -> bool:
    """Whether the remesh over points ``X`` has a longest edge on the surface more than
    :data:`RELAX_MAX_EDGE_GROWTH` times the one over ``X0`` (the unrelaxed samples'): then the
    relaxed samples are dropped.  Found on a held-out cow (sheared, noisy): relaxed, a few
    samples landed on the wrong side of a fold, and the remesh got faces that cut across the
    surface (Hausdorff remesh -> input 1.16 -> 4.07 % of the diagonal, longest edge 5.1 ->
    12.6 %), while on the shared closed meshes the longest edge changes by 0.83-1.14x."""
    return (longest(X, faces) > RELAX_MAX_EDGE_GROWTH * longest(X0, faces)
            or flattest(X, faces) < 1e-6 * flattest(X0, faces))


def flattest(X, faces) -> float:
    """The smallest face area (doubled) of the remesh over points ``X``: a relaxed candidate
    whose smallest face collapses (a million times smaller than the unrelaxed remesh's) is
    dropped too.  Found on cow with an area-capped base domain: three relaxed level-3 samples
    landed on one line (area 2e-19 against 1e-7 unrelaxed), and the remesh did not load back
    (a zero-area face)."""
    return 2.0 * float(face_areas(X, faces).min())


def finished(history, vertex_bary, D, P, Fm, G, vertex_face, sharp, r, b, pull, X, X0, error, *,
             both_orders: bool = True):
    """The samples ``(r, b, pull)`` with the input's tips that their remesh (faces ``G``,
    surface points ``X``) cuts off snapped to (:func:`_snapped`) and its regions contracted
    (:func:`_contracted`; the contractions chosen once, on the samples given).  Snapping first
    keeps each region that holds a snapped sample as it is; with ``both_orders``, contracting
    first is tried too and the order whose remesh is estimated closer is kept.  Contracting
    first can leave a tip's samples too far to snap (a sheared noisy cow at 50 base faces,
    1.70 -> 2.19 % of the diagonal); snapping first gave up rocker-arm's gain (0.38 -> 0.55 %)
    and a sheared bunny's (0.525 -> 0.688 %, though the estimate did not fall there: both
    orders are tried whenever the contraction is kept).  The second snapping is the cost:
    the 111k-face bunny's ``remesh(4)`` took 25 CPU s with both orders, 20 s with one; an
    adaptive 20k-face sphere 28 s with both, 22 s with one.

    **Arguments:** ``history`` the decimation's (its exact pull-back), ``vertex_bary`` and
    ``vertex_face`` the input vertices' places in the base domain ``D`` (a
    :class:`~jaxparam.manifold.relax.BaseDomain`), ``(P, Fm)`` the input, ``sharp`` its
    sharpest vertices, ``X0`` the plain samples' surface points, ``error`` the estimated
    distance of the remesh over ``X``."""
    c = (history, vertex_bary, D, P, Fm, G, vertex_face, sharp)
    alpha = chosen_contractions(D.F0, G, r, b, X, lift_with(history, P, Fm), P, Fm, vertex_face,
                                vertex_bary, max_edge=RELAX_MAX_EDGE_GROWTH * longest(X0, G))
    *snapped, moved = _snapped(c, r, b, pull, X, error, X0)
    if np.all(alpha == 1.0):
        return tuple(snapped[:3])
    held = regions(D.F0, np.asarray(snapped[0], np.int64)[moved], np.asarray(snapped[1])[moved])[0]
    held = held[(held >= 0) & (alpha[np.maximum(held, 0)] < 1.0)]
    kept = alpha.copy()
    kept[held] = 1.0                        # the regions holding a snapped sample stay
    snap_first = _contracted(c, *snapped, X0, kept)
    contracted = _contracted(c, r, b, pull, X, error, X0, alpha) if both_orders else None
    if contracted is None or contracted[1] is b:        # one order, or nothing to snap again
        return snap_first[:3]
    contract_first = _snapped(c, *contracted, X0)[:5]
    return min(contract_first, snap_first, key=lambda out: out[4])[:3]


def _snapped(c, r, b, pull, X, error, X0):
    """``(r, b, pull, X, error, snapped)``: the samples with the tips snapped to when the
    estimated distance falls below ``error`` by more than its rounding
    (:data:`~jaxparam.manifold.snap.SNAP_GAIN`, :func:`_snap_gains`) and the remesh does not
    stretch past the plain samples' (``X0``), their surface points, estimated distance, and
    the samples snapped; else the samples given."""
    history, vertex_bary, D, P, Fm, G, vertex_face, sharp = c
    rs, bs, Xt, source = snap_tips(D, G, r, b, X, P, Fm, sharp, vertex_face, vertex_bary)
    moved = np.flatnonzero(source >= 0)
    if not moved.size or stretches(Xt, X0, G) or not _snap_gains(P, Fm, sharp, X, Xt, G, moved, error):
        return r, b, pull, X, error, moved[:0]
    face, bary = (np.copy(a) for a in (pull or history.pull_back(r, b, verbose=False)))
    face[moved], bary[moved] = _vertex_corners(Fm, source[moved], P.shape[0])
    return rs, bs, (face, bary), Xt, estimated_distance(P, Fm, sharp, Xt, G), moved


def _contracted(c, r, b, pull, X, error, X0, alpha):
    """``(r, b, pull, X, error)``: the samples with the regions contracted by ``alpha``
    (manifold/fans.py), their surface points and estimated distance, when that does not rise
    (by more than :data:`~jaxparam.manifold.snap.SNAP_GAIN`) and the remesh does not stretch
    past the plain samples' (``X0``); else the samples given."""
    history, vertex_bary, D, P, Fm, G, vertex_face, sharp = c
    if np.all(alpha == 1.0):
        return r, b, pull, X, error
    b2, moved = contract_fans(D.F0, r, b, alpha)
    face, bary = (np.copy(a) for a in (pull or history.pull_back(r, b, verbose=False)))
    face[moved], bary[moved] = history.pull_back(np.asarray(r)[moved], b2[moved], verbose=False)
    Xc = np.einsum("kc,kcd->kd", bary, P[Fm[face]])
    err = np.inf if stretches(Xc, X0, G) else estimated_distance(P, Fm, sharp, Xc, G)
    return (r, b, pull, X, error) if err > (1 + SNAP_GAIN) * error else (r, b2, (face, bary), Xc, err)


def _snap_gains(P, Fm, sharp, X, Xt, G, moved, error) -> bool:
    """Whether the snapped remesh ``(Xt, G)`` is closer to the input ``(P, Fm)`` than the one
    over ``X`` (whose estimated distance is ``error``): the estimate
    (:func:`~jaxparam.manifold.relax.estimated_distance`) joined with how far the faces around
    the ``moved`` samples stand off the input (:func:`~jaxparam.manifold.snap.bend`), is lower
    by more than :data:`~jaxparam.manifold.snap.SNAP_GAIN`; or it is not higher and the sharp
    vertices' distance to the remesh is lower.  (Decimated-knight's estimate peaks on a long
    edge across a saddle, which no snap touches: strictly lower refused its snapped tips,
    0.53 -> 0.51 % of the diagonal.)"""
    around = np.isin(G, moved).any(1)
    before = max(error, float(bend(X[G[around]], P, Fm).max(initial=0.0)))
    after = max(estimated_distance(P, Fm, sharp, Xt, G), float(bend(Xt[G[around]], P, Fm).max(initial=0.0)))
    if after < (1 - SNAP_GAIN) * before:
        return True
    tips = lambda Y: point_triangle_distance(P[sharp], Y, G)[0].max(initial=0.0)
    return after <= (1 + SNAP_GAIN) * before and tips(Xt) < (1 - SNAP_GAIN) * tips(X)


def _vertex_corners(F: np.ndarray, v: np.ndarray, n: int):
    """A face of ``F (m, 3)`` at each vertex ``v (k,)`` and the one-hot barycentric
    coordinates ``(k, 3)`` of the vertex there: ``((k,), (k, 3))``."""
    face_at = np.empty(n, np.int64)
    face_at[F.ravel()] = np.arange(F.size) // 3
    f = face_at[v]
    return f, (F[f] == v[:, None]).astype(np.float64)


def lift_with(history, P: np.ndarray, Fm: np.ndarray):
    """``lift(r (k,), b (k, 3)) -> (k, 3)``: base-domain points pulled back through the
    decimation's ``history`` onto the input faces ``Fm`` over positions ``P``."""
    def lift(region, bary):
        face, bb = history.pull_back(region, bary, verbose=False)
        return np.einsum("kc,kcd->kd", bb, P[Fm[face]])
    return lift
