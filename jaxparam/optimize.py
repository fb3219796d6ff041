"""Flip-free minimization of distortion energies (survey §6), fixed or free boundary.

:func:`minimize` starts from a one-to-one map (the convex-combination map by
default) and never accepts an iterate with an inverted triangle: every step
along a direction ``d`` is capped by :func:`jaxparam.geometry.max_step` (the
first ``t`` where some triangle's signed area vanishes, times a safety
factor, Smith & Schaefer 2015), and the Armijo backtracking search rejects
any trial with a non-positive signed area or a non-finite energy.

Solvers:

- ``newton``: projected Newton.  Per-triangle 6x6 Hessians from JAX, each
  projected to positive semi-definite by clamping its eigenvalues, assembled
  onto a sparsity pattern computed once, factorized by
  :mod:`jaxparam.sparse` (symbolic analysis reused across iterations).
- ``lbfgs``: optimistix's L-BFGS with the step cap in a descent wrapper
  (:class:`FlipFreeDescent`) and optimistix's backtracking Armijo search;
  the barrier energies' ``+inf`` on inverted triangles rejects any trial
  that would invert one.
- ``bfgs``: optimistix's dense BFGS, the same way (small meshes only).
- ``jaxopt_lbfgs``: jaxopt's L-BFGS (optional extra), stepped with the same
  flip check.

The result is differentiable: ``jax.grad`` of a scalar of ``minimize(...).uv``
with respect to the vertex positions uses implicit differentiation at the
optimum (one solve with the true, unprojected Hessian).
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from . import energies as en_mod
from . import geometry as geo
from . import metrics
from . import sparse
from . import tol
from .errors import MeshError, SolverError

__all__ = ["MinimizeResult", "minimize", "SOLVERS", "FlipFreeDescent"]

SOLVERS = ("newton", "lbfgs", "bfgs", "jaxopt_lbfgs")


@dataclass(frozen=True)
class MinimizeResult:
    """What :func:`minimize` returns.

    **Fields:** ``uv (n, 2)``; ``energy`` (final, area-weighted mean density);
    ``iterations``; ``converged``; ``history`` (energy after each iteration,
    the start first); ``seconds`` (wall time, compilation included);
    ``reason`` (why it stopped); ``flips`` (always 0 from an injective start);
    ``boundary_overlaps`` (free boundary: crossings of the boundary with itself);
    ``times`` (seconds since the start at each entry of ``history``).
    """

    uv: object
    energy: float
    iterations: int
    converged: bool
    history: list = field(repr=False)
    seconds: float
    reason: str
    flips: int
    boundary_overlaps: int
    solver: str = "newton"
    times: list = field(default_factory=list, repr=False)


# ------------------------------------------------------------------------------------------
# The problem: free degrees of freedom, jitted energy, gradient and per-triangle Hessians
# ------------------------------------------------------------------------------------------

def _uv_of(x, base, free):
    return base.at[free].set(x.reshape(-1, 2))


@functools.partial(jax.jit, static_argnames=("en",))
def _value(x, base, free, F, frames, areas, *, en):
    return en_mod.total(en, frames, areas, _uv_of(x, base, free)[F])


@functools.partial(jax.jit, static_argnames=("en",))
def _value_and_grad(x, base, free, F, frames, areas, *, en):
    return jax.value_and_grad(lambda y: en_mod.total(en, frames, areas, _uv_of(y, base, free)[F]))(x)


@jax.jit
def _count_flipped(x, base, free, F):
    return jnp.sum(geo.signed_areas(_uv_of(x, base, free), F) <= 0)


@jax.jit
def _max_step(x, d, base, free, F):
    D = jnp.zeros_like(base).at[free].set(d.reshape(-1, 2))
    return geo.max_step(_uv_of(x, base, free), D, F)


def _projected_sv_hessian(J, f):
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
    mode = lambda M: (U @ M @ V.T).reshape(-1)
    d1, d2 = mode(jnp.diag(jnp.array([1.0, 0.0]))), mode(jnp.diag(jnp.array([0.0, 1.0])))
    tw = mode(jnp.array([[0.0, -1.0], [1.0, 0.0]])) / jnp.sqrt(2.0)
    fl = mode(jnp.array([[0.0, 1.0], [1.0, 0.0]])) / jnp.sqrt(2.0)
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


def _psd(H):
    """Clamp the eigenvalues of symmetric matrices ``(..., k, k)`` at zero."""
    lam, U = jnp.linalg.eigh(0.5 * (H + jnp.swapaxes(H, -1, -2)))
    return jnp.einsum("...ij,...j,...kj->...ik", U, jnp.maximum(lam, 0.0), U)


@jax.jit
def _jacobian_maps(frames):
    """``(m, 4, 6)``: ``vec J = D q`` for each face (J is linear in the corner UVs)."""
    def jac_map(frame):
        return jax.jacfwd(lambda qq: geo.jacobian_from_frame(frame, qq.reshape(3, 2)).reshape(-1))(
            jnp.zeros(6))
    return jax.vmap(jac_map)(frames)


@functools.partial(jax.jit, static_argnames=("en", "project"))
def _face_hessians(x, base, free, F, frames, areas, D, *, en, project):
    """``(m, 6, 6)`` Hessians of each face's weighted density in its corners' UVs.

    For densities of the Jacobian alone (``density.of_J``), ``J`` is linear in the
    UVs, ``vec J = D q`` (``D`` from :func:`_jacobian_maps`, computed once), so
    ``H_q = D^T H_J D`` with the 4x4 ``H_J``: projecting ``H_J`` to PSD projects
    ``H_q`` too, at a fraction of the cost.
    """
    Q = _uv_of(x, base, free)[F].reshape(-1, 6)
    w = areas / jnp.sum(areas)
    of_J = getattr(en.density, "of_J", None)
    if of_J is not None:
        J = jnp.einsum("mij,mj->mi", D, Q)
        of_sv = getattr(en.density, "of_sv", None)
        if project and of_sv is not None:
            HJ = jax.vmap(lambda JJ: _projected_sv_hessian(JJ.reshape(2, 2), of_sv))(J)
        else:
            HJ = jax.vmap(jax.hessian(lambda JJ: of_J(JJ.reshape(2, 2))))(J)
            if project:
                HJ = _psd(jnp.where(jnp.isfinite(HJ), HJ, 0.0))
        HJ = jnp.where(jnp.isfinite(HJ), HJ, 0.0)
        H = jnp.einsum("mai,mab,mbj->mij", D, HJ, D)
    else:
        def h(frame, q):
            return jax.hessian(lambda qq: en.density(frame, qq.reshape(3, 2)))(q)
        H = jax.vmap(h)(frames, Q)
        H = jnp.where(jnp.isfinite(H), H, 0.0)
        if project:
            H = _psd(H)
    return H * w[:, None, None]


@functools.partial(jax.jit, static_argnames=("nnz",))
def _assemble(H, pos, *, nnz):
    flat = H.reshape(-1)
    ok = pos >= 0
    return jax.ops.segment_sum(jnp.where(ok, flat, 0.0), jnp.where(ok, pos, 0), num_segments=nnz)


class _Problem:
    """Everything about one minimization that does not change between iterations."""

    def __init__(self, mesh, en, free_boundary: bool, uv0):
        t = mesh.topology
        self.mesh, self.en = mesh, en
        self.F = mesh.faces
        V = jnp.asarray(mesh.vertices, dtype=jnp.float64)
        self.frames = geo.local_frames(V, self.F)
        self.areas = geo.face_areas(V, self.F)
        free_mask = t.referenced & (np.ones(t.n_vertices, bool) if free_boundary else ~t.is_boundary)
        self.free = np.flatnonzero(free_mask)
        if self.free.size == 0:
            raise SolverError("minimize: no free vertex to optimize (every vertex is on the fixed "
                              "boundary); use free_boundary=True.", stage="init")
        base = np.nan_to_num(np.asarray(uv0, np.float64))
        self.base = jnp.asarray(base)
        self.x0 = jnp.asarray(base[self.free].reshape(-1))
        self.free_boundary = free_boundary
        self._pattern = None
        self._D = None

    def uv(self, x):
        return _uv_of(jnp.asarray(x), self.base, self.free)

    def value(self, x):
        return float(_value(jnp.asarray(x), self.base, self.free, self.F, self.frames, self.areas,
                            en=self.en))

    def value_and_grad(self, x):
        f, g = _value_and_grad(jnp.asarray(x), self.base, self.free, self.F, self.frames,
                               self.areas, en=self.en)
        return float(f), np.asarray(g)

    def flipped(self, x) -> int:
        return int(_count_flipped(jnp.asarray(x), self.base, self.free, self.F))

    def max_step(self, x, d) -> float:
        return float(_max_step(jnp.asarray(x), jnp.asarray(d), self.base, self.free, self.F))

    # -- sparse Hessian on a fixed pattern ------------------------------------------------
    def pattern(self):
        if self._pattern is None:
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
            self._pattern = (sparse.Pattern(indptr, cols, N), pos, diag)
        return self._pattern

    def hessian(self, x, *, project: bool = True):
        P, pos, diag = self.pattern()
        if self._D is None:
            self._D = _jacobian_maps(self.frames)
        H = _face_hessians(jnp.asarray(x), self.base, self.free, self.F, self.frames, self.areas,
                           self._D, en=self.en, project=project)
        vals = np.array(_assemble(H, pos, nnz=P.nnz))
        return P, vals, diag

    def normalize(self, x):
        """Free boundary, scale-invariant energy: recentre and rescale to the start's area."""
        uv = np.asarray(self.uv(x))[self.free]
        U0 = np.asarray(self.x0).reshape(-1, 2)
        a0 = float(np.sum(np.asarray(geo.signed_areas(self.uv(self.x0), self.F))))
        a = float(np.sum(np.asarray(geo.signed_areas(self.uv(x), self.F))))
        uv = (uv - uv.mean(0)) * np.sqrt(a0 / a) + U0.mean(0)
        return uv.reshape(-1)


