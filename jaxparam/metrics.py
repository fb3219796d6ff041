"""Distortion reports, flips, boundary overlaps and Theorem 1's certificate.

Conventions of the scores (area-weighted means over the faces, using the 3D
face areas; ``s1 >= s2`` the singular values of each face's Jacobian):

- ``sym_dirichlet``: ``s1^2 + s2^2 + s1^-2 + s2^-2``; 4 for an isometry.  On the map's own
  scale: a map onto the unit circle of a mesh 100 units across has tiny ``s`` and a huge
  value, so compare maps of different scales by
- ``sym_dirichlet_scaled``: the same with the UVs scaled so that their total area is the
  surface's (what the atlas benchmarks call E_sd, times 2); invariant under a scaling of the
  mesh or of the UVs.
- ``mips``: ``s1/s2 + s2/s1`` (E2 of §6); 2 for a conformal map.
- ``max_aspect``: the largest ``s1/s2``.
- ``collapsed``: faces not flipped whose ``s1/s2`` exceeds ``tol.COLLAPSED_ASPECT`` (1e6):
  numerically segments in the UVs, with no texels across.
- ``angle_distortion``: ``(s1/s2 + s2/s1)/2 - 1``; 0 for a conformal map.
- ``area_distortion``: ``(a + 1/a)/2 - 1`` with ``a = s1 s2`` rescaled so the
  UV and 3D total areas agree; 0 for an area-preserving map (up to scale).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .lazy_jax import jax, jnp  # JAX loads on first use (issue 17)
from . import boundary as bmap
from . import geometry as geo
from . import host
from . import weights as wts
from .errors import MeshError
from .io import as_mesh

__all__ = ["DistortionReport", "Theorem1", "distortion", "face_distortion", "flips",
           "boundary_overlaps", "boundary_crossings", "segment_box_pairs", "theorem1",
           "refuse_traced"]


@dataclass(frozen=True)
class Theorem1:
    """Theorem 1's sufficient conditions for a one-to-one convex-combination map.

    ``holds`` is True when the boundary polygon is convex, every weight is
    positive and no dividing edge (interior edge with both ends on the
    boundary) is mapped into the boundary.
    """

    convex_boundary: bool
    positive_weights: bool | None
    dividing_edges_ok: bool
    holds: bool
    negative_weights: int = 0
    dividing_edges_on_boundary: list = field(default_factory=list)


@dataclass(frozen=True)
class DistortionReport:
    """Summary of a UV map. See the module docstring for each score's definition."""

    vertices: int
    faces: int
    flips: int
    degenerate: int
    collapsed: int
    boundary_overlaps: int
    sym_dirichlet: float
    mips: float
    max_aspect: float
    angle_distortion: float
    area_distortion: float
    unreferenced_vertices: int
    theorem1: Theorem1 | None = None
    sym_dirichlet_scaled: float = float("nan")

    def to_dict(self) -> dict:
        d = asdict(self)
        return d


def refuse_traced(where: str, mesh, uv, *, vertices: bool = True) -> None:
    """Raise a :class:`MeshError` when ``uv`` (or, with ``vertices``, the mesh's vertices) is a
    JAX tracer: the reports and counts of this module are host floats and integers (not
    differentiable).  The counts that read only the UVs pass ``vertices=False``."""
    traced_v = vertices and isinstance(getattr(mesh, "vertices", None), jax.core.Tracer)
    if isinstance(uv, jax.core.Tracer) or traced_v:
        raise MeshError(
            f"{where}: not differentiable (a report of host floats and counts, computed in numpy) "
            "and it got a JAX tracer (under jax.grad, jax.jit or jax.vmap); differentiate "
            "jp.metrics.face_distortion(mesh, uv) (J, s1, s2 and the areas, in JAX) or an energy "
            "such as jp.ENERGIES['symmetric_dirichlet'](mesh, uv) instead, and call "
            f"{where} on concrete values.")


@jax.jit
def _face_quantities(V, F, uv):
    J = geo.jacobians(V, F, uv)
    s1, s2 = geo.singular_values(J)
    return {"J": J, "s1": s1, "s2": s2, "area3d": geo.face_areas(V, F),
            "area_uv": geo.signed_areas(uv, F)}


