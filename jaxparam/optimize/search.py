"""The flip-free Armijo line search of the host-loop solvers (Newton, jaxopt's L-BFGS)."""
from __future__ import annotations

import numpy as np

from .. import tol
from .problem import Problem

__all__ = ["flip_free_armijo"]


def flip_free_armijo(problem: Problem, x, f: float, g, d):
    """Backtracking Armijo along ``d`` from ``min(1, max_step)``; rejects flips and ``+inf``.

    ``d`` is replaced by ``-g`` when it is not a descent direction.  The first step is
    capped by :func:`jaxparam.geometry.max_step` (Smith & Schaefer 2015); each trial must
    be finite, decrease the energy by ``tol.ARMIJO_C1 * t * slope`` and invert no
    triangle; the step shrinks by ``tol.BACKTRACK_SHRINK`` up to ``tol.BACKTRACK_MAX``
    times.

    **Returns:** ``(x_new, f_new, t)``; ``t == 0.0`` (and ``x``, ``f`` unchanged) when no
    trial was accepted.
    """
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
