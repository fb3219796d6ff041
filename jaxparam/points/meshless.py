"""The meshless parameterization of unorganized points (survey §8): checks, the fans' weights,
the boundary map and eq. (4), solved as for meshes (:mod:`jaxparam.combination`)."""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from .. import boundary as bmap
from .. import combination as comb
from ..host import circle as host_circle
from .. import weights as wts
from ..options import choose, is_integer, is_number
from ..errors import ArgumentTypeError, PointCloudError, first_few
from .boundary import detect_boundary
from .defaults import GAP, K, MAX_SLOPE, MIN_SPREAD
from .graph import PointGraph, morton_keys, point_graph

__all__ = ["WEIGHTS", "check_points", "check_map_options", "check_boundary_indices",
           "meshless_map", "map_points", "symmetric_solve"]

#: The weights of the meshless map (those of :mod:`jaxparam.weights` defined on point fans).
WEIGHTS = wts.FAN_KINDS


#: Points closer than this share of the bounding-box diagonal count as duplicates.
NEAR_DUPLICATE = 1e-9


def check_points(points, *, k: int = K, merge_duplicates: bool = False, return_index: bool = False,
                 return_order: bool = False):
    """Validate a point set; returns ``(points (M, 3), kept (M,))``, ``kept`` the input
    indices of the rows of ``points``, in increasing order; with ``return_index`` also
    ``index (N,)``, the row of ``points`` that holds each input point; with ``return_order``
    (last) also ``perm (M,)``, the Morton order of ``points``
    (:func:`~jaxparam.points.graph.spatial_order`, from the keys the duplicate test sorts).

    Raises :class:`PointCloudError` for a wrong shape, non-finite coordinates,
    too few points, ``k >= M``, duplicates (unless ``merge_duplicates``: then
    the later copies are dropped, ``kept`` says which points remain and ``index`` maps a
    copy to its first occurrence) and point sets that are collinear or coincident.
    """
    if hasattr(points, "vertices") and hasattr(points, "faces"):
        raise ArgumentTypeError(f"meshless_map: points must be an (N, 3) array, got a mesh "
                                f"({type(points).__name__}); pass its vertices (mesh.vertices), "
                                "or flatten the mesh itself with jp.convex_map.")
    try:
        P = np.asarray(points, np.float64)
    except (TypeError, ValueError) as exc:
        raise ArgumentTypeError(f"meshless_map: points must be an (N, 3) array of numbers, got "
                                f"{type(points).__name__} ({exc}).") from None
    if P.ndim != 2 or P.shape[1] != 3:
        raise PointCloudError(f"meshless_map: points must have shape (N, 3), got {P.shape}.")
    if not is_integer(k) or k < 1:
        raise PointCloudError(f"meshless_map: k (neighbours per point) must be a positive "
                              f"integer, got {k!r}; the default is {K}.")
    if P.shape[0] < 4:      # before any reduction over the points (an empty set has no bounds)
        raise PointCloudError(f"meshless_map: {P.shape[0]} points are too few; at least 4 are needed.")
    bad = np.flatnonzero(~np.all(np.isfinite(P), axis=1))
    if bad.size:
        raise PointCloudError(f"meshless_map: points {first_few(bad)} have non-finite coordinates; "
                              "remove them.")
    n_in = P.shape[0]
    kept = np.arange(n_in)
    index = np.arange(n_in)
    # Equal points share a Morton key: only points whose key repeats need the exact (and, over
    # all points, 3x slower) row-wise np.unique.
    codes = morton_keys(P)
    perm = np.argsort(codes, kind="stable") if return_order else None
    key = codes[perm] if return_order else np.sort(codes)
    rep = key[1:][key[1:] == key[:-1]]
    maybe = np.flatnonzero(np.isin(codes, rep)) if rep.size else np.zeros(0, np.int64)
    dup = np.zeros(0, np.int64)
    if maybe.size:
        _, first, inv = np.unique(P[maybe], axis=0, return_index=True, return_inverse=True)
        first = maybe[first][inv.reshape(-1)]             # each point's first equal point
        # Equal up to NEAR_DUPLICATE of the diagonal counts as equal too: two points 1e-12
        # apart (distinct in the file) left 76 triangles collapsed to segments, aspect 1e12,
        # in a 3,000-point set (session 22).  Each point is compared with the first point of
        # its Morton cell (5e-7 of the box a side: near copies share one).
        srt = np.argsort(codes[maybe], kind="stable")
        head = np.r_[True, codes[maybe][srt][1:] != codes[maybe][srt][:-1]]
        lead = np.empty_like(maybe)
        lead[srt] = maybe[srt][np.maximum.accumulate(np.where(head, np.arange(srt.size), 0))]
        tol = NEAR_DUPLICATE * float(np.linalg.norm(np.ptp(P, axis=0)))
        near = np.linalg.norm(P[maybe] - P[lead], axis=1) <= tol
        first = np.where(near, np.minimum(lead, first), first)
        dup = maybe[first != maybe]
    if dup.size:
        if not merge_duplicates:
            j = int(first[maybe == dup[0]][0])
            gap = float(np.linalg.norm(P[dup[0]] - P[j]))
            how = f"equals point {j}" if gap == 0 else f"is {gap:.3g} from point {j}"
            raise PointCloudError(
                f"meshless_map: points {first_few(dup)} duplicate earlier points (point "
                f"{int(dup[0])} {how}; points closer than {NEAR_DUPLICATE:g} of the diagonal "
                "count as one); remove them or pass merge_duplicates=True.")
        kept = np.setdiff1d(kept, dup)
        P = P[kept]
        if return_order:           # the same keys: a duplicate leaves the box unchanged
            perm = np.argsort(codes[kept], kind="stable")
        index[maybe] = first
        index = np.searchsorted(kept, index)
    if P.shape[0] < 4:
        raise PointCloudError(f"meshless_map: {P.shape[0]} points are too few; at least 4 are needed.")
    if k >= P.shape[0]:
        raise PointCloudError(f"meshless_map: k = {k} neighbours needs more than {k} points, "
                              f"got {P.shape[0]}; lower k.")
    s = np.linalg.svd(P - P.mean(0), compute_uv=False)
    if s[0] == 0 or s[1] <= 1e-9 * s[0]:
        what = "coincident" if s[0] == 0 else "collinear"
        raise PointCloudError(f"meshless_map: the points are {what}; a surface needs points "
                              "spread in two directions.")
    spread = neighbourhood_spread(P, k)
    if spread < MIN_SPREAD:
        raise PointCloudError(
            f"meshless_map: the points' neighbourhoods are one-dimensional (median spread across "
            f"/ along the {k} nearest neighbours {spread:.3f}, below {MIN_SPREAD:g}): the points "
            "lie along a curve, or far more densely along lines than across them (scan lines); "
            f"a surface needs neighbours in two directions: raise k (now {k}) or resample.")
    out = (P, kept, index) if return_index else (P, kept)
    return out + (perm,) if return_order else out


