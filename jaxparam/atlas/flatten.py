"""Flattening every chart at once: one convex-combination start and one flip-free,
free-boundary minimization for all charts together.

The charts are laid side by side as one disconnected mesh, the *chart mesh*: each chart's
vertices are copied once (its own UV vertices), its faces keep their order.  One sparse
solve gives every chart's convex-combination map (each boundary loop on its own circle,
chord-length spaced, the interior by the chosen weights); one
:class:`~jaxparam.optimize.Problem` minimizes the energy over all charts (their Hessian
blocks do not couple), so compilation happens once per atlas, not once per chart.

Everything here but the minimization runs on concrete arrays in NumPy
(:mod:`jaxparam.host` twins, the host assembly and factorization of eq. (4)): a split
round's new chart-mesh shapes then compile nothing outside the minimizer's bucketed
kernels (issue 18).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import combination as comb
from .. import host
from .. import linear
from .. import metrics
from .. import tol
from .. import topology as topo
from .. import weights as wts
from ..mesh import TriMesh
from ..triangles import doubled_areas
from ..optimize import Problem, StopRules, solver_from

__all__ = ["ChartMesh", "chart_mesh", "convex_start", "minimize_charts", "chart_quality",
           "warm_charts", "uv_of_corners"]

#: A chart of a split round starts from its parent's map (:func:`warm_charts`) when it holds at
#: least this share of the parent's faces.
WARM_MIN_SHARE = 0.5


@dataclass(frozen=True, eq=False)
class ChartMesh:
    """The charts as one disconnected mesh.

    **Fields:** ``mesh`` (:class:`TriMesh` of ``n_uv`` vertices, faces in the input's face
    order); ``vertex (n_uv,)``: the input vertex each UV vertex copies; ``chart (m,)``:
    each face's chart; ``uv_chart (n_uv,)``: each UV vertex's chart; ``n_charts``.
    """

    mesh: TriMesh
    vertex: np.ndarray
    chart: np.ndarray
    uv_chart: np.ndarray
    n_charts: int


def chart_mesh(vertices, faces: np.ndarray, chart: np.ndarray) -> ChartMesh:
    """Build the :class:`ChartMesh` of ``faces (m, 3)`` cut along ``chart (m,)``: UV
    vertices numbered chart by chart, in increasing input-vertex order within a chart."""
    n = int(faces.max()) + 1
    key = np.repeat(chart.astype(np.int64), 3) * n + faces.reshape(-1)
    uniq, inv = np.unique(key, return_inverse=True)
    UF = inv.reshape(-1, 3).astype(np.int64)
    vertex = uniq % n
    uv_chart = uniq // n
    V = np.asarray(vertices, np.float64)[vertex]
    t = topo.build(UF, vertex.size, where="atlas")
    return ChartMesh(TriMesh(V, UF, t, validate=False), vertex, chart.astype(np.int64),
                     uv_chart.astype(np.int64), int(chart.max()) + 1)


def convex_start(cm: ChartMesh, *, weights: str = "shape_preserving") -> np.ndarray:
    """Every chart's convex-combination map, one sparse solve: ``uv (n_uv, 2)``.

    Each chart's boundary loop goes to a circle (chord-length spacing) of the chart's 3D
    area, so the start is one-to-one chart by chart (Theorem 1) and roughly to scale.
    """
    t = cm.mesh.topology
    V = np.asarray(cm.mesh.vertices, np.float64)
    areas = host.face_areas(V, t.faces)
    area_c = np.bincount(cm.chart, weights=areas, minlength=cm.n_charts)
    uv = np.zeros((t.n_vertices, 2))
    loops = t.boundary_loops
    lens = np.array([l.size for l in loops])
    L = np.concatenate(loops)
    owner = np.repeat(np.arange(len(loops)), lens)
    nxt = np.concatenate([np.roll(l, -1) for l in loops])
    seg = np.linalg.norm(V[nxt] - V[L], axis=1)
    tot = np.bincount(owner, weights=seg)
    start = np.r_[0, np.cumsum(lens)[:-1]]
    cum = np.cumsum(seg) - seg
    cum -= (np.cumsum(seg) - seg)[start][owner]
    theta = 2 * np.pi * cum / np.maximum(tot[owner], 1e-300)
    r = np.sqrt(area_c[cm.uv_chart[L]] / np.pi)
    uv[L] = r[:, None] * np.stack([np.cos(theta), np.sin(theta)], 1)
    if t.interior.size:
        # Host weights, assembly and factorization: no kernel traced for a new shape.
        w, sym = wts.entry_weights(V, t, weights, host=True)
        S = linear.interior_system(t)
        vals, rhs = comb.assemble(S, w, uv[t.boundary], normalize=False, host=True)
        uv[t.interior] = np.asarray(comb.solve(S, vals, rhs, symmetric=sym))
    return rescale(cm, uv)


def rescale(cm: ChartMesh, uv: np.ndarray) -> np.ndarray:
    """Each chart's UVs recentred and scaled so its UV area equals its 3D area."""
    F = cm.mesh.faces
    V = np.asarray(cm.mesh.vertices, np.float64)
    a3 = np.bincount(cm.chart, weights=host.face_areas(V, F), minlength=cm.n_charts)
    auv = np.bincount(cm.chart, weights=host.signed_areas(uv, F), minlength=cm.n_charts)
    cnt = np.bincount(cm.uv_chart, minlength=cm.n_charts)
    c = np.stack([np.bincount(cm.uv_chart, weights=uv[:, k], minlength=cm.n_charts) for k in (0, 1)], 1)
    c /= np.maximum(cnt, 1)[:, None]
    s = np.sqrt(a3 / np.maximum(auv, 1e-300))
    return (uv - c[cm.uv_chart]) * s[cm.uv_chart, None]


