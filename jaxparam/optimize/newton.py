"""Projected Newton: per-face Hessians projected to positive semi-definite (analytic
eigensystems for functions of the singular values, clamped ``eigh`` otherwise),
assembled on the problem's fixed pattern and factorized by :mod:`jaxparam.sparse`."""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .. import geometry as geo
from .. import sparse
from .. import tol
from ..errors import SolverError
from .base import HostLoopSolver, Step
from .in_callback import inside_host_callback
from .padding import bucket
from .problem import Problem, uv_of
from .search import flip_free_armijo

__all__ = ["Newton", "projected_sv_hessian", "psd_project", "jacobi_eigh", "face_hessians",
           "sparse_hessian"]


def projected_sv_hessian(J, f):
    """PSD projection of the 4x4 Hessian of ``f(s1, s2)`` in ``vec J`` (row-major), in closed
    form (Smith, De Goes, Kim 2019, "Analytic eigensystems for isotropic distortion energies").

    With the signed SVD ``J = U diag(s1, s2) V^T``, the eigenvectors are the two scaling
    modes ``U diag(1, 0) V^T`` and ``U diag(0, 1) V^T`` (coupled by the 2x2 Hessian of f),
    the twist ``U [[0, -1], [1, 0]] V^T / sqrt 2`` with eigenvalue ``(f1 + f2) / (s1 + s2)`` and
    the flip ``U [[0, 1], [1, 0]] V^T / sqrt 2`` with ``(f1 - f2) / (s1 - s2)`` (its limit
    ``f11 - f12`` when ``s1 = s2``).  Negative eigenvalues are clamped to zero.
    """
    a, b, c, d = J[0, 0], J[0, 1], J[1, 0], J[1, 1]
    E, F, G, H = 0.5 * (a + d), 0.5 * (a - d), 0.5 * (c + b), 0.5 * (c - b)
    s1, s2 = geo.singular_values(J)
    a1, a2 = jnp.arctan2(G, F), jnp.arctan2(H, E)
    th, ph = 0.5 * (a2 - a1), 0.5 * (a2 + a1)
    rot = lambda t: jnp.array([[jnp.cos(t), -jnp.sin(t)], [jnp.sin(t), jnp.cos(t)]])
    U, V = rot(ph), rot(-th)
    g = jax.grad(lambda s: f(s[0], s[1]))(jnp.stack([s1, s2]))
    h = jax.hessian(lambda s: f(s[0], s[1]))(jnp.stack([s1, s2]))
    # U M V^T = sum_ij M_ij u_i v_j^T, as outer products of the columns (elementwise under
    # vmap: a batched 2x2 matmul costs more on the CPU).
    mode = lambda i, j: jnp.outer(U[:, i], V[:, j]).reshape(-1)
    d1, d2 = mode(0, 0), mode(1, 1)
    tw = (mode(1, 0) - mode(0, 1)) / jnp.sqrt(2.0)
    fl = (mode(0, 1) + mode(1, 0)) / jnp.sqrt(2.0)
    gap = s1 - s2
    close = jnp.abs(gap) <= 1e-8 * jnp.abs(s1)
    lam_flip = jnp.where(close, h[0, 0] - h[0, 1], (g[0] - g[1]) / jnp.where(close, 1.0, gap))
    lam_twist = (g[0] + g[1]) / (s1 + s2)
    # The 2x2 scaling block, projected in closed form.
    p_, r_, q_ = h[0, 0], h[0, 1], h[1, 1]
    mid, rad = 0.5 * (p_ + q_), jnp.sqrt(0.25 * (p_ - q_) ** 2 + r_ ** 2)
    psi = 0.5 * jnp.arctan2(2 * r_, p_ - q_)
    e_plus = jnp.cos(psi) * d1 + jnp.sin(psi) * d2
    e_minus = -jnp.sin(psi) * d1 + jnp.cos(psi) * d2
    out = (jnp.maximum(mid + rad, 0.0) * jnp.outer(e_plus, e_plus)
           + jnp.maximum(mid - rad, 0.0) * jnp.outer(e_minus, e_minus)
           + jnp.maximum(lam_twist, 0.0) * jnp.outer(tw, tw)
           + jnp.maximum(lam_flip, 0.0) * jnp.outer(fl, fl))
    return out


