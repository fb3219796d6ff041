"""The atlas's UVs as a differentiable function of the vertex positions, layout held fixed.

:func:`atlas_uv` re-solves each chart's minimization for new vertex positions with
:func:`jaxparam.minimize` (its implicit gradient: one solve with the true Hessian at the
optimum) and places the result with the atlas's fixed :class:`~jaxparam.atlas.Packing`.
The discrete choices (which face is in which chart, the rotations, offsets and the scale)
are constants: they carry no gradient.  A chart's free-boundary optimum is unique only up
to a rigid motion, so the gradient is exact for losses that are invariant under a rigid
motion of each chart's UVs (distortion energies, UV areas and lengths).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .. import geometry as geo
from .. import topology as topo
from ..errors import MeshError
from ..mesh import TriMesh
from ..optimize import minimize

__all__ = ["atlas_uv", "chart_pieces"]


def _aligned(u, start):
    """``u (k, 2)`` moved by the proper rigid motion that best takes it onto ``start (k, 2)``
    (least squares), the motion held fixed (no gradient).  A free chart's optimum is unique
    only up to a rigid motion, and Newton's steps drift along it: sphere(1)'s two large
    charts came back moved by 0.03 and 0.23 of their size, so the packed UVs missed the
    atlas's by 2.6 % of the square (session 27)."""
    u0 = jax.lax.stop_gradient(u)
    S = jnp.asarray(start)
    mu, ms = u0.mean(0), S.mean(0)
    A = (S - ms[None, :]).T @ (u0 - mu[None, :])
    U, _, Wt = jnp.linalg.svd(A)
    R = U @ jnp.diag(jnp.stack([1.0, jnp.sign(jnp.linalg.det(U @ Wt))])) @ Wt   # proper rotation
    return (u - mu[None, :]) @ R.T + ms[None, :]


def _single_triangle(P, F, start):
    """A one-face chart: its optimum is the triangle laid flat (an isometry; the
    minimization's Hessian is only the rigid motions' null space there), placed by the
    rigid motion that takes the flat triangle at the atlas's positions onto ``start``."""
    q = jnp.zeros((3, 2), jnp.float64).at[F[0]].set(geo.local_frames(P, F)[0])   # (3, 2)
    return _aligned(q, start)


def chart_pieces(a) -> list:
    """``[(ids (k,) UV vertices, faces (f, 3) local, topology)]``, one per chart."""
    out = []
    for c in range(a.n_charts):
        fk = np.flatnonzero(a.chart == c)
        ids, inv = np.unique(a.uv_faces[fk], return_inverse=True)
        F = inv.reshape(-1, 3).astype(np.int64)
        out.append((ids, F, topo.build(F, ids.size, where="atlas_uv")))
    return out


def atlas_uv(vertices, a, *, max_iters: int = 200, pieces=None):
    """Packed UVs ``(n_uv, 2)`` of the atlas ``a`` for the vertex positions ``vertices (n, 3)``
    (JAX arrays or tracers), with charts and packing held fixed.

    Equals ``a.uv`` (to the solver's tolerance) at the positions the atlas was built from.
    ``pieces`` (from :func:`chart_pieces`) saves rebuilding the charts' topologies when
    called repeatedly.  One :func:`jaxparam.minimize` per chart (compiled per chart size).

    Example::

        loss = lambda X: jnp.sum(jp.atlas_uv(X, a)[a.uv_faces[:, 0]] ** 2)
        g = jax.grad(loss)(jnp.asarray(mesh.vertices))
    """
    V = jnp.asarray(vertices, jnp.float64)
    if V.ndim != 2 or V.shape[1] != 3 or V.shape[0] <= int(np.max(a.vertex)):
        raise MeshError(f"atlas_uv: vertices must be the atlas's mesh's positions, an (n, 3) "
                        f"array with n > {int(np.max(a.vertex))} (its largest vertex index), "
                        f"got shape {V.shape}.")
    pk = a.packing
    pieces = chart_pieces(a) if pieces is None else pieces
    out = jnp.zeros((a.uv.shape[0], 2), jnp.float64)
    for c, (ids, F, t) in enumerate(pieces):
        start = np.asarray(a.chart_uv)[ids]
        if F.shape[0] == 1:
            u = _single_triangle(V[a.vertex[ids]], F, start)
        else:
            sub = TriMesh(V[a.vertex[ids]], F, t, validate=False)
            res = minimize(sub, a.energy, init=start, free_boundary=True, verbose=False,
                           max_iters=max_iters)
            u = _aligned(res.uv, start)
        placed = (pk.scale * (u - jnp.asarray(pk.origin[c])[None, :]) @ jnp.asarray(pk.rotation[c]).T
                  + jnp.asarray(pk.offset[c])[None, :])
        out = out.at[ids].set(placed)
    return out
