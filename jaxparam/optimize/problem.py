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
from .padding import Padded, bucket, pad_positions, padded_arrays

__all__ = ["Problem", "HessianPattern", "uv_of", "energy_at", "energy_value",
           "energy_value_and_grad", "count_flipped", "max_step_along", "jacobian_maps",
           "free_vertices", "normalized", "hessian_pattern", "face_energies", "face_energies_of",
           "face_energies_and_steps", "Blocks"]


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


def _weighted_densities(uv, F, frames, areas, params, en):
    """``|T| f_T (m,)``: each face's weight times its density (:func:`jaxparam.energies.total`'s
    terms before the division by ``sum |T|``)."""
    return areas * jax.vmap(en.densities(params).density)(frames, uv[F])


@functools.partial(jax.jit, static_argnames=("en",))
def face_energies(x, base, free, F, frames, areas, params, *, en):
    """Per face at ``x``: ``(terms (m,), signed UV areas (m,))``, the terms ``|T| f_T``
    (divided by ``sum |T|``, they sum to the mesh energy)."""
    uv = uv_of(x, base, free)
    return _weighted_densities(uv, F, frames, areas, params, en), geo.signed_areas(uv, F)


@functools.partial(jax.jit, static_argnames=("en",))
def face_energies_of(x, base, free, F, frames, areas, idx, params, *, en):
    """:func:`face_energies` on the faces ``idx (j,)`` only: ``(|T| f_T (j,), signed UV
    areas (j,))``."""
    uv = uv_of(x, base, free)
    return (_weighted_densities(uv, F[idx], frames[idx], areas[idx], params, en),
            geo.signed_areas(uv, F[idx]))


@functools.partial(jax.jit, static_argnames=("en",))
def face_energies_and_steps(x, d, base, free, F, frames, areas, params, *, en):
    """:func:`face_energies`' terms at ``x`` and :func:`jaxparam.geometry.max_steps` (per
    face) from ``x`` along ``d``: ``(terms (m,), steps (m,))``."""
    D = jnp.zeros_like(base).at[free].set(d.reshape(-1, 2))
    uv = uv_of(x, base, free)
    return _weighted_densities(uv, F, frames, areas, params, en), geo.max_steps(uv, D, F)


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


@functools.lru_cache(maxsize=8)
def hessian_pattern(topology, free: bytes) -> HessianPattern:
    """The :class:`HessianPattern` of the faces of ``topology`` over the free vertices
    (``free``: their ``int64`` indices as bytes, the cache key), built once per pair: a
    minimization's first iteration then costs no pattern build and no PARDISO analysis when
    the same mesh is minimized again (issue 17)."""
    free = np.frombuffer(free, np.int64)
    F, K = topology.faces, free.size
    slot = np.full(topology.n_vertices, -1, np.int64)
    slot[free] = np.arange(K)
    s = slot[F]                                                 # (m, 3) free slots, -1 fixed
    # The 2x2 blocks of vertex pairs (p, q) first (9 a face: 4x fewer keys to sort than the
    # 36 dof pairs), then each block's 4 entries placed arithmetically.
    a, b = np.divmod(np.arange(9), 3)
    r, c = s[:, a], s[:, b]                                     # (m, 9)
    ok = (r >= 0) & (c >= 0)
    uniq, inv = np.unique((r * np.int64(K) + c)[ok], return_inverse=True)
    block = np.full(r.shape, -1, np.int64)
    block[ok] = inv
    vr, vq = uniq // K, uniq % K                                # block row and column vertex
    deg = np.bincount(vr, minlength=K)                          # blocks in each vertex row
    vs = np.zeros(K + 1, np.int64)
    np.cumsum(deg, out=vs[1:])
    N = 2 * K
    # dof row 2p+i holds, for each block (p, q) of vertex row p in order, columns 2q, 2q+1.
    indptr = np.empty(N + 1, np.int64)
    indptr[0:N:2], indptr[1:N:2], indptr[N] = 4 * vs[:-1], 4 * vs[:-1] + 2 * deg, 4 * vs[-1]

    def entry(k, i, j):
        """CSR slot of entry (i, j) of block ``k``."""
        p = vr[k]
        return 4 * vs[p] + i * 2 * deg[p] + 2 * (k - vs[p]) + j

    cols = np.empty(4 * uniq.size, np.int64)
    pos = np.full((F.shape[0], 6, 6), -1, np.int64)             # face entry (2a+i, 2b+j)
    kf = block.reshape(-1, 3, 3)
    for i in range(2):
        for j in range(2):
            cols[entry(np.arange(uniq.size), i, j)] = 2 * vq + j
            pos[:, i::2, j::2] = np.where(kf >= 0, entry(np.maximum(kf, 0), i, j), -1)
    kpp = np.searchsorted(uniq, np.arange(K) * np.int64(K) + np.arange(K))
    diag = np.empty(N, np.int64)
    diag[0::2], diag[1::2] = entry(kpp, 0, 0), entry(kpp, 1, 1)
    return HessianPattern(sparse.Pattern(indptr, cols, N), pos.reshape(-1), diag)


