"""``minimize`` under JAX transformations (``jax.grad``, ``jax.vmap``, ``jax.jit``): the
optimum as a differentiable function of the vertex positions, of the start (``init``) and
of the energy's parameters, by implicit differentiation (a custom VJP around host
callbacks).

**What is differentiated.**  The free DOFs ``x`` (the free vertices' UVs, see
:func:`~jaxparam.optimize.problem.free_vertices`) of a converged minimization satisfy
``grad_x E(x*, V, u_fix, p) = 0``, where ``V`` are the vertex positions, ``u_fix`` the UVs
of the fixed vertices (the boundary of a fixed-boundary run: the start's boundary rows) and
``p`` the energy's parameters (``jp.energy(f, params)``).  With ``g = dL/dx*`` and the true
Hessian ``H = d2E/dx2`` at ``x*`` (unprojected), the backward pass solves ``H lam = g`` and
returns ``-d/d(V, u_fix, p) <grad_x E(x*, V, u_fix, p), lam>``.  The output's fixed rows
are ``u_fix`` itself, so their cotangent passes straight through too.  The start reaches
``u_fix`` by ordinary JAX autodiff: the default start ``convex_map(mesh)`` is a
differentiable function of the vertices, so its boundary moves with them, and an explicit
``init`` (a traced array) gets the cotangent of its fixed rows.  The free rows of the
start do not move a converged optimum (an isolated minimum does not depend on where the
descent began): their cotangent is exactly 0.

**Free boundary.**  No vertex is pinned: every referenced vertex is free, and the energy
is invariant under translations and rotations of the UVs (and scalings, for a
scale-invariant energy), so ``H`` has that null space and the optimum is unique only up
to those motions.  The backward pass removes, from ``g`` and from ``lam``, the candidate
motions (translations, rotation, scaling) that are numerically in ``H``'s null space
(Rayleigh quotient below ``NULL_RTOL`` times ``H``'s mean diagonal): the gradient is
that of the optimum moving orthogonally to them, the minimum-norm choice.  For a
scale-invariant energy the result is recentred and rescaled to the start's centroid and
area (:func:`~jaxparam.optimize.problem.normalized`, applied again here in JAX, a no-op on
the values), so its dependence on the start's centroid and area is differentiated too.
For a loss invariant under rigid motions of the UVs (energies, edge lengths, angles,
areas, relative positions after alignment) the gradient is exact; for others the solver
output's rotation (where the descent happened to stop in the family of optima) has no
derivative, and finite differences of it see an arbitrary drift.

**Linear solve.**  ``H`` plus ``TIKHONOV * |mean diag H|`` on the diagonal is factorized
(LU), and ``REFINE_STEPS`` steps of iterative refinement against the unshifted ``H``
remove the shift's bias (to ``~(shift / smallest eigenvalue)^(steps + 1)``).

**Unconverged runs.**  When the minimization stopped without converging (``max_iters``,
``max_seconds``), the gradient is the same formula at the stopping point, which is not a
stationary point: differentiating warns :class:`~jaxparam.optimize.base.UnconvergedGradientWarning`,
or raises :class:`~jaxparam.errors.SolverError` (stage ``"gradient"``) with
``strict=True``.  Under ``jax.jit`` or ``jax.vmap`` the flag is only known inside the
backward callback, so the warning comes from there, and a strict refusal reaches the
caller as the ``jax.errors.JaxRuntimeError`` that wraps the SolverError (its message
quoted).

**Transformations.**  Every host callback is pure (its result depends only on its
arguments) and has ``vmap_method="sequential"``: ``jax.vmap`` runs one minimization per
batch element, and ``jax.jit`` works (the minimization then runs when the compiled
function is called).  Forward mode (``jax.jvp``, ``jax.jacfwd``) is refused with a
:class:`~jaxparam.errors.SolverError` that names ``jax.jacrev``: JAX cannot push a tangent
through a custom VJP, and a custom JVP instead would need the forward solve's tangent
system (``H dx = -d(grad_x E)``) to be transposable JAX code, while its Hessian, null space
and polish live on the host.  (Under ``jax.jit`` JAX differentiates the traced function
after ``minimize`` has returned, so there its own ``TypeError`` comes instead.)
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import warnings
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from .. import geometry as geo
from .. import sparse
from ..errors import SolverError
from .base import Solver, SolveResult, StopRules, UnconvergedGradientWarning
from .in_callback import host_callback
from .newton import sparse_hessian
from .problem import Problem, energy_at, free_vertices, normalized, uv_of

__all__ = ["minimize_traced", "Forward", "Runs", "TracedInfo", "TIKHONOV", "REFINE_STEPS", "IMPLICIT_RESIDUAL",
           "NULL_RTOL", "POLISH_STEPS", "unconverged_gradient", "is_traced", "polish", "cotangents"]

#: Relative diagonal shift of the backward pass's Hessian (times ``|mean diag H|``): it
#: makes the factorization succeed on the (projected-out) null space of a free boundary;
#: iterative refinement removes its bias.
TIKHONOV = 1e-9

#: Iterative-refinement steps of the backward solve against the unshifted Hessian (each
#: stops early once the residual is at rounding level).
REFINE_STEPS = 4

#: The relative residual the backward solve may leave, judged against the unshifted ``H``
#: after refinement (a Hessian singular beyond the known motions leaves the part of the
#: gradient outside its range, far above this).  The shifted factor's own solves are held
#: to it too: with a free boundary that matrix is nearly singular along the rigid motions
#: (condition ~ 1 / TIKHONOV), which the projection removes anyway, and the sparse module's
#: default 1e-8 refused sound systems at 1.09e-8 (session 28).
IMPLICIT_RESIDUAL = 1e-6

#: Newton steps (unprojected Hessian, full steps) that polish a converged optimum before it
#: is differentiated: the solvers stop when the energy stops decreasing in floating point,
#: at a gradient norm of about ``sqrt(eps)`` (``~1e-8``), and the implicit gradient is exact
#: only at a stationary point.  A step is kept only when it lowers the gradient's norm
#: without inverting a triangle.
POLISH_STEPS = 3

#: A candidate rigid motion (or scaling) of a free boundary counts as a null direction of
#: the Hessian when its Rayleigh quotient is below this times ``|mean diag H|`` (at a
#: converged optimum it is at the level of the gradient's norm; a genuine soft mode of a
#: mesh of ``n`` vertices is ``~1/n``).
NULL_RTOL = 1e-7

#: Forward problems kept for backward passes not yet run (one per batch element under
#: ``jax.vmap``; older ones are rebuilt when needed).
_KEEP = 16


def is_traced(tree) -> bool:
    """Whether any leaf of ``tree`` is a JAX tracer."""
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(tree))


@dataclass
class Forward:
    """One forward run of the host callback: the problem it solved, the solver's result and
    the flip count (the driver reads them when the callback ran exactly once, eagerly)."""

    problem: Problem
    result: SolveResult
    flips: int


class Runs:
    """What the forward callback tells the driver: how often it ran while the record was
    open (once under an eager ``jax.grad``, once per batch element under an eager
    ``jax.vmap``, never while ``jax.jit`` traces) and, when exactly once, that run's
    :class:`Forward`.  The driver reads it right after the call and closes it, so that a
    compiled function calling the callback again and again keeps nothing."""

    def __init__(self):
        self.count, self.first, self.open = 0, None, True

    def add(self, run: Forward) -> None:
        if self.open:
            self.count += 1
            self.first = run if self.count == 1 else None

    def close(self) -> Forward | None:
        """Stop recording; the single run's record, or ``None`` (none, or several)."""
        self.open = False
        return self.first