# ------------------------------------------------------------------------------------------
# Flip-free line search
# ------------------------------------------------------------------------------------------

def _line_search(prob: _Problem, x, f, g, d):
    """Backtracking Armijo along ``d`` from ``min(1, max_step)``; rejects flips and +inf."""
    slope = float(np.dot(g, d))
    if not slope < 0:
        d = -g
        slope = float(np.dot(g, d))
    t = min(1.0, prob.max_step(x, d))
    for _ in range(tol.BACKTRACK_MAX):
        xt = x + t * d
        ft = prob.value(xt)
        if np.isfinite(ft) and ft <= f + tol.ARMIJO_C1 * t * slope and prob.flipped(xt) == 0:
            return xt, ft, t
        t *= tol.BACKTRACK_SHRINK
    return x, f, 0.0


# ------------------------------------------------------------------------------------------
# optimistix: the step cap as a descent wrapper
# ------------------------------------------------------------------------------------------

class _CapState(eqx.Module):
    inner: object
    cap: jax.Array


class FlipFreeDescent(eqx.Module):
    """Wrap an optimistix descent so that its step never inverts a triangle.

    optimistix asks the search for a step size before the new direction exists,
    so the cap lives here: ``query`` computes the inner direction, then the
    largest flip-free step along it (:func:`jaxparam.geometry.max_step`);
    ``step`` scales the search's step size by ``min(1, cap)``.
    """

    inner: object
    base: jax.Array
    free: jax.Array
    faces: jax.Array

    def init(self, y, f_info_struct):
        return _CapState(self.inner.init(y, f_info_struct), jnp.array(1.0))

    def query(self, y, f_info, state):
        s = self.inner.query(y, f_info, state.inner)
        d, _ = self.inner.step(jnp.array(1.0), s)
        uv = _uv_of(y, self.base, self.free)
        D = jnp.zeros_like(self.base).at[self.free].set(d.reshape(-1, 2))
        cap = jnp.minimum(1.0, geo.max_step(uv, D, self.faces))
        return _CapState(s, cap)

    def step(self, step_size, state):
        return self.inner.step(step_size * state.cap, state.inner)


