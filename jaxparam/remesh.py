"""Remeshing with subdivision connectivity (survey §7, eq. (11), Definition 5).

A disk mesh ``S`` with a one-to-one parameterization ``psi`` (its UVs) is remeshed in three
steps:

1. a coarse *base domain* ``T^0``: a fan of triangles from the parameter domain's centre to
   ``corners`` points of its boundary polygon;
2. its ``j``-fold *dyadic refinement* ``T^j`` (every triangle split into four at its edge
   midpoints, Fig. 18); midpoints of boundary edges are moved onto the parameter domain's
   boundary (halfway along it between their two parents), so ``T^j`` covers the domain ever
   more closely while keeping subdivision connectivity of order ``j``;
3. every vertex ``v`` of ``T^j`` is mapped back to the surface, ``phi(v) = psi^{-1}(v)``
   (eq. (11)): located in the planar triangulation ``psi(S)`` and lifted with its
   barycentric coordinates.

Vertices are numbered level by level (``V^0 ⊂ V^1 ⊂ ... ⊂ V^j``), so the first ``n_l``
vertices of the remesh are those of ``T^l``; :class:`Hierarchy` keeps the counts and, for
each vertex new at a level, the two vertices whose edge it splits — everything
:mod:`jaxparam.wavelets` needs.

Topology is numpy; the lift (step 3) is a gather and a weighted sum, written in JAX so the
remesh is differentiable in the mesh's vertex positions.
"""
from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from .errors import MeshError, first_few
from .disk import disk_check
from .mesh import TriMesh
from .triangles import locate, signed_area2

#: The four children of a triangle ``(v1, v2, v3)`` in the dyadic refinement, as indices into
#: ``(v1, v2, v3, w1, w2, w3)`` (``w_i`` the midpoint of the edge opposite ``v_i``),
#: anticlockwise, corner children first; face ``f`` becomes faces ``4f .. 4f+3`` in this order.
CHILDREN = np.array([[0, 5, 4], [5, 1, 3], [4, 3, 2], [3, 4, 5]])


@dataclass(frozen=True, eq=False)
class Hierarchy:
    """The nested vertex sets of a mesh with subdivision connectivity.

    - ``counts``: ``(n_0, n_1, ..., n_j)`` vertex counts of ``T^0 ... T^j``;
    - ``parents``: ``parents[l]`` is ``(n_{l+1} - n_l, 2) int``: the endpoints of the edge of
      ``T^l`` that each vertex new in ``T^{l+1}`` splits;
    - ``faces``: ``faces[l]`` the ``(4^l m_0, 3)`` faces of ``T^l``.
    """

    counts: tuple
    parents: tuple
    faces: tuple

    @property
    def levels(self) -> int:
        return len(self.parents)


def dyadic_refine(faces: np.ndarray, n_vertices: int):
    """One dyadic refinement (the one-to-four split of §7, Fig. 18).

    **Arguments:** ``faces (m, 3) int`` anticlockwise, over ``n_vertices`` vertices.

    **Returns:** ``(faces (4m, 3), parents (e, 2), on_boundary (e,) bool)``: the new faces
    (anticlockwise; face ``f`` of the input becomes faces ``4f .. 4f+3``, corner children
    first), the two endpoints ``(p, q)`` of each input edge (vertex ``n_vertices + i`` is the
    midpoint of edge ``i``; ``p -> q`` runs along a face, anticlockwise), and whether the
    edge is on the boundary.
    """
    F = np.asarray(faces, np.int64)
    m = F.shape[0]
    # Edge opposite corner i: w_i = (v_{i+1} + v_{i+2}) / 2 (survey's w1, w2, w3).
    src, dst = F[:, [1, 2, 0]], F[:, [2, 0, 1]]
    key = (np.minimum(src, dst) * np.int64(n_vertices) + np.maximum(src, dst)).ravel()
    uniq, first, inverse, count = np.unique(key, return_index=True, return_inverse=True, return_counts=True)
    w = n_vertices + inverse.reshape(m, 3)
    parents = np.stack([src.ravel()[first], dst.ravel()[first]], axis=1)
    children = np.concatenate([F, w], axis=1)[:, CHILDREN]        # (m, 4, 3)
    return children.reshape(4 * m, 3), parents, count == 1


