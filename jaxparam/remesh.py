"""Remeshing with subdivision connectivity (survey §7, eq. (11), Definition 5).

A disk mesh ``S`` with a one-to-one parameterization ``psi`` (its UVs) is remeshed in three
steps:

1. a coarse *base domain* ``T^0``: a fan of ``base_faces`` triangles from the parameter
   domain's centre to as many points of its boundary polygon (:func:`base_domain`);
2. its ``j``-fold *dyadic refinement* ``T^j`` (every triangle split into four at its edge
   midpoints, Fig. 18; :mod:`jaxparam.subdivision`); midpoints of boundary edges are moved
   onto the parameter domain's boundary (halfway along it between their two parents), so
   ``T^j`` covers the domain ever more closely while keeping subdivision connectivity of
   order ``j`` (:func:`refine_domain`);
3. every vertex ``v`` of ``T^j`` is mapped back to the surface, ``phi(v) = psi^{-1}(v)``
   (eq. (11)): located in the planar triangulation ``psi(S)`` and lifted with its
   barycentric coordinates.

Without a given ``psi`` the map is :func:`area_aware_map`: Sander et al.'s L2 stretch (survey
ref. [27]) minimized flip-free inside the unit circle (above 40k faces Yoshizawa et al.'s
reweighted convex maps, :mod:`jaxparam.stretch_map`), so the dyadic grid samples the surface
by area, then (up to 200k faces) reweighted where the remesh is still far from the input
(:func:`level_errors`); ``errors=True`` measures each level's distance (:class:`RemeshErrors`).

Vertices are numbered level by level (``V^0 ⊂ V^1 ⊂ ... ⊂ V^j``), so the first ``n_l``
vertices of the remesh are those of ``T^l``; the result, a :class:`Remesh`, carries the
:class:`~jaxparam.subdivision.Hierarchy` (the counts and, for each vertex new at a level,
the two vertices whose edge it splits): everything :mod:`jaxparam.wavelets` needs.

Topology is numpy; the lift (step 3) is a gather and a weighted sum, written in JAX so the
remesh is differentiable in the mesh's vertex positions.  When the UVs are traced too (``uv =
jp.convex_map(mesh)`` inside ``jax.grad``), the sample points (steps 1-2) and their barycentric
coordinates are recomputed in JAX from the UVs, so the derivative also follows the sample points
as the parameter domain moves; the discrete choices (which face holds each sample point, which
boundary segment each boundary sample point lies on) are made on the concrete values and held
fixed (see :func:`remesh`).
"""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .errors import MeshError, first_few
from .disk import check_remesh_input
from . import geometry
from .distance import point_triangle_distance, surface_distance
from .energies import ENERGIES, density_stretch
from .linear import check_unfolded, convex_map
from .mesh import TriMesh, concrete_values
from .io import as_mesh
from .optimize import Newton, Problem, StopRules, minimize
from .subdivision import CHILDREN, Hierarchy, dyadic_hierarchy, dyadic_refine, hierarchy_from_faces  # noqa: F401
from .triangles import barycentric, locate, signed_area2
from .progress import progress
from .stretch_map import STRETCH_MAP_ITERS, Reweighting, reweighted_stretch_map

__all__ = ["Remesh", "RemeshErrors", "remesh", "check_remesh_input", "area_aware_map", "area_map_iters",
           "measure_errors",
           "default_samples", "level_errors", "base_domain", "refine_domain", "snap_boundary",
           "BoundaryCurve"]


@dataclass(frozen=True, eq=False)
class RemeshErrors:
    """How far each level of a remesh lies from its input surface: what :func:`remesh`
    measures (``Remesh.errors``) and ``jaxparam remesh --report`` writes.

    Every distance is relative to the input's bounding-box diagonal; one entry per level
    ``0 .. j`` (level ``l`` is the mesh ``S^l = phi(T^l)``: the first ``n_l`` vertices and
    ``hierarchy.faces[l]``).  Measured by :func:`jaxparam.distance.surface_distance`:
    ``samples`` area-weighted random points on each surface plus its vertices, each with its
    exact distance to the other mesh (k-d tree, vectorized).

    - ``levels``: ``(0, 1, ..., j)``;
    - ``hausdorff_ab``: the largest distance from the input to the remesh (``_ba``: from the
      remesh to the input); ``rms_ab``/``rms_ba``: the root-mean-square distances;
    - ``diagonal``: the input's bounding-box diagonal (mesh units); ``samples``; ``seed``.
    """

    levels: tuple
    hausdorff_ab: tuple
    hausdorff_ba: tuple
    rms_ab: tuple
    rms_ba: tuple
    diagonal: float
    samples: int
    seed: int

    @property
    def hausdorff(self) -> tuple:
        """Per level, the symmetric Hausdorff distance (the larger way), relative."""
        return tuple(max(a, b) for a, b in zip(self.hausdorff_ab, self.hausdorff_ba))

    @property
    def rms(self) -> tuple:
        """Per level, the larger of the two RMS distances, relative."""
        return tuple(max(a, b) for a, b in zip(self.rms_ab, self.rms_ba))

    def as_dict(self) -> dict:
        """Plain numbers for a JSON report: one list per field, the symmetric values too."""
        return {"levels": list(self.levels), "hausdorff": list(self.hausdorff),
                "hausdorff_ab": list(self.hausdorff_ab), "hausdorff_ba": list(self.hausdorff_ba),
                "rms": list(self.rms), "rms_ab": list(self.rms_ab), "rms_ba": list(self.rms_ba),
                "diagonal": self.diagonal, "samples": self.samples, "seed": self.seed,
                "relative_to": "input bounding-box diagonal"}


