"""Per-triangle geometry in JAX: frames, angles, areas, Jacobians, singular values, max step.

Every function takes arrays (``vertices: (n, 3)``, ``faces: (m, 3) int``,
``uv: (n, 2)``), is differentiable in the coordinates, and is written for
one triangle and ``vmap``-ed where that reads better.  Square roots and
norms are "safe" (the double-``where`` trick) so a degenerate triangle gives
``inf`` or an error upstream, never a NaN gradient.
"""
from __future__ import annotations

import functools

from .lazy_jax import jax, jnp  # JAX loads on first use (issue 17)

from . import tol

__all__ = [
    "safe_sqrt", "dot", "safe_norm", "local_frames", "face_areas", "corner_angles", "signed_areas",
    "jacobians", "jacobian_from_frame", "singular_values", "max_step", "max_steps",
]


def safe_sqrt(x):
    """``sqrt(max(x, 0))`` with a finite (zero) gradient at 0."""
    pos = x > tol.SAFE_SQRT_FLOOR
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def dot(a, b):
    """``sum(a * b, -1)`` over a short last axis (2 or 3 coordinates), written out term by term.

    XLA's CPU backend hands a ``reduce`` over a short minor axis to its YNNPACK fusions, which
    run it several times slower than the elementwise sum (and sum in another order); written
    out, the sum fuses with its neighbours (issue 17).  Its derivative (a ``jax.custom_jvp``) is
    ``sum(da * b + a * db, -1)``: reverse mode transposes that into broadcast products, where
    the written-out sum's transpose would pad each coordinate into a copy of ``a``."""
    return _dot()(a, b)


@functools.cache
def _dot():
    f = jax.custom_jvp(_dot_primal)
    f.defjvp(_dot_jvp)
    return f


def _dot_primal(a, b):
    out = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        out = out + a[..., i] * b[..., i]
    return out


def _dot_jvp(primals, tangents):
    a, b = primals
    da, db = tangents
    return _dot_primal(a, b), jnp.sum(da * b + a * db, -1)


def safe_norm(x, axis=-1):
    """Euclidean norm along ``axis`` with a finite gradient at 0."""
    if axis in (-1, x.ndim - 1) and x.shape[-1] <= 4:
        return safe_sqrt(dot(x, x))
    return safe_sqrt(jnp.sum(x * x, axis=axis))


def _cross(a, b):
    return jnp.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                      a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                      a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def local_frames(vertices, faces):
    """Each triangle in its own orthonormal frame (survey §6, before eq. (9)).

    **Returns:** ``(m, 3, 2)``: corner 0 at the origin, corner 1 on the positive
    x axis, corner 2 in the upper half plane; lengths in the vertices' units.
    """
    P = jnp.asarray(vertices)[faces]
    e1 = P[:, 1] - P[:, 0]
    e2 = P[:, 2] - P[:, 0]
    l1 = safe_norm(e1)
    x2 = dot(e1, e2) / l1
    y2 = safe_norm(_cross(e1, e2)) / l1
    zero = jnp.zeros_like(l1)
    return jnp.stack([jnp.stack([zero, zero], -1), jnp.stack([l1, zero], -1),
                      jnp.stack([x2, y2], -1)], axis=1)


def face_areas(vertices, faces):
    """``(m,)`` unsigned areas of the triangles in 3D (or 2D, lifted)."""
    P = jnp.asarray(vertices)[faces]
    if P.shape[-1] == 2:
        return jnp.abs(signed_areas(vertices, faces))
    return 0.5 * safe_norm(_cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]))


def corner_angles(vertices, faces):
    """``(m, 3)`` interior angles (radians) at the three corners, by ``atan2(|a x b|, a.b)``."""
    P = jnp.asarray(vertices)[faces]
    if P.shape[-1] == 2:
        P = jnp.concatenate([P, jnp.zeros(P.shape[:-1] + (1,), P.dtype)], -1)
    a = jnp.roll(P, -1, axis=1) - P
    b = jnp.roll(P, 1, axis=1) - P
    return jnp.arctan2(safe_norm(_cross(a, b)), dot(a, b))


def signed_areas(uv, faces):
    """``(m,)`` signed areas of the triangles in the plane (positive = counter-clockwise)."""
    Q = jnp.asarray(uv)[faces]
    d1 = Q[:, 1] - Q[:, 0]
    d2 = Q[:, 2] - Q[:, 0]
    return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])


