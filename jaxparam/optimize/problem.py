"""One minimization's fixed data: the free degrees of freedom, jitted energy, gradient and
flip count, the per-face Jacobian maps and the Hessian's sparsity pattern.

The unknowns are ``x``, the free vertices' UVs flattened to ``(2 k,)``; fixed vertices
keep their start UVs (``Problem.base``).  The kernels here are module-level ``jax.jit``
functions with the :class:`~jaxparam.Energy` as a static argument (:attr:`Energy.static
<jaxparam.Energy.static>`, without its parameters) and the energy's parameters as a dynamic
one, so every problem of the same shapes and an equal energy shares their compiled code,
whatever the parameter values.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .. import energies as en_mod
from .. import geometry as geo
from .. import sparse
from ..errors import SolverError

__all__ = ["Problem", "HessianPattern", "uv_of", "energy_at", "energy_value",
           "energy_value_and_grad", "count_flipped", "max_step_along", "jacobian_maps",
           "free_vertices", "normalized"]


def free_vertices(topology, free_boundary: bool) -> np.ndarray:
    """The free vertices of a minimization, ascending: the referenced ones with a free
    boundary, the referenced interior ones otherwise (no vertex is pinned to remove the
    rigid motions of a free boundary: the solvers and the implicit gradient handle that
    null space)."""
    t = topology
    mask = t.referenced & (np.ones(t.n_vertices, bool) if free_boundary else ~t.is_boundary)
    return np.flatnonzero(mask)


def uv_of(x, base, free):
    """The ``(n, 2)`` UVs: ``base`` with the free vertices' rows replaced by ``x (2 k,)``."""
    return base.at[free].set(x.reshape(-1, 2))


def energy_at(x, base, free, F, frames, areas, params, en):
    """The mesh energy (area-weighted mean density) at the free DOFs ``x`` (not jitted: the
    body of the kernels below, and of the implicit gradient's backward pass)."""
    return en_mod.total(en, frames, areas, uv_of(x, base, free)[F], params)


@functools.partial(jax.jit, static_argnames=("en",))
def energy_value(x, base, free, F, frames, areas, params, *, en):
    """The mesh energy (area-weighted mean density) at the free DOFs ``x``; ``params``: the
    energy's parameters (``en`` is static, without them)."""
    return energy_at(x, base, free, F, frames, areas, params, en)


@functools.partial(jax.jit, static_argnames=("en",))
def energy_value_and_grad(x, base, free, F, frames, areas, params, *, en):
    """The mesh energy and its gradient in ``x``."""
    return jax.value_and_grad(energy_at)(x, base, free, F, frames, areas, params, en)


@jax.jit
def count_flipped(x, base, free, F):
    """How many faces have a non-positive signed UV area at ``x``."""
    return jnp.sum(geo.signed_areas(uv_of(x, base, free), F) <= 0)


@jax.jit
def max_step_along(x, d, base, free, F):
    """:func:`jaxparam.geometry.max_step` from ``x`` along the free-DOF direction ``d``."""
    D = jnp.zeros_like(base).at[free].set(d.reshape(-1, 2))
    return geo.max_step(uv_of(x, base, free), D, F)


@jax.jit
def jacobian_maps(frames):
    """``(m, 4, 6)``: ``vec J = D q`` for each face (J is linear in the corner UVs)."""
    def jac_map(frame):
        return jax.jacfwd(lambda qq: geo.jacobian_from_frame(frame, qq.reshape(3, 2)).reshape(-1))(
            jnp.zeros(6))
    return jax.vmap(jac_map)(frames)


@dataclass(frozen=True)
class HessianPattern:
    """Where the per-face 6x6 Hessians land in the ``(2 k, 2 k)`` sparse Hessian.

    **Fields:** ``pattern`` (:class:`jaxparam.sparse.Pattern`, CSR, both triangles);
    ``pos (m * 36,)``: the CSR slot of each face Hessian entry (row-major per face),
    ``-1`` for entries of fixed vertices; ``diag (2 k,)``: the CSR slot of each diagonal.
    """

    pattern: sparse.Pattern
    pos: np.ndarray
    diag: np.ndarray