@jax.tree_util.register_pytree_node_class
@dataclass(frozen=True, eq=False, repr=False)
class Remesh:
    """A mesh with subdivision connectivity and its hierarchy: what :func:`remesh` and
    :meth:`jaxparam.manifold.ManifoldParameterization.remesh` return, what
    :mod:`jaxparam.wavelets` analyses.

    - ``mesh``: the :class:`TriMesh` ``S^j = phi(T^j)``, vertices numbered level by level;
      for a disk remesh ``mesh.uv`` holds the vertices' parameter points (``T^j``'s
      vertices), for a closed one it is ``None``;
    - ``hierarchy``: its :class:`~jaxparam.subdivision.Hierarchy` (``hierarchy.faces[0]``
      the base domain ``T^0``);
    - ``errors``: a :class:`RemeshErrors`, each level's distance from the input surface
      (``None`` when not measured: ``remesh(..., errors=False)``, traced vertices, a closed
      remesh, or after :meth:`with_vertices`).

    A JAX pytree: ``mesh`` is the leaf (its vertices and UVs), the hierarchy and the errors
    static data, so a remesh passes through ``jax.jit``, ``jax.grad`` and
    ``jax.tree_util.tree_map`` whole.
    """

    mesh: TriMesh
    hierarchy: Hierarchy
    errors: RemeshErrors | None = None

    @property
    def uv(self):
        """``(n_j, 2)``: the vertices' parameter points (``mesh.uv``; ``None`` when closed)."""
        return self.mesh.uv

    @property
    def base_faces(self) -> np.ndarray:
        """``(m_0, 3)``: the faces of the base domain ``T^0``."""
        return self.hierarchy.faces[0]

    @property
    def levels(self) -> int:
        """The order ``j`` of the subdivision connectivity."""
        return self.hierarchy.levels

    def level_mesh(self, level: int) -> TriMesh:
        """The level-``level`` remesh ``S^l``: the first ``n_l`` vertices and
        ``hierarchy.faces[l]`` (no UVs)."""
        if not 0 <= int(level) <= self.levels:
            raise MeshError(f"Remesh.level_mesh: level must be in [0, {self.levels}], got {level!r}.")
        n = self.hierarchy.counts[int(level)]
        return TriMesh(self.mesh.vertices[:n], self.hierarchy.faces[int(level)], validate=False,
                       name=f"remesh level {int(level)}")

    def __repr__(self) -> str:
        return (f"Remesh({self.mesh!r}, {self.base_faces.shape[0]} base faces, "
                f"{self.levels} levels)")

    def with_vertices(self, vertices) -> "Remesh":
        """The same remesh (connectivity, UVs, hierarchy) with new vertex positions (its
        ``errors`` no longer apply: ``None``)."""
        return Remesh(self.mesh.with_vertices(vertices), self.hierarchy)

    def tree_flatten(self):
        return (self.mesh,), (self.hierarchy, self.errors)

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls(children[0], *aux)


def default_samples(mesh: TriMesh, semi: Remesh) -> int:
    """Points per surface for :func:`measure_errors`: 10 per face of the larger of the input
    and the finest remesh, between 2,000 and 50,000."""
    return int(min(50_000, max(2_000, 10 * max(mesh.n_faces, semi.mesh.n_faces))))


def measure_errors(mesh: TriMesh, semi: Remesh, *, samples: int | None = None,
                   seed: int = 0) -> RemeshErrors:
    """Each level's Hausdorff (both ways) and RMS distance between the input ``mesh`` and the
    remesh ``semi``, relative to the input's bounding-box diagonal (a :class:`RemeshErrors`).

    ``samples`` area-weighted points per surface and level (plus the vertices; default
    :func:`default_samples`), ``seed`` fixed; vertices must have values (not traced under
    ``jax.jit``).

    Example::

        e = jp.remesh(mesh, levels=5, errors=True).errors
        e = measure_errors(mesh, semi, samples=200_000)
        e.hausdorff[-1], e.rms[-1]
    """
    V = concrete_values(mesh.vertices)
    X = concrete_values(semi.mesh.vertices)
    if V is None or X is None:
        raise MeshError("remesh errors: the vertex positions are traced without values (inside "
                        "jax.jit); measure outside it.")
    samples = default_samples(mesh, semi) if samples is None else int(samples)
    cols = {"hausdorff_ab": [], "hausdorff_ba": [], "rms_ab": [], "rms_ba": []}
    d = None
    for lv in progress(range(semi.levels + 1), desc="remesh errors", unit="level"):
        n = semi.hierarchy.counts[lv]
        d = surface_distance(V, mesh.faces, X[:n], semi.hierarchy.faces[lv], samples=samples,
                             seed=seed)
        for k in cols:
            cols[k].append(float(getattr(d, k)))
    return RemeshErrors(tuple(range(semi.levels + 1)), *(tuple(cols[k]) for k in cols),
                        float(d.diagonal), int(samples), int(seed))


