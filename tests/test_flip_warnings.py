"""The warnings about flipped UV triangles name their cause and remedy, in ``jaxparam flatten``
and in ``jaxparam batch`` (session 27: a batch line said only "ok" for a map with 95 flips)."""
import json

import numpy as np

import jaxparam as jp
from jaxparam.cli import main
from jaxparam.cli.pipeline import flip_warning


def open_tube(rings=200, around=16, radius=0.02, length=5.0):
    """An open cylinder (two boundary loops) ``length / radius`` = 250 radii long: its convex
    map, the second loop filled, shrinks the far end below floating-point resolution (72
    faces flip; at 150-200 radii none do)."""
    t = 2 * np.pi * np.arange(around) / around
    z = np.linspace(0.0, length, rings)
    V = np.stack([np.tile(radius * np.cos(t), rings), np.tile(radius * np.sin(t), rings),
                  np.repeat(z, around)], 1)
    i, j = np.meshgrid(np.arange(rings - 1), np.arange(around), indexing="ij")
    a, b = i * around + j, i * around + (j + 1) % around
    F = np.concatenate([np.stack([a, b, b + around], -1).reshape(-1, 3),
                        np.stack([a, b + around, a + around], -1).reshape(-1, 3)])
    return jp.TriMesh(V, F)


def test_each_cause_gets_its_own_remedy():
    assert flip_warning({"flips": 0, "theorem1": {"holds": True}}) is None
    assert flip_warning({"flips": None}) is None
    edges = flip_warning({"flips": 3, "theorem1": {"holds": False, "convex_boundary": True,
                                                    "dividing_edges_on_boundary": [[4, 9]]}})
    assert edges.startswith("3 faces") and "(4, 9)" in edges and "--boundary circle" in edges
    plane = flip_warning({"flips": 2, "theorem1": {"holds": False, "convex_boundary": False,
                                                    "positive_weights": True}})
    assert "not convex" in plane and "--boundary circle" in plane
    neg = flip_warning({"flips": 5, "theorem1": {"holds": False, "convex_boundary": True,
                                                  "positive_weights": False, "negative_weights": 17}})
    assert "17 weights are negative" in neg and "shape-preserving" in neg
    tiny = flip_warning({"flips": 7, "theorem1": {"holds": True}})
    assert "floating-point resolution" in tiny and "cut the mesh open" in tiny
    assert flip_warning({"flips": 1, "theorem1": None}) == \
        "1 faces of the map are flipped or degenerate (zero area) in the UVs"


def test_flatten_and_batch_say_why_a_long_tube_folds(tmp_path, capsys):
    tube = tmp_path / "in" / "tube.off"
    tube.parent.mkdir()
    jp.save(tube, open_tube())
    assert main(["flatten", str(tube), "-o", str(tmp_path / "t.obj"), "-q"]) == 0
    err = capsys.readouterr().err
    assert "faces of the map are flipped or degenerate" in err
    assert "floating-point resolution" in err, err
    out = tmp_path / "out"
    assert main(["batch", str(tube.parent), "-o", str(out), "-q"]) == 0
    cap = capsys.readouterr()
    rec = json.loads((out / "summary.jsonl").read_text().splitlines()[0])
    assert rec["status"] == "ok" and rec["flips"] > 0
    assert "1 map(s) have flipped or degenerate UV triangles (tube.off)" in cap.err
    assert f"tube.off: ok (warning: {rec['flips']} faces" in cap.out + cap.err