def psd_project(H, *, lapack: bool = True):
    """Clamp the eigenvalues of symmetric matrices ``(..., k, k)`` at zero: by LAPACK's
    ``eigh``, or with ``lapack=False`` by :func:`jacobi_eigh` (for kernels run inside a
    host callback: :mod:`~jaxparam.optimize.in_callback` says why)."""
    lam, U = (jnp.linalg.eigh if lapack else jacobi_eigh)(0.5 * (H + jnp.swapaxes(H, -1, -2)))
    return jnp.einsum("...ij,...j,...kj->...ik", U, jnp.maximum(lam, 0.0), U)


def jacobi_eigh(A):
    """``(lam (..., k), U (..., k, k))`` of symmetric ``A (..., k, k)`` by cyclic Jacobi
    rotations (Golub & Van Loan, Alg. 8.5.3) in plain XLA operations: no LAPACK call, so no
    thread-pool split.  Converges quadratically; ``k + 2`` sweeps reach rounding for the 4x4
    and 6x6 face Hessians (projections within 4e-15 of ``eigh``'s on 22k random ones;
    ``tests/test_optimize.py``), at 1.5-8x ``eigh``'s time on the CPU."""
    k = A.shape[-1]
    U = jnp.broadcast_to(jnp.eye(k, dtype=A.dtype), A.shape)

    def rotate(M, p, q, c, s, rows):
        # columns (and, with rows, rows) p and q of M turned by the rotation (c, s)
        Mp, Mq = M[..., :, p], M[..., :, q]
        M = M.at[..., :, p].set(c * Mp - s * Mq).at[..., :, q].set(s * Mp + c * Mq)
        if rows:
            Mp, Mq = M[..., p, :], M[..., q, :]
            M = M.at[..., p, :].set(c * Mp - s * Mq).at[..., q, :].set(s * Mp + c * Mq)
        return M

    def sweep(carry, _):
        A, U = carry
        for p in range(k - 1):
            for q in range(p + 1, k):
                apq = A[..., p, q]
                zero = apq == 0
                theta = (A[..., q, q] - A[..., p, p]) / (2 * jnp.where(zero, 1.0, apq))
                # the smaller root of t^2 + 2 theta t - 1 = 0 (t = tan of the rotation)
                t = jnp.where(theta >= 0, 1.0, -1.0) / (jnp.abs(theta) + jnp.sqrt(theta * theta + 1))
                t = jnp.where(zero, 0.0, t)
                c = 1 / jnp.sqrt(t * t + 1)
                s = (t * c)[..., None]
                c = c[..., None]
                A, U = rotate(A, p, q, c, s, True), rotate(U, p, q, c, s, False)
        return (A, U), None

    (A, U), _ = jax.lax.scan(sweep, (A, U), None, length=k + 2)
    return jnp.diagonal(A, axis1=-2, axis2=-1), U