class BoundaryCurve:
    """The parameter domain's boundary polygon ``points (b, 2)``, by arc length ``s`` in ``[0, L)``."""

    def __init__(self, points: np.ndarray):
        self.points = points
        seg = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
        self.cum = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self.cum[-1])

    def segment(self, s: np.ndarray):
        """``(s mod L (k,), i (k,) int)``: the arc lengths ``s (k,)`` taken modulo the length,
        and the polygon segment ``points[i] -> points[i + 1]`` each lies on."""
        s = np.mod(s, self.length)
        return s, np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self.points) - 1)

    def at(self, s: np.ndarray) -> np.ndarray:
        """``(k, 2)``: the points at arc lengths ``s (k,)`` (taken modulo the length)."""
        s, i = self.segment(s)
        t = (s - self.cum[i]) / np.maximum(self.cum[i + 1] - self.cum[i], 1e-300)
        return (1 - t)[:, None] * self.points[i] + t[:, None] * np.roll(self.points, -1, axis=0)[i]


def _wraps(s_raw: np.ndarray, s: np.ndarray, length: float) -> np.ndarray:
    """The integers ``n`` with ``s = s_raw - n * length`` (``s`` a ``np.mod`` of ``s_raw``)."""
    return np.rint((s_raw - s) / length)


class _CurveJax:
    """The boundary polygon of traced UVs ``U[loop]``, in JAX: the counterpart of
    :class:`BoundaryCurve` whose discrete choices (segment of each point, wraps of the arc
    length) are taken from a :class:`BoundaryCurve` of the concrete values."""

    def __init__(self, U, loop):
        self.P = U[jnp.asarray(loop)]
        self.Pn = jnp.roll(self.P, -1, axis=0)
        d = self.Pn - self.P
        self.cum = jnp.concatenate([jnp.zeros(1, self.P.dtype), jnp.cumsum(jnp.sqrt(jnp.sum(d * d, 1)))])
        self.length = self.cum[-1]

    def at(self, s, n, i):
        """The points at arc lengths ``s - n L`` on the segments ``i`` (``n``, ``i`` numpy)."""
        s = s - jnp.asarray(n) * self.length
        t = (s - self.cum[i]) / jnp.maximum(self.cum[i + 1] - self.cum[i], 1e-300)
        return (1 - t)[:, None] * self.P[i] + t[:, None] * self.Pn[i]


def base_domain(uv: np.ndarray, loop: np.ndarray, corners: int | np.ndarray = 6):
    """The base domain ``T^0``: a fan from the centre of ``corners`` boundary points.

    **Arguments:** ``uv (n, 2)``; ``loop (b,)`` the boundary loop's vertices in order;
    ``corners`` a count (points evenly spaced by arc length along the boundary polygon,
    starting at ``loop[0]``; the fan then has as many faces) or increasing positions in
    ``loop`` (the vertices ``loop[corners]``).

    **Returns:** ``(uv0 (c+1, 2), faces0 (c, 3), s0 (c+1,), curve)``: the base vertices (the
    centre last), the fan (anticlockwise), each base vertex's arc-length position on the
    boundary (``nan`` for the centre) and the boundary polygon, a :class:`BoundaryCurve`.
    """
    curve = BoundaryCurve(np.asarray(uv, np.float64)[loop])
    if np.ndim(corners) == 0:
        c = int(corners)
        if c < 3:
            raise MeshError(f"remesh: the base domain needs at least 3 corners (base faces), got {c}.")
        s = curve.length * np.arange(c) / c
    else:
        pos = np.asarray(corners)
        if (pos.ndim != 1 or pos.size < 3 or not np.issubdtype(pos.dtype, np.integer)
                or pos.min() < 0 or pos.max() >= len(loop) or np.any(np.diff(pos) <= 0)):
            raise MeshError(f"remesh: corners must be >= 3 increasing positions in the boundary loop "
                            f"of {len(loop)} vertices (as convex_map's corners), got {pos.tolist()}.")
        s = curve.cum[pos]
        c = pos.size
    pts = curve.at(s)
    centre = pts.mean(0)
    uv0 = np.concatenate([pts, centre[None]])
    faces0 = np.stack([np.arange(c), (np.arange(c) + 1) % c, np.full(c, c)], axis=1)
    area = signed_area2(uv0, faces0)
    if np.all(area < 0):                       # the loop runs clockwise in the plane
        faces0 = faces0[:, [1, 0, 2]]
        area = -area
    if np.any(area <= 0):
        raise MeshError(f"remesh: the base fan has {int(np.sum(area <= 0))} inverted triangles: the "
                        "parameter domain is not star-shaped from the corners' centre; use a convex "
                        "boundary map (circle, square).")
    return uv0, faces0, np.concatenate([s, [np.nan]]), curve


