"""Inputs the commands cannot use are refused before the work (session 27's held-out sweep:
``jaxparam remesh`` on an annulus said "the convex map folds" after the map's work, and a
``--levels -1`` took 9 s to refuse)."""
import importlib
import re

import numpy as np
import pytest

import jaxparam as jp
from jaxparam.cli import main
from jaxparam.errors import MeshError

remesh_module = importlib.import_module("jaxparam.remesh")   # jp.remesh is the function


def annulus(n_around=24, n_rings=4):
    """A flat ring: two boundary loops."""
    t = 2 * np.pi * np.arange(n_around) / n_around
    r = np.linspace(1.0, 2.0, n_rings)
    V = np.stack([np.outer(r, np.cos(t)).ravel(), np.outer(r, np.sin(t)).ravel(),
                  np.zeros(n_around * n_rings)], 1)
    i, j = np.meshgrid(np.arange(n_rings - 1), np.arange(n_around), indexing="ij")
    a, b = i * n_around + j, i * n_around + (j + 1) % n_around
    F = np.concatenate([np.stack([a, b, b + n_around], -1).reshape(-1, 3),
                        np.stack([a, b + n_around, a + n_around], -1).reshape(-1, 3)])
    return jp.TriMesh(V, F)


@pytest.fixture
def no_map(monkeypatch):
    """Fail the test if the remesh command starts its map."""
    def refuse(*a, **k):
        raise AssertionError("the map ran before the input was checked")
    monkeypatch.setattr(remesh_module, "area_aware_map", refuse)


@pytest.mark.parametrize("make,args,message", [
    (annulus, [], "2 boundary loops; remeshing needs a disk"),
    (lambda: jp.shapes.disk(4), ["--levels", "-1"], r"levels must be an integer in \[0, 10\], got -1"),
    (lambda: jp.shapes.disk(4), ["--levels", "11"], "got 11"),
])
def test_remesh_refuses_before_its_map(tmp_path, capsys, no_map, make, args, message):
    src = tmp_path / "m.off"
    jp.save(src, make())
    assert main(["remesh", str(src), "-o", str(tmp_path / "r.obj"), "-q", *args]) == 3
    err = capsys.readouterr().err
    assert re.search(message, err), err
    assert not (tmp_path / "r.obj").exists()


def test_check_remesh_input_is_what_remesh_refuses():
    ring = annulus()
    with pytest.raises(MeshError, match="2 boundary loops"):
        remesh_module.check_remesh_input(ring, 3)
    with pytest.raises(MeshError, match="2 boundary loops"):
        jp.remesh(ring, levels=3)
    with pytest.raises(MeshError, match="base_faces or corners, not both"):
        remesh_module.check_remesh_input(jp.shapes.disk(4), 3, base_faces=5, corners=[0, 3, 6])
    remesh_module.check_remesh_input(jp.shapes.disk(4), 3)          # a disk passes


@pytest.mark.parametrize("value", ["-3", "0", "2.5"])
def test_max_iters_must_be_a_positive_integer_at_parse_time(tmp_path, capsys, value):
    src = tmp_path / "m.off"
    jp.save(src, jp.shapes.disk(3))
    with pytest.raises(SystemExit) as exc:
        main(["flatten", str(src), "-o", str(tmp_path / "f.obj"), "--energy", "mips",
              "--max-iters", value])
    assert exc.value.code == 2
    assert f"--max-iters must be a positive integer, got '{value}'" in capsys.readouterr().err
