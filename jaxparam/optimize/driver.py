""":func:`minimize` and :class:`MinimizeResult`: argument checks, the start, and the hand-off
to a solver (or to :func:`~jaxparam.optimize.implicit.minimize_traced` under ``jax.grad``)."""
from __future__ import annotations

from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from .. import energies as en_mod
from .. import geometry as geo
from .. import metrics
from .. import tol
from ..errors import MeshError, SolverError
from .base import Solver, StopRules
from .implicit import minimize_traced
from .problem import Problem
from .solvers import solver_from

__all__ = ["MinimizeResult", "minimize", "check_start"]


@dataclass(frozen=True)
class MinimizeResult:
    """What :func:`minimize` returns.

    **Fields:** ``uv (n, 2)``; ``energy`` (final, area-weighted mean density);
    ``iterations`` (accepted steps); ``converged``; ``history`` (energy after each
    iteration, the start first); ``seconds`` (wall time, compilation included);
    ``reason`` (why it stopped); ``flips`` (always 0 from an injective start);
    ``boundary_overlaps`` (free boundary: crossings of the boundary with itself);
    ``solver`` (the solver's registry name); ``times`` (seconds since the start at each
    entry of ``history``).
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


def check_start(mesh, uv0, where: str = "minimize") -> None:
    """Raise :class:`SolverError` (stage ``"init"``) unless every face of ``uv0 (n, 2)`` has
    a positive signed area."""
    A = np.asarray(geo.signed_areas(jnp.asarray(np.nan_to_num(np.asarray(uv0, np.float64))), mesh.faces))
    bad = np.flatnonzero(A <= 0)
    if bad.size:
        raise SolverError(
            f"{where}: the start is not injective: {bad.size} of {A.size} triangles are flipped or "
            f"degenerate (first: face {int(bad[0])}); start from a one-to-one map such as "
            "jp.convex_map(mesh) (positive weights, convex boundary).", stage="init")


def minimize(mesh, energy="symmetric_dirichlet", *, init=None, free_boundary: bool = False,
             solver: str | Solver = "newton", max_iters: int = 200,
             energy_rtol: float = tol.ENERGY_RTOL, grad_rtol: float = tol.GRAD_RTOL,
             max_seconds: float | None = None, verbose: bool = True) -> MinimizeResult:
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
    - ``solver``: a name of :data:`jaxparam.optimize.SOLVERS` (``"newton"``, ``"lbfgs"``,
      ``"bfgs"``, ``"jaxopt_lbfgs"``; hyphens allowed), or a solver instance with its own
      settings, e.g. ``jp.optimize.Newton(regularization=1e-9)``.
    - ``max_iters``, ``energy_rtol``, ``grad_rtol``, ``max_seconds``: stopping rules
      (:class:`jaxparam.optimize.StopRules`).
    - ``verbose``: a progress bar for runs longer than a second.

    **Returns:** a :class:`MinimizeResult`.

    Raises :class:`SolverError` (stage ``"init"``) when the start has a flipped triangle,
    :class:`MeshError` for an unknown solver or a bad argument.

    Example::

        res = jp.minimize(mesh, "symmetric_dirichlet", free_boundary=True)
        res.uv, res.energy, res.iterations
    """
    from ..linear import convex_map, disk_check

    en = en_mod.get(energy)
    solver = solver_from(solver)
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
    check_start(mesh, uv0)
    if free_boundary and not en.scale_invariant:
        V = np.asarray(jax.lax.stop_gradient(jnp.asarray(Vc)))
        a3 = float(np.sum(np.asarray(geo.face_areas(V, mesh.faces))))
        auv = float(np.sum(np.asarray(geo.signed_areas(jnp.asarray(np.nan_to_num(uv0)), mesh.faces))))
        c = np.nanmean(uv0, axis=0)
        uv0 = (uv0 - c) * np.sqrt(a3 / auv)
    stop = StopRules(max_iters=max_iters, energy_rtol=energy_rtol, grad_rtol=grad_rtol,
                     max_seconds=max_seconds)

    if traced:
        uv, forward = minimize_traced(mesh, en, uv0, free_boundary, solver, stop, verbose)
        res = forward.result
        if res is None:       # the forward callback has not run (e.g. under jax.jit)
            return MinimizeResult(uv=uv, energy=float("nan"), iterations=0, converged=False,
                                  history=[], seconds=0.0, reason="", flips=0,
                                  boundary_overlaps=0, solver=solver.name, times=[])
        return MinimizeResult(uv=uv, energy=res.energy, iterations=res.iterations,
                              converged=res.converged, history=res.history, seconds=res.seconds,
                              reason=res.reason, flips=forward.flips, boundary_overlaps=0,
                              solver=solver.name, times=res.times)
    prob = Problem(mesh, en, free_boundary, uv0)
    res = solver.run(prob, stop, verbose=verbose)
    uv = np.array(prob.uv(res.x))
    uv[~mesh.topology.referenced] = np.nan
    return MinimizeResult(uv=uv, energy=res.energy, iterations=res.iterations,
                          converged=res.converged, history=res.history, seconds=res.seconds,
                          reason=res.reason, flips=prob.flipped(res.x),
                          boundary_overlaps=metrics.boundary_overlaps(mesh, uv) if free_boundary else 0,
                          solver=solver.name, times=res.times)
