"""Run the short notebook (code cells in order) so the documentation stays true."""
import json
import os
from pathlib import Path

import pytest

NB = Path(__file__).resolve().parents[1] / "notebooks"


def run_notebook(path: Path, workdir: Path) -> dict:
    cells = json.loads(path.read_text())["cells"]
    ns: dict = {}
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        for cell in cells:
            if cell["cell_type"] == "code":
                exec(compile("".join(cell["source"]), f"{path.name}", "exec"), ns)
    finally:
        os.chdir(cwd)
    return ns


def test_notebook_01_runs(tmp_path):
    ns = run_notebook(NB / "01_convex_combination_maps.ipynb", tmp_path)
    assert (tmp_path / "out" / "nb01_uv.png").stat().st_size > 1000
    assert float(ns["g"].__abs__().max()) > 0


def test_notebook_04_runs(tmp_path):
    (tmp_path / "out").mkdir()
    ns = run_notebook(NB / "04_remeshing_and_wavelets.ipynb", tmp_path)
    assert (tmp_path / "out" / "nb04_remesh.png").stat().st_size > 1000
    assert ns["err"] < 1e-12 and float(ns["g"].__abs__().max()) > 0


def test_notebook_05_runs(tmp_path):
    ns = run_notebook(NB / "05_closed_meshes.ipynb", tmp_path)
    assert (tmp_path / "out" / "nb05_torus_remesh.png").stat().st_size > 1000
    assert ns["err"] < 1e-12 and ns["semi"].topology.genus == 1
