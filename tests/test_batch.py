"""`jaxparam batch`: a folder of two good generated meshes and one broken file."""
import json
import os
import sys
import types

import numpy as np
import pytest

import jaxparam as jp
from jaxparam.cli import batch, main

KEYS = ["file", "status", "error", "error_type", "output", "seconds", "vertices", "faces", "flips",
        "boundary_overlaps", "sym_dirichlet", "mips", "max_aspect", "angle_distortion",
        "area_distortion", "holes_filled"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("batch") / "in"
    d.mkdir()
    jp.save(d / "grid.obj", jp.shapes.graph_surface(8))
    disk = jp.shapes.disk(4, seed=1, height=0.2)
    F = disk.faces
    body = "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in np.asarray(disk.vertices))
    body += "".join(f"3 {a} {b} {c}\n" for a, b, c in F)
    (d / "disk.off").write_text(f"OFF\n{disk.n_vertices} {len(F)} 0\n{body}")
    (d / "broken.off").write_text("OFF\n5 2 0\n0 0 0\n1 0 0\n")      # truncated
    (d / "notes.txt").write_text("not a mesh, not picked up")
    return d


def read_summary(out):
    return [json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()]


def check_run(folder, out, capsys):
    recs = read_summary(out)
    assert [os.path.basename(r["file"]) for r in recs] == ["broken.off", "disk.off", "grid.obj"]
    for r in recs:
        assert set(KEYS) - {"vertices", "faces", "flips", "boundary_overlaps", "sym_dirichlet", "mips",
                            "max_aspect", "angle_distortion", "area_distortion",
                            "holes_filled"} <= set(r)
    bad, *good = recs
    assert bad["status"] == "error" and bad["error_type"] == "MeshFileError"
    assert "promises 5 vertices" in bad["error"] and bad["output"] is None
    for r in good:
        assert set(KEYS) <= set(r), set(KEYS) - set(r)
        assert r["status"] == "ok" and r["error"] is None and r["flips"] == 0
        assert r["holes_filled"] == 0 and r["seconds"] > 0
        src, res = jp.load(r["file"]), jp.load(r["output"])
        np.testing.assert_array_equal(res.faces, src.faces)          # input vertex order kept
        np.testing.assert_allclose(res.vertices, src.vertices)
        assert np.isfinite(res.uv).all()
    assert sorted(p.name for p in out.iterdir()) == ["disk.obj", "grid.obj", "summary.jsonl"]
    err = capsys.readouterr().err
    assert "broken.off: error" in err and "[3/3]" in err
    return good


def test_batch_in_process_and_with_a_pool_agree(folder, tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    assert main(["batch", str(folder), "-o", str(a), "--weights", "mean-value"]) == 3
    good = check_run(folder, a, capsys)
    assert all(r["weights"] == "mean-value" for r in good)
    assert main(["batch", str(folder), "-o", str(b), "--weights", "mean-value", "--workers", "2"]) == 3
    check_run(folder, b, capsys)
    for name in ["disk.obj", "grid.obj"]:      # same input, same output, whichever process ran it
        assert (a / name).read_bytes() == (b / name).read_bytes()


def test_all_good_exits_0_and_shared_stems_keep_their_extension(folder, tmp_path, capsys):
    d = tmp_path / "in"
    d.mkdir()
    (d / "grid.obj").write_bytes((folder / "grid.obj").read_bytes())
    (d / "grid.off").write_bytes((folder / "disk.off").read_bytes())
    out = tmp_path / "out"
    assert main(["batch", str(d), "-o", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["grid.obj.obj", "grid.off.obj", "summary.jsonl"]
    assert [r["status"] for r in read_summary(out)] == ["ok", "ok"]
    assert "2 of 2 files flattened" in capsys.readouterr().out


def test_no_two_inputs_write_the_same_output(folder, tmp_path, capsys):
    """x.off, x.obj and x.obj.off: the stem rule alone gave x.obj and x.obj.off the same
    x.obj.obj (one result silently lost, both 'ok' in the summary)."""
    d = tmp_path / "in"
    d.mkdir()
    for name in ["x.off", "x.obj.off"]:
        (d / name).write_bytes((folder / "disk.off").read_bytes())
    (d / "x.obj").write_bytes((folder / "grid.obj").read_bytes())
    out = tmp_path / "out"
    assert main(["batch", str(d), "-o", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["summary.jsonl", "x.obj.obj", "x.obj.off.obj",
                                                      "x.off.obj"]
    recs = read_summary(out)
    assert [os.path.basename(r["output"]) for r in recs] == ["x.obj.obj", "x.obj.off.obj", "x.off.obj"]
    assert jp.load(out / "x.obj.obj").n_vertices == jp.load(d / "x.obj").n_vertices
    assert "3 of 3 files flattened" in capsys.readouterr().out


@pytest.mark.parametrize("names, expected", [
    (["a.obj", "b.off"], ["a.obj", "b.obj"]),
    (["x.obj", "x.obj.off", "x.off"], ["x.obj.obj", "x.obj.off.obj", "x.off.obj"]),
    (["A.obj", "a.off"], ["A.obj.obj", "a.off.obj"]),               # same name on macOS/Windows
    (["A.obj", "a.obj"], ["A.obj.obj", "a.obj-2.obj"]),
])
def test_output_names_are_unique_ignoring_case(names, expected):
    outs = batch.output_paths(names, "o")
    assert [p.name for p in outs] == expected
    assert len({p.name.casefold() for p in outs}) == len(names)


def test_batch_usage_and_input_errors(folder, tmp_path, capsys, monkeypatch):
    assert main(["batch", str(tmp_path / "nope"), "-o", str(tmp_path / "o")]) == 3
    assert "no such folder" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["batch", str(empty), "-o", str(tmp_path / "o")]) == 3
    assert "holds no mesh files" in capsys.readouterr().err
    assert main(["batch", str(folder), "-o", str(folder)]) == 2
    assert "would overwrite the inputs" in capsys.readouterr().err
    assert not (tmp_path / "o").exists() and not (folder / "summary.jsonl").exists()
    with pytest.raises(SystemExit) as e:
        main(["batch", str(folder), "-o", str(tmp_path / "o"), "--workers", "0"])
    assert e.value.code == 2
    monkeypatch.setitem(sys.modules, "ray", None)          # `import ray` raises ImportError
    assert main(["batch", str(folder), "-o", str(tmp_path / "o"), "--engine", "ray"]) == 2
    assert "needs the 'ray' package" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


class _Ref:
    def __init__(self, value):
        self.value = value


def fake_ray():
    """Enough of Ray's API (init, remote, wait, get) to run the ray engine's plumbing in-process."""
    def remote(fn):
        return types.SimpleNamespace(remote=lambda *a: _Ref(fn(*a)))
    return types.SimpleNamespace(init=lambda **k: None, remote=remote, get=lambda r: r.value,
                                 wait=lambda refs, num_returns: (refs[:num_returns], refs[num_returns:]))


def test_ray_engine_plumbing(folder, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", fake_ray())
    out = tmp_path / "r"
    assert main(["batch", str(folder), "-o", str(out), "--engine", "ray"]) == 3
    check_run(folder, out, capsys)


def crashing_flatten_file(path, out_path, options):
    """Kills its worker process on the file named 'disk' (a stand-in for a segfault or OOM kill)."""
    if os.path.basename(path).startswith("disk."):
        os._exit(7)
    return batch.flatten_file(path, out_path, options)


@pytest.mark.slow
def test_a_dying_worker_is_named_and_the_rest_finish(folder, tmp_path):
    files = batch.find_mesh_files(folder)
    outs = batch.output_paths(files, tmp_path)
    opts = {"weights": "uniform", "boundary": "circle", "spacing": "chord", "energy": None,
            "free_boundary": False, "solver": "newton", "max_iters": 10}
    recs = batch.run_batch(files, outs, opts, work=crashing_flatten_file, workers=2,
                           say=lambda m: None)
    assert [r["status"] for r in recs] == ["error", "error", "ok"]
    assert recs[0]["error_type"] == "MeshFileError"
    assert recs[1]["error_type"] == "WorkerDied" and "worker process died" in recs[1]["error"]
    assert batch.exit_code(recs) == 3 and batch.exit_code(recs[1:]) == 1
    assert batch.exit_code(recs[2:]) == 0
    assert (tmp_path / "grid.obj").exists() and not (tmp_path / "disk.obj").exists()
