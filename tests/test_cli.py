import json
import subprocess
import sys

import numpy as np
import pytest

import jaxparam as jp
from jaxparam.cli import main
from jaxparam.cli.pipeline import flatten_mesh


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


def _obj_with_nan_vertex(path):
    m = jp.shapes.graph_surface(6)
    V = np.array(m.vertices)
    V[5, 2] = np.nan
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in V.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(m.faces).tolist()]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_refused_input_leaves_no_solver_warm_up_running(tmp_path, capsys):
    """flatten starts the sparse solver's runtime in a thread while it reads; a refused input
    must not return (and exit the interpreter) with that thread inside MKL's start-up."""
    import threading

    p = _obj_with_nan_vertex(tmp_path / "nan.obj")
    assert main(["flatten", str(p), "-o", str(tmp_path / "o.obj")]) == 3
    assert "vertex 5" in capsys.readouterr().err
    assert not [t for t in threading.enumerate() if t.name == "jaxparam-sparse-warm-up"]


def test_refused_input_exits_3_as_a_whole_process(tmp_path):
    """The whole process exits 3 with the message (it crashed with a segmentation fault,
    exit code 139, when the interpreter finalized during the warm-up)."""
    p = _obj_with_nan_vertex(tmp_path / "nan.obj")
    r = subprocess.run([sys.executable, "-m", "jaxparam", "-q", "flatten", str(p), "-o",
                        str(tmp_path / "o.obj")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 3, r.stderr
    assert "non-finite" in r.stderr and not (tmp_path / "o.obj").exists()


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


# Found in QA (session 21): these options did nothing without --energy, silently.
@pytest.mark.parametrize("command", ["flatten", "batch"])
@pytest.mark.parametrize("extra, named", [
    (["--free-boundary"], "--free-boundary sets"),
    (["--max-iters", "5", "--solver", "lbfgs"], "--solver and --max-iters set")])
def test_minimization_options_without_an_energy_are_refused(mesh_file, tmp_path, capsys,
                                                             command, extra, named):
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / mesh_file.name).write_bytes(mesh_file.read_bytes())
    src = str(folder / mesh_file.name) if command == "flatten" else str(folder)
    out = tmp_path / ("o.obj" if command == "flatten" else "out")
    assert main([command, src, "-o", str(out)] + extra) == 2
    err = capsys.readouterr().err
    assert f"jaxparam {command}: error: {named} how an energy is minimized, but no --energy" in err
    assert "--energy symmetric-dirichlet" in err and not out.exists()
    assert main([command, src, "-o", str(out), "--energy", "mips"] + extra) == 0


def test_console_script_runs(mesh_file, tmp_path):
    r = subprocess.run([sys.executable, "-m", "jaxparam.cli", "info", str(mesh_file)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "genus" in r.stdout


def test_python_dash_m_jaxparam_runs_the_command(mesh_file):
    # Found in QA: "python -m jaxparam info ..." said "'jaxparam' is a package and cannot be
    # directly executed"; only "python -m jaxparam.cli" worked.
    r = subprocess.run([sys.executable, "-m", "jaxparam", "info", str(mesh_file)],
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


# --- issue 16: help with examples and defaults, --version, --quiet, output format first,
# the unconverged warning, a GLB with its checker texture ---------------------------------

SUBCOMMANDS = ["info", "flatten", "meshless", "fit", "remesh", "compress", "manifold", "atlas",
               "batch"]


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_every_subcommand_help_has_an_example_and_defaults(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "example:" in out and f"jaxparam {command} " in out.split("example:")[1]
    assert "--quiet" in out
    if command not in ("info",):
        assert "(default: " in out


def test_version_is_the_packages(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"jaxparam {jp.__version__}"


def test_unknown_output_extension_fails_before_any_work(tmp_path, capsys):
    # The input does not exist: an error about the extension proves nothing was loaded.
    code = main(["flatten", str(tmp_path / "missing.obj"), "-o", str(tmp_path / "x.stl")])
    assert code == 3
    err = capsys.readouterr().err
    assert ".stl" in err and "missing.obj" not in err
    assert not any(tmp_path.iterdir())


def test_quiet_switches_the_library_bars_off(mesh_file, tmp_path):
    before = jp.config.progress
    try:
        jp.config.progress = True
        assert main(["flatten", str(mesh_file), "-o", str(tmp_path / "o.obj"), "--quiet"]) == 0
        assert jp.config.progress is False
        jp.config.progress = True
        assert main(["-q", "info", str(mesh_file)]) == 0
        assert jp.config.progress is False
    finally:
        jp.config.progress = before


def test_unconverged_minimization_warns_on_stderr(mesh_file, tmp_path, capsys):
    rep = tmp_path / "r.json"
    code = main(["flatten", str(mesh_file), "-o", str(tmp_path / "o.obj"), "--energy",
                 "symmetric-dirichlet", "--free-boundary", "--max-iters", "1", "--report", str(rep)])
    assert code == 0
    assert json.loads(rep.read_text())["converged"] is False
    err = capsys.readouterr().err
    assert "warning" in err and "without converging" in err and "--max-iters" in err
    # a converged run says nothing of the sort
    code = main(["flatten", str(mesh_file), "-o", str(tmp_path / "o2.obj"), "--energy",
                 "symmetric-dirichlet", "--max-iters", "200"])
    assert code == 0 and "without converging" not in capsys.readouterr().err


def test_glb_with_checker_texture_opens_in_trimesh(mesh_file, tmp_path):
    trimesh = pytest.importorskip("trimesh")
    out = tmp_path / "flat.glb"
    assert main(["flatten", str(mesh_file), "-o", str(out), "--checker-texture"]) == 0
    scene = trimesh.load(out, process=False)
    geom = list(scene.geometry.values())[0] if hasattr(scene, "geometry") else scene
    assert geom.visual.uv is not None and len(geom.visual.uv) == geom.vertices.shape[0]
    image = geom.visual.material.baseColorTexture
    assert image is not None and min(image.size) >= 64


@pytest.mark.slow
def test_batch_on_a_local_ray(tmp_path):
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'jaxparam[ray]')")
    folder = tmp_path / "in"
    folder.mkdir()
    jp.save(folder / "a.obj", jp.shapes.graph_surface(6))
    jp.save(folder / "b.obj", jp.shapes.disk(3))
    ray.init(num_cpus=2, include_dashboard=False, ignore_reinit_error=True,
             log_to_driver=False)
    try:
        out = tmp_path / "out"
        assert main(["batch", str(folder), "-o", str(out), "--engine", "ray", "--quiet"]) == 0
    finally:
        ray.shutdown()
    recs = [json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()]
    assert [r["status"] for r in recs] == ["ok", "ok"]
    for r in recs:
        m = jp.load(r["output"])
        assert m.uv is not None and jp.distortion(m, m.uv).flips == 0


@pytest.mark.parametrize("ext", [".ply", ".glb", ".obj"])
def test_flatten_writes_the_format_the_extension_names(mesh_file, tmp_path, ext):
    """`jaxparam flatten X -o x.ply` writes a PLY that trimesh reads with its UVs (and so on)."""
    trimesh = pytest.importorskip("trimesh")
    out = tmp_path / f"flat{ext}"
    assert main(["flatten", str(mesh_file), "-o", str(out), "--quiet"]) == 0
    t = trimesh.load(out, process=False, force="mesh")
    src = jp.load(mesh_file)
    assert t.vertices.shape == np.asarray(src.vertices).shape
    mine = jp.load(out)
    assert t.visual.uv is not None
    np.testing.assert_allclose(np.asarray(t.visual.uv), np.asarray(mine.uv), atol=1e-6)


def test_flatten_repeats_the_minimize_defaults_that_its_parser_shows():
    # The parser reads --solver's and --max-iters' defaults from flatten_mesh, so that a
    # linear flatten imports no optimizer (issue 17): they must stay minimize's.
    from jaxparam.cli.pipeline import flatten_mesh
    from jaxparam.options import default_of

    for name in ("solver", "max_iters"):
        assert default_of(flatten_mesh, name) == default_of(jp.minimize, name)
    args = __import__("jaxparam.cli", fromlist=["build_parser"]).build_parser("flatten").parse_args(
        ["flatten", "m.off", "-o", "x.obj"])
    assert (args.solver, args.max_iters, args.energy) == ("newton", 200, None)


def test_flatten_warns_when_the_map_has_flat_or_flipped_faces(tmp_path, capsys):
    # Found in QA (snail refined, --boundary square): two faces whose dividing edges land on
    # one side of the square were written with zero area, exit 0 and nothing on stderr.
    p = tmp_path / "patch.obj"
    jp.save(p, jp.shapes.cylinder_patch(12, 4))
    assert main(["flatten", str(p), "-o", str(tmp_path / "sq.obj"), "--boundary", "square"]) == 0
    err = capsys.readouterr().err
    assert "warning: 2 faces of the map are flipped or degenerate" in err
    assert "dividing edges (2, 7), (40, 45)" in err and "--boundary circle" in err
    assert main(["flatten", str(p), "-o", str(tmp_path / "c.obj")]) == 0
    assert "warning" not in capsys.readouterr().err


def test_flatten_a_strip_with_no_interior_vertex(tmp_path, capsys):
    # Found in QA: a 8 x 2 grid (every vertex on the boundary) failed with exit 3, "weights:
    # the mesh has no interior vertices", raised by the report's Theorem 1 check, although
    # the map itself (the boundary map) is fine.
    p = tmp_path / "strip.obj"
    jp.save(p, jp.shapes.plane_grid(8, 2))
    out, rep = tmp_path / "s.obj", tmp_path / "s.json"
    assert main(["flatten", str(p), "-o", str(out), "--report", str(rep)]) == 0
    r = json.loads(rep.read_text())
    assert r["flips"] == 0 and r["theorem1"]["holds"] is True
    assert jp.load(out).uv.shape == (16, 2)


def test_library_warnings_are_printed_as_the_commands_own_lines(tmp_path, capsys):
    # Found in QA: "jaxparam remesh ... -o semi.off" printed Python's
    # "/.../cli/commands.py:103: UserWarning: save: ... OFF holds no texture coordinates"
    # followed by the source line "save(args.output, mesh, uv)".
    p = tmp_path / "g.obj"
    jp.save(p, jp.shapes.graph_surface(5))
    assert main(["flatten", str(p), "-o", str(tmp_path / "flat.off")]) == 0
    err = capsys.readouterr().err
    assert "jaxparam flatten: warning: save: " in err and "OFF holds no texture coordinates" in err
    assert "UserWarning" not in err and "commands.py" not in err


def test_fit_names_seamed_uvs_as_such(tmp_path, capsys):
    # Found in QA: jaxparam fit on an atlas OBJ (vt per corner) said "the mesh has no
    # per-vertex texture coordinates (vt)", though the file has vt lines.
    mesh = jp.shapes.graph_surface(4)
    F = np.asarray(mesh.faces)
    tex = np.asarray(jp.convex_map(mesh))[F.reshape(-1)]
    tex[0] += 0.01                                     # a seam at vertex F[0, 0]
    p = tmp_path / "seamed.obj"
    jp.save(p, mesh, tex, uv_faces=np.arange(F.size).reshape(-1, 3))
    assert main(["fit", str(p), "-o", str(tmp_path / "s.obj")]) == 3
    err = capsys.readouterr().err
    assert "texture coordinates have seams" in err and "jaxparam flatten" in err


# Found in QA (session 21): an atlas saved as .glb (its vertices split at the seams, one UV
# each) was fitted as one surface across all its charts; --resolution -1 crashed in numpy.
def test_fit_refuses_split_charts_and_a_bad_resolution(tmp_path, capsys):
    a, b = jp.shapes.graph_surface(4), jp.shapes.graph_surface(4)
    V = np.concatenate([np.asarray(a.vertices), np.asarray(b.vertices) + [3.0, 0, 0]])
    uv = np.concatenate([np.asarray(jp.convex_map(a)) * 0.4, np.asarray(jp.convex_map(b)) * 0.4 + 0.5])
    p = tmp_path / "charts.ply"
    jp.save(p, jp.TriMesh(V, np.concatenate([a.faces, b.faces + a.n_vertices])), uv)
    assert main(["fit", str(p), "-o", str(tmp_path / "s.obj")]) == 3
    assert "2 connected components (an atlas's charts" in capsys.readouterr().err
    q = tmp_path / "one.obj"
    jp.save(q, a, np.asarray(jp.convex_map(a)))
    for bad in ("-1", "1"):
        assert main(["fit", str(q), "-o", str(tmp_path / "s.obj"), "--resolution", bad]) == 3
        assert f"resolution (grid points along each side) must be an integer >= 2, got {bad}" in \
            capsys.readouterr().err
    assert not (tmp_path / "s.obj").exists()


def test_fit_stays_near_the_mesh_and_warns_where_the_map_squeezes(tmp_path, capsys):
    # Found in QA (session 20): jaxparam fit of a flattened halftunnel wrote a surface 7.6e9
    # across for a mesh 12 across, exit 0.  A disk map of a vase (a tube with a cap) squeezes
    # the tube into a ring, as camelhead's circle map squeezes its head.
    tube = jp.shapes.revolution(16, 8)
    V, F = np.asarray(tube.vertices), np.asarray(tube.faces)
    i, c = np.arange(16), V.shape[0]
    vase = jp.TriMesh(np.vstack([V, [0.0, 0.0, 0.0]]),
                      np.vstack([F, np.stack([(i + 1) % 16, i, np.full(16, c)], 1)]))
    for name, mesh, warned in (("vase", vase, True), ("graph", jp.shapes.graph_surface(8), False)):
        p = tmp_path / f"{name}.obj"
        jp.save(p, mesh, np.asarray(jp.convex_map(mesh)))
        out = tmp_path / f"{name}_fit.obj"
        assert main(["fit", str(p), "-o", str(out), "-q"]) == 0
        captured = capsys.readouterr()
        assert ("jaxparam fit: warning: the spline misses" in captured.err) == warned, captured.err
        assert "residual RMS" in captured.out
        X, S = np.asarray(mesh.vertices), np.asarray(jp.load(out).vertices)
        assert np.all(np.isfinite(S))
        assert np.abs(S - X.mean(0)).max() < 1.5 * np.abs(X - X.mean(0)).max()


def test_meshless_merges_duplicate_points_when_asked(tmp_path, capsys):
    # Found in QA: a scan with repeated points was refused with "pass merge_duplicates=True",
    # an option the command did not have, so no command line could read it.
    P = jp.shapes.graph_surface(8).vertices
    pts = tmp_path / "dups.xyz"
    np.savetxt(pts, np.vstack([P, P[:5]]))
    out = tmp_path / "m.obj"
    assert main(["meshless", str(pts), "-o", str(out)]) == 3
    assert "pass --merge-duplicates" in capsys.readouterr().err
    assert main(["meshless", str(pts), "-o", str(out), "--merge-duplicates"]) == 0
    mesh = jp.load(out)
    assert mesh.n_vertices == len(P) + 5 and mesh.faces.max() < len(P)


def test_flatten_free_boundary_starts_as_minimize_does(mesh_file, tmp_path):
    """``flatten --free-boundary`` takes jp.minimize's start: the conformal map for symmetric
    Dirichlet (here one-to-one), the convex map for the scale-invariant MIPS; the report
    says which, and the symmetric Dirichlet result is jp.minimize's default one."""
    rep = tmp_path / "r.json"
    for energy, want in (("symmetric-dirichlet", "conformal-map"), ("mips", "convex-map")):
        assert main(["-q", "flatten", str(mesh_file), "-o", str(tmp_path / "o.obj"), "--energy",
                     energy, "--free-boundary", "--report", str(rep)]) == 0
        r = json.loads(rep.read_text())
        assert r["start"] == want and r["converged"] is True
    mesh = jp.load(mesh_file)
    res = jp.minimize(mesh, "symmetric_dirichlet", free_boundary=True, verbose=False)
    uv, rep2 = flatten_mesh(mesh, energy="symmetric-dirichlet", free_boundary=True, say=lambda s: None)
    assert rep2["start"] == "conformal-map"
    np.testing.assert_allclose(uv, np.asarray(res.uv), rtol=0, atol=1e-12)


def test_compress_of_a_level_0_remesh_says_to_remesh_deeper(mesh_file, tmp_path, capsys):
    # Found in QA (session 21): it said "make it with jaxparam remesh", which is how it was made.
    semi = tmp_path / "lv0.obj"
    assert main(["-q", "remesh", str(mesh_file), "-o", str(semi), "--levels", "0"]) == 0
    capsys.readouterr()
    assert main(["-q", "compress", str(semi), "-o", str(tmp_path / "c.obj")]) == 3
    assert "at 1 level or more (a remesh of level 0 is its base domain alone" in capsys.readouterr().err


@pytest.mark.slow
def test_remesh_with_a_square_boundary_takes_the_area_aware_map(tmp_path):
    """Found by session 22's held-out sweep: ``remesh --boundary square`` took the plain convex
    map, 21 % of the diagonal off at level 4 on a sphere with one face removed (the circle's
    area-aware map: 0.6 %); it now minimizes the stretch inside the square too."""
    s = jp.shapes.sphere(2)
    src = tmp_path / "cap.obj"
    jp.save(src, jp.TriMesh(s.vertices, np.delete(np.asarray(s.faces), 0, axis=0)))
    err = {}
    for b in ("circle", "square"):
        rep = tmp_path / f"{b}.json"
        assert main(["-q", "remesh", str(src), "-o", str(tmp_path / f"{b}.obj"), "--levels", "3",
                     "--boundary", b, "--report", str(rep)]) == 0
        err[b] = json.loads(rep.read_text())["errors"]["hausdorff"][-1]
    assert err["square"] < 2 * err["circle"] + 0.005, err


def test_atlas_option_errors_name_the_flags(mesh_file, tmp_path, capsys):
    """The atlas's messages named its Python options (margin_texels, texture_size) on the
    command line (session 22's held-out sweep)."""
    assert main(["-q", "atlas", str(mesh_file), "-o", str(tmp_path / "a.obj"),
                 "--texture-size", "16", "--margin-texels", "8"]) == 3
    err = capsys.readouterr().err
    assert "--margin-texels must be >= 0" in err and "margin_texels" not in err