def face_distortion(mesh, uv) -> dict:
    """Per-face quantities: ``J (m, 2, 2)``, ``s1``, ``s2`` (signed), ``area3d``, ``area_uv`` (signed)."""
    return _face_quantities(jnp.asarray(mesh.vertices, dtype=jnp.float64), mesh.faces,
                            jnp.asarray(uv, dtype=jnp.float64))


def flips(mesh, uv) -> int:
    """Number of faces whose UV image is clockwise or degenerate (signed area <= 0, or not
    finite)."""
    refuse_traced("metrics.flips", mesh, uv, vertices=False)
    Q = np.asarray(uv, np.float64)[mesh.faces]
    d1, d2 = Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]
    return int(np.sum(~(0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) > 0)))   # nan: flipped


def boundary_overlaps(mesh, uv) -> int:
    """Number of pairs of non-adjacent boundary edges whose UV images intersect.

    Local injectivity does not prevent a free boundary from overlapping
    itself; this counts such crossings (:func:`boundary_crossings`).
    """
    refuse_traced("metrics.boundary_overlaps", mesh, uv, vertices=False)
    return int(boundary_crossings(mesh, uv)[1].shape[0])


def boundary_crossings(mesh, uv):
    """The boundary edges of ``mesh`` and which pairs of them cross in ``uv (n, 2)``.

    **Returns:** ``(segments (k, 2), pairs (p, 2))``: the boundary edges as vertex pairs,
    loop by loop (``mesh.topology.boundary_loops``), and the index pairs ``i < j`` of
    edges that share no vertex and properly cross (strict orientation tests; edges with
    a non-finite end cross nothing).  Candidates come from a uniform grid of about one
    edge length (:func:`segment_box_pairs`): the time grows with the edges, not with
    their square.
    """
    refuse_traced("metrics.boundary_crossings", mesh, uv, vertices=False)
    U = np.asarray(uv, np.float64)
    loops = mesh.topology.boundary_loops
    if not loops:
        return np.zeros((0, 2), np.int64), np.zeros((0, 2), np.int64)
    S = np.concatenate([np.stack([loop, np.roll(loop, -1)], 1) for loop in loops]).astype(np.int64)
    A, B = U[S[:, 0]], U[S[:, 1]]
    ii, jj = segment_box_pairs(np.minimum(A, B), np.maximum(A, B))
    share = ((S[ii, 0] == S[jj, 0]) | (S[ii, 0] == S[jj, 1]) | (S[ii, 1] == S[jj, 0])
             | (S[ii, 1] == S[jj, 1]))
    ii, jj = ii[~share], jj[~share]

    def orient(p, q, r):
        return np.sign((q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0]))

    cross = ((orient(A[ii], B[ii], A[jj]) * orient(A[ii], B[ii], B[jj]) < 0)
             & (orient(A[jj], B[jj], A[ii]) * orient(A[jj], B[jj], B[ii]) < 0))
    return S, np.stack([ii[cross], jj[cross]], 1)


