"""What every solver shares: the stopping rules, the typed result, the solver interface
and the host iteration loop of the solvers that step on the host (Newton, jaxopt).

A solver is an object with a registry ``name`` and a ``run(problem, stop, verbose=...)``
method returning a :class:`SolveResult`; :class:`HostLoopSolver` implements ``run``
for solvers that only say how to take one step (``start`` and ``step``).
"""
from __future__ import annotations

import abc
import time
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from .. import tol
from ..errors import MeshError, SolverError, first_few
from ..options import is_integer, is_number
from ..progress import progress
from .problem import Problem

__all__ = ["StopRules", "SolveResult", "Step", "Solver", "HostLoopSolver", "Monitor",
           "start_point", "progress_bar", "REASONS", "UnconvergedGradientWarning",
           "CollapsedMapWarning", "BoundaryOverlapWarning"]


class UnconvergedGradientWarning(UserWarning):
    """Issued when a :func:`jaxparam.minimize` that did not converge is differentiated.

    The gradient is then that of the stopping point: the implicit-function formula
    evaluated there as if it were the optimum (exact only at a stationary point).
    ``minimize(..., strict=True)`` raises :class:`~jaxparam.errors.SolverError` (stage
    ``"gradient"``) instead; ``warnings.simplefilter("error", UnconvergedGradientWarning)``
    turns every such warning into an error.
    """


class CollapsedMapWarning(UserWarning):
    """Issued when :func:`jaxparam.minimize` ends with collapsed UV triangles: none flipped,
    but some with an aspect ``s1 / s2`` above :data:`jaxparam.tol.COLLAPSED_ASPECT`, segments
    in all but name (the result's ``collapsed`` counts them).  Energies without a barrier
    against it (``"arap"``, ``"conformal"``, ``"angle"``, user energies) can end there; the
    barrier energies (``"symmetric_dirichlet"``, ``"mips"``) cannot.
    """


class BoundaryOverlapWarning(UserWarning):
    """Issued when a free-boundary :func:`jaxparam.minimize` ends with a boundary that
    crosses itself: every triangle keeps its orientation, but the map folds over itself as
    a whole (the result's ``boundary_overlaps`` counts the crossing pairs of boundary
    edges).  The energies keep triangles from flipping, not the boundary from meeting
    itself (a long, thin or spiral part can swing round onto another)."""


#: The ``reason`` strings of :class:`SolveResult`, by the rule that stopped the run.
REASONS = {
    "max_iters": "max_iters",
    "no_decrease": "no further decrease along the search direction",
    "gradient": "gradient norm below tolerance",
    "energy": "relative energy decrease below tolerance",
    "time": "time limit",
    "max_steps": "optimistix max_steps reached",
}

#: A run stopped because the energy stopped falling (``"no_decrease"``, ``"energy"``) counts
#: as converged only near a stationary point: its gradient norm fell to ``STALL_GRAD_SHARE``
#: of the start's, or moving the free UVs by a relative ``e`` changes the energy by at most
#: ``STALL_RTOL e`` relative (``|g| |x - mean x| <= STALL_RTOL |f|``).  An energy unbounded
#: below (``-(s1^2 + s2^2)`` with a free boundary) stalled at the flip-free line search with
#: its start's gradient and was reported converged (session 28).
STALL_GRAD_SHARE = 1e-2
STALL_RTOL = 1e-4


@dataclass(frozen=True)
class StopRules:
    """When a solver stops (the stopping arguments of :func:`jaxparam.minimize`).

    **Fields:** ``max_iters`` (accepted steps at most); ``energy_rtol`` (stop after
    ``patience`` consecutive iterations, a solver setting, whose relative energy
    decrease is in ``[0, energy_rtol)``); ``grad_rtol`` (stop when the gradient norm is
    at most ``grad_rtol`` times the start's); ``max_seconds`` (stop after the iteration
    that passes this wall time; ``None``: no limit).
    """

    max_iters: int = 200
    energy_rtol: float = tol.ENERGY_RTOL
    grad_rtol: float = tol.GRAD_RTOL
    max_seconds: float | None = None

    def __post_init__(self):
        # checked here, before any work (session 21: max_iters="5" and 2.5 reached a
        # comparison deep in the driver as TypeErrors; True ran one iteration)
        it = self.max_iters
        if not is_integer(it) or it < 0:
            raise MeshError(f"minimize: max_iters must be an integer >= 0, got {it!r}.")
        for name in ("energy_rtol", "grad_rtol"):
            v = getattr(self, name)
            if not is_number(v) or not v >= 0:
                raise MeshError(f"minimize: {name} must be a number >= 0, got {v!r}.")
        v = self.max_seconds
        if v is not None and (not is_number(v) or not v >= 0):
            raise MeshError(f"minimize: max_seconds must be a number >= 0 or None, got {v!r}.")


