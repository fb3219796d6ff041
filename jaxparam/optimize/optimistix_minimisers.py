"""optimistix's quasi-Newton minimisers with a replaceable descent (imported on first use,
so ``import jaxparam`` does not import optimistix).

optimistix documents subclassing ``AbstractLBFGS`` / ``AbstractBFGS`` to choose another
descent and search; these classes do just that, for
:class:`~jaxparam.optimize.quasi_newton.LBFGS` and ``BFGS``.  Defined once, at module
level, so that two runs build equal solvers and share the compiled ``optx.minimise``.
"""
from __future__ import annotations

from typing import Callable

import optimistix as optx

__all__ = ["FlipFreeLBFGS", "FlipFreeBFGS"]


class FlipFreeLBFGS(optx.AbstractLBFGS):
    """L-BFGS with a given descent (the inverse-Hessian form), optimistix's backtracking
    Armijo search and its max norm in the Cauchy test."""

    rtol: float
    atol: float
    descent: object
    verbose: Callable
    history_length: int = 10
    norm: Callable = optx.max_norm
    use_inverse: bool = True
    search: object = optx.BacktrackingArmijo()


class FlipFreeBFGS(optx.AbstractBFGS):
    """Dense BFGS with a given descent, as :class:`FlipFreeLBFGS`."""

    rtol: float
    atol: float
    descent: object
    verbose: Callable
    norm: Callable = optx.max_norm
    use_inverse: bool = True
    search: object = optx.BacktrackingArmijo()
