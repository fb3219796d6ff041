"""Surface reconstruction from unorganized points through their meshless parameterization
(survey §8): :func:`reconstruct_surface` and its result, :class:`Reconstruction`."""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import jax
import numpy as np
from scipy.spatial import cKDTree

from .. import topology as topo
from ..clock import StageClock
from ..progress import StageBar
from ..errors import PointCloudError, first_few
from ..memory import reuse_freed_memory
from ..mesh import TriMesh
from ..options import is_integer, is_number
from ..topology import half_edge_twins
from .boundary import detect_boundary
from .defaults import (BRIDGE_FACTOR, CHORD_ROUNDS, FLIP_ROUNDS, GAP, HOLE_FACES, HOLE_INRADIUS,
                       HOLE_REFERENCE_POINTS, HOLE_SHARE, K, K_DETECT, K_FRAME, MAX_SLOPE,
                       OUTLIER_ROUNDS)
from .graph import (Frames, global_frame, nearest_neighbours, point_graph_in_order, refresh_frames,
                    robust_frames, unreachable)
from .outliers import drop_points, find_outliers
from .smoothing import SMOOTHING, smooth_points
from .squeeze import SQUEEZED_SHARE, SqueezedMapWarning, squeeze_message, squeezed_share
from .meshless import (check_boundary_indices, check_gap, check_map_options, check_points,
                       map_points, symmetric_solve)
