"""Surface reconstruction from unorganized points through their meshless parameterization
(survey §8): :func:`reconstruct_surface` and its result, :class:`Reconstruction`."""
from __future__ import annotations

from dataclasses import dataclass

import jax
import numpy as np

from .. import topology as topo
from ..clock import StageClock
from ..errors import PointCloudError
from ..memory import reuse_freed_memory
from ..mesh import TriMesh
from .boundary import detect_boundary
from .defaults import BRIDGE_FACTOR, FLIP_ROUNDS, GAP, K, K_DETECT, MAX_SLOPE
from .graph import point_graph_in_order, spatial_order
from .meshless import (check_boundary_indices, check_map_options, check_points, map_points,
                       symmetric_solve)
from .triangulation import (delaunay, flip_towards_3d_delaunay, largest_manifold_disk,
                            outside_bridges, peel_ears)

__all__ = ["Reconstruction", "reconstruct_surface"]


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """The result of :func:`reconstruct_surface`; every index is into the input points.

    **Fields** (``N`` input points):

    - ``mesh``: a :class:`~jaxparam.TriMesh` over all ``N`` input points, in their order
      (points left out of the disk, and merged duplicates, are unreferenced), carrying
      ``mesh.uv = uv``;
    - ``uv (N, 2)``: the meshless map's parameter point of every input point (a merged
      duplicate has the UV of the point it repeats);
    - ``boundary (b,) int``: the boundary polygon the map used (detected or given), as
      input indices in order (anticlockwise when detected);
    - ``points_used (u,) int``: the input points the faces reference, increasing;
    - ``seconds``: wall-clock seconds per stage, ``{"neighbours", "boundary" (when
      detected), "weights_and_solve", "delaunay", "flips" (when ``flip_rounds``),
      "peel_and_topology"}``.

    Example::

        rec = jp.reconstruct_surface(points)
        rec.mesh.faces, rec.uv, rec.boundary
    """

    mesh: TriMesh
    uv: np.ndarray
    boundary: np.ndarray
    points_used: np.ndarray
    seconds: dict


def reconstruct_surface(points, *, k: int = K, weights: str = "shape_preserving",
                        boundary: str = "circle", spacing: str = "chord",
                        boundary_indices=None, radius: float | None = None,
                        symmetric: bool = True, gap: float = GAP, merge_duplicates: bool = False,
                        max_slope: float = MAX_SLOPE, bridge_factor: float = BRIDGE_FACTOR,
                        flip_rounds: int = FLIP_ROUNDS, **unknown) -> Reconstruction:
    """Triangulate unorganized points ``(N, 3)`` through their meshless parameterization (§8).

    The meshless map (:func:`~jaxparam.points.meshless_map`, whose options ``k``,
    ``weights``, ``boundary``, ``spacing``, ``boundary_indices`` (input indices), ``radius``,
    ``symmetric``, ``gap``, ``merge_duplicates`` and ``max_slope`` it takes) uses
    shape-preserving weights unless ``weights`` says otherwise.  Delaunay triangulation of
    the parameter points, lifted to 3D, then made closer to a Delaunay triangulation *in
    3D*: an interior edge whose two opposite 3D angles sum to more than pi is flipped when
    both new triangles keep a positive area in the parameter plane (so the UVs stay
    one-to-one), for at most ``flip_rounds`` rounds of independent flips (0 turns this
    off).  Triangles on the outside whose longest 3D edge exceeds ``bridge_factor`` times
    the local point spacing (they bridge concave parts of the boundary) are peeled off,
    then the ears over boundary points the detection missed, and the largest manifold disk
    is kept.

    **Returns:** a :class:`Reconstruction` (``rec.mesh``, ``rec.uv``, ``rec.boundary``,
    ``rec.points_used``, ``rec.seconds``).  Raises :class:`PointCloudError` for an option
    it does not know.

    Example::

        rec = jp.reconstruct_surface(points)
        jp.distortion(rec.mesh, rec.uv).flips
    """
    if unknown:
        raise PointCloudError(f"reconstruct_surface: unknown options {sorted(unknown)}.")
    if isinstance(points, jax.core.Tracer):
        raise PointCloudError(
            "reconstruct_surface: not differentiable (Delaunay triangulation, edge flips and "
            "region growing are discrete) and it got a JAX tracer; differentiate "
            "jp.meshless_map(points, graph=..., boundary_indices=...) or the reconstructed mesh's "
            "own maps (e.g. jp.convex_map(jp.TriMesh(P, rec.mesh.faces))) instead.")
    weights, boundary, spacing = check_map_options("reconstruct_surface", weights, boundary, spacing)
    with reuse_freed_memory(np.shape(points)[0] if np.ndim(points) == 2 else 0):
        return _reconstruct(points, k=k, radius=radius, symmetric=symmetric, weights=weights,
                            boundary=boundary, spacing=spacing, gap=gap, user_bnd=boundary_indices,
                            merge=merge_duplicates, max_slope=max_slope,
                            bridge_factor=bridge_factor, flip_rounds=flip_rounds)


