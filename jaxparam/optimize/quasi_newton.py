"""Quasi-Newton solvers: optimistix's L-BFGS and BFGS driven by ``optx.minimise``, with the
flip-free step cap as a descent wrapper, and jaxopt's L-BFGS stepped on the host.

optimistix runs the whole solve inside one compiled loop, so the library's stopping rules
(:class:`~jaxparam.optimize.base.StopRules`) and its per-iteration record reach it
through the descent, the extension point optimistix documents for this: after each
accepted iterate optimistix asks the descent for a new direction (``query``), and
:class:`StoppingDescent` then reports the iterate's energy and gradient norm to the
run's :class:`~jaxparam.optimize.base.Monitor` on the host (``jax.experimental.io_callback``).
Once a rule fires, the descent returns zero steps; the next trial is then accepted
unchanged and optimistix's own Cauchy test (``rtol``, ``atol``) ends the solve.
"""
from __future__ import annotations

import abc
import contextlib
import itertools
from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import io_callback

from .. import geometry as geo
from .. import tol
from ..energies import Energy
from ..errors import SolverError
from .base import REASONS, HostLoopSolver, Monitor, Solver, SolveResult, StopRules, Step
from .problem import Problem, energy_value, uv_of
from .search import flip_free_armijo

__all__ = ["FlipFreeDescent", "StoppingDescent", "EnergyObjective", "OptimistixSolver", "LBFGS",
           "BFGS", "JaxoptLBFGS"]


# ------------------------------------------------------------------------------------------
# optimistix: the step cap and the stopping rules as descent wrappers
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

    **Fields:** ``inner`` (an optimistix descent, e.g. ``optx.NewtonDescent()``);
    ``base (n, 2)``, ``free (k,)``, ``faces (m, 3)`` as in
    :class:`~jaxparam.optimize.problem.Problem`.
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
        uv = uv_of(y, self.base, self.free)
        D = jnp.zeros_like(self.base).at[self.free].set(d.reshape(-1, 2))
        cap = jnp.minimum(1.0, geo.max_step(uv, D, self.faces))
        return _CapState(s, cap)

    def step(self, step_size, state):
        return self.inner.step(step_size * state.cap, state.inner)


# The monitors of the optimistix runs in progress, by run number: the host callback of a
# compiled loop finds its run's Monitor here (the number is a traced argument, so one
# compiled loop serves every run).  An entry lives exactly as long as its run.
_MONITORS: dict[int, Monitor] = {}
_RUN_NUMBERS = itertools.count()


@contextlib.contextmanager
def _watched(monitor: Monitor):
    number = next(_RUN_NUMBERS)
    _MONITORS[number] = monitor
    try:
        yield number
    finally:
        del _MONITORS[number]


def _report(run, f, grad_norm):
    return np.bool_(_MONITORS[int(run)].accepted(float(f), float(grad_norm)))


class _StopState(eqx.Module):
    inner: object
    stop: jax.Array


class StoppingDescent(eqx.Module):
    """Wrap an optimistix descent to report each accepted iterate to the host and to stop.

    ``query`` (called by optimistix at the start and after each accepted step) sends the
    energy and gradient norm to run ``run``'s :class:`~jaxparam.optimize.base.Monitor`,
    which records them and applies the stopping rules; from then on ``step`` returns
    zero steps, so optimistix accepts the unchanged iterate and its Cauchy test ends the
    solve.

    **Fields:** ``inner`` (the wrapped descent); ``run`` (a scalar int array, the key of
    the run's monitor).
    """

    inner: object
    run: jax.Array

    def init(self, y, f_info_struct):
        return _StopState(self.inner.init(y, f_info_struct), jnp.array(False))

    def query(self, y, f_info, state):
        inner = self.inner.query(y, f_info, state.inner)
        stop = io_callback(_report, jax.ShapeDtypeStruct((), jnp.bool_), self.run, f_info.f,
                           jnp.linalg.norm(f_info.grad), ordered=False)
        return _StopState(inner, stop)

    def step(self, step_size, state):
        diff, result = self.inner.step(step_size, state.inner)
        return jnp.where(state.stop, jnp.zeros_like(diff), diff), result