@dataclass(frozen=True)
class TracedInfo:
    """The run's summary as JAX arrays, returned by the forward callback alongside the
    optimum (traced, and batched under ``jax.vmap``): ``energy``, ``iterations``,
    ``converged``, ``flips``."""

    energy: jax.Array
    iterations: jax.Array
    converged: jax.Array
    flips: jax.Array


def unconverged_gradient(strict: bool, detail: str = "") -> None:
    """Warn :class:`UnconvergedGradientWarning`, or raise :class:`SolverError` (stage
    ``"gradient"``) when ``strict``: a minimization that did not converge is being
    differentiated."""
    msg = ("minimize: differentiating a minimization that did not converge"
           f"{' (' + detail + ')' if detail else ''}: the gradient is that of the stopping "
           "point (the implicit-function formula evaluated there), not of the optimum; "
           "raise max_iters or max_seconds, or loosen energy_rtol/grad_rtol")
    if strict:
        raise SolverError(msg + ".", stage="gradient")
    warnings.warn(msg + "; strict=True refuses it.", UnconvergedGradientWarning, stacklevel=3)


def _is_float(leaf) -> bool:
    return jnp.issubdtype(jnp.result_type(leaf), jnp.inexact)


def _key(*arrays) -> bytes:
    h = hashlib.sha1()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.shape, a.dtype.str)).encode())
        h.update(a.tobytes())
    return h.digest()


