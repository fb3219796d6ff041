import json
import subprocess
import sys

import numpy as np
import pytest

import jaxparam as jp
from jaxparam.cli import main


@pytest.fixture(scope="module")
def mesh_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("cli") / "graph.obj"
    jp.save(p, jp.shapes.graph_surface(10))
    return p


def test_info_json(mesh_file, capsys):
    assert main(["info", str(mesh_file), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["vertices"] == 100 and info["boundary_loops"] == 1 and info["is_disk"]


def test_flatten_writes_obj_report_and_plot(mesh_file, tmp_path):
    out, rep, png = tmp_path / "o.obj", tmp_path / "r.json", tmp_path / "p.png"
    code = main(["flatten", str(mesh_file), "-o", str(out), "--weights", "mean-value",
                 "--boundary", "square", "--report", str(rep), "--plot", str(png)])
    assert code == 0
    m = jp.load(out)
    src = jp.load(mesh_file)
    np.testing.assert_array_equal(m.faces, src.faces)
    np.testing.assert_allclose(m.vertices, src.vertices)
    assert m.uv is not None and np.isfinite(m.uv).all()
    r = json.loads(rep.read_text())
    for key in ["vertices", "faces", "flips", "boundary_overlaps", "sym_dirichlet", "mips",
                "max_aspect", "angle_distortion", "area_distortion", "seconds"]:
        assert key in r
    assert r["flips"] == 0 and r["weights"] == "mean-value"
    assert png.stat().st_size > 1000


def test_bad_input_exit_3(tmp_path, capsys):
    p = tmp_path / "bad.off"
    p.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n")
    assert main(["flatten", str(p), "-o", str(tmp_path / "o.obj")]) == 3
    err = capsys.readouterr().err
    assert "truncated" in err
    assert not (tmp_path / "o.obj").exists()


def test_closed_mesh_exit_3(tmp_path, capsys):
    p = tmp_path / "s.obj"
    jp.save(p, jp.shapes.sphere(1))
    assert main(["flatten", str(p), "-o", str(tmp_path / "o.obj")]) == 3
    assert "closed" in capsys.readouterr().err


def test_usage_exit_2(mesh_file):
    with pytest.raises(SystemExit) as e:
        main(["flatten", str(mesh_file)])
    assert e.value.code == 2
    with pytest.raises(SystemExit) as e:
        main(["flatten", str(mesh_file), "-o", "x.obj", "--weights", "cot"])
    assert e.value.code == 2


def test_console_script_runs(mesh_file, tmp_path):
    r = subprocess.run([sys.executable, "-m", "jaxparam.cli", "info", str(mesh_file)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "genus" in r.stdout