def refine_domain(uv0, faces0, s0, curve: BoundaryCurve, levels: int):
    """``levels`` dyadic refinements of a base domain whose boundary vertices sit at arc
    lengths ``s0`` on ``curve``; new boundary vertices go onto the curve halfway between
    their parents.  **Returns:** ``(uv (n_j, 2), Hierarchy)``."""
    uv, H, _, _ = _refine(uv0, faces0, s0, curve, levels)
    return uv, H


def _refine(uv0, faces0, s0, curve: BoundaryCurve, levels: int):
    """:func:`refine_domain`, also returning per level the discrete choices that
    :func:`_refine_jax` repeats: ``(p, q, n_half, n_new, n_at, seg)`` for the new boundary
    vertices (parents, the wraps of the half arc, of the new arc length and of the point
    lookup, the polygon segment), and every vertex's arc length ``s (n_j,)`` (``nan``
    inside)."""
    uv, s = np.asarray(uv0, np.float64), np.asarray(s0, np.float64)
    H = dyadic_hierarchy(faces0, uv.shape[0], levels)
    L = curve.length
    steps = []
    for par, on_bnd in zip(H.parents, H.on_boundary):
        mid = 0.5 * (uv[par[:, 0]] + uv[par[:, 1]])
        s_new = np.full(par.shape[0], np.nan)
        p, q = par[on_bnd, 0], par[on_bnd, 1]
        # Boundary half-edges p -> q run along an anticlockwise face; the curve may run
        # either way, so take the arc between s_p and s_q that is shorter than half.
        x = s[q] - s[p] + 0.5 * L
        d = np.mod(x, L) - 0.5 * L
        y = s[p] + 0.5 * d
        s_b = np.mod(y, L)
        s_at, seg = curve.segment(s_b)
        if on_bnd.any():
            s_new[on_bnd] = s_b
            mid[on_bnd] = curve.at(s_b)
        steps.append((p, q, _wraps(x, d + 0.5 * L, L), _wraps(y, s_b, L), _wraps(s_b, s_at, L), seg))
        uv = np.concatenate([uv, mid])
        s = np.concatenate([s, s_new])
    return uv, H, steps, s


def _refine_jax(uv0, s0, curve: _CurveJax, H: Hierarchy, steps):
    """:func:`_refine` on traced base points ``uv0`` and arc lengths ``s0`` (JAX; the
    interior vertices' ``s0`` entries are unused), with its discrete choices ``steps``."""
    uv, s, L = uv0, s0, curve.length
    for par, on_bnd, (p, q, n_half, n_new, n_at, seg) in zip(H.parents, H.on_boundary, steps):
        mid = 0.5 * (uv[par[:, 0]] + uv[par[:, 1]])
        s_new = jnp.zeros(par.shape[0], uv.dtype)
        if on_bnd.any():
            d = s[q] - s[p] + 0.5 * L - jnp.asarray(n_half) * L - 0.5 * L
            s_b = s[p] + 0.5 * d - jnp.asarray(n_new) * L
            b = np.flatnonzero(on_bnd)
            s_new = s_new.at[b].set(s_b)
            mid = mid.at[b].set(curve.at(s_b, n_at, seg))
        uv = jnp.concatenate([uv, mid])
        s = jnp.concatenate([s, s_new])
    return uv


def _sample_points_jax(uv, loop, fan, s0, curve: BoundaryCurve, H: Hierarchy, steps):
    """The sample points ``T^j`` (``(n_j, 2)``, JAX) as functions of traced UVs: the base
    corners on the boundary polygon ``uv[loop]``, their centre, the refinement; each point's
    polygon segment and arc-length wraps are those of the concrete computation."""
    cj = _CurveJax(uv, loop)
    c = H.counts[0] - 1
    if np.ndim(fan) == 0:
        s_raw = cj.length * jnp.arange(c) / c
    else:
        s_raw = cj.cum[np.asarray(fan)]
    s_at, seg = curve.segment(s0[:c])
    pts = cj.at(s_raw, _wraps(s0[:c], s_at, curve.length), seg)
    uv0 = jnp.concatenate([pts, jnp.mean(pts, axis=0, keepdims=True)])
    return _refine_jax(uv0, jnp.concatenate([s_raw, jnp.zeros(1, s_raw.dtype)]), cj, H, steps)