def _optimistix_solver(kind: str, prob: _Problem):
    import optimistix as optx

    base_cls = optx.AbstractLBFGS if kind == "lbfgs" else optx.AbstractBFGS

    class FlipFree(base_cls):
        rtol: float
        atol: float
        norm: object
        use_inverse: bool
        descent: object
        search: object
        verbose: object
        history_length: int = 10

    descent = FlipFreeDescent(optx.NewtonDescent(), prob.base, jnp.asarray(prob.free), jnp.asarray(prob.F))
    kw = dict(rtol=1e-12, atol=1e-12, norm=optx.max_norm, use_inverse=True, descent=descent,
              search=optx.BacktrackingArmijo(), verbose=lambda *a, **k: None)
    solver = FlipFree(**kw)
    return solver


# ------------------------------------------------------------------------------------------
# The driver
# ------------------------------------------------------------------------------------------

def _run(prob: _Problem, solver: str, max_iters: int, energy_rtol: float, grad_rtol: float,
         max_seconds: float | None, verbose: bool):
    from tqdm.auto import tqdm

    t0 = time.perf_counter()
    x = np.asarray(prob.x0)
    f, g = prob.value_and_grad(x)
    if not np.isfinite(f):
        raise SolverError(f"minimize: the start has infinite energy ({prob.en.name}); "
                          "a degenerate or inverted triangle?", stage="init")
    g0 = max(np.linalg.norm(g), np.finfo(float).tiny)
    history = [f]
    times = [time.perf_counter() - t0]
    reason, converged, it = "max_iters", False, 0
    bar = tqdm(total=max_iters, desc=f"{prob.en.name} ({solver})", delay=1.0, disable=not verbose,
               leave=False)
    opt_state = None
    small = 0
    if solver in ("lbfgs", "bfgs"):
        import optimistix as optx

        osolver = _optimistix_solver(solver, prob)
        fn = lambda y, args: (_value(y, prob.base, prob.free, prob.F, prob.frames, prob.areas, en=prob.en), None)
        y = jnp.asarray(x)
        f_struct = jax.ShapeDtypeStruct((), jnp.float64)
        opt_state = osolver.init(fn, y, None, {}, f_struct, None, frozenset())
        step_fn = eqx.filter_jit(lambda y, st: osolver.step(fn, y, None, {}, st, frozenset()))
        term_fn = eqx.filter_jit(lambda y, st: osolver.terminate(fn, y, None, {}, st, frozenset()))
    if solver == "jaxopt_lbfgs":
        try:
            import jaxopt
        except ImportError:
            raise SolverError("minimize: solver 'jaxopt_lbfgs' needs jaxopt (pip install "
                              "'jaxparam[jaxopt]').", stage="init") from None
        jfun = lambda y: _value(y, prob.base, prob.free, prob.F, prob.frames, prob.areas, en=prob.en)
        jsolver = jaxopt.LBFGS(fun=jfun, maxiter=max_iters, linesearch="backtracking", maxls=40,
                               jit=True)
        jstate = jsolver.init_state(jnp.asarray(x))
        jupdate = jax.jit(jsolver.update)
    for it in range(1, max_iters + 1):
        if solver == "newton":
            P, vals, diag = prob.hessian(x)
            vals[diag] += 1e-10 * max(float(np.mean(vals[diag])), 1e-300) + (
                1e-8 * float(np.mean(vals[diag])) if prob.free_boundary else 0.0)
            fac = sparse.factorize(P, vals, symmetric=True)
            d = -fac.solve(g, residual_tol=tol.NEWTON_RESIDUAL)
            x_new, f_new, step = _line_search(prob, x, f, g, d)
        elif solver in ("lbfgs", "bfgs"):
            # optimistix takes search trials; one iteration here is one accepted step.
            y = jnp.asarray(x)
            x_new, f_new, step = x, f, 0.0
            for _ in range(tol.BACKTRACK_MAX):
                y, opt_state, _ = step_fn(y, opt_state)
                yn = np.asarray(y)
                if not np.array_equal(yn, x):
                    fy = prob.value(yn)
                    if np.isfinite(fy) and prob.flipped(yn) == 0 and fy <= f:
                        x_new, f_new, step = yn, fy, 1.0
                        break
                done, _ = term_fn(y, opt_state)
                if bool(done):
                    break
        elif solver == "jaxopt_lbfgs":
            y_new, jstate_new = jupdate(jnp.asarray(x), jstate)
            x_new = np.asarray(y_new)
            f_new = prob.value(x_new)
            if not np.isfinite(f_new) or prob.flipped(x_new) or f_new > f:
                d = x_new - x
                x_new, f_new, step = _line_search(prob, x, f, g, d)
                jstate = jsolver.init_state(jnp.asarray(x_new))
            else:
                jstate, step = jstate_new, 1.0
        else:  # pragma: no cover (checked by minimize)
            raise AssertionError(solver)
        if prob.free_boundary and prob.en.scale_invariant and solver == "newton" and step > 0:
            x_new = prob.normalize(x_new)
            f_new = prob.value(x_new)
        dec = (f - f_new) / max(abs(f), np.finfo(float).tiny)
        x, f = x_new, f_new
        f, g = prob.value_and_grad(x)
        history.append(f)
        times.append(time.perf_counter() - t0)
        bar.update(1)
        small = small + 1 if 0 <= dec < energy_rtol else 0
        if step == 0.0:
            reason, converged = "no further decrease along the search direction", True
            break
        if np.linalg.norm(g) <= grad_rtol * g0:
            reason, converged = "gradient norm below tolerance", True
            break
        if small >= (1 if solver == "newton" else 3):
            reason, converged = "relative energy decrease below tolerance", True
            break
        if max_seconds is not None and time.perf_counter() - t0 > max_seconds:
            reason = "time limit"
            break
    bar.close()
    if prob.free_boundary and prob.en.scale_invariant and solver != "newton":
        x = prob.normalize(x)
        f = prob.value(x)
        history[-1] = f
    return x, f, it, converged, (history, times), reason, time.perf_counter() - t0


