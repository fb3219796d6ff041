"""Boundary maps: a boundary loop onto a convex polygon (survey §3, §4 Fig. 10, §6 Fig. 12c).

Every function takes the loop's 3D positions ``loop_xyz: (k, 3)`` in loop
order (counter-clockwise, interior on the left) and returns ``(k, 2)`` UVs in
the same order, counter-clockwise too.  Positions may be JAX tracers: with
chord-length spacing the boundary UVs are differentiable in them (with a kink
where a vertex sits exactly on a corner of the square or polygon: see
:func:`polygon`).

``"plane"`` needs a loop whose projection is a simple polygon; :func:`plane`
checks that on concrete inputs, and :func:`check_plane_boundary` does the same
check before a ``jit`` (inside one the positions are tracers and nothing is
checked).
"""
from __future__ import annotations

import numpy as np

from .lazy_jax import jax, jnp  # JAX loads on first use (issue 17)
from . import tol
from .errors import MeshError, first_few
from .geometry import safe_norm
from .io import as_mesh
from .options import choose
from .triangles import polygon_area

__all__ = [
    "arc_parameters", "circle", "square", "polygon", "plane", "plane_frame", "check_plane_boundary",
    "boundary_uv", "check_user_uv", "is_convex_polygon", "crossing_edges", "SHAPES", "SPACINGS",
    "boundary_loop", "BoundaryUV", "user_boundary", "in_loop_order",
]

SHAPES = ("circle", "square", "plane")
SPACINGS = ("uniform", "chord")


def arc_parameters(loop_xyz, spacing: str = "chord"):
    """``(k,)`` parameters in ``[0, 1)`` along a closed loop, the first vertex at 0.

    ``spacing="chord"``: proportional to the accumulated edge lengths;
    ``"uniform"``: ``i / k``.
    """
    k = loop_xyz.shape[0]
    spacing = choose(spacing, SPACINGS, what="spacing", where="boundary")
    if spacing == "uniform":
        return jnp.arange(k, dtype=jnp.float64) / k
    seg = safe_norm(jnp.roll(loop_xyz, -1, axis=0) - loop_xyz)
    cum = jnp.concatenate([jnp.zeros(1), jnp.cumsum(seg)[:-1]])
    return cum / jnp.sum(seg)


def circle(loop_xyz, *, spacing: str = "chord", radius: float = 1.0):
    """The loop on a circle of ``radius`` centred at the origin, counter-clockwise."""
    t = 2 * jnp.pi * arc_parameters(loop_xyz, spacing)
    return radius * jnp.stack([jnp.cos(t), jnp.sin(t)], axis=1)


def polygon(loop_xyz, corners_uv, *, spacing: str = "chord", corner_positions=None):
    """The loop on a convex polygon, by arc length along its perimeter.

    **Arguments:** ``corners_uv: (q, 2)`` the polygon, counter-clockwise;
    ``corner_positions``: optional ``(q,)`` increasing loop indices of the
    vertices that land on the corners (the first must be 0); by default the
    loop's parameter is matched to the polygon's arc length.

    **Kink at the corners.** A vertex's UV is a piecewise-linear function of
    its arc parameter ``t`` (:func:`arc_parameters`), with a kink at each
    corner's parameter (the corner's share of the perimeter).  Where a
    vertex's ``t`` equals a corner's exactly (by default, with chord spacing,
    a vertex whose share of the loop's length is exactly the corner's), the
    UVs are continuous but not differentiable in ``loop_xyz``, and JAX
    returns the one-sided derivative of the side *after* the corner: the
    vertex is placed on the polygon side that starts at the corner
    (``searchsorted(..., side="right")``), so a perturbation that increases
    ``t`` gets the forward (right) difference and one that decreases ``t``
    the backward (left) difference; the other one-sided derivative, along
    the side that ends at the corner, is not returned
    (``tests/test_boundary_gradients.py``).  Elsewhere the map is smooth.
    No kink with ``corner_positions`` (the pinned vertices stay on their
    corners and the others cannot reach one) nor with ``spacing="uniform"``
    (``t`` does not depend on the positions).
    """
    C = np.asarray(corners_uv, np.float64)
    if C.ndim != 2 or C.shape[1] != 2 or C.shape[0] < 3:
        raise MeshError(f"boundary polygon: corners must have shape (q, 2) with q >= 3, got {C.shape}.")
    if not is_convex_polygon(C):
        raise MeshError("boundary polygon: the corners do not form a convex counter-clockwise "
                        f"polygon ({_why_not_convex(C)}); Theorem 1 needs a convex boundary: "
                        "reorder the corners counter-clockwise or use their convex hull.")
    edges = np.roll(C, -1, axis=0) - C
    seglen = np.linalg.norm(edges, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seglen)]) / seglen.sum()    # corner parameters
    t = arc_parameters(loop_xyz, spacing)
    if corner_positions is not None:
        t = _pin_corners(t, np.asarray(corner_positions), cum[:-1], loop_xyz.shape[0])
    seg = jnp.clip(jnp.searchsorted(jnp.asarray(cum), t, side="right") - 1, 0, C.shape[0] - 1)
    local = (t - jnp.asarray(cum)[seg]) / jnp.asarray(cum[1:] - cum[:-1])[seg]
    return jnp.asarray(C)[seg] + local[:, None] * jnp.asarray(edges)[seg]


