"""Boundary maps: a boundary loop onto a convex polygon (survey §3, §4 Fig. 10, §6 Fig. 12c).

Every function takes the loop's 3D positions ``loop_xyz: (k, 3)`` in loop
order (counter-clockwise, interior on the left) and returns ``(k, 2)`` UVs in
the same order, counter-clockwise too.  Positions may be JAX tracers: with
chord-length spacing the boundary UVs are differentiable in them.
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from . import tol
from .errors import MeshError, first_few
from .geometry import safe_norm
from .options import choose

__all__ = [
    "arc_parameters", "circle", "square", "polygon", "plane", "boundary_uv", "is_convex_polygon",
    "SHAPES", "SPACINGS",
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
    """
    C = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return polygon(loop_xyz, C, spacing=spacing, corner_positions=corners)


def plane(loop_xyz):
    """Project the loop onto its least-squares plane (survey §6, Fig. 12c).

    The in-plane axes are the two leading principal directions of the loop's
    vertices; the result is turned counter-clockwise.  It is convex only when
    the boundary is: Theorem 1's guarantee then needs checking (see
    ``metrics.theorem1``).
    """
    X = loop_xyz - jnp.mean(loop_xyz, axis=0, keepdims=True)
    _, _, Vt = jnp.linalg.svd(X, full_matrices=False)
    uv = X @ Vt[:2].T
    area = 0.5 * jnp.sum(uv[:, 0] * jnp.roll(uv[:, 1], -1) - jnp.roll(uv[:, 0], -1) * uv[:, 1])
    return uv * jnp.stack([jnp.ones(()), jnp.where(area < 0, -1.0, 1.0)])[None, :]


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