def jacobian_from_frame(frame, q):
    """Jacobian of the affine map of one triangle (survey eq. (9)).

    **Arguments:** ``frame: (3, 2)`` the triangle in its local frame (from
    :func:`local_frames`), ``q: (3, 2)`` its corners' UVs.
    **Returns:** ``J: (2, 2)`` with ``q_i - q_0 = J (p_i - p_0)``.
    """
    P = jnp.stack([frame[1] - frame[0], frame[2] - frame[0]], axis=1)   # columns p1-p0, p2-p0
    Q = jnp.stack([q[1] - q[0], q[2] - q[0]], axis=1)
    det = P[0, 0] * P[1, 1] - P[0, 1] * P[1, 0]
    Pinv = jnp.array([[P[1, 1], -P[0, 1]], [-P[1, 0], P[0, 0]]]) / det
    return Q @ Pinv


def jacobians(vertices, faces, uv, frames=None):
    """``(m, 2, 2)`` Jacobians of the piecewise-linear map from the surface to the plane."""
    if frames is None:
        frames = local_frames(vertices, faces)
    return jax.vmap(jacobian_from_frame)(frames, jnp.asarray(uv)[faces])


def singular_values(J):
    """Signed singular values of 2x2 matrices in closed form.

    **Arguments:** ``J: (..., 2, 2)``.  **Returns:** ``(s1, s2)``, each ``(...)``,
    ``s1 >= |s2|`` and ``s2 < 0`` exactly when ``det J < 0``.

    With ``E, F, G, H = (a+d)/2, (a-d)/2, (c+b)/2, (c-b)/2``, ``s1 = Q + R`` and
    ``s2 = Q - R`` where ``Q = |(E, H)|`` and ``R = |(F, G)|``.  The safe
    square root makes symmetric functions of ``(s1, s2)`` differentiable at
    ``s1 = s2`` (where ``R = 0``).
    """
    a, b, c, d = J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1]
    E, F = 0.5 * (a + d), 0.5 * (a - d)
    G, H = 0.5 * (c + b), 0.5 * (c - b)
    Q = safe_sqrt(E * E + H * H)
    R = safe_sqrt(F * F + G * G)
    return Q + R, Q - R


def max_step(uv, direction, faces, *, safety: float = tol.MAX_STEP_SAFETY):
    """Largest step ``t`` along ``direction`` before any triangle inverts (Smith & Schaefer 2015).

    Per triangle, ``det [q1 - q0 + t (d1 - d0), q2 - q0 + t (d2 - d0)] = 0`` is a
    quadratic in ``t``; its smallest positive root bounds the step.

    **Arguments:** ``uv: (n, 2)``, ``direction: (n, 2)``, ``faces: (m, 3)``.
    **Returns:** a scalar: ``safety`` times the smallest positive root over all
    triangles, or ``inf`` when no triangle can invert along this direction.
    """
    return jnp.min(max_steps(uv, direction, faces, safety=safety))


def max_steps(uv, direction, faces, *, safety: float = tol.MAX_STEP_SAFETY):
    """:func:`max_step` face by face: ``(m,)``, ``safety`` times each triangle's smallest
    positive root (``inf`` where it cannot invert along ``direction``)."""
    Q = jnp.asarray(uv)[faces]
    D = jnp.asarray(direction)[faces]
    u1, u2 = Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]
    d1, d2 = D[:, 1] - D[:, 0], D[:, 2] - D[:, 0]
    cross = lambda x, y: x[:, 0] * y[:, 1] - x[:, 1] * y[:, 0]
    a = cross(d1, d2)
    b = cross(u1, d2) + cross(d1, u2)
    c = cross(u1, u2)
    return safety * _smallest_positive_root(a, b, c)


def _smallest_positive_root(a, b, c):
    """Smallest positive root of ``a t^2 + b t + c`` per entry (``inf`` if none), stably."""
    scale = jnp.maximum(jnp.maximum(jnp.abs(a), jnp.abs(b)), jnp.abs(c))
    scale = jnp.where(scale > 0, scale, 1.0)
    a, b, c = a / scale, b / scale, c / scale
    inf = jnp.inf
    # Linear case.
    lin = jnp.where(jnp.abs(b) > 0, -c / jnp.where(jnp.abs(b) > 0, b, 1.0), inf)
    lin = jnp.where(lin > 0, lin, inf)
    disc = b * b - 4 * a * c
    sq = jnp.sqrt(jnp.maximum(disc, 0.0))
    # Citardauq form avoids cancellation.
    qq = -0.5 * (b + jnp.where(b >= 0, sq, -sq))
    r1 = jnp.where(a != 0, qq / jnp.where(a != 0, a, 1.0), inf)
    r2 = jnp.where(qq != 0, c / jnp.where(qq != 0, qq, 1.0), inf)
    r1 = jnp.where(r1 > 0, r1, inf)
    r2 = jnp.where(r2 > 0, r2, inf)
    quad = jnp.where(disc >= 0, jnp.minimum(r1, r2), inf)
    small_a = jnp.abs(a) <= 1e-14
    return jnp.where(small_a, lin, quad)