def _pin_corners(t, pos, corner_t, k):
    """Remap loop parameters so that loop vertex ``pos[j]`` lands on corner ``j``."""
    if pos.ndim != 1 or pos.size != corner_t.size:
        raise MeshError(f"boundary: {corner_t.size} corner vertices needed, got {pos.size}.")
    if pos[0] != 0 or np.any(np.diff(pos) <= 0) or pos[-1] >= k:
        raise MeshError("boundary: corner positions must start at 0 and increase strictly "
                        f"within the loop of {k} vertices, got {pos.tolist()}.")
    ends = np.concatenate([pos, [k]])
    t_ext = jnp.concatenate([t, jnp.ones(1)])
    idx = np.arange(k)
    j = np.searchsorted(pos, idx, side="right") - 1
    t0, t1 = t_ext[ends[j]], t_ext[ends[j + 1]]
    frac = (t - t0) / (t1 - t0)
    c_ext = np.concatenate([corner_t, [1.0]])
    return jnp.asarray(c_ext[j]) + frac * jnp.asarray(c_ext[j + 1] - c_ext[j])


def square(loop_xyz, *, spacing: str = "chord", corners=None):
    """The loop on the unit square ``[0, 1]^2``, counter-clockwise from ``(0, 0)``.

    Corners at quarter arc length by default, or at the loop positions
    ``corners`` (4 increasing indices into the loop, the first 0).

    **Kink at the corners**, as in :func:`polygon`: with the default corners a
    vertex whose arc parameter is exactly 1/4, 1/2 or 3/4 of the loop's
    length sits on a corner, where the UVs are not differentiable; JAX
    returns the derivative along the side after that corner (the forward
    difference when the perturbation increases the vertex's parameter, the
    backward one when it decreases it).  No kink with ``corners`` given.
    """
    C = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return polygon(loop_xyz, C, spacing=spacing, corner_positions=corners)