def _null_basis(H, x, scale: bool):
    """The orthonormal candidate motions of free UVs ``x (2 k,)`` that are numerically in
    ``H``'s null space: translations, the rotation about the centroid, and the scaling
    about it when ``scale``; ``(2 k, c)``."""
    U = np.asarray(x, np.float64).reshape(-1, 2)
    C = U - U.mean(0)
    cands = [np.tile([1.0, 0.0], len(U)), np.tile([0.0, 1.0], len(U)),
             np.column_stack([-C[:, 1], C[:, 0]]).reshape(-1)]
    if scale:
        cands.append(C.reshape(-1))
    diag = abs(float(np.mean(H.diagonal())))
    keep = []
    for q in cands:
        nq = np.linalg.norm(q)
        if nq == 0:
            continue
        q = q / nq
        if abs(float(q @ (H @ q))) <= NULL_RTOL * diag:
            keep.append(q)
    if not keep:
        return np.zeros((x.size, 0))
    Q, _ = np.linalg.qr(np.column_stack(keep))
    return Q


def minimize_traced(mesh, en, base, free_boundary: bool, solver: Solver, stop: StopRules,
                    verbose: bool, strict: bool = False, checked: bool = True):
    """``minimize`` when the vertices, the start or the energy's parameters are traced.

    **Arguments:** ``mesh`` (its vertices may be tracers); ``en`` the energy (its
    ``params`` may be tracers); ``base (n, 2)`` the start, NaN rows zeroed (a JAX array,
    maybe traced: the fixed rows' dependence on the inputs is differentiated);
    ``free_boundary``, ``solver``, ``stop``, ``verbose`` as in :func:`jaxparam.minimize`;
    ``strict``: refuse to differentiate an unconverged run; ``checked``: whether the start
    was checked (one-to-one) already, else the forward callback checks it.

    **Returns:** ``(uv, info, runs)``: ``uv (n, 2)`` the traced optimum, ``info`` a
    :class:`TracedInfo`, ``runs`` the :class:`Runs` record of the forward callback (the
    caller closes it).

    The module docstring says what is differentiated, and how.
    """
    from .driver import check_start

    F = mesh.faces
    free = free_vertices(mesh.topology, free_boundary)
    if free.size == 0:
        raise SolverError("minimize: no free vertex to optimize (every vertex is on the fixed "
                          "boundary); use free_boundary=True.", stage="init")
    k2 = 2 * free.size
    static = en.static
    leaves, treedef = jax.tree_util.tree_flatten(en.params)
    leaves = [jnp.asarray(leaf) for leaf in leaves]
    is_float = [_is_float(leaf) for leaf in leaves]
    V = jnp.asarray(mesh.vertices, jnp.float64)
    base = jnp.asarray(base, jnp.float64)
    runs = Runs()
    # The problems the differentiated forward solved, by their inputs, for the backward pass
    # (which takes its own out; at most _KEEP are waiting, e.g. a vjp never pulled back).
    problems: dict[bytes, Problem] = {}

    def problem_of(Vh, bh, lh, *, store: bool = False, take: bool = False) -> Problem:
        key = _key(Vh, bh, *lh)
        prob = problems.pop(key, None) if take else problems.get(key)
        if prob is None:
            params = jax.tree_util.tree_unflatten(treedef, [np.asarray(a) for a in lh])
            prob = Problem(mesh.with_vertices(np.asarray(Vh, np.float64)),
                           en.with_params(params), free_boundary, np.asarray(bh, np.float64))
        if store:
            while len(problems) >= _KEEP:
                problems.pop(next(iter(problems)))
            problems[key] = prob
        return prob

    def solve_host(store, Vh, bh, *lh):
        if not checked:
            check_start(mesh, bh)
        prob = problem_of(Vh, bh, lh, store=store)
        with host_callback():       # no blocking LAPACK in the solver's kernels (in_callback)
            res = solver.run(prob, stop, verbose=verbose)
            if res.converged:
                x = polish(prob, res.x)
                if x is not res.x:
                    res = dataclasses.replace(res, x=x, energy=prob.value(x))
        flips = prob.flipped(res.x)
        runs.add(Forward(prob, res, flips))
        return (np.asarray(res.x, np.float64), np.float64(res.energy), np.int64(res.iterations),
                np.bool_(res.converged), np.int64(flips))

    out_shapes = (jax.ShapeDtypeStruct((k2,), jnp.float64), jax.ShapeDtypeStruct((), jnp.float64),
                  jax.ShapeDtypeStruct((), jnp.int64), jax.ShapeDtypeStruct((), jnp.bool_),
                  jax.ShapeDtypeStruct((), jnp.int64))

    def lambda_host(Vh, bh, x, g, converged, check, *lh, inside=True):
        if bool(check) and not bool(converged):
            unconverged_gradient(strict)
        prob = problem_of(Vh, bh, lh, take=True)
        try:
            with host_callback() if inside else contextlib.nullcontext():
                return _implicit_solve(prob, np.asarray(x, np.float64), np.asarray(g, np.float64))
        except SolverError as exc:
            raise SolverError(
                f"minimize: the implicit gradient's linear system (the Hessian at the optimum) "
                f"is singular beyond the motions the energy is known to ignore ({exc}). A free "
                "boundary with an energy unchanged when the map is scaled needs "
                "jp.energy(..., scale_invariant=True) (the default tests it); else the optimum "
                "is not isolated (a flat direction of the energy) and has no derivative there.",
                stage="gradient") from None

    def solve(store, Vv, bb, fl, il):
        return jax.pure_callback(functools.partial(solve_host, store), out_shapes, Vv, bb,
                                 *_merge(fl, il, is_float), vmap_method="sequential")

    @jax.custom_vjp
    def optimum(Vv, bb, fl, il):
        return solve(False, Vv, bb, fl, il)

    def fwd(Vv, bb, fl, il):
        out = solve(True, Vv, bb, fl, il)      # keeps its problem for the backward pass
        return out, (Vv, bb, fl, il, out[0], out[3])

    def bwd(res, cts):
        Vv, bb, fl, il, x, converged = res
        g = cts[0]
        check = True
        if not isinstance(converged, jax.core.Tracer):       # eager: warn or raise right here
            check = False
            if not bool(converged):
                detail = ""
                if runs.first is not None:
                    r = runs.first.result
                    detail = f"stopped by {r.reason!r} after {r.iterations} iterations"
                unconverged_gradient(strict, detail)
        merged = _merge(fl, il, is_float)
        if not is_traced((Vv, bb, x, g, merged)):
            # eager: solved right here, so a SolverError reaches the caller as itself, not
            # wrapped in the JaxRuntimeError of a failed callback
            lam = jnp.asarray(lambda_host(*(np.asarray(a) for a in (Vv, bb, x, g)), converged,
                                          False, *(np.asarray(a) for a in merged), inside=False))
        else:
            lam = jax.pure_callback(lambda_host, jax.ShapeDtypeStruct((k2,), jnp.float64), Vv, bb,
                                    x, g, converged, jnp.asarray(check), *merged,
                                    vmap_method="sequential")
        dV, db, dfl = cotangents(Vv, bb, fl, il, x, lam, free, F, en=static, treedef=treedef,
                                 is_float=tuple(is_float))
        dil = tuple(np.zeros(np.shape(a), jax.dtypes.float0) for a in il)
        return dV, db, dfl, dil

    optimum.defvjp(fwd, bwd)

    fl = tuple(a for a, f in zip(leaves, is_float) if f)
    il = tuple(a for a, f in zip(leaves, is_float) if not f)
    try:
        x, energy, iterations, converged, flips = optimum(V, base, fl, il)
    except TypeError as exc:
        if "forward-mode" not in str(exc):
            raise
        raise SolverError(
            "minimize: forward-mode differentiation (jax.jvp, jax.jacfwd, jax.hessian) is not "
            "supported: the optimum's derivative is a reverse-mode rule (a custom VJP around "
            "the host solver and the backward solve). Use jax.grad, jax.vjp or jax.jacrev "
            "(one backward solve per output row); for second derivatives differentiate "
            "something else than minimize's output twice.", stage="gradient") from None
    if free_boundary and en.scale_invariant:
        x = normalized(x, base, free, F)       # a no-op on the values; differentiates the
    uv = uv_of(x, base, free)                  # dependence on the start's centroid and area
    return uv, TracedInfo(energy, iterations, converged, flips), runs