def snap_boundary(uvj: np.ndarray, s: np.ndarray, curve: BoundaryCurve, faces: np.ndarray):
    """Boundary sample points moved onto the input's boundary vertices, so that the remesh's
    boundary passes through the input's boundary corners instead of cutting them.

    **Arguments:** ``uvj (n_j, 2)`` the sample points, ``s (n_j,)`` their arc lengths on
    ``curve`` (``nan`` inside), ``faces`` the finest faces (to check for folds).

    Each input boundary vertex ``k`` (at arc length ``curve.cum[k]``) takes the boundary
    sample nearest it by arc length; a sample claimed by several keeps the nearest.  A sample
    moves by at most half the gap to a neighbour, so the boundary's order is kept; if a
    refined triangle would fold all the same, nothing moves.

    **Returns:** ``(uv (n_j, 2), idx (k,), pos (k,))``: the moved points and which samples
    ``idx`` went onto which boundary polygon vertices ``pos`` (positions in the loop).
    """
    bidx = np.flatnonzero(np.isfinite(s))
    L = curve.length
    if bidx.size < 3 or not L > 0:
        return uvj, np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.argsort(s[bidx], kind="stable")
    bidx, ss = bidx[order], s[bidx][order]
    c = curve.cum[:-1]
    j = np.searchsorted(ss, c) % ss.size                 # the sample at or after each vertex
    i = (j - 1) % ss.size                                # the one before
    d_j = np.abs(np.mod(ss[j] - c + 0.5 * L, L) - 0.5 * L)
    d_i = np.abs(np.mod(ss[i] - c + 0.5 * L, L) - 0.5 * L)
    near = np.where(d_j <= d_i, j, i)
    dist = np.minimum(d_j, d_i)
    pick = np.lexsort((dist, near))                      # by sample, nearest first
    first = np.concatenate([[True], near[pick][1:] != near[pick][:-1]])
    pos = pick[first]
    idx = bidx[near[pos]]
    out = uvj.copy()
    out[idx] = curve.points[pos]
    if np.any(signed_area2(out, faces) <= 0):
        return uvj, np.zeros(0, np.int64), np.zeros(0, np.int64)
    return out, idx.astype(np.int64), pos.astype(np.int64)


#: Newton steps of the default area-aware map (:func:`area_aware_map`) on meshes of up to
#: :data:`AREA_MAP_FULL_FACES` faces: the stretch drops by > 99 % of its excess within about
#: 10-15 steps on the shared disk meshes; later steps change the remesh error by under 1 %.
AREA_MAP_ITERS = 25
#: Above this many faces the default map is :func:`jaxparam.stretch_map.reweighted_stretch_map`
#: (camelhead x16, level 6: 0.74 % of the diagonal against 6.0 % for 3 Newton steps, 14 s
#: against 86 s); where Newton still runs there (a given ``max_iters`` or ``weights``, another
#: energy, traced under ``jax.jit``) its steps fall as ``AREA_MAP_ITERS * FULL / faces``.
AREA_MAP_FULL_FACES = 40_000
AREA_MAP_MIN_ITERS = 3
#: Rounds of error-driven reweighting when :func:`area_aware_map` is given ``levels`` (as
#: :func:`remesh` and ``jaxparam remesh`` give it) up to :data:`AREA_MAP_FULL_FACES` faces, and
#: the Newton steps of each: camelhead, level 6, 0.66 -> 0.12 % of the diagonal.
AREA_MAP_ROUNDS = 4
AREA_MAP_ROUND_ITERS = 10
#: From :data:`AREA_MAP_FULL_FACES` to this many faces, :data:`REWEIGHTED_ROUNDS` error-driven
#: rounds of one :class:`~jaxparam.stretch_map.Reweighting` solve each (camelhead x4, level 6:
#: 0.795 -> 0.136 %); none above (at 363k they would pass twice the convex map's time).
REWEIGHTED_ROUNDS_MAX_FACES = 200_000
REWEIGHTED_ROUNDS = 12


def area_map_iters(n_faces: int) -> int:
    """The default Newton step count of :func:`area_aware_map` for a mesh of ``n_faces``."""
    scaled = AREA_MAP_ITERS * AREA_MAP_FULL_FACES // max(int(n_faces), 1)
    return int(min(AREA_MAP_ITERS, max(AREA_MAP_MIN_ITERS, scaled)))


def _stretch_newton(mesh, uv0, areas, iters: int) -> np.ndarray:
    """Projected Newton (closed-form singular-value Hessians) on ``sum areas * stretch``
    from ``uv0 (n, 2)``, its boundary fixed: the free UVs after at most ``iters`` steps."""
    prob = Problem(mesh, ENERGIES["stretch"], False, uv0, areas=areas)
    res = Newton().run(prob, StopRules(max_iters=int(iters)), verbose=None)
    return np.array(prob.uv(res.x))


def level_errors(mesh: TriMesh, uv, levels: int, corners=6) -> np.ndarray:
    """``(m,)``: for each input face, the larger distance (mesh units) between it and the
    level-``levels`` remesh through ``uv``: from its vertices to the remesh, and from the
    centres of the remesh faces nearest it to the input (exact point-triangle distances)."""
    semi = remesh(mesh, uv, levels, corners=corners)
    V, F = np.asarray(mesh.vertices, np.float64), mesh.faces
    X, G = np.asarray(semi.mesh.vertices), semi.mesh.faces
    e = np.asarray(point_triangle_distance(V, X, G)[0])[F].max(1)
    d, face, _ = point_triangle_distance(X[G].mean(1), V, F)
    np.maximum.at(e, np.asarray(face), np.asarray(d))
    return e


