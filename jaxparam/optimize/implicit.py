"""``minimize`` under ``jax.grad``: the optimum as a differentiable function of the vertex
positions, by implicit differentiation (a custom VJP around a host callback)."""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .. import energies as en_mod
from .. import geometry as geo
from .. import sparse
from .base import Solver, SolveResult, StopRules
from .newton import sparse_hessian
from .problem import Problem, uv_of

__all__ = ["minimize_traced", "TIKHONOV"]

#: Relative diagonal shift of the backward pass's Hessian (times ``|mean diag H|``): it
#: removes the translation/rotation null space of a free boundary, and is negligible
#: otherwise.
TIKHONOV = 1e-9


@dataclass
class _Forward:
    """What the forward callback leaves for the backward pass and the result: the problem
    it solved and the solver's result (``None`` until the callback has run)."""

    problem: Problem | None = None
    result: SolveResult | None = None
    flips: int = 0


def minimize_traced(mesh, en, uv0, free_boundary: bool, solver: Solver, stop: StopRules,
                    verbose: bool):
    """``minimize`` when ``mesh.vertices`` is a JAX tracer.

    Returns ``(uv, forward)``: ``uv (n, 2)`` is the traced optimum, and ``forward`` (a
    record filled in when the forward callback runs, eagerly under ``jax.grad``) holds the
    problem, the :class:`~jaxparam.optimize.base.SolveResult` and the flip count.

    Backward: with ``g = dL/dx`` at the optimum ``x*``, solve ``H lam = g`` with the true
    Hessian ``H = d2E/dx2`` (unprojected; ``TIKHONOV * |mean(diag H)|`` on the diagonal for
    the translation/rotation null space of a free boundary), then
    ``dL/dV = -d/dV <grad_x E(x*, V), lam>``.  The boundary of a fixed-boundary run is
    the start's and treated as constant.  The state crosses from the forward callback to
    the backward pass through ``forward``, so the function cannot be wrapped in
    ``jax.jit``.
    """
    forward = _Forward()

    def solve_concrete(V):
        prob = Problem(mesh.with_vertices(V), en, free_boundary, uv0)
        res = solver.run(prob, stop, verbose=verbose)
        forward.problem, forward.result, forward.flips = prob, res, prob.flipped(res.x)
        return np.asarray(prob.uv(res.x))

    @jax.custom_vjp
    def optimum(V):
        return jax.pure_callback(solve_concrete,
                                 jax.ShapeDtypeStruct((mesh.n_vertices, 2), jnp.float64), V)

    def fwd(V):
        uv = optimum(V)
        return uv, (V, uv)

    def bwd(res, g_uv):
        V, uv = res
        prob = forward.problem
        x = jnp.asarray(forward.result.x)
        free = jnp.asarray(prob.free)
        g = g_uv[free].reshape(-1)

        def grad_x(Vv, xx):
            frames = geo.local_frames(Vv, prob.F)
            areas = geo.face_areas(Vv, prob.F)
            return jax.grad(lambda y: en_mod.total(en, frames, areas, uv_of(y, prob.base, free)[prob.F]))(xx)

        def host_lambda(gg):
            vals = sparse_hessian(prob, np.asarray(x), project=False)
            diag = prob.hessian_pattern.diag
            vals[diag] += TIKHONOV * abs(float(np.mean(vals[diag])))
            return sparse.factorize(prob.hessian_pattern.pattern, vals,
                                    symmetric=False).solve(np.asarray(gg))

        lam = jax.pure_callback(host_lambda, jax.ShapeDtypeStruct(g.shape, jnp.float64), g)
        dV = jax.grad(lambda Vv: jnp.vdot(grad_x(Vv, x), lam))(V)
        return (-dV,)

    optimum.defvjp(fwd, bwd)
    return optimum(mesh.vertices), forward