@functools.partial(jax.jit, static_argnames=("en", "treedef", "is_float"))
def cotangents(V, base, fl, il, x, lam, free, F, *, en, treedef, is_float):
    """The backward pass's cotangents ``-d/d(V, base, fl) <grad_x E(x, V, base, p), lam>``,
    ``p`` the energy's parameters rebuilt from their float leaves ``fl`` and other leaves
    ``il`` (``treedef``, ``is_float``), ``en`` static (without parameters).  Jitted: eager
    second-order autodiff would dispatch op by op."""
    def grad_x(Vv, bb, ff):
        params = jax.tree_util.tree_unflatten(treedef, _merge(ff, il, is_float))
        frames = geo.local_frames(Vv, F)
        areas = geo.face_areas(Vv, F)
        return jax.grad(energy_at)(x, bb, free, F, frames, areas, params, en)

    _, vjp = jax.vjp(grad_x, V, base, fl)
    return vjp(-lam)


def _merge(fl, il, is_float):
    fi, ii = iter(fl), iter(il)
    return [next(fi) if f else next(ii) for f in is_float]


def polish(prob: Problem, x):
    """Up to :data:`POLISH_STEPS` Newton steps from the converged ``x`` towards the
    stationary point (``x`` itself when none helps): the step solves ``H d = -grad``
    (:func:`_implicit_solve`, the rigid motions of a free boundary projected out) and is
    kept when it lowers the gradient's norm, keeps the energy finite and inverts no
    triangle."""
    x = np.asarray(x, np.float64)
    out = x
    f, g = prob.value_and_grad(x)
    gn = np.linalg.norm(g)
    for _ in range(POLISH_STEPS):
        if not gn > 0:
            break
        try:
            d = -_implicit_solve(prob, x, g)
        except SolverError:
            break
        xt = x + d
        ft, gt = prob.value_and_grad(xt)
        gtn = np.linalg.norm(gt)
        if not (np.isfinite(ft) and gtn < gn and prob.flipped(xt) == 0):
            break
        x, g, gn = xt, gt, gtn
        out = x
    return out