class _BoundaryCurve:
    """The parameter domain's boundary polygon, by arc length ``s`` in ``[0, L)``."""

    def __init__(self, points: np.ndarray):
        self.points = points
        seg = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
        self.cum = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self.cum[-1])

    def at(self, s: np.ndarray) -> np.ndarray:
        s = np.mod(s, self.length)
        i = np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self.points) - 1)
        t = (s - self.cum[i]) / np.maximum(self.cum[i + 1] - self.cum[i], 1e-300)
        return (1 - t)[:, None] * self.points[i] + t[:, None] * np.roll(self.points, -1, axis=0)[i]


def base_domain(uv: np.ndarray, loop: np.ndarray, corners: int | np.ndarray = 6):
    """The base domain ``T^0``: a fan from the centre of ``corners`` boundary points.

    **Arguments:** ``uv (n, 2)``; ``loop (b,)`` the boundary loop's vertices in order;
    ``corners`` a count (points evenly spaced by arc length along the boundary polygon,
    starting at ``loop[0]``) or increasing positions in ``loop`` (the vertices
    ``loop[corners]``).

    **Returns:** ``(uv0 (c+1, 2), faces0 (c, 3), s0 (c+1,), curve)``: the base vertices (the
    centre last), the fan (anticlockwise), each base vertex's arc-length position on the
    boundary (``nan`` for the centre) and the boundary polygon.
    """
    curve = _BoundaryCurve(np.asarray(uv, np.float64)[loop])
    if np.ndim(corners) == 0:
        c = int(corners)
        if c < 3:
            raise MeshError(f"remesh: the base domain needs at least 3 corners, got {c}.")
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


def refine_domain(uv0, faces0, s0, curve: _BoundaryCurve, levels: int):
    """``levels`` dyadic refinements of a base domain whose boundary vertices sit at arc
    lengths ``s0`` on ``curve``; new boundary vertices go onto the curve halfway between
    their parents.  **Returns:** ``(uv (n_j, 2), Hierarchy)``."""
    uv, F, s = np.asarray(uv0, np.float64), np.asarray(faces0, np.int64), np.asarray(s0, np.float64)
    L = curve.length
    counts, parents, faces = [uv.shape[0]], [], [F]
    for _ in range(levels):
        F, par, on_bnd = dyadic_refine(F, uv.shape[0])
        mid = 0.5 * (uv[par[:, 0]] + uv[par[:, 1]])
        s_new = np.full(par.shape[0], np.nan)
        if on_bnd.any():
            p, q = par[on_bnd, 0], par[on_bnd, 1]
            # Boundary half-edges p -> q run along an anticlockwise face; the curve may run
            # either way, so take the arc between s_p and s_q that is shorter than half.
            d = np.mod(s[q] - s[p] + 0.5 * L, L) - 0.5 * L
            s_new[on_bnd] = np.mod(s[p] + 0.5 * d, L)
            mid[on_bnd] = curve.at(s_new[on_bnd])
        uv = np.concatenate([uv, mid])
        s = np.concatenate([s, s_new])
        counts.append(uv.shape[0])
        parents.append(par)
        faces.append(F)
    return uv, Hierarchy(tuple(counts), tuple(parents), tuple(faces))


