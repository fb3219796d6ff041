"""Run every notebook in notebooks/ (code cells in order, in this process) so the documentation
stays true, then check what each one claims.

The cells are executed with ``exec`` in one namespace per notebook, in a fresh working folder
(the plots go to ``out/`` there; matplotlib picks a backend that needs no display, Agg, where
there is none).  nbclient/nbconvert are not needed.  Each notebook runs under a time limit
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
    # Fig. 4: the spline approximates the real mesh closely over the square map.
    diag = np.linalg.norm(np.ptp(np.asarray(ns["bump"].vertices), 0))
    assert ns["spline"].residual_rms < 0.01 * diag
    # Figs. 6 and 8: shape-preserving weights distort less than uniform ones; both one-to-one.
    f68 = ns["fit68"]
    assert f68["shape_preserving"].mips < f68["uniform"].mips
    assert f68["uniform"].flips == f68["shape_preserving"].flips == 0
    # Fig. 12: the best-fit plane boundary beats the circle and the rectangle.
    f12 = ns["fit12"]
    assert f12["plane"].mips < min(f12["circle"].mips, f12["square"].mips)
    assert f12["plane"].flips == 0 and f12["circle"].flips == 0


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
    # Fig. 16: the most isometric map converges, flips nothing and lowers MIPS.
    assert ns["most"].converged and ns["after"].flips == 0
    assert ns["after"].mips < ns["before"].mips


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
    # Figs. 20-22: camelhead.xyz and a noisy scan with outliers, each one disk without a
    # flipped UV face; >= 99 % of the (non-outlier) points used; most planted outliers found
    # (measured 37 of 40) and few false ones; the noisy scan within 1.5 % of the diagonal both
    # ways (measured 1.18 % and 1.08 %; the noise is 0.2 % RMS).
    for name in ("nb03_fig20_21_uv.png", "nb03_fig21_mesh.png", "nb03_fig22_noisy.png"):
        assert_png(out, name)
    for r, d in ((ns["rec20"], ns["d20"]), (ns["rec22"], ns["d22"])):
        assert r.mesh.topology.is_disk and d.flips == 0
    assert ns["used20"] >= 0.99 and ns["used22"] >= 0.99
    assert ns["found"] >= 0.85 and ns["rec22"].outliers.size <= 1.1 * ns["planted"].size
    assert ns["faces_to_surface"] < 0.015 and ns["surface_to_faces"] < 0.015
    np.testing.assert_array_equal(np.asarray(ns["rec22"].mesh.vertices), ns["P22"])


def check_04(ns, out):
    assert_png(out, "nb04_remesh.png")
    assert ns["err"] < 1e-12
    # The remesh's details are differentiable in the input positions: against a difference.
    assert_gradient_matches_fd(ns["g"], ns["detail_energy"], ns["mesh"].vertices, h=1e-6, rtol=1e-5)
    assert_png(out, "nb04_rate_distortion.png")
    assert_png(out, "nb04_fig17_18.png")                                 # Figs. 17-18, lilium
    assert_png(out, "nb04_fig17b.png")
    assert ns["kept"] < 1e-12 and ns["moved"] > 0.1                      # editing keeps details
    assert ns["rd"]["butterfly"][2] < ns["rd"]["lazy"][2]                 # 5 %: butterfly beats lazy
    e = ns["semi_area"].errors
    assert all(a > b for a, b in zip(e.rms, e.rms[1:]))


def check_05(ns, out):
    assert_png(out, "nb05_torus_remesh.png")
    assert_png(out, "nb05_fig26_remesh.png")
    assert_png(out, "nb05_fig26_compressed.png")
    assert ns["err"] < 1e-12 and ns["semi"].mesh.topology.genus == 1


def check_06(ns, out):
    assert_png(out, "nb06_weights.png")
    assert_png(out, "nb06_shape.png")
    # Learned spring weights: MIPS falls from Tutte's by more than 4 % (measured 2.386 ->
    # 2.278) and ends below the mean-value map's (2.299); the weights stay positive.
    lw = ns["losses_w"]
    assert lw[-1] < 0.96 * lw[0] and lw[-1] < ns["mips_mean_value"], (lw[0], lw[-1])
    assert np.all(ns["mu"] > 0)
    jp, mesh = ns["jp"], ns["mesh"]
    assert jp.metrics.flips(mesh, ns["uv_after"]) == 0
    # Through minimize: the loss falls, and the minimized energy's excess over an isometry
    # falls by more than half (measured 2.6e-2 -> 3e-3).
    lv = ns["losses_v"]
    assert lv[-1] < lv[0] and all(b <= a + 1e-12 for a, b in zip(lv, lv[1:])), lv
    assert 0 < ns["excess_after"] < 0.5 * ns["excess_before"], (ns["excess_before"], ns["excess_after"])


CHECKS = {
    "01_convex_combination_maps": check_01,
    "02_nonlinear_methods": check_02,
    "03_unorganized_points": check_03,
    "04_remeshing_and_wavelets": check_04,
    "05_closed_meshes": check_05,
    "06_optimize_through_the_map": check_06,
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
@pytest.mark.notebook
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs(path, tmp_path):
    (tmp_path / "out").mkdir()
    ns = run_notebook(path, tmp_path)
    try:
        CHECKS[path.stem](ns, tmp_path / "out")
    finally:
        import matplotlib.pyplot as plt

        plt.close("all")


# --- the stored notebooks (make notebooks: notebooks/execute.py) ----------------------------

#: Notebooks stored executed, and how many figures each shows at least.  `make notebooks`
#: executes all of them; add a notebook here once it is stored executed.
STORED = {"01_convex_combination_maps": 12, "02_nonlinear_methods": 2, "03_unorganized_points": 6,
          "04_remeshing_and_wavelets": 4, "05_closed_meshes": 3, "06_optimize_through_the_map": 4}

#: The largest stored notebook, in bytes: small enough to review.
MAX_BYTES = 3_000_000


def outputs_of(path: Path) -> list[dict]:
    cells = json.loads(path.read_text())["cells"]
    return [o for c in cells if c["cell_type"] == "code" for o in c.get("outputs", [])]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_stored_outputs_hold_no_progress_or_stderr(path):
    """Whatever a notebook stores is clean: no stderr, no progress bars, no widgets."""
    for o in outputs_of(path):
        assert not (o["output_type"] == "stream" and o.get("name") == "stderr"), (path.name, o)
        assert "\r" not in "".join(o.get("text", "")), (path.name, "a text progress bar")
        assert "application/vnd.jupyter.widget-view+json" not in o.get("data", {}), path.name
    assert path.stat().st_size < MAX_BYTES


@pytest.mark.parametrize("stem", sorted(STORED))
def test_stored_notebooks_are_executed_with_their_figures(stem):
    path = NB / f"{stem}.ipynb"
    cells = [c for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code"]
    assert all(c.get("execution_count") for c in cells), f"{path.name}: run make notebooks"
    pngs = sum("image/png" in o.get("data", {}) for o in outputs_of(path))
    assert pngs >= STORED[stem], (path.name, pngs)


def test_strip_drops_progress_and_stderr_only():
    import importlib.util

    spec = importlib.util.spec_from_file_location("nb_execute", NB / "execute.py")
    execute = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(execute)
    nbformat = pytest.importorskip("nbformat", reason="the notebooks extra is not installed")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("x", outputs=[
        nbformat.v4.new_output("stream", name="stderr", text="warning\n"),
        nbformat.v4.new_output("stream", name="stdout", text="  5%|5/100\r 10%|10/100\r"),
        nbformat.v4.new_output("display_data", data={
            "application/vnd.jupyter.widget-view+json": {"model_id": "x"}, "text/plain": "bar"}),
        nbformat.v4.new_output("stream", name="stdout", text="result 42\n"),
        nbformat.v4.new_output("display_data", data={"image/png": "iVBORw0KGgo=",
                                                     "text/plain": "<Figure>"}),
    ])])
    nb.cells[0].metadata["execution"] = {"iopub.status.busy": "2026-12-01"}
    assert execute.strip(nb) == 3
    kept = nb.cells[0].outputs
    assert [o.get("text", "") for o in kept][0] == "result 42\n" and "image/png" in kept[1]["data"]
    assert "execution" not in nb.cells[0].metadata