def _implicit_solve(prob: Problem, x, g):
    """``lam`` with ``H lam = g`` at ``x`` (the true Hessian; on the complement of its
    rigid-motion null space with a free boundary), on the host."""
    hp = prob.hessian_pattern
    vals = sparse_hessian(prob, x, project=False)
    P = hp.pattern
    H = sp.csr_matrix((vals, P.indices, P.indptr), shape=(P.n, P.n))
    Q = (_null_basis(H, x, prob.en.scale_invariant) if prob.free_boundary
         else np.zeros((x.size, 0)))

    def project(v):
        return v - Q @ (Q.T @ v) if Q.shape[1] else v

    g = project(g)
    gn = np.linalg.norm(g)
    if gn == 0:
        return np.zeros_like(g)
    shifted = vals.copy()
    shifted[hp.diag] += TIKHONOV * max(abs(float(np.mean(vals[hp.diag]))), 1e-300)
    fac = sparse.factorize(P, shifted, symmetric=False)
    lam = project(fac.solve(g, residual_tol=IMPLICIT_RESIDUAL))
    r = g - project(H @ lam)
    rn = np.linalg.norm(r)
    for _ in range(REFINE_STEPS):
        if rn <= 1e-15 * gn:
            break
        cand = project(lam + fac.solve(r, residual_tol=IMPLICIT_RESIDUAL))
        r_new = g - project(H @ cand)
        rn_new = np.linalg.norm(r_new)
        if not rn_new < rn:         # refinement does not converge (an indefinite H far from
            break                   # a minimum): keep the best iterate
        lam, r, rn = cand, r_new, rn_new
    if not rn <= IMPLICIT_RESIDUAL * gn:
        raise SolverError(f"sparse: the solve of a {P.n} x {P.n} system left a relative residual "
                          f"of {rn / gn:.3g} (> {IMPLICIT_RESIDUAL:g}) against the unshifted "
                          "Hessian; the matrix is singular or badly conditioned.",
                          stage="gradient")
    return lam