def segment_box_pairs(lo, hi, *, max_pairs: int = 4_000_000):
    """Every pair ``i < j`` of boxes ``[lo, hi]`` (``(k, 2)`` each) that intersect (closed).

    The boxes are entered in the cells of a uniform grid they touch (cell side: the
    median box side, doubled while the entries exceed ``8 k``); two boxes that intersect
    share the cell of their intersection's lower corner, where the pair is counted (so
    once).  Boxes with a non-finite corner meet nothing.  Pairs are formed cell by cell,
    about ``max_pairs`` at a time.  **Returns:** ``(i, j)``, int arrays.
    """
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    ok = np.flatnonzero(np.all(np.isfinite(lo) & np.isfinite(hi), axis=1))
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    if ok.size < 2:
        return empty
    lo_k, hi_k = lo[ok], hi[ok]
    origin = lo_k.min(0)
    span = float(np.max(hi_k.max(0) - origin))
    h = max(float(np.median(np.max(hi_k - lo_k, axis=1))), 1e-9 * span, 1e-300)
    while True:
        c0 = np.floor((lo_k - origin) / h).astype(np.int64)
        c1 = np.floor((hi_k - origin) / h).astype(np.int64)
        size = c1 - c0 + 1
        cells = size[:, 0] * size[:, 1]
        if cells.sum() <= 8 * ok.size + 64:
            break
        h *= 2.0
    # one entry per (box, cell): cell x varies fastest within a box
    box = np.repeat(np.arange(ok.size), cells)
    r = np.arange(box.size) - np.repeat(np.cumsum(cells) - cells, cells)
    cx = c0[box, 0] + r % size[box, 0]
    cy = c0[box, 1] + r // size[box, 0]
    key = cx * (int(c1[:, 1].max()) + 1) + cy
    order = np.argsort(key, kind="stable")
    key, box = key[order], box[order]
    cx, cy = cx[order], cy[order]
    end = np.searchsorted(key, key, side="right")
    partners = end - np.arange(key.size) - 1
    out_i, out_j = [], []
    bounds = np.searchsorted(np.cumsum(partners), np.arange(0, partners.sum(), max_pairs),
                             side="right")
    bounds = np.unique(np.r_[0, bounds, key.size])
    for s, e in zip(bounds[:-1], bounds[1:]):
        cnt = partners[s:e]
        p = np.repeat(np.arange(s, e), cnt)
        q = p + 1 + (np.arange(p.size) - np.repeat(np.cumsum(cnt) - cnt, cnt))
        a, b = box[p], box[q]
        meet = ((np.maximum(lo_k[a, 0], lo_k[b, 0]) <= np.minimum(hi_k[a, 0], hi_k[b, 0]))
                & (np.maximum(lo_k[a, 1], lo_k[b, 1]) <= np.minimum(hi_k[a, 1], hi_k[b, 1])))
        # counted once: in the cell of the intersection's lower corner
        home = (np.maximum(c0[a, 0], c0[b, 0]) == cx[p]) & (np.maximum(c0[a, 1], c0[b, 1]) == cy[p])
        keep = meet & home
        a, b = a[keep], b[keep]
        out_i.append(ok[np.minimum(a, b)])
        out_j.append(ok[np.maximum(a, b)])
    return np.concatenate(out_i), np.concatenate(out_j)