def _check_start(mesh, uv0, where="minimize"):
    A = np.asarray(geo.signed_areas(jnp.asarray(np.nan_to_num(np.asarray(uv0, np.float64))), mesh.faces))
    bad = np.flatnonzero(A <= 0)
    if bad.size:
        raise SolverError(
            f"{where}: the start is not injective: {bad.size} of {A.size} triangles are flipped or "
            f"degenerate (first: face {int(bad[0])}); start from a one-to-one map such as "
            "jp.convex_map(mesh) (positive weights, convex boundary).", stage="init")


def minimize(mesh, energy="symmetric_dirichlet", *, init=None, free_boundary: bool = False,
             solver: str = "newton", max_iters: int = 200, energy_rtol: float = tol.ENERGY_RTOL,
             grad_rtol: float = tol.GRAD_RTOL, max_seconds: float | None = None,
             verbose: bool = True) -> MinimizeResult:
    """Minimize a distortion energy over the UVs without ever inverting a triangle.

    **Arguments:**

    - ``mesh``: a disk :class:`~jaxparam.TriMesh` (its vertices may be a JAX
      tracer under ``jax.grad``: the optimum is then differentiated implicitly).
    - ``energy``: a name (``"symmetric_dirichlet"``, ``"mips"``, ``"angle"``, ...) or
      ``jp.energy(f)``.
    - ``init``: ``(n, 2)`` one-to-one start; default ``convex_map(mesh)``
      (shape-preserving weights, circle).  With ``free_boundary`` and a
      scale-dependent energy the start is rescaled to the 3D area.
    - ``free_boundary``: let the boundary move (False: the start's boundary stays).
    - ``solver``: ``"newton"``, ``"lbfgs"``, ``"bfgs"`` or ``"jaxopt_lbfgs"``.
    - ``max_iters``, ``energy_rtol``, ``grad_rtol``, ``max_seconds``: stopping rules.
    - ``verbose``: a progress bar for runs longer than a second.

    **Returns:** a :class:`MinimizeResult`.

    Raises :class:`SolverError` (stage ``"init"``) when the start has a flipped triangle.

    Example::

        res = jp.minimize(mesh, "symmetric_dirichlet", free_boundary=True)
        res.uv, res.energy, res.iterations
    """
    from .linear import convex_map, disk_check

    en = en_mod.get(energy)
    solver = solver.replace("-", "_")
    if solver not in SOLVERS:
        raise MeshError(f"minimize: unknown solver {solver!r}; use one of {SOLVERS}.")
    if max_iters < 0:
        raise MeshError(f"minimize: max_iters must be >= 0, got {max_iters}.")
    disk_check(mesh, "minimize")
    traced = isinstance(mesh.vertices, jax.core.Tracer)
    Vc = mesh.vertices
    if init is None:
        init = convex_map(mesh.with_vertices(jax.lax.stop_gradient(Vc)) if traced else mesh)
    uv0 = np.asarray(jax.lax.stop_gradient(jnp.asarray(init)), np.float64)
    if uv0.shape != (mesh.n_vertices, 2):
        raise MeshError(f"minimize: init must have shape ({mesh.n_vertices}, 2), got {uv0.shape}.")
    _check_start(mesh, uv0)
    if free_boundary and not en.scale_invariant:
        V = np.asarray(jax.lax.stop_gradient(jnp.asarray(Vc)))
        a3 = float(np.sum(np.asarray(geo.face_areas(V, mesh.faces))))
        auv = float(np.sum(np.asarray(geo.signed_areas(jnp.asarray(np.nan_to_num(uv0)), mesh.faces))))
        c = np.nanmean(uv0, axis=0)
        uv0 = (uv0 - c) * np.sqrt(a3 / auv)

    if traced:
        return _minimize_traced(mesh, en, uv0, free_boundary, solver, max_iters, energy_rtol,
                                grad_rtol, max_seconds, verbose)
    prob = _Problem(mesh, en, free_boundary, uv0)
    x, f, it, conv, (hist, times), reason, secs = _run(prob, solver, max_iters, energy_rtol,
                                                       grad_rtol, max_seconds, verbose)
    uv = np.array(prob.uv(x))
    uv[~mesh.topology.referenced] = np.nan
    return MinimizeResult(uv=uv, energy=f, iterations=it, converged=conv, history=hist,
                          seconds=secs, reason=reason, flips=prob.flipped(x),
                          boundary_overlaps=metrics.boundary_overlaps(mesh, uv) if free_boundary else 0,
                          solver=solver, times=times)