@functools.partial(jax.jit, static_argnames=("en", "project", "lapack"))
def face_hessians(x, base, free, F, frames, areas, params, D, *, en, project, lapack=True):
    """``(m, 6, 6)`` Hessians of each face's weighted density in its corners' UVs.

    For densities of the Jacobian alone (``en.of_J``), ``J`` is linear in the UVs,
    ``vec J = D q`` (``D`` from :func:`jaxparam.optimize.problem.jacobian_maps`), so
    ``H_q = D^T H_J D`` with the 4x4 ``H_J``: projecting ``H_J`` to PSD projects ``H_q``
    too, at a fraction of the cost; with ``en.of_sv`` the projection is analytic
    (:func:`projected_sv_hessian`).  Non-finite entries are zeroed.  ``params``: the
    energy's parameters (``en`` is static, without them).  ``lapack``: as in
    :func:`psd_project` (False inside a host callback).
    """
    Q = uv_of(x, base, free)[F].reshape(-1, 6)
    w = areas / jnp.sum(areas)
    fns = en.densities(params)
    if fns.of_J is not None:
        J = jnp.einsum("mij,mj->mi", D, Q)
        if project and fns.of_sv is not None:
            HJ = jax.vmap(lambda JJ: projected_sv_hessian(JJ.reshape(2, 2), fns.of_sv))(J)
        else:
            HJ = jax.vmap(jax.hessian(lambda JJ: fns.of_J(JJ.reshape(2, 2))))(J)
            if project:
                HJ = psd_project(jnp.where(jnp.isfinite(HJ), HJ, 0.0), lapack=lapack)
        HJ = jnp.where(jnp.isfinite(HJ), HJ, 0.0)
        H = _pull_back(HJ, D)
    else:
        def h(frame, q):
            return jax.hessian(lambda qq: fns.density(frame, qq.reshape(3, 2)))(q)
        H = jax.vmap(h)(frames, Q)
        H = jnp.where(jnp.isfinite(H), H, 0.0)
        if project:
            H = psd_project(H, lapack=lapack)
    return H * w[:, None, None]


def _pull_back(HJ, D):
    """``(m, 6, 6)``: ``D^T H_J D`` for symmetric ``H_J (m, 4, 4)`` and the Jacobian maps
    ``D (m, 4, 6)`` (:func:`~jaxparam.optimize.problem.jacobian_maps`).

    ``J = [q1 - q0, q2 - q0] P^{-1}``: row ``i`` of ``J`` depends on the corners' ``i``-th
    UV coordinate only, so ``D[2 i + c, 2 a + i] = G[c, a]`` with ``G = D[:, 0:2, 0::2]``
    (``(m, 2, 3)``, the face's gradient operator) and zero elsewhere.  The 21 distinct
    entries are written out on ``(m,)`` columns, which XLA fuses into one loop: 4x
    faster on the CPU than a batched ``einsum`` of the dense 4x6 maps.
    """
    g = [[D[:, c, 2 * a] for a in range(3)] for c in range(2)]
    h = [[HJ[:, k, l] for l in range(4)] for k in range(4)]
    # (H_J D)[k, 2 b + j] = sum_d H_J[k, 2 j + d] G[d, b]
    T = [[h[k][2 * j] * g[0][b] + h[k][2 * j + 1] * g[1][b] for b in range(3) for j in range(2)]
         for k in range(4)]
    out = [[None] * 6 for _ in range(6)]
    for r in range(6):
        a, i = divmod(r, 2)
        for col in range(r, 6):     # (D^T H_J D)[2 a + i, col] = sum_c G[c, a] (H_J D)[2 i + c, col]
            out[r][col] = out[col][r] = g[0][a] * T[2 * i][col] + g[1][a] * T[2 * i + 1][col]
    return jnp.stack([jnp.stack(row, axis=-1) for row in out], axis=-2)


@functools.partial(jax.jit, static_argnames=("nnz",))
def _assemble(H, pos, *, nnz):
    flat = H.reshape(-1)
    ok = pos >= 0
    return jax.ops.segment_sum(jnp.where(ok, flat, 0.0), jnp.where(ok, pos, 0), num_segments=nnz)