class Problem:
    """Everything about one minimization that does not change between iterations.

    **Attributes:** ``mesh``, ``en`` (the :class:`~jaxparam.Energy` without its parameters,
    :attr:`~jaxparam.Energy.static`), ``params`` (its parameters), ``F (m, 3)`` faces,
    ``frames (m, 3, 2)`` and ``areas (m,)`` of the 3D triangles, ``free (k,)`` the free
    vertices (referenced ones; all of them with ``free_boundary``, else the interior),
    ``base (n, 2)`` the start UVs (NaN rows zeroed), ``x0 (2 k,)`` the start's free DOFs,
    ``free_boundary``.  The methods take and return host (NumPy) values.
    """

    def __init__(self, mesh, en, free_boundary: bool, uv0):
        t = mesh.topology
        self.mesh, self.en = mesh, en.static
        self.params = jax.tree_util.tree_map(jnp.asarray, en.params)
        self.F = mesh.faces
        V = jnp.asarray(mesh.vertices, dtype=jnp.float64)
        self.frames = geo.local_frames(V, self.F)
        self.areas = geo.face_areas(V, self.F)
        self.free = free_vertices(t, free_boundary)
        if self.free.size == 0:
            raise SolverError("minimize: no free vertex to optimize (every vertex is on the fixed "
                              "boundary); use free_boundary=True.", stage="init")
        base = np.nan_to_num(np.asarray(uv0, np.float64))
        self.base = jnp.asarray(base)
        self.x0 = jnp.asarray(base[self.free].reshape(-1))
        self.free_boundary = free_boundary

    @property
    def arrays(self) -> tuple:
        """``(base, free, F, frames, areas, params)``: what the energy kernels take after
        ``x``."""
        return self.base, self.free, self.F, self.frames, self.areas, self.params

    def uv(self, x):
        """The ``(n, 2)`` UVs (a JAX array) of the free DOFs ``x``."""
        return uv_of(jnp.asarray(x), self.base, self.free)

    def value(self, x) -> float:
        """The energy at ``x``."""
        return float(energy_value(jnp.asarray(x), *self.arrays, en=self.en))

    def value_and_grad(self, x):
        """``(energy, gradient (2 k,))`` at ``x``."""
        f, g = energy_value_and_grad(jnp.asarray(x), *self.arrays, en=self.en)
        return float(f), np.asarray(g)

    def flipped(self, x) -> int:
        """How many faces are inverted or degenerate at ``x``."""
        return int(count_flipped(jnp.asarray(x), self.base, self.free, self.F))

    def max_step(self, x, d) -> float:
        """The largest flip-free step from ``x`` along ``d`` (``inf`` when unbounded)."""
        return float(max_step_along(jnp.asarray(x), jnp.asarray(d), self.base, self.free, self.F))

    @functools.cached_property
    def jacobian_maps(self):
        """``(m, 4, 6)`` maps ``vec J = D q`` (:func:`jacobian_maps`), computed on first use."""
        return jacobian_maps(self.frames)

    @functools.cached_property
    def hessian_pattern(self) -> HessianPattern:
        """The sparse Hessian's :class:`HessianPattern`, computed on first use."""
        n = self.mesh.n_vertices
        slot = np.full(n, -1, np.int64)
        slot[self.free] = np.arange(self.free.size)
        s = slot[self.F]                                            # (m, 3)
        dof = np.where(s[:, :, None] >= 0, 2 * s[:, :, None] + np.arange(2), -1).reshape(-1, 6)
        r = np.repeat(dof, 6, axis=1)                               # (m, 36) row dofs
        c = np.tile(dof, (1, 6))                                    # (m, 36) col dofs
        ok = (r >= 0) & (c >= 0)
        N = 2 * self.free.size
        key = np.where(ok, r * np.int64(N) + c, -1).reshape(-1)
        uniq, inv = np.unique(key[key >= 0], return_inverse=True)
        pos = np.full(key.size, -1, np.int64)
        pos[key >= 0] = inv
        rows, cols = uniq // N, uniq % N
        indptr = np.zeros(N + 1, np.int64)
        np.cumsum(np.bincount(rows, minlength=N), out=indptr[1:])
        diag = np.searchsorted(uniq, np.arange(N) * np.int64(N) + np.arange(N))
        return HessianPattern(sparse.Pattern(indptr, cols, N), pos, diag)

    def normalize(self, x):
        """Free boundary, scale-invariant energy: recentre and rescale to the start's area
        (on the host; :func:`normalized` is the same map in JAX)."""
        uv = np.asarray(self.uv(x))[self.free]
        U0 = np.asarray(self.x0).reshape(-1, 2)
        a0 = float(np.sum(np.asarray(geo.signed_areas(self.uv(self.x0), self.F))))
        a = float(np.sum(np.asarray(geo.signed_areas(self.uv(x), self.F))))
        uv = (uv - uv.mean(0)) * np.sqrt(a0 / a) + U0.mean(0)
        return uv.reshape(-1)


def normalized(x, base, free, F):
    """:meth:`Problem.normalize` in JAX (differentiable in ``x`` and in the start ``base``):
    the free UVs of ``x`` recentred on the start's free UVs' mean and rescaled to the
    start's signed UV area."""
    uv = uv_of(x, base, free)
    U, U0 = uv[free], base[free]
    a0 = jnp.sum(geo.signed_areas(base, F))
    a = jnp.sum(geo.signed_areas(uv, F))
    U = (U - U.mean(0, keepdims=True)) * jnp.sqrt(a0 / a) + U0.mean(0, keepdims=True)
    return U.reshape(-1)