def _minimize_traced(mesh, en, uv0, free_boundary, solver, max_iters, energy_rtol, grad_rtol,
                     max_seconds, verbose):
    """``minimize`` under ``jax.grad``: the optimum as a differentiable function of the
    vertices, by implicit differentiation (custom VJP).

    Backward: with ``g = dL/dx`` at the optimum ``x*``, solve ``H lam = g`` with the true
    Hessian ``H = d2E/dx2`` (unprojected; a tiny Tikhonov term ``1e-9 mean(diag H)`` for the
    translation/rotation null space of a free boundary), then
    ``dL/dV = -d/dV <grad_x E(x*, V), lam>``.  The boundary of a fixed-boundary run is
    the start's and treated as constant.
    """
    info = {}

    def solve_concrete(V):
        m = mesh.with_vertices(V)
        prob = _Problem(m, en, free_boundary, uv0)
        x, f, it, conv, (hist, times), reason, secs = _run(prob, solver, max_iters, energy_rtol,
                                                           grad_rtol, max_seconds, verbose)
        info.update(energy=f, iterations=it, converged=conv, history=hist, reason=reason,
                    seconds=secs, flips=prob.flipped(x), prob=prob, x=x, times=times)
        return np.asarray(prob.uv(x))

    @jax.custom_vjp
    def optimum(V):
        return jax.pure_callback(solve_concrete, jax.ShapeDtypeStruct((mesh.n_vertices, 2), jnp.float64), V)

    def fwd(V):
        uv = optimum(V)
        return uv, (V, uv)

    def bwd(res, g_uv):
        V, uv = res
        prob = info["prob"]
        x = jnp.asarray(info["x"])
        free = jnp.asarray(prob.free)
        g = g_uv[free].reshape(-1)

        def grad_x(Vv, xx):
            frames = geo.local_frames(Vv, prob.F)
            areas = geo.face_areas(Vv, prob.F)
            return jax.grad(lambda y: en_mod.total(en, frames, areas, _uv_of(y, prob.base, free)[prob.F]))(xx)

        def host_lambda(gg):
            P, vals, diag = prob.hessian(np.asarray(x), project=False)
            vals = vals.copy()
            vals[diag] += 1e-9 * abs(float(np.mean(vals[diag])))
            return sparse.factorize(P, vals, symmetric=False).solve(np.asarray(gg))

        lam = jax.pure_callback(host_lambda, jax.ShapeDtypeStruct(g.shape, jnp.float64), g)
        dV = jax.grad(lambda Vv: jnp.vdot(grad_x(Vv, x), lam))(V)
        return (-dV,)

    optimum.defvjp(fwd, bwd)
    uv = optimum(mesh.vertices)
    return MinimizeResult(uv=uv, energy=info.get("energy", float("nan")),
                          iterations=info.get("iterations", 0), converged=info.get("converged", False),
                          history=info.get("history", []), seconds=info.get("seconds", 0.0),
                          reason=info.get("reason", ""), flips=info.get("flips", 0),
                          boundary_overlaps=0, solver=solver, times=info.get("times", []))