#: Below this fraction of the farthest vertex's distance from the centroid (in the plane), the
#: first loop vertex is too close to the centroid to fix the ``u`` axis of :func:`plane_frame`,
#: and the farthest vertex fixes it instead.
PLANE_FIRST_VERTEX_REL = 1e-8


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def plane_frame(loop_xyz):
    """The projection plane of a closed loop: ``(centre (3,), axes (3, 3))``.

    ``axes`` holds the rows ``e1, e2, n``, orthonormal and right-handed
    (``e1 x e2 = n``); a point ``x`` has plane coordinates
    ``(x - centre) @ axes[:2].T``.  The rule, continuous in ``loop_xyz``:

    - ``centre``: the mean of the loop's vertices;
    - ``n``: the direction of the loop's vector area
      ``a = 1/2 sum_i (x_i - centre) x (x_{i+1} - centre)``, ``n = a / |a|``.
      The loop winds counter-clockwise around it (``n . a > 0``), and of all
      planes it is the one onto which the loop encloses the largest signed
      area; for a planar loop it is the loop's plane.  No singular vectors
      are involved, so nothing jumps when the loop is (nearly) circular or
      its principal directions swap;
    - ``e1``: the first loop vertex's direction from the centre, projected
      into the plane (so the first vertex lands on ``+u``, as in
      :func:`circle`), or the farthest vertex's when the first one projects
      within ``PLANE_FIRST_VERTEX_REL`` of the centre; ``e2 = n x e1``.

    Differentiable (finite gradients) wherever ``|a| > 0``; at ``a = 0`` the
    frame is finite but meaningless, and :func:`plane` refuses such a loop.
    """
    loop_xyz = jnp.asarray(loop_xyz)
    centre = jnp.mean(loop_xyz, axis=0)
    X = loop_xyz - centre[None, :]
    a = 0.5 * jnp.sum(jnp.cross(X, jnp.roll(X, -1, axis=0)), axis=0)
    na = safe_norm(a)
    n = a / jnp.where(na > 0, na, 1.0)
    Xp = X - (X @ n)[:, None] * n[None, :]
    r = safe_norm(Xp)
    j = jnp.where(r[0] > PLANE_FIRST_VERTEX_REL * jnp.max(r), 0, jnp.argmax(r))
    nr = r[j]
    e1 = Xp[j] / jnp.where(nr > 0, nr, 1.0)
    e2 = jnp.cross(n, e1)
    return centre, jnp.stack([e1, e2, n])


def _plane_uv(loop_xyz):
    centre, axes = plane_frame(loop_xyz)
    return (jnp.asarray(loop_xyz) - centre[None, :]) @ axes[:2].T


def plane(loop_xyz, *, check: bool = True):
    """Project the loop onto its plane (survey §6, Fig. 12c), counter-clockwise.

    The plane and its axes are those of :func:`plane_frame`: the normal is
    the loop's vector-area direction (so the layout winds counter-clockwise,
    like the faces, and is never mirrored), and the first loop vertex lies
    on ``+u``.  Both are continuous in ``loop_xyz``: a tiny perturbation
    gives a tiny change (no 180° turn or mirror image, as singular vectors
    would give), and the gradient is finite, also for a circular planar
    loop.  The projection is isometric for a planar loop.  It is convex
    only when the boundary is: Theorem 1's guarantee then needs checking
    (see ``metrics.theorem1``).

    **Checks** (concrete inputs only; skipped under ``jit``/``grad``, where
    the positions are tracers: call :func:`check_plane_boundary` first, and
    skipped with ``check=False``, e.g. to project a point set that is not a
    loop): a loop with no vector area, or whose projection is not a simple
    polygon (it crosses itself, e.g. a figure eight), raises
    :class:`MeshError` naming the crossing edges.
    """
    uv = _plane_uv(loop_xyz)
    if check and _is_concrete(loop_xyz) and _is_concrete(uv):
        _refuse_bad_plane_boundary(np.asarray(loop_xyz, np.float64), np.asarray(uv), None)
    return uv


def check_plane_boundary(loop_xyz, loop=None) -> None:
    """Raise :class:`MeshError` when ``boundary="plane"`` cannot map this loop one-to-one.

    Refused: a loop whose vector area is zero (no plane to project onto),
    and one whose projection by :func:`plane` is not a simple polygon (two
    boundary edges cross or touch, or two consecutive vertices project to
    the same point).  The message names the first few crossing edges and
    suggests ``boundary="circle"``.  ``loop``: optional ``(k,)`` mesh vertex
    ids of the loop, used to name the edges (by default, loop positions).

    Numpy, ``O(k log k)`` for a typical boundary (edges bucketed in a grid
    of cells).  Does nothing on JAX tracers: call it before a ``jit``.
    """
    if not _is_concrete(loop_xyz):
        return
    P = np.asarray(loop_xyz, np.float64)
    uv = np.asarray(_plane_uv(P))
    _refuse_bad_plane_boundary(P, uv, None if loop is None else np.asarray(loop))