class EnergyObjective(eqx.Module):
    """``fn(x, args)`` for ``optx.minimise``: the energy at the free DOFs ``x``, with
    ``args = problem.arrays``.  The energy is a static field, compared by value, so runs
    with equal energies and shapes share the compiled solve."""

    en: Energy = eqx.field(static=True)

    def __call__(self, x, args):
        return energy_value(x, *args, en=self.en)


def _quiet(**kwargs):
    """optimistix's ``verbose`` hook: print nothing (a module function, so it compares equal
    across runs)."""


@dataclass(frozen=True)
class OptimistixSolver(Solver):
    """A solver run by ``optx.minimise``: optimistix's Newton descent (on its quasi-Newton
    Hessian estimate) capped by :class:`FlipFreeDescent`, reporting through
    :class:`StoppingDescent`, with optimistix's backtracking Armijo search; the barrier
    energies' ``+inf`` on inverted triangles rejects any trial that would invert one.
    With a free boundary and a scale-invariant energy the result is recentred and
    rescaled once, at the end.

    **Fields** (shared by the subclasses, which build the optimistix minimiser in
    ``minimiser(descent)``):

    - ``rtol``, ``atol``: optimistix's Cauchy test (the step and the energy change both
      below ``atol + rtol * |value|``), which ends the solve when the search finds no
      further decrease (``1e-12`` each).
    - ``patience``: consecutive iterations of relative energy decrease below
      ``energy_rtol`` before stopping (3).

    One iteration is one accepted step (optimistix's rejected search trials are not
    counted); ``history`` holds the energy optimistix evaluated at the start and at each
    accepted iterate, the last entry re-evaluated on the host (after the final
    rescaling).  The run stops by the rules of :func:`jaxparam.minimize` (``max_iters``
    accepted steps, ``energy_rtol``, ``grad_rtol``, ``max_seconds``, each checked after an
    accepted step), by the Cauchy test (reason ``"no further decrease along the search
    direction"``, converged) or after ``(max_iters + 2) * tol.BACKTRACK_MAX`` optimistix
    steps (reason ``"optimistix max_steps reached"``).
    """

    rtol: float = 1e-12
    atol: float = 1e-12
    patience: int = 3

    @abc.abstractmethod
    def minimiser(self, descent):
        """The ``optx.AbstractMinimiser`` to run, with this descent."""

    def run(self, problem: Problem, stop: StopRules, *, verbose: bool = False) -> SolveResult:
        import optimistix as optx

        x, f, g, monitor = Monitor.start(problem, self, stop, verbose)
        capped = FlipFreeDescent(optx.NewtonDescent(), problem.base, jnp.asarray(problem.free),
                                 jnp.asarray(problem.F))
        with _watched(monitor) as run:
            sol = optx.minimise(EnergyObjective(problem.en),
                                self.minimiser(StoppingDescent(capped, jnp.asarray(run))),
                                jnp.asarray(x), args=problem.arrays,
                                max_steps=(stop.max_iters + 2) * tol.BACKTRACK_MAX, throw=False)
            x = np.asarray(sol.value)
        reason, converged = None, None
        if not monitor.stopped:       # optimistix ended the solve
            if sol.result == optx.RESULTS.successful:
                reason, converged = REASONS["no_decrease"], True
            elif sol.result == optx.RESULTS.max_steps_reached:
                reason = REASONS["max_steps"]
            else:
                reason = f"optimistix: {optx.RESULTS[sol.result]}"
        if problem.free_boundary and problem.en.scale_invariant:
            x = problem.normalize(x)
        f = problem.value(x)
        monitor.history[-1] = f
        return monitor.result(x, f, reason=reason, converged=converged)


@dataclass(frozen=True)
class LBFGS(OptimistixSolver):
    """optimistix's L-BFGS (``"lbfgs"``), as :class:`OptimistixSolver` says.

    **Fields:** ``history_length`` (past steps in the inverse-Hessian estimate, 10), and
    ``rtol``, ``atol``, ``patience`` (:class:`OptimistixSolver`).
    """

    name: ClassVar[str] = "lbfgs"

    history_length: int = 10

    def minimiser(self, descent):
        from .optimistix_minimisers import FlipFreeLBFGS

        return FlipFreeLBFGS(rtol=self.rtol, atol=self.atol, descent=descent, verbose=_quiet,
                             history_length=self.history_length)