def area_aware_map(mesh: TriMesh, *, energy="density_stretch", max_iters: int | None = None,
                   weights: str = "shape_preserving", levels: int | None = None, corners=6,
                   boundary: str = "circle"):
    """The default parameterization of :func:`remesh`: one that samples by area.

    A convex-combination map (``weights``, the boundary on the unit circle by chord length, or
    on ``boundary``, e.g. ``"square"``: the remesh's base fan needs a convex domain),
    then a flip-free minimization (projected Newton, at most ``max_iters`` steps; default
    :func:`area_map_iters`: 25 up to 40k faces, fewer above) of ``energy`` with that boundary
    fixed.  By default Sander et al.'s L2 stretch (survey ref. [27]) weighted by the input's
    face density (:func:`jaxparam.energies.density_stretch`: every face counts the same):
    the stretch grows without bound where a triangle is small in the plane for its area on
    the surface (the squeeze that a convex-combination map gives the parts of a mesh far
    from its centre, which leaves the remesh's dyadic grid too few samples there), and the
    weight gives the regions that the input resolves finely (a scan's detail) more parameter
    area.  That default is solved as the plain stretch with per-face weights (the same
    minimizer; closed-form projected Hessians instead of per-face automatic ones).  Above
    :data:`AREA_MAP_FULL_FACES` faces (``max_iters`` and ``weights`` not given, vertex values
    known) it is approximated by :func:`jaxparam.stretch_map.reweighted_stretch_map`: maps
    whose weights are divided where the last one stretches, each one Cholesky factorization
    of ``n`` unknowns where a Newton step factorizes ``2n`` (flip-free by Tutte's theorem;
    differentiable with its reweighting factors held fixed).

    With ``levels`` (what :func:`remesh` passes, with its ``corners``) the default energy then
    samples where the error is: :data:`AREA_MAP_ROUNDS` rounds each measure every input face's
    distance to the level-``levels`` remesh (:func:`level_errors`), multiply the weights of the
    faces above 0.3 times the largest by ``(e / (0.3 max e)) ** 2`` (spread to their
    neighbours) and take :data:`AREA_MAP_ROUND_ITERS` more Newton steps (above 40k faces, up to
    :data:`REWEIGHTED_ROUNDS_MAX_FACES`: :data:`REWEIGHTED_ROUNDS` rounds of one reweighted map
    each); the map with the smallest largest error is returned (the first one included).

    **Arguments:** ``mesh`` a disk; ``energy`` ``"density_stretch"``, another name of
    ``jp.energies.ENERGIES`` or a :class:`jaxparam.Energy` (measured on camelhead at level 6,
    the remesh's Hausdorff error is 0.54 % of the diagonal with ``"density_stretch"``, 0.12 %
    with it and ``levels=6``, 0.98 % with ``"stretch"``, 1.37 % with
    ``"symmetric_dirichlet"``, 7.8 % with the plain convex map); ``levels``, ``corners``: the
    remesh to sample for (see below; ``None``: no reweighting).

    **Returns:** ``uv (n, 2)``, one-to-one (every step is flip-free), boundary on the unit
    circle (or ``boundary``); differentiable in ``mesh.vertices`` (the implicit gradient of the minimization of
    :func:`~jaxparam.energies.density_stretch` on the whole mesh, when they are traced).

    Example::

        uv = area_aware_map(mesh, levels=5)
        semi = jp.remesh(mesh, uv, levels=5)      # the same as jp.remesh(mesh, levels=5)
    """
    default = isinstance(energy, str) and energy == "density_stretch"
    if (default and max_iters is None and weights == "shape_preserving" and boundary == "circle"
            and mesh.n_faces > AREA_MAP_FULL_FACES and np.all(mesh.topology.referenced)
            and concrete_values(mesh.vertices) is not None):
        if levels is None or mesh.n_faces > REWEIGHTED_ROUNDS_MAX_FACES:
            return reweighted_stretch_map(mesh)   # no Newton: one Cholesky per round
        # the rounds on the values; traced vertices (jax.grad) get the chosen map's factors
        traced = isinstance(mesh.vertices, jax.core.Tracer)
        V = TriMesh(concrete_values(mesh.vertices), mesh.faces, mesh.topology, validate=False) if traced else mesh
        rw = Reweighting(V)
        best = _sample_where_the_error_is(V, rw.rounds(STRETCH_MAP_ITERS), np.mean(rw.area) / rw.area,
                                          int(levels), corners, lambda uv, w: rw.reweighted(w),
                                          REWEIGHTED_ROUNDS)
        return reweighted_stretch_map(mesh, factors=rw.factors_of(best)) if traced else best
    iters = area_map_iters(mesh.n_faces) if max_iters is None else int(max_iters)
    start = convex_map(mesh, weights=weights, boundary=boundary)
    if mesh.topology.interior.size == 0:    # every vertex on the circle: nothing to minimize
        return start
    check_unfolded(mesh, start, weights, "area_aware_map")
    if default and not isinstance(mesh.vertices, jax.core.Tracer):
        V = np.asarray(mesh.vertices, np.float64)
        area = np.asarray(geometry.face_areas(V, mesh.faces))
        weight = np.mean(area) / np.maximum(area, 1e-300)        # density_stretch's (A / mean)^-1
        uv = _stretch_newton(mesh, np.asarray(start), area * weight, iters=iters)
        if levels is not None and mesh.n_faces <= AREA_MAP_FULL_FACES:
            uv = _sample_where_the_error_is(
                mesh, uv, weight, int(levels), corners,
                lambda uv, w: _stretch_newton(mesh, uv, area * w, AREA_MAP_ROUND_ITERS), AREA_MAP_ROUNDS)
        uv[~mesh.topology.referenced] = np.nan
        return uv
    if default:
        areas = geometry.face_areas(jax.lax.stop_gradient(jnp.asarray(mesh.vertices)), mesh.faces)
        energy = density_stretch(jnp.mean(areas))
    res = minimize(mesh, energy, init=start, free_boundary=False, solver="newton",
                   max_iters=iters, verbose=None)      # a bar when it lasts (jp.config.progress)
    return res.uv