def minimize_charts(cm: ChartMesh, energy, uv0: np.ndarray, *, solver="newton",
                    max_iters: int = 200, max_seconds: float | None = None, cold=None):
    """Minimize ``energy`` (a :class:`~jaxparam.Energy`) over every chart at once, free
    boundary, flip-free, from ``uv0 (n_uv, 2)`` (one-to-one chart by chart); each chart
    takes its own step (:attr:`Problem.blocks <jaxparam.optimize.Problem>`).

    ``cold (n_uv, 2)``: where the charts would have started without ``uv0``'s earlier maps
    (:func:`warm_charts`).  The run then stops at the gradient norm where a run from ``cold``
    would (``GRAD_RTOL`` of the gradient there): relative to the warm start's gradient, which
    is already small, that rule never fired, and a warm start took as many slow steps as a
    cold one until the energy rule stopped it (issue 18).
    **Returns:** ``(uv (n_uv, 2), SolveResult)``."""
    prob = Problem(cm.mesh, energy, True, uv0, face_blocks=cm.chart)
    grad_rtol = tol.GRAD_RTOL
    if cold is not None:
        g_cold = np.linalg.norm(prob.value_and_grad(np.asarray(cold)[prob.free].reshape(-1))[1])
        g_warm = np.linalg.norm(prob.value_and_grad(np.asarray(prob.x0))[1])
        if np.isfinite(g_cold) and g_warm > 0:
            grad_rtol = min(1.0, tol.GRAD_RTOL * g_cold / g_warm)
    stop = StopRules(max_iters=max_iters, max_seconds=max_seconds, grad_rtol=grad_rtol)
    res = solver_from(solver).run(prob, stop, verbose=False)
    return np.array(prob.uv(res.x)), res


def warm_charts(chart: np.ndarray, corner_uv: np.ndarray, parent: np.ndarray,
                parent_faces: np.ndarray, *, min_share: float = WARM_MIN_SHARE) -> np.ndarray:
    """``(k,) bool``: which of the charts ``chart (m,)`` (labels ``0..k-1``) can start from an
    earlier round's map.

    **Arguments:** ``corner_uv (m, 3, 2)`` the earlier map at the faces' corners; ``parent
    (m,)`` each face's chart in that round; ``parent_faces`` the face count of each of those
    charts (indexed by ``parent``).  A chart starts warm when all its faces come from one
    earlier chart, hold at least ``min_share`` of it, and the earlier map inverts none of
    them: the piece that keeps most of a split chart starts where its minimization ended,
    not from a new conformal map (issue 18: the split rounds were most of the atlas's time
    on fine meshes)."""
    k = int(chart.max()) + 1
    lo = np.full(k, np.iinfo(np.int64).max)
    hi = np.full(k, -1)
    np.minimum.at(lo, chart, parent)
    np.maximum.at(hi, chart, parent)
    warm = lo == hi
    size = np.bincount(chart, minlength=k)
    warm[warm] = size[warm] >= min_share * np.asarray(parent_faces)[lo[warm]]
    inverted = doubled_areas(corner_uv) <= 0
    return warm & (np.bincount(chart, weights=inverted, minlength=k) == 0)