@dataclass(frozen=True)
class SolveResult:
    """What :meth:`Solver.run` returns.

    **Fields:** ``x (2 k,)`` the final free DOFs (host array); ``energy`` at ``x``;
    ``iterations`` (accepted steps); ``converged``; ``reason`` (one of :data:`REASONS`'
    values, or a solver's own); ``history`` (the energy at the start and after each
    accepted step: ``iterations + 1`` entries); ``times`` (seconds since the start at each
    entry of ``history``); ``seconds`` (wall time, compilation included).
    """

    x: np.ndarray
    energy: float
    iterations: int
    converged: bool
    reason: str
    history: list = field(repr=False)
    times: list = field(repr=False)
    seconds: float


@dataclass(frozen=True)
class Step:
    """One host-loop step: the new point ``x``, its ``energy``, and the step ``length``
    taken along the search direction (``0.0``: no acceptable step, the run stops)."""

    x: np.ndarray
    energy: float
    length: float


class Solver(abc.ABC):
    """A minimizer :func:`jaxparam.minimize` can run.

    Subclasses are frozen dataclasses whose fields are the solver's settings, with a
    class attribute ``name`` (its key in :data:`jaxparam.optimize.SOLVERS`).  ``run``
    starts from ``problem.x0``, never accepts an iterate with an inverted triangle, and
    obeys ``stop``.
    """

    name: ClassVar[str]

    @abc.abstractmethod
    def run(self, problem: Problem, stop: StopRules, *, verbose: bool = False) -> SolveResult:
        """Minimize ``problem``'s energy from ``problem.x0``."""


def start_point(problem: Problem):
    """``(x0, f0, g0)`` on the host; raises :class:`SolverError` (stage ``"init"``) when the
    start's energy is infinite."""
    x = np.asarray(problem.x0)
    f, g = problem.value_and_grad(x)
    if not np.isfinite(f):
        raise SolverError(_non_finite_start(problem, x, f), stage="init")
    return x, f, g


def _non_finite_start(problem: Problem, x, f: float) -> str:
    """Why the start's energy ``f`` is not finite: the faces whose terms are not, and whether
    their start triangles are turned over or degenerate (the start's fault) or positive (the
    energy's: it is not finite on a valid triangle)."""
    what = "NaN" if np.isnan(f) else "infinite"
    terms, areas = problem.face_energies(x)
    bad = np.flatnonzero(~np.isfinite(terms))
    head = f"minimize: the start's energy ({problem.en.name}) is {what}"
    if not bad.size:
        return head + "; a degenerate or inverted triangle?"
    turned = bad[areas[bad] <= 0]
    if turned.size:
        return (f"{head} on faces {first_few(turned)}, whose start triangles are turned over or "
                "degenerate: start from a flip-free map (init=, e.g. jp.convex_map(mesh)).")
    return (f"{head} on faces {first_few(bad)}, whose start triangles are positive (face "
            f"{bad[0]}: signed UV area {areas[bad[0]]:.3g}): the energy itself is not finite "
            "there; check its formula (a log or a root of a negative number?) on valid "
            "triangles.")


def progress_bar(problem: Problem, solver: Solver, total: int, verbose: bool | None):
    """A bar (:func:`jaxparam.progress.progress`) that shows only for runs longer than a
    second; ``verbose`` None follows ``jp.config.progress``."""
    return progress(total=total, desc=f"{problem.en.name} ({solver.name})", unit="step",
                    verbose=verbose)


