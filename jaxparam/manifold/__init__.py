"""Closed meshes of any genus (survey §9): a base domain by decimation, a global
parameterization over the base domain, and semi-regular remeshing.

Two routes (``manifold_map(..., method=)``):

- ``"maps"`` (the default; :mod:`~jaxparam.manifold.maps`, Lee et al. 1998, the survey's
  ref. [20]): the map is built *during* the decimation.  Each level collapses a set of
  half-edges whose one-rings do not meet; before a collapse its one-ring is flattened
  conformally, the collapse is allowed only when the new triangles are positive there, and
  every input vertex the ring holds is relocated in the new triangles.  No path is ever
  traced, so nothing can be blocked: on a closed, oriented, connected mesh it succeeds for
  every even ``base_faces`` from :func:`fewest_faces` up (the decimation drops its shape
  rules before it gives up).  The levels are kept (:class:`MapsHistory`), and the remesh
  runs them backwards, so each remesh vertex is the exact preimage of its base-domain point
  (the map is a bijection by construction).  Before the finest level, the remesh relaxes its
  samples in the base domain, across base edges and error-driven
  (:mod:`~jaxparam.manifold.relax`; ``remesh(levels, relax=False)`` turns it off).
- ``"paths"``: the method of Floater, Hormann and Reimers (ref. [11]) described below; it
  can fail with a :class:`~jaxparam.SolverError` where paths are walled off.

A mesh of several closed components: :func:`manifold_map_each`
(:mod:`~jaxparam.manifold.components`) parameterizes each over a base domain of its own.

The method of Floater, Hormann and Reimers (the survey's ref. [11]), in four steps, one
module each:

1. **Base domain** ``T^0`` (:func:`decimate`, :mod:`~jaxparam.manifold.decimate`):
   quadric-error half-edge collapses of the mesh until ``base_faces`` triangles remain.  A
   collapse keeps the surviving vertex where it is, so ``V^0 ⊂ V``; the link condition keeps
   the genus, and collapses that would turn a face over are refused.
2. **Surface edges** (:mod:`~jaxparam.manifold.paths`): every edge ``[v, w]`` of ``T^0``
   becomes a path along the mesh's edges between ``v`` and ``w``.  First the mesh is refined
   without moving its surface until the paths have room: 1-to-3 splits of the faces around
   base vertices with too few neighbours, then 1-to-4 splits of every face until there are
   40 vertices per base face.  The base edges are traced in Praun et al.'s order: a shortest
   spanning tree first, then the ``2g`` edges that complete a cut graph, then the rest, each
   group shortest first.  Each path is a shortest one that shares no vertex with the others
   but its ends and leaves and enters its base vertices in the sector between its
   neighbours in ``T^0``'s cyclic order, so the paths cut the surface into one disk, a
   *surface triangle*, per base triangle.
3. **Parameterization** (:mod:`~jaxparam.manifold.charts`): each base triangle is the
   reference triangle :data:`REFERENCE` ``(0, 0), (1, 0), (1/2, sqrt(3)/2)``; path vertices
   are placed on its sides by chord length, and the vertices inside each surface triangle by
   one convex-combination solve (eq. (4), mean value weights by default) for all surface
   triangles at once.  When a path is walled off by earlier ones, or the pieces or charts
   come out wrong, every face is split 1-to-4 again and steps 2 and 3 are retried (twice at
   most).
4. **Remesh** (:meth:`ManifoldParameterization.remesh`,
   :mod:`~jaxparam.manifold.parameterization`): the ``j``-fold dyadic refinement of ``T^0``,
   each vertex mapped to the surface through its base triangle's chart, as eq. (11); the
   result, a :class:`jaxparam.remesh.Remesh`, has subdivision connectivity and feeds
   :mod:`jaxparam.wavelets`.

**Differentiation.**  :func:`manifold_map` runs eagerly (its discrete stages need concrete
positions; traced vertices raise :class:`~jaxparam.MeshError`), and
:meth:`ManifoldParameterization.with_vertices` re-solves its charts for new positions of the
input's vertices with every discrete choice held fixed (:class:`ManifoldStructure`), so
``jax.grad(lambda V: loss(param.with_vertices(V).remesh(2).mesh.vertices))(V0)`` works.

Steps 1 and 2 are sequential by nature (one collapse, one path at a time) and run as
Python loops over collapses and paths; everything per vertex or per face is vectorized.
"""
from __future__ import annotations

from .charts import REFERENCE
from .components import ComponentMap, manifold_map_each, split_components
from .decimate import decimate
from .maps import MapsHistory, maps_decimate
from .parameterization import METHODS, ManifoldParameterization, ManifoldStructure, fewest_faces, manifold_map
from .report import ManifoldReport, check_closed_manifold, fidelity

__all__ = ["REFERENCE", "decimate", "maps_decimate", "MapsHistory", "METHODS", "ManifoldParameterization",
           "ManifoldStructure", "fewest_faces", "manifold_map", "ManifoldReport", "check_closed_manifold",
           "fidelity", "ComponentMap", "manifold_map_each", "split_components"]