def neighbourhood_spread(P: np.ndarray, k: int, *, sample: int = 2000) -> float:
    """The median, over up to ``sample`` points of ``P (N, 3)`` (a fixed stride), of the
    second singular value over the first of each one's ``k`` nearest neighbours (centred): about
    0.5-1 on a surface sample, near 0 where the neighbours lie on a line."""
    from scipy.spatial import cKDTree

    rows = np.arange(0, P.shape[0], max(1, P.shape[0] // sample))
    kk = int(min(max(k, 3), P.shape[0] - 1))
    _, nb = cKDTree(P).query(P[rows], k=kk + 1)
    Q = P[nb] - P[nb].mean(1, keepdims=True)
    s = np.linalg.svd(Q, compute_uv=False)
    return float(np.median(s[:, 1] / np.maximum(s[:, 0], 1e-300)))


def check_gap(where: str, gap) -> None:
    """Raise :class:`PointCloudError` (naming ``where``) unless the boundary detector's
    angular ``gap`` (radians) lies in ``(0, 2 pi)``: at 0 every point is a boundary candidate
    (session 21: a noisy camelhead scan came back with 2,696 faces instead of 9,836), and no
    gap reaches 2 pi."""
    if not (is_number(gap) and 0.0 < float(gap) < 2.0 * np.pi):
        raise PointCloudError(f"{where}: gap is the angular gap (radians) that makes a point a "
                              f"boundary candidate and must lie in (0, 2 pi), got {gap!r}; the "
                              f"default is {GAP:.4f} (0.7 pi).")


def check_map_options(where: str, weights, boundary, spacing) -> tuple[str, str, str]:
    """The canonical ``(weights, boundary, spacing)`` (either spelling accepted), or a
    :class:`PointCloudError` (naming ``where``) unless ``weights`` is one of :data:`WEIGHTS`,
    ``boundary`` ``"circle"`` or ``"square"`` and ``spacing`` one of
    :data:`jaxparam.boundary.SPACINGS`."""
    weights = choose(weights, WEIGHTS, what="weights", where=where, error=PointCloudError)
    if not isinstance(boundary, str) or boundary not in ("circle", "square"):
        raise PointCloudError(f"{where}: boundary must be 'circle' or 'square', got {boundary!r}; "
                              "to choose the boundary points pass boundary_indices.")
    spacing = choose(spacing, bmap.SPACINGS, what="spacing", where=where, error=PointCloudError)
    return weights, boundary, spacing


def check_boundary_indices(where: str, indices, n: int, index: np.ndarray | None = None) -> np.ndarray:
    """User boundary indices into ``n`` input points as ``(b,) int64``, or a
    :class:`PointCloudError`.

    With ``index (n,)`` (from :func:`check_points` after merging duplicates) they are
    renamed to the merged points: copies of one point listed next to each other count once.
    """
    bnd = np.asarray(indices, np.int64)
    if bnd.ndim != 1 or bnd.size < 3 or bnd.min() < 0 or bnd.max() >= n or np.unique(bnd).size != bnd.size:
        raise PointCloudError(f"{where}: boundary_indices must be >= 3 distinct point indices "
                              f"in [0, {n}), in order; got {bnd.size} values.")
    if index is None:
        return bnd
    merged = index[bnd]
    merged = merged[merged != np.roll(merged, 1)]        # neighbouring copies of one point
    if merged.size < 3 or np.unique(merged).size != merged.size:
        raise PointCloudError(f"{where}: boundary_indices name {np.unique(merged).size} distinct "
                              "points once duplicates are merged; a boundary needs >= 3, each "
                              "once, in order.")
    return merged


def symmetric_solve(weights: str, symmetric: bool, radius) -> bool:
    """Whether the meshless system is symmetric (a Cholesky solve): spring weights on a
    symmetric kNN graph."""
    return weights in ("uniform", "inverse_distance") and symmetric and radius is None


def meshless_map(points, *, k: int = K, weights: str = "inverse_distance", boundary="circle",
                 spacing: str = "chord", boundary_indices=None, radius: float | None = None,
                 symmetric: bool = True, gap: float = GAP, graph: PointGraph | None = None,
                 merge_duplicates: bool = False, max_slope: float = MAX_SLOPE):
    """Meshless parameterization of unorganized points (survey §8).

    **Arguments:** ``points: (N, 3)`` (numpy, JAX or a tracer with ``graph`` given);
    ``k`` neighbours (or ``radius``); ``weights`` one of :data:`WEIGHTS` (the unsymmetric
    ``shape_preserving`` and ``mean_value`` are normalized to eq. (3)'s ``lambda`` as in
    :func:`jaxparam.convex_map`); ``boundary`` ``"circle"`` or ``"square"``;
    ``boundary_indices`` the ordered boundary points (input indices; default: detected);
    ``graph`` a precomputed :func:`~jaxparam.points.point_graph` (needed under
    ``jax.grad``: neighbourhoods are topology, computed from concrete points; with
    ``merge_duplicates`` it must describe the merged points of :func:`check_points`);
    ``max_slope`` drops neighbour pairs that leave the tangent planes steeply (see
    :func:`~jaxparam.points.point_graph`); ``merge_duplicates`` maps repeated points once.

    **Returns:** ``(uv (N, 2), boundary (b,) int)``, both in the input's numbering: ``uv[i]``
    belongs to ``points[i]`` (a merged copy gets the UV of the point it repeats), and
    ``boundary`` lists input indices (the first copy of a merged point).

    Differentiable in the points: ``jax.grad`` flows through the weights,
    the boundary map and the sparse solve.

    Example::

        uv, bnd = jp.meshless_map(points, k=10, weights="inverse_distance")
    """
    weights, boundary, spacing = check_map_options("meshless_map", weights, boundary, spacing)
    check_gap("meshless_map", gap)
    sym = symmetric_solve(weights, symmetric, radius)
    if isinstance(points, jax.core.Tracer):
        if graph is None or boundary_indices is None:
            raise PointCloudError("meshless_map: under jax.grad/jit pass graph=jp.points.point_graph("
                                  "concrete_points) and boundary_indices=... computed from concrete points.")
        bnd = check_boundary_indices("meshless_map", boundary_indices, points.shape[0])
        return map_points(points, graph, bnd, weights=weights, boundary=boundary, spacing=spacing,
                          symmetric=sym), bnd
    n_in = np.shape(points)[0] if np.ndim(points) == 2 else 0
    Pc, kept, index = check_points(points, k=k, merge_duplicates=merge_duplicates, return_index=True)
    merged = kept.size != n_in
    if graph is None:
        graph = point_graph(Pc, k, radius=radius, symmetric=symmetric, max_slope=max_slope)
    elif graph.n_points != Pc.shape[0]:
        raise PointCloudError(f"meshless_map: graph has {graph.n_points} points, the points "
                              f"{Pc.shape[0]}" + (" once duplicates are merged" if merged else "")
                              + "; build it with jp.points.point_graph of those points.")
    if boundary_indices is None:
        bnd = detect_boundary(Pc, graph, gap=gap)
    else:
        bnd = check_boundary_indices("meshless_map", boundary_indices, n_in,
                                     index if merged else None)
    if merged:
        uv = map_points(Pc, graph, bnd, weights=weights, boundary=boundary, spacing=spacing,
                        symmetric=sym)
        return uv[index], kept[bnd]
    P = points if isinstance(points, jax.Array) else Pc
    return map_points(P, graph, bnd, weights=weights, boundary=boundary, spacing=spacing,
                      symmetric=sym), bnd


def _check_solvable(E: wts.FanEntries, N: int, boundary: np.ndarray, P=None) -> None:
    """Every interior point must reach a boundary point along G (end of §8); ``P (N, 3)``
    (concrete, optional) places the first such point in the message."""
    src = E.free[E.row]
    G = sp.csr_matrix((np.ones(src.size), (E.nbr, src)), shape=(N + 1, N + 1))   # reversed edges
    G = G + sp.csr_matrix((np.ones(boundary.size), (np.full(boundary.size, N), boundary)),
                          shape=(N + 1, N + 1))
    reached = breadth_first_order(G, N, directed=True, return_predecessors=False)
    ok = np.zeros(N + 1, bool)
    ok[reached] = True
    bad = E.free[~ok[E.free]]
    if bad.size:
        where = ""
        if P is not None and not isinstance(P, jax.core.Tracer):
            x, y, z = (float(c) for c in np.asarray(P)[int(bad[0])])
            where = f" at ({x:.4g}, {y:.4g}, {z:.4g})"
        piece = (f"; they are {bad.size} of the {N} points: a separate piece of the point set "
                 "(reconstruct each piece on its own), or one that the k nearest neighbours do "
                 "not join to the rest (a sampling much denser along one direction than the "
                 "other: raise k)" if bad.size >= 0.1 * N else "")
        raise PointCloudError(
            f"meshless_map: {bad.size} points cannot reach the boundary through their neighbours "
            f"(e.g. point {int(bad[0])}{where}); the system (3) would be singular: increase k, use "
            f"symmetric neighbourhoods, or remove the isolated cluster{piece}.")


def map_points(P, graph: PointGraph, bnd: np.ndarray, *, weights: str, boundary: str, spacing: str,
               symmetric: bool, host: bool = False):
    """The meshless map of checked points ``P (N, 3)`` (array or tracer) with their graph and
    boundary polygon ``bnd`` (indices into ``P``): fan weights, boundary map, eq. (4) and its
    sparse solve (``symmetric``: Cholesky).  ``host=True`` with concrete points and the circle
    computes the boundary map, eq. (4)'s assembly and the scatter in NumPy
    (:mod:`jaxparam.host`, ``combination.assemble(host=True)``: no compilation; equal to the
    JAX path to rounding, about 1e-15) and returns a NumPy array.
    **Returns:** ``(N, 2)`` UVs."""
    N = P.shape[0]
    fixed = np.zeros(N, bool)
    fixed[bnd] = True
    E = wts.fan_entries(graph.indptr, graph.indices, fixed)
    _check_solvable(E, N, bnd, P)
    if E.n_rows == 0:       # every point is on the boundary polygon: nothing to solve for
        Pj = P if isinstance(P, jax.core.Tracer) else jnp.asarray(P, dtype=jnp.float64)
        uv_b = _boundary_map(Pj, jax.device_put(bnd), boundary=boundary, spacing=spacing)
        U = jnp.zeros((N, 2)).at[jax.device_put(bnd)].set(uv_b, unique_indices=True)
        return np.asarray(U) if host and wts.is_concrete(P) else U
    slot = np.full(N, -1, np.int64)
    slot[E.free] = np.arange(E.n_rows)
    bslot = np.full(N, -1, np.int64)
    bslot[bnd] = np.arange(bnd.size)
    system = comb.combination_system(E.row, slot[E.nbr], bslot[E.nbr], E.n_rows)
    if host and boundary == "circle" and wts.is_concrete(P):
        # The weights stay the JAX kernel's (the NumPy twin of the shape-preserving weights
        # measured 15-25 % slower at 1M points); the rest needs no compilation.
        Pn = np.asarray(P, np.float64)
        uv_b = host_circle(Pn[bnd], spacing)
        w = np.asarray(wts.fan_weights(jnp.asarray(Pn), E, weights))
        vals, rhs = comb.assemble(system, w, uv_b, normalize=comb.normalizes(weights), host=True)
        U = np.full((N, 2), np.nan)
        U[E.free] = comb.solve(system, vals, rhs, symmetric=symmetric)
        U[bnd] = uv_b
        return U
    Pj = P if isinstance(P, jax.core.Tracer) else jnp.asarray(P, dtype=jnp.float64)
    w = wts.fan_weights(Pj, E, weights)
    uv_b = _boundary_map(Pj, jax.device_put(bnd), boundary=boundary, spacing=spacing)
    x = comb.solve_weights(system, w, uv_b, normalize=comb.normalizes(weights), symmetric=symmetric)
    return comb.scatter(x, uv_b, jax.device_put(E.free), jax.device_put(bnd), n=N)


# One compiled kernel instead of a dozen eager operations (each compiled on its own for every
# new point count).
@functools.partial(jax.jit, static_argnames=("boundary", "spacing"))
def _boundary_map(P, bnd, *, boundary, spacing):
    return bmap.boundary_uv(P[bnd], boundary, spacing=spacing)
