"""Flip-free minimization of distortion energies (survey §6), fixed or free boundary.

:func:`minimize` starts from a one-to-one map (the convex-combination map by
default) and never accepts an iterate with an inverted triangle: every step
along a direction ``d`` is capped by :func:`jaxparam.geometry.max_step` (the
first ``t`` where some triangle's signed area vanishes, times a safety
factor, Smith & Schaefer 2015), and the Armijo backtracking search rejects
any trial with a non-positive signed area or a non-finite energy.

Solvers are objects (frozen dataclasses holding their settings) in the registry
:data:`SOLVERS`; ``minimize(..., solver="newton")`` builds one with its defaults, and
``minimize(..., solver=Newton(regularization=1e-9))`` passes your own:

- :class:`Newton` (``"newton"``): projected Newton.  Per-triangle 6x6 Hessians from
  JAX, each projected to positive semi-definite, assembled onto a sparsity pattern
  computed once, factorized by :mod:`jaxparam.sparse` (symbolic analysis reused).
- :class:`LBFGS` (``"lbfgs"``): optimistix's L-BFGS through ``optx.minimise``, the step
  cap in a descent wrapper (:class:`FlipFreeDescent`) and optimistix's backtracking
  Armijo search; the barrier energies' ``+inf`` on inverted triangles rejects any trial
  that would invert one.
- :class:`BFGS` (``"bfgs"``): optimistix's dense BFGS, the same way (small meshes only).
- :class:`JaxoptLBFGS` (``"jaxopt_lbfgs"``): jaxopt's L-BFGS (optional extra), stepped
  with the same flip check.

A solver of your own subclasses :class:`Solver` (``run(problem, stop) -> SolveResult``)
or :class:`HostLoopSolver` (only ``step``); add it to :data:`SOLVERS` to use it by name.

The result is differentiable: ``jax.grad`` of a scalar of ``minimize(...).uv``
with respect to the vertex positions, to ``init`` or to an energy's parameters
(``jp.energy(f, params)``) uses implicit differentiation at the optimum (one solve
with the true, unprojected Hessian), through the fixed boundary too (the default
start moves with the vertices); differentiating a run that did not converge warns
:class:`UnconvergedGradientWarning` (``strict=True``: raises).  ``jax.vmap`` and
``jax.jit`` work through ``minimize`` (:mod:`~jaxparam.optimize.implicit`).

Modules: ``driver`` (minimize, MinimizeResult, start check), ``problem`` (free DOFs,
jitted kernels, Hessian pattern), ``base`` (stopping rules, results, the host loop),
``newton``, ``quasi_newton`` (optimistix and jaxopt), ``optimistix_minimisers``,
``search`` (flip-free Armijo), ``implicit`` (implicit gradients), ``solvers`` (the
registry).
"""
from .base import (BoundaryOverlapWarning, CollapsedMapWarning, HostLoopSolver, SolveResult, Solver, StopRules,
                   UnconvergedGradientWarning)
from .driver import MinimizeResult, minimize
from .newton import Newton
from .problem import Problem
from .quasi_newton import BFGS, LBFGS, FlipFreeDescent, JaxoptLBFGS, OptimistixSolver
from .solvers import SOLVERS, solver_from

__all__ = ["MinimizeResult", "minimize", "SOLVERS", "FlipFreeDescent", "Solver",
           "HostLoopSolver", "SolveResult", "StopRules", "Problem", "Newton", "LBFGS", "BFGS",
           "JaxoptLBFGS", "OptimistixSolver", "solver_from", "UnconvergedGradientWarning",
           "CollapsedMapWarning", "BoundaryOverlapWarning"]