@dataclass(frozen=True)
class Blocks:
    """A problem made of disconnected pieces (e.g. an atlas's charts): its energy is the sum
    of the pieces' energies and no face couples two pieces, so each piece can take its own
    step (:func:`jaxparam.optimize.search.flip_free_armijo`).

    **Fields:** ``face (M,)`` each padded face's piece (the ghost faces in piece ``n``),
    ``dof (2 k,)`` each free DOF's piece, ``n`` the piece count; ``order (M,)`` the faces
    sorted by piece and ``starts (n + 1,)`` where each piece begins in it (every piece,
    the ghosts' included, has a face)."""

    face: np.ndarray
    dof: np.ndarray
    n: int
    order: np.ndarray
    starts: np.ndarray

    def face_min(self, values: np.ndarray) -> np.ndarray:
        """``(n + 1,)``: the smallest of ``values (M,)`` over each piece's faces."""
        return np.minimum.reduceat(values[self.order], self.starts)

    def faces_of(self, pieces: np.ndarray) -> np.ndarray:
        """The faces of ``pieces (j,)`` (int), piece after piece."""
        pieces = np.asarray(pieces, np.int64)
        ends = np.r_[self.starts[1:], self.order.size][pieces]
        cnt = ends - self.starts[pieces]
        pos = np.repeat(self.starts[pieces] - (np.cumsum(cnt) - cnt), cnt) + np.arange(cnt.sum())
        return self.order[pos]