def uv_of_corners(cm: ChartMesh, corner_uv: np.ndarray) -> np.ndarray:
    """``(n_uv, 2)``: the UVs that ``corner_uv (m, 3, 2)`` gives the corners of ``cm``'s faces
    (one map per chart, so a UV vertex's corners agree; every UV vertex is a face's corner)."""
    uv = np.zeros((cm.mesh.n_vertices, 2))
    uv[cm.mesh.faces.reshape(-1)] = corner_uv.reshape(-1, 2)
    return uv


def chart_quality(cm: ChartMesh, uv: np.ndarray) -> dict:
    """Per-chart checks of a flattening: ``flips (c,)``, ``overlaps (c,)`` (boundary
    self-crossings, :func:`jaxparam.metrics.boundary_overlaps` with the charts moved
    apart), ``max_aspect (c,)`` (largest ``s1/s2``), ``sym_dirichlet (c,)`` (area-weighted
    mean of ``s1^2 + s2^2 + s1^-2 + s2^-2``, 4 for an isometry) and ``area3d (c,)``."""
    q = host.face_quantities(np.asarray(cm.mesh.vertices, np.float64), cm.mesh.faces,
                             np.asarray(uv, np.float64))     # twin of metrics.face_distortion
    s1, s2 = np.asarray(q["s1"]), np.asarray(q["s2"])
    a3, auv = np.asarray(q["area3d"]), np.asarray(q["area_uv"])
    c, k = cm.chart, cm.n_charts
    flips = np.bincount(c, weights=(auv <= 0).astype(float), minlength=k).astype(int)
    with np.errstate(divide="ignore", invalid="ignore"):
        aspect = np.where(auv > 0, np.abs(s1) / np.abs(s2), np.inf)
        sd = s1 ** 2 + s2 ** 2 + s1 ** -2.0 + s2 ** -2.0
    max_aspect = np.full(k, 0.0)
    np.maximum.at(max_aspect, c, aspect)
    area_c = np.bincount(c, weights=a3, minlength=k)
    sd_c = np.bincount(c, weights=np.where(np.isfinite(sd), sd, 1e30) * a3, minlength=k) / area_c
    overlaps = self_overlaps(cm, uv)
    return {"flips": flips, "overlaps": overlaps, "max_aspect": max_aspect,
            "sym_dirichlet": sd_c, "area3d": area_c}


def self_overlaps(cm: ChartMesh, uv: np.ndarray) -> np.ndarray:
    """``(c,) int``: boundary self-crossings of each chart's UVs (the charts are moved
    apart along u first, so crossings between charts are not counted; each crossing is
    counted for the chart of its edges)."""
    lo = np.full((cm.n_charts, 2), np.inf)
    hi = np.full((cm.n_charts, 2), -np.inf)
    np.minimum.at(lo, cm.uv_chart, uv)
    np.maximum.at(hi, cm.uv_chart, uv)
    width = hi[:, 0] - lo[:, 0]
    gap = float(np.max(hi - lo)) + 1.0
    shift = np.cumsum(np.r_[0.0, width[:-1] + gap]) - lo[:, 0]
    U = uv.copy()
    U[:, 0] += shift[cm.uv_chart]
    segments, pairs = metrics.boundary_crossings(cm.mesh, U)
    owner = cm.uv_chart[segments[pairs[:, 0], 0]]
    return np.bincount(owner, minlength=cm.n_charts).astype(int)


def sub_mesh(cm: ChartMesh, k: int):
    """``(TriMesh, uv_ids)``: chart ``k`` alone (its UV vertices renumbered ``0..``)."""
    fk = np.flatnonzero(cm.chart == k)
    ids, inv = np.unique(cm.mesh.faces[fk], return_inverse=True)
    V = np.asarray(cm.mesh.vertices)[ids]
    return TriMesh(V, inv.reshape(-1, 3), validate=False), ids