def _reconstruct(points, *, k, radius, symmetric, weights, boundary, spacing, gap, user_bnd, merge,
                 max_slope, bridge_factor, flip_rounds) -> Reconstruction:
    clock = StageClock()
    P0, kept, index = check_points(points, k=k, merge_duplicates=merge, return_index=True)
    n_in = index.size
    merged = kept.size != n_in
    # Everything below runs on the points in Morton order (neighbours close in memory: the
    # weights, the triangulation and the flips run 1.3-2x faster on a large shuffled cloud);
    # the result is renumbered to the input's order at the end.  ``kept[perm]`` names each
    # point here by its input index.
    perm = spatial_order(P0)
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.size)
    P = P0[perm]
    graph = point_graph_in_order(P, k, radius=radius, symmetric=symmetric, k_detect=K_DETECT,
                                 max_slope=max_slope, names=kept[perm])
    clock("neighbours")
    if user_bnd is None:
        bnd = detect_boundary(P, graph, gap=gap)
        clock("boundary")
    else:
        bnd = inv[check_boundary_indices("reconstruct_surface", user_bnd, n_in,
                                         index if merged else None)]
    U = np.asarray(map_points(P, graph, bnd, weights=weights, boundary=boundary, spacing=spacing,
                              symmetric=symmetric_solve(weights, symmetric, radius)))
    clock("weights_and_solve")
    F = delaunay(U)
    F = F[np.argsort(F.min(axis=1), kind="stable")]     # faces in the points' (Morton) order too
    clock("delaunay")
    if flip_rounds:
        F = flip_towards_3d_delaunay(F, P, U, flip_rounds)
        clock("flips")
    L = np.stack([np.linalg.norm(P[F[:, i]] - P[F[:, (i + 1) % 3]], axis=1) for i in range(3)], 1)
    local = graph.spacing[F].mean(1)
    too_long = L.max(1) > bridge_factor * local
    # Peel in one pass: the too-long faces connected to the outside through too-long faces.
    keep = ~outside_bridges(F, too_long, len(P))
    F = peel_ears(F[keep], P, graph)
    F, topology = largest_manifold_disk(F, len(P))
    if merged:                                           # onto all input points, copies unused
        name = kept[perm]
        topology = topo.build(name[topology.faces], n_in, where="reconstruct_surface")
        uv = U[inv][index]
    else:
        topology = topo.renumber(topology, perm)
        uv = U[inv]
    mesh = TriMesh(np.asarray(points, np.float64), None, topology, uv=uv, validate=False,
                   name="reconstruction")
    clock("peel_and_topology")
    return Reconstruction(mesh=mesh, uv=uv, boundary=kept[perm[bnd]],
                          points_used=np.flatnonzero(topology.referenced), seconds=clock.seconds)