class Problem:
    """Everything about one minimization that does not change between iterations.

    **Attributes:** ``mesh``, ``en`` (the :class:`~jaxparam.Energy` without its parameters,
    :attr:`~jaxparam.Energy.static`), ``params`` (its parameters), ``F (m, 3)`` faces,
    ``frames (m, 3, 2)`` and ``areas (m,)`` of the 3D triangles, ``free (k,)`` the free
    vertices (referenced ones; all of them with ``free_boundary``, else the interior),
    ``base (n, 2)`` the start UVs (NaN rows zeroed), ``x0 (2 k,)`` the start's free DOFs,
    ``free_boundary``.  The methods take and return host (NumPy) values; they, and
    Newton's Hessian, evaluate the kernels on :attr:`padded` (the arrays at bucket sizes,
    :mod:`jaxparam.optimize.padding`), so problems of similar size share compiled code;
    ``frames`` and ``areas`` (unpadded) are computed on first use.

    ``areas (m,)``, when given, replaces the 3D areas as each face's weight in the energy's
    sum (e.g. :func:`jaxparam.remesh.area_aware_map`'s per-face density weights).

    ``face_blocks (m,) int``, when given, labels pieces of the mesh that share no vertex
    (the atlas's charts): the line search then steps each piece on its own (:attr:`blocks`).
    """

    def __init__(self, mesh, en, free_boundary: bool, uv0, areas=None, face_blocks=None):
        t = mesh.topology
        self.mesh, self.en = mesh, en.static
        self.params = jax.tree_util.tree_map(jnp.asarray, en.params)
        self.F = mesh.faces
        self._areas = areas
        self.free = free_vertices(t, free_boundary)
        if self.free.size == 0:
            raise SolverError("minimize: no free vertex to optimize (every vertex is on the fixed "
                              "boundary); use free_boundary=True.", stage="init")
        base = np.nan_to_num(np.asarray(uv0, np.float64))
        # device_put, not jnp.asarray: that compiles a conversion kernel per new shape here
        self.base = jax.device_put(base)
        self.x0 = jax.device_put(base[self.free].reshape(-1))
        self.free_boundary = free_boundary
        self._face_blocks = None if face_blocks is None else np.asarray(face_blocks, np.int64)

    @functools.cached_property
    def blocks(self) -> Blocks | None:
        """The :class:`Blocks` of ``face_blocks`` (``None`` without): the pieces of the
        padded faces and of the free DOFs."""
        if self._face_blocks is None:
            return None
        fb, F = self._face_blocks, np.asarray(self.F)
        n = int(fb.max()) + 1 if fb.size else 0
        vb = np.full(self.mesh.n_vertices, n, np.int64)
        vb[F.reshape(-1)] = np.repeat(fb, 3)
        M = int(self.padded.F.shape[0])
        face = np.full(M + 1, n, np.int64)          # one ghost slot more: piece n has a face
        face[:fb.size] = fb
        order = np.argsort(face[:M], kind="stable")
        starts = np.searchsorted(face[:M][order], np.arange(n + 1))
        if M == fb.size:                            # no ghost face: piece n borrows face 0
            order, starts = np.r_[order, 0], np.r_[starts[:n], M]
        return Blocks(face=face[:M], dof=np.repeat(vb[self.free], 2), n=n, order=order,
                      starts=starts)

    @functools.cached_property
    def frames(self):
        """``(m, 3, 2)``: the 3D triangles in their own frames (computed on first use)."""
        return geo.local_frames(jnp.asarray(self.mesh.vertices, dtype=jnp.float64), self.F)

    @functools.cached_property
    def areas(self):
        """``(m,)``: each face's weight (the 3D areas unless ``areas`` was given)."""
        if self._areas is not None:
            return jnp.asarray(self._areas, dtype=jnp.float64)
        return geo.face_areas(jnp.asarray(self.mesh.vertices, dtype=jnp.float64), self.F)

    @functools.cached_property
    def padded(self) -> Padded:
        """The kernels' arrays at bucket sizes (:mod:`jaxparam.optimize.padding`): what the
        host methods below and Newton's Hessian evaluate, so that problems of similar size
        share compiled code."""
        return padded_arrays(self.mesh.vertices, self.F, self.free, self._host_base, self._areas)

    @property
    def arrays(self) -> tuple:
        """``(base, free, F, frames, areas, params)``: what the energy kernels take after
        ``x`` (unpadded: the traced and optimistix paths)."""
        return self.base, self.free, self.F, self.frames, self.areas, self.params

    @property
    def padded_arrays(self) -> tuple:
        """:attr:`arrays` at bucket sizes (after the padded ``x``, :meth:`Padded.x`)."""
        p = self.padded
        return p.base, p.free, p.F, p.frames, p.areas, self.params

    def uv(self, x):
        """The ``(n, 2)`` UVs (a JAX array) of the free DOFs ``x``."""
        if isinstance(x, jax.core.Tracer):
            return uv_of(x, self.base, self.free)
        return jax.device_put(self._host_uv(np.asarray(x, np.float64).reshape(-1, 2)))

    def value(self, x) -> float:
        """The energy at ``x``."""
        return float(energy_value(self.padded.x(x), *self.padded_arrays, en=self.en))

    def value_and_grad(self, x):
        """``(energy, gradient (2 k,))`` at ``x``."""
        f, g = energy_value_and_grad(self.padded.x(x), *self.padded_arrays, en=self.en)
        return float(f), np.asarray(g)[:2 * self.free.size]

    def flipped(self, x) -> int:
        """How many faces are inverted or degenerate at ``x``."""
        p = self.padded
        return int(count_flipped(p.x(x), p.base, p.free, p.F))

    def max_step(self, x, d) -> float:
        """The largest flip-free step from ``x`` along ``d`` (``inf`` when unbounded)."""
        p = self.padded
        return float(max_step_along(p.x(x), p.x(d), p.base, p.free, p.F))

    def face_energies(self, x):
        """``(terms (M,), signed areas (M,))`` at ``x`` on the padded faces, the terms
        ``|T| f_T / sum |T|`` summing to the energy (:func:`face_energies`; the ghost
        faces' terms are 0, their areas positive)."""
        p = self.padded
        e, a = face_energies(p.x(x), *self.padded_arrays, en=self.en)
        return np.asarray(e) / self._total_weight, np.asarray(a)

    def face_energies_of(self, x, faces: np.ndarray):
        """:meth:`face_energies` on the padded faces ``faces (j,)`` alone: ``(terms (j,),
        signed areas (j,))``, evaluated at a bucketed length (:func:`face_energies_of`)."""
        faces = np.asarray(faces, np.int64)
        j = faces.size
        idx = np.full(bucket(j), faces[0] if j else 0, np.int64)
        idx[:j] = faces
        e, a = face_energies_of(self.padded.x(x), *self.padded_arrays[:5], jax.device_put(idx),
                                self.params, en=self.en)
        return np.asarray(e)[:j] / self._total_weight, np.asarray(a)[:j]

    @functools.cached_property
    def _total_weight(self) -> float:
        return float(np.sum(np.asarray(self.padded.areas)))

    def face_energies_and_steps(self, x, d):
        """``(terms (M,), steps (M,))``: :meth:`face_energies`' terms at ``x`` and each
        padded face's largest flip-free step from ``x`` along ``d``."""
        p = self.padded
        base, free, F, frames, areas, params = self.padded_arrays
        e, t = face_energies_and_steps(p.x(x), p.x(d), base, free, F, frames, areas, params,
                                       en=self.en)
        return np.asarray(e) / self._total_weight, np.asarray(t)

    @functools.cached_property
    def jacobian_maps(self):
        """``(m, 4, 6)`` maps ``vec J = D q`` (:func:`jacobian_maps`), computed on first use."""
        return jacobian_maps(self.frames)

    @functools.cached_property
    def hessian_pattern(self) -> HessianPattern:
        """The sparse Hessian's :class:`HessianPattern` (:func:`hessian_pattern`: one per
        topology and free set, so a second minimization reuses it, and PARDISO its symbolic
        analysis)."""
        return hessian_pattern(self.mesh.topology, np.asarray(self.free, np.int64).tobytes())

    @functools.cached_property
    def assembly(self):
        """``(nnz, M * 36)`` SciPy CSR matrix of ones, ``M`` the padded face count:
        ``assembly @ H.reshape(-1)`` sums the face Hessians ``H (M, 6, 6)`` into
        :attr:`hessian_pattern`'s slots, each slot's terms in face order, as the device
        scatter does (:func:`jaxparam.optimize.newton.sparse_hessian`, on the CPU).  Built as
        the transpose of the one-entry-a-row map from face entries to slots (a counting sort
        in SciPy): 0.6 s at 363k faces, where one assembly costs 0.07 s against the XLA
        scatter's 0.24 s (benchmarks/README.md, session 14)."""
        import scipy.sparse as sps

        pos = pad_positions(self.hessian_pattern.pos, int(self.padded.F.shape[0]))
        nnz = self.hessian_pattern.pattern.nnz
        ok = pos >= 0
        idx = np.int32 if max(pos.size, nnz) < 2 ** 31 else np.int64
        indptr = np.zeros(pos.size + 1, idx)
        np.cumsum(ok, out=indptr[1:])
        to_slot = sps.csr_matrix((np.ones(int(indptr[-1])), pos[ok].astype(idx), indptr),
                                 shape=(pos.size, nnz))
        return to_slot.T.tocsr()

    @functools.cached_property
    def padded_positions(self):
        """``(M * 36,)`` device array: :attr:`hessian_pattern`'s ``pos`` at the padded face
        count (``-1``, nowhere, for the ghost faces)."""
        return jax.device_put(pad_positions(self.hessian_pattern.pos, int(self.padded.F.shape[0])))

    def normalize(self, x):
        """Free boundary, scale-invariant energy: recentre and rescale to the start's area
        (in NumPy, no device round trip: :func:`normalized` is the same map in JAX)."""
        U = np.asarray(x, np.float64).reshape(-1, 2)
        a0, centre0 = self._start_area_and_centre
        a = _signed_area_sum(self._host_uv(U), self.F)
        return ((U - U.mean(0)) * np.sqrt(a0 / a) + centre0).reshape(-1)

    def _host_uv(self, U):
        uv = self._host_base.copy()
        uv[self.free] = U
        return uv

    @functools.cached_property
    def _host_base(self):
        return np.asarray(self.base, np.float64)

    @functools.cached_property
    def _start_area_and_centre(self):
        U0 = np.asarray(self.x0, np.float64).reshape(-1, 2)
        return _signed_area_sum(self._host_uv(U0), self.F), U0.mean(0)


def _signed_area_sum(uv, F) -> float:
    """The sum of the signed UV areas of the faces (NumPy twin of ``geo.signed_areas``)."""
    Q = uv[F]
    d1, d2 = Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]
    return float(np.sum(0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])))


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