def sparse_hessian(problem: Problem, x, *, project: bool = True) -> np.ndarray:
    """The ``(nnz,)`` values of the energy's Hessian at ``x`` on ``problem.hessian_pattern``
    (a writable host array), each face's block PSD-projected when ``project``.  Evaluated
    on the problem's padded arrays (:attr:`Problem.padded`): the face Hessians at the
    bucketed face count, then summed into the slots on the host (:attr:`Problem.assembly`)
    on the CPU, or by a device scatter into a bucketed ``nnz`` elsewhere."""
    hp, p = problem.hessian_pattern, problem.padded
    H = face_hessians(p.x(x), *problem.padded_arrays, p.D, en=problem.en, project=project,
                      lapack=not inside_host_callback())
    if jax.default_backend() == "cpu":
        # SciPy's CSR product sums the same terms in the same order as the scatter below,
        # 3.4x faster (single-threaded C against XLA's CPU scatter): bitwise equal values.
        return problem.assembly @ np.asarray(H).reshape(-1)
    nnz = hp.pattern.nnz
    vals = _assemble(H, problem.padded_positions, nnz=bucket(nnz))
    return np.array(np.asarray(vals)[:nnz])


@dataclass(frozen=True)
class Newton(HostLoopSolver):
    """Projected Newton with the flip-free Armijo search (the default solver, ``"newton"``).

    Each iteration assembles the PSD-projected Hessian, adds
    ``regularization * max(mean diag, 1e-300)`` to its diagonal (plus
    ``free_boundary_shift * mean diag`` with a free boundary, for the translation and
    rotation null space), factorizes it (:func:`jaxparam.sparse.factorize`, Cholesky, the
    symbolic analysis reused), solves for the direction and searches along it
    (:func:`jaxparam.optimize.search.flip_free_armijo`).  With a free boundary and a
    scale-invariant energy every iterate is recentred and rescaled to the start's area.

    **Fields:**

    - ``regularization``: relative diagonal shift of every Hessian (default ``1e-10``).
    - ``free_boundary_shift``: extra relative shift with a free boundary (``1e-8``).
    - ``residual_tol``: relative residual the direct solve must reach
      (``tol.NEWTON_RESIDUAL``); a Hessian whose solve misses it is shifted further
      (``tol.NEWTON_FALLBACK_SHIFT``) and its direction kept if it descends.
    - ``patience``: consecutive iterations of relative energy decrease below
      ``energy_rtol`` before stopping (``1``).
    """

    name: ClassVar[str] = "newton"
    normalize_each_step: ClassVar[bool] = True

    regularization: float = 1e-10
    free_boundary_shift: float = 1e-8
    residual_tol: float = tol.NEWTON_RESIDUAL
    patience: int = 1

    def step(self, problem: Problem, state, x, f: float, g):
        P = problem.hessian_pattern.pattern
        diag = problem.hessian_pattern.diag
        vals = sparse_hessian(problem, x)
        vals[diag] += self.regularization * max(float(np.mean(vals[diag])), 1e-300) + (
            self.free_boundary_shift * float(np.mean(vals[diag])) if problem.free_boundary else 0.0)
        fac = sparse.factorize(P, vals, symmetric=True)
        try:
            d = -fac.solve(g, residual_tol=self.residual_tol)
        except SolverError as exc:
            d = self._shifted_direction(P, vals, diag, g, exc)
        x_new, f_new, t = flip_free_armijo(problem, x, f, g, d)
        return Step(x_new, f_new, t), state

    def _shifted_direction(self, P, vals, diag, g, exc: SolverError) -> np.ndarray:
        """A direction from a Hessian too badly conditioned for its solve to reach
        ``residual_tol`` (camelhead scaled 1000 : 1 : 0.01 under the ``angle`` energy left
        1.45e-6): the diagonal is shifted by ``NEWTON_FALLBACK_SHIFT`` of its mean, as
        Levenberg-Marquardt would, and the direction is kept if it descends (the flip-free
        search then checks the step); else the solve's error is raised."""
        shifted = vals.copy()
        shifted[diag] += tol.NEWTON_FALLBACK_SHIFT * max(float(np.mean(vals[diag])), 1e-300)
        d = -sparse.factorize(P, shifted, symmetric=True).solve(g, residual_tol=np.inf)
        if not (np.all(np.isfinite(d)) and float(np.vdot(g, d)) < 0):
            raise exc
        return d
