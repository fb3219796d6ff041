"""solver="bfgs" refuses problems whose dense Hessian estimate would not fit, before any step,
and names the solvers that scale."""
import time

import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import SolverError
from jaxparam.optimize import BFGS


def test_bfgs_refuses_a_large_problem_and_names_newton_and_lbfgs():
    mesh = jp.shapes.plane_grid(48, 48, jitter=0.2, seed=0)      # 2116 interior: 4232 unknowns
    t0 = time.perf_counter()
    with pytest.raises(SolverError, match=r"dense 4232 x 4232 .*0\.14 GB.*at most 4000 unknowns "
                                          r"\(128 MB\).*solver='newton'.*solver='lbfgs'") as e:
        jp.minimize(mesh, solver="bfgs", init=np.asarray(mesh.vertices)[:, :2], max_iters=2, verbose=False)
    assert e.value.stage == "solver"
    assert time.perf_counter() - t0 < 60                         # refused, not run


def test_bfgs_limit_is_a_field(disk_mesh):
    """(Small problems under the default limit run: tests/test_optimize.py runs "bfgs".)"""
    with pytest.raises(SolverError, match=r"at most 10 unknowns"):
        jp.minimize(disk_mesh, solver=BFGS(max_dofs=10), max_iters=2, verbose=False)
