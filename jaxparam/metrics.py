"""Distortion reports, flips, boundary overlaps and Theorem 1's certificate.

Conventions of the scores (area-weighted means over the faces, using the 3D
face areas; ``s1 >= s2`` the singular values of each face's Jacobian):

- ``sym_dirichlet``: ``s1^2 + s2^2 + s1^-2 + s2^-2``; 4 for an isometry.
- ``mips``: ``s1/s2 + s2/s1`` (E2 of §6); 2 for a conformal map.
- ``max_aspect``: the largest ``s1/s2``.
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
           "boundary_overlaps", "theorem1", "refuse_traced"]


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
    boundary_overlaps: int
    sym_dirichlet: float
    mips: float
    max_aspect: float
    angle_distortion: float
    area_distortion: float
    unreferenced_vertices: int
    theorem1: Theorem1 | None = None

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
    itself; this counts such crossings (bounding boxes first, exact
    orientation tests after, in chunks).
    """
    refuse_traced("metrics.boundary_overlaps", mesh, uv, vertices=False)
    U = np.asarray(uv, np.float64)
    segs = []
    for loop in mesh.topology.boundary_loops:
        segs.append(np.stack([loop, np.roll(loop, -1)], 1))
    if not segs:
        return 0
    S = np.concatenate(segs)
    A, B = U[S[:, 0]], U[S[:, 1]]
    lo, hi = np.minimum(A, B), np.maximum(A, B)
    count = 0
    k = S.shape[0]
    chunk = max(1, 4_000_000 // max(k, 1))
    for s in range(0, k, chunk):
        i = np.arange(s, min(k, s + chunk))[:, None]
        j = np.arange(k)[None, :]
        mask = j > i
        mask &= (lo[i, 0] <= hi[j, 0]) & (lo[j, 0] <= hi[i, 0]) & (lo[i, 1] <= hi[j, 1]) & (lo[j, 1] <= hi[i, 1])
        ii, jj = np.nonzero(mask)
        ii = ii + s
        share = ((S[ii, 0] == S[jj, 0]) | (S[ii, 0] == S[jj, 1]) | (S[ii, 1] == S[jj, 0]) | (S[ii, 1] == S[jj, 1]))
        ii, jj = ii[~share], jj[~share]
        if ii.size == 0:
            continue
        def orient(p, q, r):
            return np.sign((q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0]))
        o1 = orient(A[ii], B[ii], A[jj])
        o2 = orient(A[ii], B[ii], B[jj])
        o3 = orient(A[jj], B[jj], A[ii])
        o4 = orient(A[jj], B[jj], B[ii])
        count += int(np.sum((o1 * o2 < 0) & (o3 * o4 < 0)))
    return count


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
        else:
            sd = mips = aspect = area_d = float("inf")
    ang = 0.5 * mips - 1 if np.isfinite(mips) else float("inf")
    t = mesh.topology
    cert = theorem1(mesh, uv, weights=weights) if t.boundary_loops else None
    return DistortionReport(
        # A face with a non-finite UV corner is no triangle: flipped and degenerate both.
        vertices=t.n_vertices, faces=t.n_faces, flips=int(np.sum(~(auv > 0))),
        degenerate=int(np.sum((auv == 0) | ~np.isfinite(auv))), boundary_overlaps=boundary_overlaps(mesh, uv),
        sym_dirichlet=sd, mips=mips, max_aspect=aspect, angle_distortion=float(ang),
        area_distortion=area_d, unreferenced_vertices=int((~t.referenced).sum()), theorem1=cert)