class Monitor:
    """The host-side record of one run and its :class:`StopRules`.

    Holds ``history`` and ``times`` (the start's entry first), ``reason``, ``converged``
    and ``stopped`` (whether a rule has ended the run).  ``t0`` is the run's
    ``time.perf_counter()`` start; ``patience`` the solver's.
    """

    def __init__(self, stop: StopRules, patience: int, f0: float, g0, t0: float, bar):
        self.stop, self.patience, self.t0, self.bar = stop, patience, t0, bar
        self.grad0 = float(np.linalg.norm(g0))
        self.grad_norm = self.grad0               # at the last recorded iterate
        self.grad_tol = stop.grad_rtol * max(self.grad0, np.finfo(float).tiny)
        self.history = [f0]
        self.times = [time.perf_counter() - t0]
        self.reason, self.converged, self.stopped = REASONS["max_iters"], False, False
        self.small = 0
        self.started = False

    @property
    def iterations(self) -> int:
        """Accepted steps recorded so far."""
        return len(self.history) - 1

    def record(self, f: float, grad_norm: float, decrease: float, step_length: float) -> bool:
        """Record the iterate after one step (energy ``f``, gradient norm, relative energy
        ``decrease`` of the step, its ``step_length``); True when a rule stops the run."""
        self.history.append(f)
        self.times.append(time.perf_counter() - self.t0)
        self.bar.update(1)
        self.grad_norm = float(grad_norm)
        self.small = self.small + 1 if 0 <= decrease < self.stop.energy_rtol else 0
        if step_length == 0.0:
            self.reason, self.converged = REASONS["no_decrease"], True
        elif grad_norm <= self.grad_tol:
            self.reason, self.converged = REASONS["gradient"], True
        elif self.small >= self.patience:
            self.reason, self.converged = REASONS["energy"], True
        elif (self.stop.max_seconds is not None
              and time.perf_counter() - self.t0 > self.stop.max_seconds):
            self.reason = REASONS["time"]
        elif self.iterations < self.stop.max_iters:
            return False
        self.stopped = True
        return True

    def _stationary(self, x, f: float, reason: str) -> tuple[bool, str]:
        """``(converged, reason)`` of a run stopped by a stall rule at ``x`` (free UVs, flat)
        with energy ``f``, by :data:`STALL_GRAD_SHARE` and :data:`STALL_RTOL`."""
        g = self.grad_norm
        U = np.asarray(x, np.float64).reshape(-1, 2)
        spread = float(np.linalg.norm(U - U.mean(0))) if U.size else 0.0
        if g <= STALL_GRAD_SHARE * self.grad0 or g * spread <= STALL_RTOL * abs(f):
            return True, reason
        return False, (f"{reason}, but not at a stationary point (gradient norm {g:.3g}, "
                       f"{g / max(self.grad0, np.finfo(float).tiny):.2g} of the start's): the "
                       "energy may be unbounded below, not smooth, or stiff beyond the solver")

    @classmethod
    def start(cls, problem: Problem, solver: Solver, stop: StopRules, verbose: bool):
        """Start a run: ``(x0, f0, g0, monitor)``, the clock and the progress bar running
        (:func:`start_point` raises when the start's energy is infinite)."""
        t0 = time.perf_counter()
        x, f, g = start_point(problem)
        bar = progress_bar(problem, solver, stop.max_iters, verbose)
        return x, f, g, cls(stop, solver.patience, f, g, t0, bar)

    def result(self, x, f: float, *, reason: str | None = None,
               converged: bool | None = None) -> SolveResult:
        """Close the bar and return the :class:`SolveResult` at ``x`` (energy ``f``);
        ``reason`` and ``converged`` default to the rule that stopped the run."""
        self.bar.close()
        converged = self.converged if converged is None else converged
        reason = self.reason if reason is None else reason
        if converged and reason in (REASONS["no_decrease"], REASONS["energy"]):
            converged, reason = self._stationary(x, f, reason)
        return SolveResult(x=x, energy=f, iterations=self.iterations,
                           converged=converged, reason=reason,
                           history=self.history, times=self.times,
                           seconds=time.perf_counter() - self.t0)

    def accepted(self, f: float, grad_norm: float) -> bool:
        """For solvers that report each accepted iterate, the start first (optimistix's
        descent query): record it unless it is the start, or the run has stopped
        already; True when the run must stop."""
        if self.stopped:
            return True
        if not self.started:
            self.started = True
            self.stopped = self.stop.max_iters <= 0
            return self.stopped
        prev = self.history[-1]
        return self.record(f, grad_norm, (prev - f) / max(abs(prev), np.finfo(float).tiny), 1.0)


class HostLoopSolver(Solver):
    """A solver stepped from Python: ``run`` evaluates the energy and gradient on the host
    after each step and applies :class:`StopRules` (through a :class:`Monitor`).

    Subclasses give ``step(problem, state, x, f, g) -> (Step, state)``, optionally
    ``start(problem, x, stop) -> state``, a ``patience`` field (consecutive small
    decreases before stopping) and the class attribute ``normalize_each_step``: with a
    free boundary and a scale-invariant energy the iterate is recentred and rescaled to
    the start's area after every step (True) or once at the end (False: for solvers
    whose state would not survive the rescaling).
    """

    patience: int
    normalize_each_step: ClassVar[bool] = False

    def start(self, problem: Problem, x, stop: StopRules) -> Any:
        """The solver's state at the start ``x`` (``None`` by default)."""
        return None

    @abc.abstractmethod
    def step(self, problem: Problem, state, x, f: float, g) -> tuple[Step, Any]:
        """One step from ``x`` (energy ``f``, gradient ``g``): the new point and state."""

    def run(self, problem: Problem, stop: StopRules, *, verbose: bool = False) -> SolveResult:
        x, f, g, monitor = Monitor.start(problem, self, stop, verbose)
        state = self.start(problem, x, stop)
        rescale = problem.free_boundary and problem.en.scale_invariant
        for _ in range(stop.max_iters):
            step, state = self.step(problem, state, x, f, g)
            x_new, f_new = step.x, step.energy
            if rescale and self.normalize_each_step and step.length > 0:
                x_new = problem.normalize(x_new)
                f_new = problem.value(x_new)
            decrease = (f - f_new) / max(abs(f), np.finfo(float).tiny)
            x = x_new
            f, g = problem.value_and_grad(x)
            if monitor.record(f, np.linalg.norm(g), decrease, step.length):
                break
        if rescale and not self.normalize_each_step:
            x = problem.normalize(x)
            f = problem.value(x)
            monitor.history[-1] = f
        return monitor.result(x, f)