def _refuse_bad_plane_boundary(P, uv, ids) -> None:
    """The checks of :func:`check_plane_boundary` on the loop ``P: (k, 3)`` and its plane UVs."""
    k = P.shape[0]
    what = "loop positions" if ids is None else "vertices"
    ids = np.arange(k) if ids is None else ids
    remedy = ('use boundary="circle" (or "square"), which maps any boundary loop to a convex '
              'polygon.')
    if k < 3:
        raise MeshError(f"boundary 'plane': the boundary loop has {k} vertices; it needs at least "
                        f"3; {remedy}")
    per = float(np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1).sum())
    X = P - P.mean(axis=0)
    area3 = float(np.linalg.norm(0.5 * np.cross(X, np.roll(X, -1, axis=0)).sum(axis=0)))
    area2 = polygon_area(uv)
    small = tol.DEGENERATE_AREA_REL * per * per
    if not (area3 > small and area2 > small):
        raise MeshError(
            f"boundary 'plane': the boundary loop encloses no area in any plane (vector area "
            f"{area3:.3g} <= tol.DEGENERATE_AREA_REL x perimeter^2 = {small:.3g}; e.g. it runs "
            f"along both sides of a cut, or is a figure eight with equal lobes), so there is no "
            f"plane to project it onto; {remedy}")
    same = np.flatnonzero(np.all(uv == np.roll(uv, -1, axis=0), axis=1))
    if same.size:
        raise MeshError(
            f"boundary 'plane': the boundary loop projected onto its plane is not a simple "
            f"polygon: consecutive {what} "
            f"{first_few([(int(ids[i]), int(ids[(i + 1) % k])) for i in same])} project to the "
            f"same point; {remedy}")
    cross = crossing_edges(uv)
    if cross.size:
        def edge(i):
            return f"({int(ids[i])}, {int(ids[(i + 1) % k])})"
        raise MeshError(
            f"boundary 'plane': the boundary loop projected onto its plane crosses itself, so it "
            f"is not a simple polygon and the map would fold over: these pairs of boundary edges "
            f"cross: {first_few(cross, fmt=lambda p: f'{edge(p[0])} with {edge(p[1])}')} (an edge "
            f"is named by its two {what}); {remedy}")


def boundary_uv(loop_xyz, shape="circle", *, spacing: str = "chord", corners=None):
    """Dispatch on a boundary name or a user polygon/UV array.

    **Arguments:** ``shape``: ``"circle"``, ``"square"``, ``"plane"``, a
    ``(k, 2)`` array of UVs for the loop's vertices (used as given), or a
    dict ``{"polygon": (q, 2) corners}`` for a convex polygon.
    """
    k = loop_xyz.shape[0]
    if isinstance(shape, str):
        shape = choose(shape, SHAPES, what="boundary", where="boundary")
        if shape == "circle":
            return circle(loop_xyz, spacing=spacing)
        if shape == "square":
            return square(loop_xyz, spacing=spacing, corners=corners)
        if shape == "plane":
            return plane(loop_xyz)
    if isinstance(shape, dict) and "polygon" in shape:
        return polygon(loop_xyz, shape["polygon"], spacing=spacing, corner_positions=corners)
    uv = jnp.asarray(shape, dtype=jnp.float64)
    if uv.shape != (k, 2):
        raise MeshError(f"boundary: the user boundary UVs must have shape ({k}, 2), one row per "
                        f"boundary-loop vertex in loop order, got {tuple(uv.shape)}.")
    return uv


def _why_not_convex(P) -> str:
    """Name what makes the polygon ``P: (k, 2)`` not convex and counter-clockwise (for messages)."""
    d = np.roll(P, -1, axis=0) - P
    same = np.flatnonzero(np.linalg.norm(d, axis=1) == 0)
    if same.size:
        return f"corners {int(same[0])} and {(int(same[0]) + 1) % len(P)} coincide"
    dn = np.roll(d, -1, axis=0)
    cross = d[:, 0] * dn[:, 1] - d[:, 1] * dn[:, 0]
    sin = cross / (np.linalg.norm(d, axis=1) * np.linalg.norm(dn, axis=1))
    cw = (np.flatnonzero(sin <= -tol.CONVEX_SIN) + 1) % len(P)
    if cw.size == len(P):
        return "the corners run clockwise"
    if cw.size:
        return f"it turns clockwise at corners {first_few(np.sort(cw))}"
    return "it winds around more than once"