def _sample_where_the_error_is(mesh, uv, weight, levels: int, corners, step, rounds: int) -> np.ndarray:
    """:func:`area_aware_map`'s ``rounds`` of error-driven reweighting (see there) from ``uv``
    and face weights ``weight (m,)``; ``step(uv, weight) -> uv`` the map under new weights."""
    F = mesh.faces
    best, best_e = uv, np.inf
    for r in range(rounds + 1):
        e = level_errors(mesh, uv, levels, corners)
        if e.max() < best_e:
            best, best_e = uv, float(e.max())
        if r == rounds or not best_e > 0:
            return best
        m = np.maximum(1.0, e / (0.3 * e.max())) ** 2
        at_v = np.zeros(mesh.n_vertices)
        np.maximum.at(at_v, F.ravel(), np.repeat(m, 3))
        weight = weight * at_v[F].mean(1)
        uv = step(uv, weight)
    return best


def remesh(mesh: TriMesh, uv=None, levels: int = 4, *, base_faces: int = 6, corners=None,
           errors: bool = False, samples: int | None = None) -> Remesh:
    """A remesh of a disk mesh with subdivision connectivity of order ``levels`` (§7).

    **Arguments:**

    - ``mesh`` a disk; ``uv (n, 2)`` a one-to-one parameterization of it (e.g.
      :func:`jaxparam.convex_map`; a convex boundary such as ``"circle"`` or ``"square"``
      guarantees the base domain fits); by default (``None``) the area-aware map of
      :func:`area_aware_map` (circle boundary, L2 stretch minimized flip-free, reweighted
      convex maps above 40k faces; up to 200k faces reweighted where this level's remesh is
      far from the input), which samples the surface by area instead of squeezing its far parts;
    - ``levels`` the number of dyadic refinements;
    - ``base_faces`` the number of base triangles: the fan's corners, evenly spaced by arc
      length along the boundary from its first vertex (the same name as
      :func:`jaxparam.manifold_map`'s);
    - ``corners`` instead of ``base_faces`` (an alias that also takes positions): a count
      (the same as ``base_faces``) or increasing positions in the boundary loop, as
      :func:`jaxparam.convex_map` takes them (e.g. the four corners of a square map);
    - ``errors`` measure each level's distance from the input (Hausdorff both ways and RMS,
      relative to the input's bounding-box diagonal; :func:`measure_errors` with ``samples``
      points per surface, default :func:`default_samples`; ``jaxparam remesh --report``
      turns it on): ``.errors`` of the result; ``None`` when ``False`` (the default: the
      measurement takes longer than the remesh) or when the vertices are traced.

    **Returns:** a :class:`Remesh`: ``.mesh`` a :class:`TriMesh` with ``base_faces *
    4**levels`` faces whose vertices lie on the input surface (eq. (11)), numbered level by
    level, ``.mesh.uv`` (also ``.uv``) their parameter points; ``.hierarchy`` a
    :class:`~jaxparam.subdivision.Hierarchy`; ``.base_faces`` the faces of ``T^0``;
    ``.errors`` a :class:`RemeshErrors`.

    **Differentiable** in ``mesh.vertices`` and in ``uv``, under ``jax.grad`` and ``jax.jvp``
    (not under ``jax.jit`` or ``jax.vmap`` when ``uv`` is traced: point location runs on the
    host and needs the UVs' values, and the :class:`~jaxparam.subdivision.Hierarchy` is static
    data; a traced ``mesh.vertices`` with concrete UVs is fine under ``jit``).  A remesh vertex
    is ``X_k = sum_c b_kc(uv) V[F[f_k, c]]``: the barycentric coordinates ``b`` of the sample
    point ``q_k`` in its face's UV triangle, taken with the vertices of that face.  With
    concrete UVs only ``V`` moves.  With traced UVs (``uv = jp.convex_map(mesh)`` inside
    ``jax.grad``, or any UVs you differentiate in) ``b`` and the sample points ``q_k`` are
    recomputed in JAX from ``uv``: the base corners on the boundary polygon ``uv[loop]`` (at
    their arc lengths, evenly spaced fractions of its length, or its vertices ``loop[corners]``),
    the fan's centre (their mean), the edge midpoints and the new boundary points halfway along
    the polygon by arc length; ``.mesh.uv`` is then that JAX array.  **Held fixed** (chosen on
    the concrete values, piecewise constant in them): the face ``f_k`` holding each sample point
    (:func:`jaxparam.triangles.locate`, coordinates clipped to ``>= 0`` as there), the polygon
    segment each boundary sample point lies on, the integer wraps of the arc length modulo the
    polygon's length, and the base fan's orientation and the hierarchy.  The derivative is the
    exact derivative of the map wherever those choices do not change under a small move; at the
    UVs where one does (a sample point on a UV edge, a boundary point on a polygon vertex) it is
    a one-sided one.

    Example::

        semi = jp.remesh(mesh, levels=6, errors=True)   # area-aware map by default
        semi.errors.hausdorff[-1]                       # level 6's distance / diagonal
        uv = jp.convex_map(mesh, boundary="circle")
        semi = jp.remesh(mesh, uv, levels=4, base_faces=6)
        jp.save("semi.obj", semi.mesh)          # with the parameter points as vt

        def loss(V):                             # gradient also through the sample points
            m = jp.TriMesh(V, mesh.faces)
            return jnp.sum(jp.remesh(m, jp.convex_map(m), levels=3).mesh.vertices[:, 2] ** 2)
        jax.grad(loss)(mesh.vertices)
    """
    mesh = as_mesh(mesh, "remesh")
    check_remesh_input(mesh, levels, base_faces=base_faces, corners=corners)
    fan = base_faces if corners is None else corners
    t = mesh.topology
    if uv is None:
        uv = area_aware_map(mesh, levels=int(levels), corners=fan)   # reweighted for this remesh
    traced = isinstance(uv, jax.core.Tracer)
    U = concrete_values(uv)
    if U is None:
        raise MeshError("remesh: the UVs are traced without a value (inside jax.jit or jax.vmap); "
                        "remesh locates the sample points on the host from the UVs' values: call "
                        "it outside jax.jit (jax.grad and jax.jvp are fine), or pass concrete UVs.")
    if U.shape != (mesh.n_vertices, 2):
        hint = (f" (the levels are the third argument: jp.remesh(mesh, levels={uv!r}))"
                if U.shape == () and isinstance(uv, (int, np.integer)) else "")
        raise MeshError(f"remesh: uv must be a finite ({mesh.n_vertices}, 2) array (one UV per vertex), "
                        f"got shape {U.shape}{hint}.")
    # Vertices in no face carry no UV (jp.convex_map gives them nan): only the used ones count.
    used = np.zeros(mesh.n_vertices, bool)
    used[np.asarray(mesh.faces).ravel()] = True
    nonfinite = np.flatnonzero(used & ~np.all(np.isfinite(U), axis=1))
    if nonfinite.size:
        raise MeshError(f"remesh: uv is not finite at vertices {first_few(nonfinite)} (vertex "
                        f"{int(nonfinite[0])} has {tuple(U[nonfinite[0]])}); pass finite UVs for "
                        "every vertex of a face.")
    if not used.all():
        U = np.where(used[:, None], U, U[used][0])
    flipped = np.flatnonzero(~(signed_area2(U, mesh.faces) > 0))
    if flipped.size:
        on_loop = np.zeros(mesh.n_vertices, bool)
        on_loop[t.boundary_loops[0]] = True
        if np.all(on_loop[np.asarray(mesh.faces)[flipped]]):
            why = ("every corner of these faces is on the boundary, and the boundary map put "
                   "each face's three corners on one straight side of its polygon (Theorem 1's "
                   "dividing edges): use the circle boundary (boundary='circle', the default)")
        else:
            why = "use a convex-combination map with a convex boundary"
        raise MeshError(f"remesh: the parameterization is not one-to-one: faces {first_few(flipped)} "
                        f"are flipped or degenerate in the UVs; {why}.")
    loop = t.boundary_loops[0]
    uv0, F0, s0, curve = base_domain(U, loop, fan)
    uvj, H, steps, s_all = _refine(uv0, F0, s0, curve, int(levels))
    bad = np.flatnonzero(signed_area2(uvj, H.faces[-1]) <= 0)
    if bad.size:
        raise MeshError(f"remesh: {bad.size} refined triangles fold over where the boundary bends "
                        f"(e.g. face {int(bad[0])}); use more corners or a convex boundary map.")
    uvj, snap_idx, snap_pos = snap_boundary(uvj, s_all, curve, H.faces[-1])
    face, bary = locate(U, mesh.faces, uvj)
    idx = mesh.faces[face]
    V = jnp.asarray(mesh.vertices, jnp.float64)
    if traced:
        # The same sample points and coordinates as functions of the traced UVs (the located
        # faces, segments and wraps held fixed), clipped and normalized as locate does.
        uvj = _sample_points_jax(uv, loop, fan, s0, curve, H, steps)
        if snap_idx.size:
            uvj = uvj.at[jnp.asarray(snap_idx)].set(uv[jnp.asarray(loop[snap_pos])])
        b = jnp.maximum(barycentric(uv[jnp.asarray(idx)], uvj, xp=jnp), 0.0)
        bary = b / jnp.sum(b, axis=1, keepdims=True)
    X = jnp.einsum("kc,kcd->kd", jnp.asarray(bary, jnp.float64), V[jax.device_put(idx)])
    semi = Remesh(TriMesh(X, H.faces[-1], uv=uvj, validate=False, name="remesh"), H)
    if errors and not isinstance(X, jax.core.Tracer):
        semi = Remesh(semi.mesh, H, measure_errors(mesh, semi, samples=samples))
    return semi