def remesh(mesh: TriMesh, uv, levels: int = 4, *, corners=6) -> TriMesh:
    """A remesh of a disk mesh with subdivision connectivity of order ``levels`` (§7).

    **Arguments:** ``mesh`` a disk; ``uv (n, 2)`` a one-to-one parameterization of it (e.g.
    :func:`jaxparam.convex_map`; a convex boundary such as ``"circle"`` or ``"square"``
    guarantees the base domain fits); ``levels`` the number of dyadic refinements;
    ``corners`` the base domain's boundary points: a count, evenly spaced, or increasing
    positions in the boundary loop, as :func:`jaxparam.convex_map` takes them (e.g. the four
    corners of a square map).

    **Returns:** a :class:`TriMesh` with ``corners * 4**levels`` faces whose vertices lie on
    the input surface (eq. (11)), numbered level by level; ``.uv`` the vertices' parameter
    points, ``.hierarchy`` a :class:`Hierarchy`, ``.base_faces`` the faces of ``T^0``.

    Example::

        uv = jp.convex_map(mesh, boundary="circle")
        semi = jp.remesh(mesh, uv, levels=4)
    """
    disk_check(mesh, "remesh")
    t = mesh.topology
    if len(t.boundary_loops) != 1:
        raise MeshError(f"remesh: the mesh has {len(t.boundary_loops)} boundary loops; remeshing "
                        "needs a disk (one boundary loop): fill the holes first.")
    if not (isinstance(levels, (int, np.integer)) and 0 <= levels <= 10):
        raise MeshError(f"remesh: levels must be an integer in [0, 10], got {levels!r}.")
    U = np.asarray(uv, np.float64)
    if U.shape != (mesh.n_vertices, 2) or not np.all(np.isfinite(U)):
        raise MeshError(f"remesh: uv must be a finite ({mesh.n_vertices}, 2) array, got shape {U.shape}.")
    flipped = np.flatnonzero(signed_area2(U, mesh.faces) <= 0)
    if flipped.size:
        raise MeshError(f"remesh: the parameterization is not one-to-one: faces {first_few(flipped)} "
                        "are flipped or degenerate in the UVs; use a convex-combination map.")
    uv0, F0, s0, curve = base_domain(U, t.boundary_loops[0], corners)
    uvj, H = refine_domain(uv0, F0, s0, curve, int(levels))
    bad = np.flatnonzero(signed_area2(uvj, H.faces[-1]) <= 0)
    if bad.size:
        raise MeshError(f"remesh: {bad.size} refined triangles fold over where the boundary bends "
                        f"(e.g. face {int(bad[0])}); use more corners or a convex boundary map.")
    face, bary = locate(U, mesh.faces, uvj)
    idx = jnp.asarray(mesh.faces[face])
    V = jnp.asarray(mesh.vertices)
    X = jnp.einsum("kc,kcd->kd", jnp.asarray(bary), V[idx])
    out = TriMesh(X, H.faces[-1], uv=uvj, validate=False, name="remesh")
    out.hierarchy = H
    out.base_faces = H.faces[0]
    return out


def hierarchy_from_faces(faces: np.ndarray, n_vertices: int) -> Hierarchy:
    """Recover the :class:`Hierarchy` of a mesh numbered as :func:`remesh` writes it (faces
    ``4f .. 4f+3`` the children of face ``f`` of the level above, in :func:`dyadic_refine`'s
    order; new vertices after old ones), e.g. one read back from an OBJ file.  Coarsens while
    every group of four faces is such a split.  Raises :class:`MeshError` when not even one
    level is found."""
    F = np.asarray(faces, np.int64)
    levels_faces = [F]
    while F.shape[0] % 4 == 0 and F.shape[0] > 0:
        c = F.reshape(-1, 4, 3)
        v1, v2, v3 = c[:, 0, 0], c[:, 1, 1], c[:, 2, 2]
        w1, w2, w3 = c[:, 1, 2], c[:, 0, 2], c[:, 0, 1]
        ok = (np.array_equal(c[:, 1, 0], w3) and np.array_equal(c[:, 2, 0], w2)
              and np.array_equal(c[:, 2, 1], w1) and np.array_equal(c[:, 3], np.stack([w1, w2, w3], 1)))
        parent = np.stack([v1, v2, v3], 1)
        if not ok or parent.max() >= np.stack([w1, w2, w3]).min():
            break
        levels_faces.append(parent)
        F = parent
    if len(levels_faces) == 1:
        raise MeshError("the mesh does not have subdivision connectivity in jaxparam's numbering "
                        "(each face split into four children, new vertices after old ones): make "
                        "it with jaxparam remesh / jp.remesh.")
    levels_faces.reverse()
    counts, parents = [int(levels_faces[0].max()) + 1], []
    for lv in range(len(levels_faces) - 1):
        Fc, par, _ = dyadic_refine(levels_faces[lv], counts[-1])
        if not np.array_equal(Fc, levels_faces[lv + 1]):
            raise MeshError(f"the mesh's level {lv + 1} is not numbered as jaxparam's dyadic "
                            "refinement numbers it (new vertices in edge order): make it with "
                            "jaxparam remesh / jp.remesh.")
        counts.append(counts[-1] + par.shape[0])
        parents.append(par)
    if counts[-1] != n_vertices:
        raise MeshError(f"the mesh has {n_vertices} vertices but its subdivision hierarchy has "
                        f"{counts[-1]}: unreferenced or extra vertices.")
    return Hierarchy(tuple(counts), tuple(parents), tuple(levels_faces))