def is_convex_polygon(P, *, strict: bool = False) -> bool:
    """Whether the closed polygon ``P: (k, 2)`` is convex and counter-clockwise.

    Collinear runs count as convex unless ``strict``; the polygon must turn once.
    """
    P = np.asarray(P, np.float64)
    d = np.roll(P, -1, axis=0) - P
    dn = np.roll(d, -1, axis=0)
    cross = d[:, 0] * dn[:, 1] - d[:, 1] * dn[:, 0]
    scale = np.linalg.norm(d, axis=1) * np.linalg.norm(dn, axis=1)
    sin = cross / np.where(scale > 0, scale, 1.0)
    if np.any(scale == 0):
        return False
    ok = sin > tol.CONVEX_SIN if strict else sin > -tol.CONVEX_SIN
    if not np.all(ok):
        return False
    # Total turning must be 2*pi (a convex polygon winds once).
    ang = np.arctan2(cross, np.sum(d * dn, axis=1))
    return bool(abs(ang.sum() - 2 * np.pi) < 1e-6)


def crossing_edges(P, *, chunk: int = 1 << 21) -> np.ndarray:
    """The pairs of edges of the closed polygon ``P: (k, 2)`` that cross or touch: ``(p, 2)`` int.

    Edge ``i`` joins ``P[i]`` and ``P[(i + 1) % k]``; each row is ``(i, j)`` with ``i < j``, rows
    sorted.  Non-adjacent edges count when they share any point (crossing, touching, collinear
    overlap); adjacent ones when the polygon doubles back along them.  Empty for a simple
    polygon (a zero-length edge makes its two neighbours touch).

    Vectorized numpy: each edge's bounding box is bucketed into a uniform grid of square
    cells (side twice the median edge length, doubled while the buckets would hold more than
    ``16 k`` entries), and only edges sharing a cell are tested, each pair once (in the cell
    of its boxes' overlap's lower corner), by exact orientation signs; ``chunk`` bounds the
    pairs tested at a time.  About ``O(k log k)`` for a boundary of similar edge lengths
    (10^4 vertices: ~0.1 s); a pathological one, with thousands of long edges crowding one
    region (a star of thin spikes), degrades towards testing ``O(k^2)`` pairs.
    """
    P = np.asarray(P, np.float64)
    k = P.shape[0]
    if k < 3:
        return np.zeros((0, 2), np.int64)
    A, B = P, np.roll(P, -1, axis=0)
    D = B - A
    lo, hi = np.minimum(A, B), np.maximum(A, B)
    found = []
    # Adjacent edges i, i + 1 share a vertex; they overlap only when the loop turns back by 180°.
    Dn = np.roll(D, -1, axis=0)
    turn = D[:, 0] * Dn[:, 1] - D[:, 1] * Dn[:, 0]
    back = np.flatnonzero((turn == 0) & (np.sum(D * Dn, axis=1) < 0))
    if back.size:
        found.append(np.sort(np.column_stack([back, (back + 1) % k]), axis=1))
    bmin = P.min(axis=0)
    span = float(np.max(P.max(axis=0) - bmin))
    if k > 3 and span > 0:
        length = np.hypot(D[:, 0], D[:, 1])
        h = max(2.0 * float(np.median(length)), span * 2.0 ** -20)
        while True:
            c0 = np.floor((lo - bmin) / h).astype(np.int64)
            c1 = np.floor((hi - bmin) / h).astype(np.int64)
            ncell = c1 - c0 + 1
            count = ncell[:, 0] * ncell[:, 1]
            if count.sum() <= 16 * k:
                break
            h *= 2.0
        found.extend(_grid_crossings(A, B, lo, hi, bmin, h, c0, ncell, count, chunk))
    if not found:
        return np.zeros((0, 2), np.int64)
    return np.unique(np.concatenate(found).astype(np.int64), axis=0)