from .triangulation import (delaunay, flip_towards_3d_delaunay, interior_holes,
                            largest_manifold_disk, lone_points, long_faces, longest_edges,
                            onto_chords, outside_bridges, peel_ears)

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
      input indices in order (anticlockwise when detected), with the interior points the map
      put on one of its chords inserted there
      (:func:`~jaxparam.points.triangulation.onto_chords`);
    - ``points_used (u,) int``: the input points the faces reference, increasing;
    - ``outliers (o,) int``: the input points found far from the surface their neighbours
      define (:func:`~jaxparam.points.outliers.find_outliers`), increasing; left out of the
      map and the faces (their ``uv`` is that of their nearest kept point), and the points
      whose every Delaunay face bridges far beyond the spacing (they keep the map's ``uv``);
    - ``seconds``: wall-clock seconds per stage, ``{"neighbours", "boundary" (when
      detected), "weights_and_solve", "delaunay", "flips" (when ``flip_rounds``),
      "peel_and_topology"}`` ("neighbours" includes the outlier test and the smoothing);
    - ``squeezed``: the share of the map's Delaunay triangles whose share of the parameter
      domain is below 1/1000 of their share of the 3D area (:mod:`~jaxparam.points.squeeze`);
      above 0.2 the points seem to sample a closed surface (open scans measured 0-0.12,
      closed ones 0.30-0.99): a detected boundary's map is then refused
      (:class:`PointCloudError`), the user's ``boundary_indices``' returned with a
      :class:`~jaxparam.points.squeeze.SqueezedMapWarning`;
    - ``holes``: the holes of the mesh (its boundary loops less the outer one), opened where
      the scan has holes (``reconstruct_surface(..., holes=True)``, the default).

    Example::

        rec = jp.reconstruct_surface(points)
        rec.mesh.faces, rec.uv, rec.boundary
    """

    mesh: TriMesh
    uv: np.ndarray
    boundary: np.ndarray
    points_used: np.ndarray
    seconds: dict
    outliers: np.ndarray
    squeezed: float
    holes: int


def reconstruct_surface(points, *, k: int = K, weights: str = "shape_preserving",
                        boundary: str = "circle", spacing: str = "chord",
                        boundary_indices=None, radius: float | None = None,
                        symmetric: bool = True, gap: float = GAP, merge_duplicates: bool = False,
                        max_slope: float = MAX_SLOPE, bridge_factor: float = BRIDGE_FACTOR,
                        flip_rounds: int = FLIP_ROUNDS, outliers: bool = True,
                        holes: bool = True, smooth: str | None = None, verbose: bool | None = None,
                        **unknown) -> Reconstruction:
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
    is kept.  ``holes``: such long faces inside the surface open a hole where they span an
    empty disk whose edge points see an angular gap larger than ``gap`` (a hole in the scan:
    :func:`~jaxparam.points.triangulation.interior_holes` with ``HOLE_SHARE``,
    ``HOLE_INRADIUS`` (widened for large sets) and ``HOLE_FACES``); the mesh is then a disk
    with holes, its UVs still one-to-one (``holes=False`` bridges them, as a disk).

    An interior point that the map puts on a chord of the boundary polygon (a boundary point
    the detection missed) would get a face of zero parameter area: it joins the polygon
    between the chord's ends and the map is solved again.

    Scans: points far from the plane of their ``K_FRAME`` nearest neighbours are outliers
    (``outliers=True``): reported in ``rec.outliers``, left out of the mesh, the other points
    keep their indices.  The test needs ``OUTLIER_MIN_NEIGHBOURS`` (8) neighbours per point:
    sets of at most 8 points keep all of theirs.  When the outliers leave ``k`` points or
    fewer, each remaining point takes all the others as neighbours; when they leave fewer than
    4, :class:`PointCloudError`.  ``smooth`` moves the vertices onto a fitted surface to cut
    noise: ``"mls"`` (a weighted quadratic height field over each point's robust tangent plane,
    evaluated at the point) or ``"plane"`` (onto that plane); by default (``None``) the
    mesh's vertices are the input points, in their order.

    ``verbose``: a progress bar over the stages (None: as ``jp.config.progress`` says; it
    shows for runs longer than a second).

    **Returns:** a :class:`Reconstruction` (``rec.mesh``, ``rec.uv``, ``rec.boundary``,
    ``rec.points_used``, ``rec.seconds``).  Raises :class:`PointCloudError`, before any work,
    for an option it does not know or a value out of its range (``gap`` in ``(0, 2 pi)``,
    ``bridge_factor > 1``, ``flip_rounds >= 0``).

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
    check_gap("reconstruct_surface", gap)
    if not (is_number(bridge_factor) and bridge_factor > 1.0):
        raise PointCloudError("reconstruct_surface: bridge_factor (how many local spacings a "
                              "face's longest edge may span before it counts as a bridge) must be "
                              f"a number above 1, got {bridge_factor!r}; the default is "
                              f"{BRIDGE_FACTOR}.")
    if not (is_integer(flip_rounds) and flip_rounds >= 0):
        raise PointCloudError("reconstruct_surface: flip_rounds (rounds of 3D Delaunay edge "
                              f"flips; 0 turns them off) must be an integer >= 0, got "
                              f"{flip_rounds!r}.")
    if smooth not in SMOOTHING:
        raise PointCloudError(f"reconstruct_surface: smooth must be one of {SMOOTHING}, got {smooth!r}.")
    with reuse_freed_memory(np.shape(points)[0] if np.ndim(points) == 2 else 0):
        return _reconstruct(points, k=k, radius=radius, symmetric=symmetric, weights=weights,
                            boundary=boundary, spacing=spacing, gap=gap, user_bnd=boundary_indices,
                            merge=merge_duplicates, max_slope=max_slope,
                            bridge_factor=bridge_factor, flip_rounds=flip_rounds,
                            outliers=outliers, holes=holes, smooth=smooth, verbose=verbose)


def _reconstruct(points, *, k, radius, symmetric, weights, boundary, spacing, gap, user_bnd, merge,
                 max_slope, bridge_factor, flip_rounds, outliers, holes, smooth,
                 verbose) -> Reconstruction:
    clock = StageClock()
    mark = StageBar(clock, total=6, desc="reconstruct_surface", verbose=verbose)
    P0, kept, index, perm = check_points(points, k=k, merge_duplicates=merge, return_index=True,
                                         return_order=True)
    n_in = index.size
    merged = kept.size != n_in
    # Everything below runs on the points in Morton order (neighbours close in memory: the
    # weights, the triangulation and the flips run 1.3-2x faster on a large shuffled cloud);
    # the result is renumbered to the input's order at the end.  ``kept[perm]`` names each
    # point here by its input index.
    P = P0[perm]                       # perm: spatial_order(P0)
    order = perm                       # the rows of P0 in the working order
    user = None
    if user_bnd is not None:
        user = check_boundary_indices("reconstruct_surface", user_bnd, n_in, index if merged else None)
    near = None
    gone = []                          # (outliers, their neighbours), rows of P0, per round
    if radius is None:
        kq = min(max(k, K_DETECT, K_FRAME) + 4, len(P) - 1)
        dist, near = nearest_neighbours(P, kq)
        # One best-fit normal for the frames' signs (an SVD of all points: 0.16 s at 1M), also
        # for the rows refreshed after outliers leave: the signs are provisional, the
        # orientation below makes them consistent whatever they are.
        towards = global_frame(P)[2]
        frames = robust_frames(P, near[:, :K_FRAME], towards=towards)
        protect = np.zeros(len(P0), bool)            # the user's boundary points stay
        if user is not None:
            protect[user] = True
        # Up to OUTLIER_ROUNDS rounds: outliers close to each other hide each other in the first.
        for _ in range(OUTLIER_ROUNDS if outliers else 0):
            bad = find_outliers(P, frames, dist[:, :K_FRAME], near[:, :K_FRAME]) & ~protect[order]
            if not bad.any():
                break
            left = len(P) - int(bad.sum())
            if left < 4:
                raise PointCloudError(
                    "reconstruct_surface: the outlier test finds points "
                    f"{first_few(np.sort(kept[order[bad]]))} far from the surface their "
                    f"neighbours define, leaving {left} of the {n_in} points; a surface needs at "
                    "least 4: the points may not sample a surface, or pass outliers=False to "
                    "keep them all.")
            # Each outlier's neighbours, nearest first (input rows): its nearest kept point
            # is the first of them that stays (its UV below, without a tree over all points).
            gone.append((order[bad], order[near[bad]]))
            keep_k = min(max(k, K_DETECT, K_FRAME), left - 1)
            sub, P, dist, near, changed = drop_points(P, dist, near, bad, keep_k)
            order = order[sub]
            # Only the points that lost a neighbour get new frames.
            frames = refresh_frames(P, near[:, :K_FRAME], Frames(*(getattr(frames, f)[sub] for f in (
                "normal", "e1", "e2", "height", "noise", "radius"))), changed, towards=towards)
        if smooth is not None:
            P = smooth_points(P, near[:, :K_FRAME], frames, smooth)
            frames = robust_frames(P, near[:, :K_FRAME])
    elif smooth is not None:
        raise PointCloudError("reconstruct_surface: smooth needs k nearest neighbours, not radius.")
    # The outliers gone, fewer than k + 1 points may remain (12 points, k = 10, two outliers):
    # then every remaining point is a neighbour of every other.
    k = min(k, len(P) - 1)
    where = np.full(len(P0), -1, np.int64)            # P0 row -> working index (-1: outlier)
    where[order] = np.arange(order.size)
    graph = point_graph_in_order(P, k, radius=radius, symmetric=symmetric, k_detect=K_DETECT,
                                 max_slope=max_slope, names=kept[order],
                                 nearest=None if near is None else (dist, near),
                                 frames=None if near is None else frames)
    mark("neighbours")
    if user is None:
        bnd = detect_boundary(P, graph, gap=gap)
        mark("boundary")
    else:
        bnd = where[user]
    cut_off = unreachable(graph, bnd)
    if cut_off.any() and max_slope < 1:
        # Clusters that dropping steep pairs cut off from the boundary (a few points at the
        # tip of a thin part): they keep their steep pairs, so that eq. (4) stays solvable.
        graph = point_graph_in_order(P, k, radius=radius, symmetric=symmetric, k_detect=K_DETECT,
                                     max_slope=max_slope, names=kept[order],
                                     nearest=None if near is None else (dist, near),
                                     frames=None if near is None else frames, exempt=cut_off)
    def solve(bnd):
        sym = symmetric_solve(weights, symmetric, radius)
        return np.asarray(map_points(P, graph, bnd, weights=weights, boundary=boundary,
                                     spacing=spacing, symmetric=sym, host=True))

    U = solve(bnd)
    # Interior points the map put on a chord of the boundary polygon (Delaunay would give them
    # a face of zero area over it): boundary points the detection missed; they join the
    # polygon and the map is solved again.
    for _ in range(CHORD_ROUNDS):
        grown = onto_chords(U, bnd)
        if grown is None:
            break
        bnd = grown
        U = solve(bnd)
    mark("weights_and_solve")
    F = delaunay(U)
    F = F[np.argsort(F.min(axis=1), kind="stable")]     # faces in the points' (Morton) order too
    squeezed = squeezed_share(F, P, U)
    if squeezed > SQUEEZED_SHARE and user is None:
        # A detected boundary that leaves most of the surface squeezed is no boundary: going on
        # would drop thousands of points as "outliers" of bridging faces (session 27, camel_b).
        raise PointCloudError(squeeze_message(squeezed, bnd.size, n_in, detected=True))
    if squeezed > SQUEEZED_SHARE:
        warnings.warn(squeeze_message(squeezed, bnd.size, n_in), SqueezedMapWarning, stacklevel=3)
    mark("delaunay")
    twin = None                        # the faces' half-edge twins, once known (the flips keep them)
    if flip_rounds:
        F, twin = flip_towards_3d_delaunay(F, P, U, flip_rounds, return_twin=True)
        mark("flips")
    longest = longest_edges(F, P)
    too_long = long_faces(F, P, graph.spacing, bridge_factor, longest=longest)
    late = (lone_points(F, long_faces(F, P, graph.spacing, 2 * bridge_factor, np.min, longest=longest),
                        len(P), bnd)
            if outliers else np.zeros(0, np.int64))
    del longest
    if late.size:
        # Points whose every face is longer than twice the bridge length (of the smallest
        # vertex spacing): outliers the neighbourhood test missed, alone or in pairs.  Triangulate again without them (their UVs stay; they stay unused).
        rest = np.setdiff1d(np.arange(len(P)), late)
        F = rest[delaunay(U[rest])]
        F = F[np.argsort(F.min(axis=1), kind="stable")]
        twin = None
        if flip_rounds:
            F, twin = flip_towards_3d_delaunay(F, P, U, flip_rounds, return_twin=True)
        too_long = long_faces(F, P, graph.spacing, bridge_factor)
    # Peel in one pass: the too-long faces connected to the outside through too-long faces.
    twin = half_edge_twins(F, len(P)) if twin is None else twin
    keep = ~outside_bridges(F, too_long, len(P), twin=twin)
    if holes and graph.detect_gap is not None:
        widen = np.sqrt(max(np.log(len(P)) / np.log(HOLE_REFERENCE_POINTS), 1.0))
        keep &= ~interior_holes(F, P, too_long & keep, graph.detect_gap > gap, graph.spacing,
                                share=HOLE_SHARE, inradius=HOLE_INRADIUS * widen,
                                faces=HOLE_FACES, twin=twin)
    keep = peel_ears(F, P, graph, twin=twin, alive=keep, return_mask=True)
    name = kept[order]                                   # working index -> input index
    dropped = np.flatnonzero(where < 0)                  # outliers, as rows of P0 (not mapped)
    # Without merged copies the outliers' rows follow the working points' (unreferenced), so
    # that the input numbering is a permutation: renumber, not build (a third of its cost).
    F, topology = largest_manifold_disk(F, len(P) if merged else len(P0), twin=twin, alive=keep)
    del twin
    U0 = np.empty((len(P0), 2))
    U0[order] = U
    if dropped.size:                                     # an outlier gets its nearest kept point's UV
        U0[dropped] = U[_nearest_kept(P, P0, dropped, where, gone if smooth is None else [])]
    if merged:                                           # onto all input points, copies unused
        topology = topo.build(name[topology.faces], n_in, where="reconstruct_surface")
    else:                                                # working rows, then the outliers' rows
        topology = topo.renumber(topology, np.concatenate([order, dropped]))
    uv = U0[index] if merged else U0
    V = np.array(points, np.float64)
    if smooth is not None:                               # moved points (copies with their first)
        V0 = P0.copy()
        V0[order] = P
        V = V0[index]
    mesh = TriMesh(V, None, topology, uv=uv, validate=False, name="reconstruction")
    mark("peel_and_topology")
    mark.close()
    return Reconstruction(mesh=mesh, uv=uv, boundary=name[bnd],
                          points_used=np.flatnonzero(topology.referenced), seconds=clock.seconds,
                          outliers=np.sort(np.concatenate([kept[dropped], name[late]])),
                          squeezed=squeezed, holes=max(len(topology.boundary_loops) - 1, 0))


def _nearest_kept(P: np.ndarray, P0: np.ndarray, dropped: np.ndarray, where: np.ndarray,
                  gone: list) -> np.ndarray:
    """``(d,)`` the working index of the kept point (``P (M, 3)``) nearest to each dropped
    row ``dropped (d,)`` of ``P0``: the first kept one of the neighbours recorded in ``gone``
    (``[(rows (r,), neighbours (r, q))]``, nearest first, rows of ``P0``; ``where`` maps a row
    of ``P0`` to its working index, -1 when dropped), else a tree query over ``P``."""
    out = np.full(dropped.size, -1, np.int64)
    if gone:
        rows = np.concatenate([g[0] for g in gone])
        q = min(g[1].shape[1] for g in gone)
        cand = where[np.concatenate([g[1][:, :q] for g in gone])]       # (r, q), -1: dropped
        ok = cand >= 0
        first = np.argmax(ok, axis=1)
        slot = np.full(P0.shape[0], -1, np.int64)
        slot[rows] = np.where(ok.any(1), cand[np.arange(rows.size), first], -1)
        out = slot[dropped]
    miss = out < 0
    if miss.any():
        out[miss] = cKDTree(P).query(P0[dropped[miss]], 1, workers=-1)[1]
    return out