def theorem1(mesh, uv, *, weights=None) -> Theorem1:
    """Check Theorem 1's conditions for ``uv`` (survey §3).

    **Arguments:** ``weights``: the convex-combination weights used (a kind
    name or ``(k,)`` values on the ring entries), or None when unknown (then
    ``positive_weights`` is None and ``holds`` only reflects the boundary).
    """
    refuse_traced("metrics.theorem1", mesh, uv, vertices=isinstance(weights, str))
    t = mesh.topology
    U = np.asarray(uv, np.float64)
    if not t.boundary_loops:
        return Theorem1(False, None, False, False)
    loop = t.boundary_loops[0]
    P = U[loop]
    convex = bmap.is_convex_polygon(P)
    pos = None
    neg = 0
    if weights is not None and t.interior.size == 0:
        pos = True      # no interior vertex, no weight: the map is the boundary map itself
    elif weights is not None:
        if isinstance(weights, str):
            # The sign check needs no compilation: the weights in NumPy (jaxparam.host).
            w, _ = wts.entry_weights(mesh.vertices, t, weights, host=True)
            R = wts.ring_entries(t)
            w = w / np.bincount(R.row, w, minlength=R.n_rows)[R.row]
        else:
            w = np.asarray(weights)
        neg = int(np.sum(w <= 0))
        pos = neg == 0
    # A dividing edge is mapped into the boundary when its midpoint lies on the polygon.
    bad = []
    D = t.dividing_edges
    on_outer = np.zeros(t.n_vertices, bool)
    on_outer[loop] = True
    D = D[on_outer[D[:, 0]] & on_outer[D[:, 1]]] if D.size else D
    if D.size:
        mid = 0.5 * (U[D[:, 0]] + U[D[:, 1]])
        A, B = P, np.roll(P, -1, axis=0)
        ab = B - A
        L = np.maximum(np.sum(ab * ab, 1), 1e-300)
        scale = np.max(np.ptp(P, axis=0))
        for chunk in np.array_split(np.arange(len(D)), max(1, len(D) // 2048)):
            m = mid[chunk][:, None, :]
            tt = np.clip(np.sum((m - A[None]) * ab[None], -1) / L[None], 0, 1)
            dist = np.linalg.norm(m - (A[None] + tt[..., None] * ab[None]), axis=-1).min(1)
            bad.extend([tuple(int(x) for x in D[c]) for c in chunk[dist <= 1e-9 * scale]])
    ok_div = len(bad) == 0
    holds = bool(convex and ok_div and (pos is True))
    return Theorem1(bool(convex), pos, ok_div, holds, neg, bad[:10])


def distortion(mesh, uv, *, weights=None) -> DistortionReport:
    """Distortion report of a UV map.

    **Arguments:** ``mesh`` a TriMesh, ``uv: (n, 2)``; ``weights`` as in
    :func:`theorem1` (adds the certificate to the report).

    Example::

        rep = jp.distortion(mesh, uv)
        rep.flips, rep.sym_dirichlet, rep.max_aspect

    Not differentiable (host floats and counts): a traced ``uv`` or mesh is refused with a
    :class:`MeshError` that names :func:`face_distortion`, whose ``J``, ``s1``, ``s2`` and
    areas are JAX and differentiable.
    """
    mesh = as_mesh(mesh, "distortion")
    refuse_traced("distortion", mesh, uv)
    if np.shape(uv) != (mesh.n_vertices, 2):
        raise MeshError(f"distortion: uv must have shape ({mesh.n_vertices}, 2), one row per "
                        f"vertex, got {np.shape(uv)}.")
    # Concrete values (always, here): the per-face quantities in NumPy, no compilation; equal
    # to face_distortion's JAX values to about 1e-15 relative (tests/test_speed_paths.py).
    fd = host.face_quantities(np.asarray(mesh.vertices, np.float64), mesh.faces,
                              np.asarray(uv, np.float64))
    s1 = np.asarray(fd["s1"])
    s2 = np.asarray(fd["s2"])
    a3 = np.asarray(fd["area3d"])
    auv = np.asarray(fd["area_uv"])
    ok = s2 > 0
    w = a3 / a3.sum()
    with np.errstate(divide="ignore", invalid="ignore"):
        if np.all(ok):
            sd = float(np.sum(w * (s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2)))
            mips = float(np.sum(w * (s1 / s2 + s2 / s1)))
            aspect = float(np.max(s1 / s2))
            scale = a3.sum() / auv.sum()
            a = s1 * s2 * scale
            area_d = float(np.sum(w * (0.5 * (a + 1 / a) - 1)))
            # the UVs scaled by sqrt(scale): s^2 -> scale s^2
            sd_scaled = float(np.sum(w * (scale * (s1 ** 2 + s2 ** 2) + (s1 ** -2 + s2 ** -2) / scale)))
        else:
            sd = mips = aspect = area_d = sd_scaled = float("inf")
    ang = 0.5 * mips - 1 if np.isfinite(mips) else float("inf")
    t = mesh.topology
    cert = theorem1(mesh, uv, weights=weights) if t.boundary_loops else None
    return DistortionReport(
        # A face with a non-finite UV corner is no triangle: flipped and degenerate both.
        vertices=t.n_vertices, faces=t.n_faces, flips=int(np.sum(~(auv > 0))),
        degenerate=int(np.sum((auv == 0) | ~np.isfinite(auv))),
        collapsed=int(np.sum(host.collapsed_faces(fd))),
        boundary_overlaps=boundary_overlaps(mesh, uv),
        sym_dirichlet=sd, mips=mips, max_aspect=aspect, angle_distortion=float(ang),
        area_distortion=area_d, unreferenced_vertices=int((~t.referenced).sum()), theorem1=cert,
        sym_dirichlet_scaled=sd_scaled)