def _grid_crossings(A, B, lo, hi, bmin, h, c0, ncell, count, chunk):
    """The non-adjacent crossing pairs of :func:`crossing_edges`, by cells of side ``h``."""
    k = A.shape[0]
    total = int(count.sum())
    edge = np.repeat(np.arange(k), count)
    q = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    nx = ncell[edge, 0]
    cx = c0[edge, 0] + q % nx
    cy = c0[edge, 1] + q // nx
    ny_all = int(cy.max()) + 1
    key = cx * ny_all + cy
    order = np.argsort(key, kind="stable")
    key, edge, cx, cy = key[order], edge[order], cx[order], cy[order]
    start = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
    size = np.diff(np.concatenate([start, [total]]))
    group = np.repeat(np.arange(start.size), size)
    partners = size[group] - 1 - (np.arange(total) - start[group])     # later entries, same cell
    cum = np.cumsum(partners)
    out = []
    s = 0
    while s < total:
        e = max(int(np.searchsorted(cum, (cum[s - 1] if s else 0) + chunk, side="right")), s + 1)
        cnt = partners[s:e]
        n = int(cnt.sum())
        s0 = s
        s = e
        if n == 0:
            continue
        first = np.repeat(np.arange(s0, e), cnt)
        second = first + 1 + (np.arange(n) - np.repeat(np.cumsum(cnt) - cnt, cnt))
        i, j = edge[first], edge[second]
        gap = (i - j) % k
        olo = np.maximum(lo[i], lo[j])
        keep = (gap != 1) & (gap != k - 1) & np.all(olo <= np.minimum(hi[i], hi[j]), axis=1)
        ref = np.floor((olo - bmin) / h).astype(np.int64)     # count each pair in one cell only
        keep &= (ref[:, 0] == cx[first]) & (ref[:, 1] == cy[first])
        i, j = i[keep], j[keep]
        p1, p2, q1, q2 = A[i], B[i], A[j], B[j]
        hit = ((_orient(p1, p2, q1) * _orient(p1, p2, q2) <= 0)
               & (_orient(q1, q2, p1) * _orient(q1, q2, p2) <= 0))
        if hit.any():
            out.append(np.sort(np.column_stack([i[hit], j[hit]]), axis=1))
    return out


