"""The solver registry: names to solver classes, and the lookup :func:`jaxparam.minimize`
uses for its ``solver`` argument."""
from __future__ import annotations

from ..errors import MeshError
from .base import Solver
from .newton import Newton
from .quasi_newton import BFGS, LBFGS, JaxoptLBFGS

__all__ = ["SOLVERS", "solver_from"]

#: The solvers :func:`jaxparam.minimize` knows by name (the ``solver`` argument), each a
#: :class:`~jaxparam.optimize.base.Solver` class built with its default settings.  Add
#: your own class here to make its name known.
SOLVERS: dict[str, type[Solver]] = {
    Newton.name: Newton,
    LBFGS.name: LBFGS,
    BFGS.name: BFGS,
    JaxoptLBFGS.name: JaxoptLBFGS,
}


def solver_from(spec) -> Solver:
    """A :class:`~jaxparam.optimize.base.Solver` from a registry name (hyphens or
    underscores), a solver instance (returned as is) or a solver class (built with its
    defaults).  Raises :class:`MeshError` for anything else."""
    if isinstance(spec, Solver):
        return spec
    if isinstance(spec, type) and issubclass(spec, Solver):
        return spec()
    key = spec.replace("-", "_") if isinstance(spec, str) else None
    if key in SOLVERS:
        return SOLVERS[key]()
    raise MeshError(f"minimize: unknown solver {spec!r}; use one of {sorted(SOLVERS)} or pass a "
                    "solver instance with its own settings, e.g. "
                    "solver=jp.optimize.Newton(regularization=1e-9).")
