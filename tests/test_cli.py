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


# -- one vocabulary: both spellings, the API's defaults ------------------------------------

def parse(*argv):
    from jaxparam.cli import build_parser

    return build_parser().parse_args(list(argv))


@pytest.mark.parametrize("flag, value, parsed", [
    ("--weights", "mean_value", "mean-value"), ("--weights", "mean-value", "mean-value"),
    ("--weights", "inverse_distance", "inverse-distance"), ("--solver", "jaxopt_lbfgs", "jaxopt-lbfgs"),
    ("--solver", "jaxopt-lbfgs", "jaxopt-lbfgs"), ("--energy", "symmetric_dirichlet", "symmetric-dirichlet"),
    ("--spacing", "uniform", "uniform"), ("--boundary", "square", "square"),
])
def test_flatten_accepts_both_spellings(flag, value, parsed):
    args = parse("flatten", "m.obj", "-o", "o.obj", flag, value)
    assert getattr(args, flag[2:].replace("-", "_")) == parsed


@pytest.mark.parametrize("argv, dest, parsed", [
    (["meshless", "p.xyz", "-o", "o.obj", "--weights", "shape_preserving"], "weights", "shape-preserving"),
    (["fit", "m.obj", "-o", "o.obj", "--surface", "clough_tocher"], "surface", "clough-tocher"),
    (["remesh", "m.obj", "-o", "o.obj", "--weights", "mean_value"], "weights", "mean-value"),
    (["batch", "d", "-o", "o", "--weights", "mean_value"], "weights", "mean-value"),
])
def test_other_commands_accept_both_spellings(argv, dest, parsed):
    assert getattr(parse(*argv), dest) == parsed


def test_a_bad_name_is_a_usage_error_listing_the_choices(mesh_file, capsys):
    with pytest.raises(SystemExit) as e:
        main(["flatten", str(mesh_file), "-o", "x.obj", "--weights", "cot"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "argument --weights: unknown weights 'cot'; use one of uniform, inverse-distance" in err
    with pytest.raises(SystemExit) as e:
        main(["flatten", str(mesh_file), "-o", "x.obj", "--energy", "nope"])
    assert e.value.code == 2 and "unknown energy 'nope'" in capsys.readouterr().err


def test_help_lists_the_choices(capsys):
    with pytest.raises(SystemExit):
        parse("flatten", "--help")
    out = capsys.readouterr().out
    assert "{uniform,inverse-distance,shape-preserving,mean-value,harmonic}" in out
    assert "jaxopt-lbfgs" in out and "(default: shape-preserving)" in out


def test_defaults_are_the_apis():
    from jaxparam.options import default_of, hyphenated

    f = parse("flatten", "m.obj", "-o", "o.obj")
    assert f.max_iters == default_of(jp.minimize, "max_iters")
    assert f.solver == hyphenated(default_of(jp.minimize, "solver"))
    assert f.free_boundary == default_of(jp.minimize, "free_boundary")
    for name in ("weights", "boundary", "spacing"):
        assert getattr(f, name) == hyphenated(default_of(jp.convex_map, name))
    r = parse("remesh", "m.obj", "-o", "o.obj")
    assert r.levels == default_of(jp.remesh, "levels")
    assert r.base_faces == default_of(jp.remesh, "base_faces")
    c = parse("compress", "m.obj", "-o", "o.obj")
    assert c.keep == default_of(jp.wavelets.compress, "keep")
    assert c.wavelet == default_of(jp.wavelets.compress, "wavelet")
    m = parse("manifold", "m.obj", "-o", "o.obj")
    assert m.base_faces == default_of(jp.manifold_map, "base_faces")
    assert m.levels == default_of(jp.manifold.ManifoldParameterization.remesh, "levels")
    fit = parse("fit", "m.obj", "-o", "o.obj")
    assert fit.surface == hyphenated(default_of(jp.fit_surface, "kind"))
    assert fit.resolution == default_of(jp.fitting.Surface.sample, "resolution")
    p = parse("meshless", "p.xyz", "-o", "o.obj")
    assert p.k == default_of(jp.reconstruct_surface, "k")
    assert p.weights == hyphenated(default_of(jp.reconstruct_surface, "weights"))
    assert p.boundary == default_of(jp.reconstruct_surface, "boundary")
    b = parse("batch", "d", "-o", "o")
    assert all(getattr(b, k) == getattr(f, k) for k in ("weights", "boundary", "spacing", "solver",
                                                        "max_iters", "energy", "free_boundary"))


def test_both_spellings_give_the_same_flattening(mesh_file, tmp_path):
    a, b = tmp_path / "a.obj", tmp_path / "b.obj"
    ra, rb = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["flatten", str(mesh_file), "-o", str(a), "--weights", "inverse_distance",
                 "--report", str(ra)]) == 0
    assert main(["flatten", str(mesh_file), "-o", str(b), "--weights", "inverse-distance",
                 "--report", str(rb)]) == 0
    assert a.read_bytes() == b.read_bytes()
    assert json.loads(ra.read_text())["weights"] == json.loads(rb.read_text())["weights"] == "inverse-distance"
    assert set(json.loads(ra.read_text())["seconds"]) == {"load", "convex_map", "report", "save"}


def test_python_m_jaxparam_cli_and_the_pipeline_are_importable():
    from jaxparam.cli import pipeline

    assert pipeline.EXIT_INPUT == 3 and pipeline.EXIT_SOLVER == 4
    code, message = pipeline.failure(jp.SolverError("singular", stage="factorize"))
    assert code == 4 and message == "solver failed at stage 'factorize': singular"
    assert pipeline.failure(jp.MeshFileError("x: no such file."))[0] == 3
    assert pipeline.failure(KeyError("k"))[0] == 1