def _orient(a, b, c):
    """Sign of the turn ``a -> b -> c`` per row (+1 counter-clockwise, 0 collinear)."""
    return np.sign((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                   - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


# ------------------------------------------------------------------------------------------
# User boundary UVs given per vertex, in any order
# ------------------------------------------------------------------------------------------

def boundary_loop(mesh) -> np.ndarray:
    """The boundary loop that :func:`jaxparam.convex_map` maps onto its boundary: the
    longest one, ``(k,) int64`` vertex indices in jaxparam's loop order (counter-clockwise,
    the surface on the left).  A ``(k, 2)`` ``boundary=`` array without
    ``boundary_indices`` must follow this order.

    Example::

        loop = jp.boundary_loop(mesh)
        uv = jp.convex_map(mesh, boundary=dict(zip(loop.tolist(), my_uv)))
    """
    loops = as_mesh(mesh, "boundary_loop").topology.boundary_loops
    if not loops:
        raise MeshError("boundary_loop: the mesh is closed (no boundary loop); cut it open first "
                        "or use jp.manifold_map.")
    return loops[0]


class BoundaryUV:
    """Boundary UVs given per vertex: ``indices (k,) int64`` (concrete, distinct) and
    ``uv (k, 2)`` (numpy, JAX, or traced), row ``i`` the UV of vertex ``indices[i]``."""

    __slots__ = ("indices", "uv")

    def __init__(self, indices, uv):
        self.indices, self.uv = indices, uv


def user_boundary(boundary, boundary_indices=None):
    """``boundary`` as :func:`jaxparam.convex_map` takes it, with per-vertex UVs made a
    :class:`BoundaryUV`: a mapping ``{vertex: (u, v)}`` or a ``(k, 2)`` array with
    ``boundary_indices (k,)``; anything else is returned unchanged."""
    if isinstance(boundary, dict) and "polygon" not in boundary:
        if boundary_indices is not None:
            raise MeshError("boundary: give the vertex indices either as the mapping's keys or "
                            "as boundary_indices, not both.")
        try:
            idx = np.asarray([int(k) for k in boundary.keys()], np.int64)
        except (TypeError, ValueError):
            raise MeshError("boundary: a mapping of boundary UVs needs integer vertex indices as "
                            f"keys (or the key 'polygon'), got keys {list(boundary)[:5]}.") from None
        vals = list(boundary.values())
        uv = jnp.stack([jnp.asarray(v, jnp.float64) for v in vals]) if vals else jnp.zeros((0, 2))
        return _checked(idx, uv)
    if boundary_indices is None:
        return boundary
    if isinstance(boundary, str) or isinstance(boundary, dict):
        raise MeshError("boundary_indices: given only with a (k, 2) array of boundary UVs, got "
                        f"boundary={boundary!r}.")
    idx = np.asarray(boundary_indices)
    if idx.ndim != 1 or not (np.issubdtype(idx.dtype, np.integer) or idx.size == 0):
        raise MeshError(f"boundary_indices: must be a (k,) integer array, got shape {idx.shape} of "
                        f"dtype {idx.dtype}.")
    return _checked(idx.astype(np.int64), jnp.asarray(boundary, jnp.float64))


def _checked(idx: np.ndarray, uv) -> BoundaryUV:
    if uv.shape != (idx.size, 2):
        raise MeshError(f"boundary: {idx.size} boundary vertices need ({idx.size}, 2) UVs, one row "
                        f"each, got {tuple(uv.shape)}.")
    u, counts = np.unique(idx, return_counts=True)
    if np.any(counts > 1):
        raise MeshError(f"boundary_indices: vertices {first_few(u[counts > 1])} are given more "
                        "than once; give each boundary vertex one UV.")
    return BoundaryUV(idx, uv)


def check_user_uv(uv) -> None:
    """Refuse user boundary UVs ``(k, 2)`` (in loop order) that no convex-combination map
    can use: non-finite rows, or a polygon that runs clockwise or encloses no area (every
    triangle of the map would turn over or collapse; the loop runs counter-clockwise, the
    interior on its left).  Traced UVs are not checked."""
    if not _is_concrete(uv):
        return
    U = np.asarray(uv, np.float64)
    bad = np.flatnonzero(~np.isfinite(U).all(axis=1))
    if bad.size:
        raise MeshError(f"boundary: the user boundary UVs (one row per boundary-loop vertex, "
                        f"{len(U)} rows in loop order) are not finite in rows {first_few(bad)}: "
                        "give every boundary vertex a finite (u, v).")
    area = polygon_area(U)
    extent = float(np.max(np.ptp(U, axis=0))) if len(U) else 0.0
    if area <= 1e-12 * extent * extent:
        what = ("run clockwise (signed area {:.3g}): mirror them (negate one coordinate), keeping "
                "the rows in loop order".format(area) if area < -1e-12 * extent * extent else
                "enclose no area (all on one point or one line): place them on a convex polygon")
        raise MeshError(f"boundary: the user boundary UVs {what}.  The boundary loop runs "
                        "counter-clockwise with the interior on its left, so every triangle of "
                        "the map would turn over or collapse.")


def in_loop_order(boundary, loop: np.ndarray):
    """A :class:`BoundaryUV` as the ``(k, 2)`` UVs of ``loop`` in loop order (a gather: JAX
    gradients flow to the given UVs); anything else unchanged.

    Raises :class:`MeshError` unless the indices are exactly the loop's vertices, naming the
    missing ones and the ones not on the loop.
    """
    if not isinstance(boundary, BoundaryUV):
        return boundary
    idx = boundary.indices
    missing = np.setdiff1d(loop, idx)
    extra = np.setdiff1d(idx, loop)
    if missing.size or extra.size:
        parts = ([f"missing vertices {first_few(missing)}"] if missing.size else []) + \
                ([f"vertices {first_few(extra)} are not on it"] if extra.size else [])
        raise MeshError(f"boundary: the boundary UVs must cover exactly the {loop.size} vertices "
                        f"of the longest boundary loop (jp.boundary_loop(mesh)): "
                        f"{'; '.join(parts)}.")
    row = np.empty(int(max(loop.max(), idx.max())) + 1, np.int64)
    row[idx] = np.arange(idx.size)
    return boundary.uv[row[loop]]