@dataclass(frozen=True)
class BFGS(OptimistixSolver):
    """optimistix's dense BFGS (``"bfgs"``, small meshes only), as :class:`OptimistixSolver`
    says.

    **Fields:** ``max_dofs`` (the most unknowns, 2 per free vertex, it accepts: 4000, whose
    dense ``n x n`` float64 inverse-Hessian estimate takes 128 MB; a 22k-face mesh would need
    about 4 GB and minutes per step), and ``rtol``, ``atol``, ``patience``
    (:class:`OptimistixSolver`).  Larger problems raise :class:`SolverError` naming the
    solvers that scale: ``"newton"`` (sparse) and ``"lbfgs"`` (``O(n)`` memory).
    """

    name: ClassVar[str] = "bfgs"

    max_dofs: int = 4000

    def run(self, problem: Problem, stop: StopRules, *, verbose: bool = False) -> SolveResult:
        n = 2 * int(np.size(problem.free))
        if n > self.max_dofs:
            raise SolverError(
                f"minimize: solver='bfgs' keeps a dense {n} x {n} inverse-Hessian estimate for "
                f"{n // 2} free vertices: {8 * n * n / 1e9:.2g} GB in float64 (and as much again "
                f"while updating it); it takes at most {self.max_dofs} unknowns "
                f"({8 * self.max_dofs ** 2 / 1e6:.0f} MB).  Use solver='newton' (sparse projected "
                "Newton, the default) or solver='lbfgs' (O(n) memory), or BFGS(max_dofs=...) to "
                "insist.", stage="solver")
        return super().run(problem, stop, verbose=verbose)

    def minimiser(self, descent):
        from .optimistix_minimisers import FlipFreeBFGS

        return FlipFreeBFGS(rtol=self.rtol, atol=self.atol, descent=descent, verbose=_quiet)


# ------------------------------------------------------------------------------------------
# jaxopt, stepped on the host
# ------------------------------------------------------------------------------------------

class _JaxoptState(NamedTuple):
    solver: object      # the jaxopt.LBFGS instance
    update: object      # its jitted update
    state: object       # its state at the current iterate


@dataclass(frozen=True)
class JaxoptLBFGS(HostLoopSolver):
    """jaxopt's L-BFGS (``"jaxopt_lbfgs"``, the optional ``jaxparam[jaxopt]`` extra), one
    jaxopt update per iteration; an update that is non-finite, inverts a triangle or
    raises the energy is replaced by the flip-free Armijo search along it, and jaxopt's
    state restarts there.  With a free boundary and a scale-invariant energy the result
    is recentred and rescaled once, at the end.

    **Fields:** ``linesearch`` (jaxopt's, ``"backtracking"``); ``maxls`` (its largest
    number of trials, 40); ``patience`` (consecutive iterations of relative energy
    decrease below ``energy_rtol`` before stopping, 3).
    """

    name: ClassVar[str] = "jaxopt_lbfgs"

    linesearch: str = "backtracking"
    maxls: int = 40
    patience: int = 3

    def start(self, problem: Problem, x, stop: StopRules) -> _JaxoptState:
        try:
            import jaxopt
        except ImportError:
            raise SolverError("minimize: solver 'jaxopt_lbfgs' needs jaxopt (pip install "
                              "'jaxparam[jaxopt]').", stage="init") from None
        fun = lambda y: energy_value(y, *problem.arrays, en=problem.en)
        solver = jaxopt.LBFGS(fun=fun, maxiter=stop.max_iters, linesearch=self.linesearch,
                              maxls=self.maxls, jit=True)
        return _JaxoptState(solver, jax.jit(solver.update), solver.init_state(jnp.asarray(x)))

    def step(self, problem: Problem, state: _JaxoptState, x, f: float, g):
        y_new, jstate_new = state.update(jnp.asarray(x), state.state)
        x_new = np.asarray(y_new)
        f_new = problem.value(x_new)
        if not np.isfinite(f_new) or problem.flipped(x_new) or f_new > f:
            x_new, f_new, t = flip_free_armijo(problem, x, f, g, x_new - x)
            return Step(x_new, f_new, t), state._replace(
                state=state.solver.init_state(jnp.asarray(x_new)))
        return Step(x_new, f_new, 1.0), state._replace(state=jstate_new)
