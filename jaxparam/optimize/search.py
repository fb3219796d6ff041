"""The flip-free Armijo line search of the host-loop solvers (Newton, jaxopt's L-BFGS)."""
from __future__ import annotations

import numpy as np

from .. import tol
from .problem import Problem

__all__ = ["flip_free_armijo", "blockwise_armijo"]


def flip_free_armijo(problem: Problem, x, f: float, g, d):
    """Backtracking Armijo along ``d`` from ``min(1, max_step)``; rejects flips and ``+inf``.

    ``d`` is replaced by ``-g`` when it is not a descent direction.  The first step is
    capped by :func:`jaxparam.geometry.max_step` (Smith & Schaefer 2015); each trial must
    be finite, decrease the energy by ``tol.ARMIJO_C1 * t * slope`` and invert no
    triangle; the step shrinks by ``tol.BACKTRACK_SHRINK`` up to ``tol.BACKTRACK_MAX``
    times.

    A problem of disconnected pieces (:attr:`Problem.blocks`) is searched piece by piece
    (:func:`blockwise_armijo`).

    **Returns:** ``(x_new, f_new, t)``; ``t == 0.0`` (and ``x``, ``f`` unchanged) when no
    trial was accepted.
    """
    if problem.blocks is not None:
        return blockwise_armijo(problem, x, f, g, d)
    slope = float(np.dot(g, d))
    if not slope < 0:
        d = -g
        slope = float(np.dot(g, d))
    t = min(1.0, problem.max_step(x, d))
    for _ in range(tol.BACKTRACK_MAX):
        xt = x + t * d
        ft = problem.value(xt)
        if np.isfinite(ft) and ft <= f + tol.ARMIJO_C1 * t * slope and problem.flipped(xt) == 0:
            return xt, ft, t
        t *= tol.BACKTRACK_SHRINK
    return x, f, 0.0


def blockwise_armijo(problem: Problem, x, f: float, g, d):
    """:func:`flip_free_armijo` with one step per piece of :attr:`Problem.blocks`.

    The energy is the sum of the pieces' energies and no face couples two pieces, so the
    Armijo test, the flip-free bound and the backtracking are applied to each piece on its
    own: a piece far from its optimum is no longer held back by another piece's first flip
    (an atlas's charts).  A trial evaluates the pieces still searching in one kernel
    (:meth:`Problem.face_energies`, or :meth:`Problem.face_energies_of` on their faces
    when they hold less than half); accepted pieces keep their step while the others
    shrink.  A piece whose direction is not a descent one searches along ``-g``.  The
    new energy is the sum of the pieces' accepted ones (equal to :meth:`Problem.value`
    to rounding).

    **Returns:** ``(x_new, f_new, t)``, ``t`` the largest accepted step (``0.0``, and ``x``,
    ``f`` unchanged, when no piece moved).
    """
    B = problem.blocks
    d = np.array(d, np.float64)
    g = np.asarray(g, np.float64)
    slope = np.bincount(B.dof, weights=g * d, minlength=B.n + 1)
    bad = ~(slope < 0)
    if bad[B.dof].any():
        flip_dir = bad[B.dof]
        d[flip_dir] = -g[flip_dir]
        slope = np.bincount(B.dof, weights=g * d, minlength=B.n + 1)
    moves = np.bincount(B.dof, weights=np.abs(d), minlength=B.n + 1) > 0
    e0, steps = problem.face_energies_and_steps(x, d)
    t = np.minimum(1.0, B.face_min(steps))
    e0 = np.bincount(B.face, weights=e0, minlength=B.n + 1)
    e_new = e0.copy()
    todo = moves.copy()
    todo[B.n] = False                        # the ghost faces' piece has no DOF
    done = np.zeros(B.n + 1, bool)
    M = B.face.size
    for _ in range(tol.BACKTRACK_MAX):
        if not todo.any():
            break
        xt = x + np.where(done | todo, t, 0.0)[B.dof] * d
        faces = B.faces_of(np.flatnonzero(todo))
        if 2 * faces.size < M:            # the pieces still searching: their faces alone
            e, area = problem.face_energies_of(xt, faces)
            owner = B.face[faces]
        else:
            (e, area), owner = problem.face_energies(xt), B.face
        e = np.bincount(owner, weights=e, minlength=B.n + 1)
        flips = np.bincount(owner, weights=(area <= 0), minlength=B.n + 1)
        ok = todo & np.isfinite(e) & (e <= e0 + tol.ARMIJO_C1 * t * slope) & (flips == 0)
        e_new[ok] = e[ok]
        done |= ok
        todo &= ~ok
        t[todo] *= tol.BACKTRACK_SHRINK
    t = np.where(done, t, 0.0)
    if not done.any():
        return x, f, 0.0
    return x + t[B.dof] * d, float(e_new.sum()), float(t.max())
