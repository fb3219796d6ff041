"""Run every notebook in notebooks/ (code cells in order, in this process) so the documentation
stays true, then check what each one claims.

The cells are executed with ``exec`` in one namespace per notebook, in a fresh working folder
(the plots go to ``out/`` there; ``jaxparam.plot`` forces matplotlib's Agg backend, so nothing
needs a display).  nbclient/nbconvert are not needed.  Each notebook runs under a time limit
(``TIMEOUT_S``), and the tests are marked ``slow``: ``make test-fast`` leaves them out,
``make test`` and ``make notebooks`` run them.
"""
import json
import os
import signal
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

NB = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NB.glob("*.ipynb"))
TIMEOUT_S = 300          # per notebook; each takes well under a minute on an idle machine


class NotebookTimeout(Exception):
    pass


def run_notebook(path: Path, workdir: Path, timeout: int = TIMEOUT_S) -> dict:
    """Execute the code cells of ``path`` in order in ``workdir``; returns their namespace.

    Raises :class:`NotebookTimeout` when the notebook runs longer than ``timeout`` seconds."""
    cells = json.loads(path.read_text())["cells"]
    ns: dict = {"__name__": "__main__"}
    cwd = os.getcwd()

    def on_alarm(signum, frame):
        raise NotebookTimeout(f"{path.name} ran longer than {timeout} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(timeout)
    os.chdir(workdir)
    try:
        for i, cell in enumerate(cells):
            if cell["cell_type"] == "code":
                exec(compile("".join(cell["source"]), f"{path.name}[cell {i}]", "exec"), ns)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        os.chdir(cwd)
    return ns


def directional_fd(f, x0: np.ndarray, d: np.ndarray, h: float) -> float:
    """Central difference of the scalar ``f`` at ``x0`` along ``d``."""
    return float((f(jnp.asarray(x0 + h * d)) - f(jnp.asarray(x0 - h * d))) / (2 * h))


def assert_gradient_matches_fd(g, f, x0, *, h, rtol, seed=0):
    """``<g, d>`` equals the finite difference of ``f`` along a random direction ``d``."""
    x0 = np.asarray(x0, np.float64)
    d = np.random.default_rng(seed).standard_normal(x0.shape)
    fd = directional_fd(f, x0, d, h)
    dg = float(np.sum(np.asarray(g) * d))
    assert abs(fd) > 1e-8, "the finite difference is zero: the check would be vacuous"
    assert abs(dg - fd) <= rtol * abs(fd), (dg, fd)


def assert_png(out: Path, name: str):
    p = out / name
    assert p.stat().st_size > 1000, p
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", p


def check_01(ns, out):
    assert_png(out, "nb01_uv.png")
    assert_png(out, "nb01_checker.png")
    jp, mesh = ns["jp"], ns["mesh"]
    # The weights loop (circle boundary) ends with harmonic weights: no flip.
    assert ns["rep"].flips == 0 and ns["rep"].theorem1.convex_boundary
    # The square map of the picture: every face it collapses or flips is excused by Theorem 1,
    # i.e. cut off by a dividing edge that the certificate reports along a side of the square.
    rep = jp.distortion(mesh, ns["uv"], weights="shape_preserving")
    areas = np.asarray(jp.geometry.signed_areas(ns["uv"], mesh.faces))
    excused = [set(e) for e in rep.theorem1.dividing_edges_on_boundary]
    for f in np.flatnonzero(areas <= 0):
        assert any(e <= set(mesh.faces[f].tolist()) for e in excused), f
    assert rep.flips == int(np.sum(areas <= 0)) and rep.boundary_overlaps == 0
    # jax.grad through the sparse solve: the notebook's gradient against a finite difference.
    assert ns["g"].shape == ns["mesh"].vertices.shape
    assert_gradient_matches_fd(ns["g"], ns["loss"], ns["mesh"].vertices, h=1e-6, rtol=1e-5)


def check_02(ns, out):
    # example5 is developable: the last energy of the loop (condition_f_squared) finds an
    # isometry, and the user-defined energy's minimizer flips nothing.
    assert ns["rep"].max_aspect < 1 + 1e-3
    assert ns["res"].flips == 0 and np.isfinite(ns["res"].energy)
    # Implicit differentiation of the optimum: jax.grad of the notebook's loss (again, now that
    # the notebook has compiled it) against a finite difference through two full minimizations.
    V0 = ns["small"].vertices
    g = jax.grad(ns["loss"])(jnp.asarray(V0))
    assert_gradient_matches_fd(g, ns["loss"], V0, h=1e-5, rtol=1e-5)


def check_03(ns, out):
    assert_png(out, "nb03_iso.png")
    assert len(ns["boundary"]) > 0
    rec = ns["rec"]
    jp = ns["jp"]
    assert rec.mesh.topology.is_disk and jp.distortion(rec.mesh, rec.uv).flips == 0
    # The Clough-Tocher surface interpolates the points it was fitted to.
    used = rec.mesh.topology.referenced
    X = ns["surf"].evaluate(np.asarray(rec.uv)[used])
    np.testing.assert_allclose(X, np.asarray(rec.mesh.vertices)[used], atol=1e-8)


def check_04(ns, out):
    assert_png(out, "nb04_remesh.png")
    assert ns["err"] < 1e-12
    # The remesh's details are differentiable in the input positions: against a difference.
    assert_gradient_matches_fd(ns["g"], ns["detail_energy"], ns["mesh"].vertices, h=1e-6, rtol=1e-5)


def check_05(ns, out):
    assert_png(out, "nb05_torus_remesh.png")
    assert ns["err"] < 1e-12 and ns["semi"].mesh.topology.genus == 1


CHECKS = {
    "01_convex_combination_maps": check_01,
    "02_nonlinear_methods": check_02,
    "03_unorganized_points": check_03,
    "04_remeshing_and_wavelets": check_04,
    "05_closed_meshes": check_05,
}


def test_every_notebook_is_run_and_checked():
    """Each notebook in notebooks/ has its checks here (a new notebook needs some)."""
    assert NOTEBOOKS, f"no notebook found in {NB}"
    assert sorted(p.stem for p in NOTEBOOKS) == sorted(CHECKS)


def test_the_time_limit_stops_a_notebook(tmp_path):
    nb = tmp_path / "loop.ipynb"
    nb.write_text(json.dumps({"cells": [{"cell_type": "code", "source": ["while True:\n", "    pass\n"]}]}))
    with pytest.raises(NotebookTimeout, match="loop.ipynb ran longer than 1 s"):
        run_notebook(nb, tmp_path, timeout=1)


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs(path, tmp_path):
    (tmp_path / "out").mkdir()
    ns = run_notebook(path, tmp_path)
    CHECKS[path.stem](ns, tmp_path / "out")
