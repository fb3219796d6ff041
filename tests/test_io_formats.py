"""Every format jp.save writes round-trips through trimesh and through jp.load: vertex order,
faces and UVs exact (glTF: exact to float32, the only precision the format has)."""
import warnings

import numpy as np
import pytest

import jaxparam as jp
from jaxparam import io
from jaxparam.errors import MeshError, MeshFileError

trimesh = pytest.importorskip("trimesh")

FORMATS = [".obj", ".ply", ".glb", ".gltf"]
F32 = {".glb", ".gltf"}       # glTF stores float32 positions and UVs


@pytest.fixture(scope="module")
def mesh_uv():
    mesh = jp.shapes.disk(4, seed=2, height=0.3)
    rng = np.random.default_rng(5)
    # Distinct UVs with full float64 mantissas, so a lossy writer cannot pass.
    return mesh, rng.random((mesh.n_vertices, 2)) * 3 - 1


def seamed(mesh):
    """Per-corner UVs with a seam: every face gets its own three texcoords, shifted per face."""
    m = mesh.n_faces
    uv_faces = np.arange(3 * m).reshape(m, 3)
    tex = np.asarray(mesh.vertices)[mesh.faces.reshape(-1), :2] + np.repeat(np.arange(m), 3)[:, None] * 1e-3
    return tex, uv_faces


def close(a, b, ext):
    if ext in F32:
        np.testing.assert_allclose(a, np.asarray(b, np.float32), rtol=0, atol=2e-7 * max(1, np.abs(b).max()))
    else:
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("ext", FORMATS)
def test_round_trip_through_jaxparam(tmp_path, mesh_uv, ext):
    mesh, uv = mesh_uv
    p = tmp_path / f"m{ext}"
    jp.save(p, mesh, uv)
    back = jp.load(p)
    np.testing.assert_array_equal(back.faces, mesh.faces)
    close(back.vertices, np.asarray(mesh.vertices), ext)
    assert back.uv is not None and back.texcoords is None
    close(back.uv, uv, ext)


@pytest.mark.parametrize("ext", FORMATS)
def test_round_trip_through_trimesh(tmp_path, mesh_uv, ext):
    """What we write, trimesh reads (process=False) with the same vertex order and its UVs; and
    what trimesh writes for the same mesh, we read the same way."""
    mesh, uv = mesh_uv
    p = tmp_path / f"m{ext}"
    jp.save(p, mesh, uv)
    t = trimesh.load(p, process=False, force="mesh")
    np.testing.assert_array_equal(t.faces, mesh.faces)
    close(t.vertices, np.asarray(mesh.vertices), ext)
    close(np.asarray(t.visual.uv), uv, ext)
    q = tmp_path / f"t{ext}"
    io.to_trimesh(mesh, uv).export(q)
    back = jp.load(q)
    np.testing.assert_array_equal(back.faces, mesh.faces)
    # trimesh's own PLY and OBJ exporters are float32 / 8 decimals: compare to that precision.
    np.testing.assert_allclose(back.vertices, mesh.vertices, atol=1e-6)
    np.testing.assert_allclose(back.uv, uv, atol=1e-6)


def test_trimesh_off_round_trip(tmp_path, mesh_uv):
    mesh, uv = mesh_uv
    p = tmp_path / "m.off"
    with pytest.warns(UserWarning, match=r"OFF holds no texture coordinates.*not written"):
        jp.save(p, mesh, uv)
    t = trimesh.load(p, process=False)
    np.testing.assert_array_equal(t.faces, mesh.faces)
    np.testing.assert_allclose(t.vertices, mesh.vertices, rtol=1e-12)
    back = jp.load(p)
    np.testing.assert_array_equal(back.vertices, np.asarray(mesh.vertices))
    assert back.uv is None
    trimesh.Trimesh(np.asarray(mesh.vertices), mesh.faces, process=False).export(tmp_path / "t.off")
    np.testing.assert_array_equal(jp.load(tmp_path / "t.off").faces, mesh.faces)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        jp.save(tmp_path / "plain.off", mesh.with_uv(None))      # no UVs: no warning


def test_the_file_is_the_named_format(tmp_path, mesh_uv):
    mesh, uv = mesh_uv
    for ext, magic in [(".ply", b"ply\nformat binary_little_endian"), (".glb", b"glTF"),
                       (".off", b"OFF\n"), (".gltf", b"{"), (".obj", b"# written by jaxparam\nv ")]:
        jp.save(tmp_path / f"x{ext}", mesh, uv if ext != ".off" else None)
        assert (tmp_path / f"x{ext}").read_bytes().startswith(magic), ext


@pytest.mark.parametrize("ext", [".obj", ".ply"])
def test_per_corner_uvs_round_trip(tmp_path, mesh_uv, ext):
    mesh, _ = mesh_uv
    tex, T = seamed(mesh)
    p = tmp_path / f"s{ext}"
    jp.save(p, mesh, tex, uv_faces=T)
    if ext == ".obj":
        assert "\nf 1/1 " in p.read_text() or "/" in p.read_text()
    back = jp.load(p)
    assert back.uv is None and back.texcoords is not None
    np.testing.assert_array_equal(back.vertices, np.asarray(mesh.vertices))
    np.testing.assert_array_equal(back.faces, mesh.faces)
    # Corner by corner the same UV (the table itself may be renumbered by a format).
    np.testing.assert_array_equal(back.texcoords[back.uv_faces], tex[T])
    # And saving the loaded mesh again keeps them (mesh.texcoords are written by default).
    jp.save(tmp_path / f"again{ext}", back)
    again = jp.load(tmp_path / f"again{ext}")
    np.testing.assert_array_equal(again.texcoords[again.uv_faces], tex[T])


def test_per_corner_uvs_in_gltf_split_vertices_at_seams(tmp_path, mesh_uv):
    mesh, _ = mesh_uv
    tex, T = seamed(mesh)
    jp.save(tmp_path / "s.glb", mesh, tex, uv_faces=T)
    back = jp.load(tmp_path / "s.glb")
    assert back.n_vertices == 3 * mesh.n_faces     # every corner is its own UV here
    source, F2, uv2 = io.split_seams(mesh.faces, tex, T)
    np.testing.assert_array_equal(back.faces, F2)
    close(back.vertices, np.asarray(mesh.vertices)[source], ".glb")
    close(back.uv, uv2, ".glb")
    # Corner positions and UVs are those of the original corners.
    close(back.uv[back.faces], tex[T], ".glb")


@pytest.mark.parametrize("ext", [".glb", ".gltf"])
@pytest.mark.parametrize("offset", [0.0, 1e6, 1e8])
def test_gltf_far_from_the_origin_keeps_float32_precision_of_the_mesh_size(tmp_path, mesh_uv, ext, offset):
    # float32 positions of camelhead moved by 1e6 kept 420 distinct positions of 11,381 (the
    # held-out sweep, session 26): a far mesh is written about its centre, the centre in the
    # node's transform, and read back through it, corners and seams as written
    mesh, _ = mesh_uv
    tex, T = seamed(mesh)
    V = np.asarray(mesh.vertices, np.float64) + offset
    p = tmp_path / f"far{ext}"
    jp.save(p, jp.TriMesh(V, mesh.faces), tex, uv_faces=T)
    back = jp.load(p)
    source, F2, uv2 = io.split_seams(mesh.faces, tex, T)
    np.testing.assert_array_equal(back.faces, F2)
    size = float(np.ptp(V, axis=0).max())
    assert np.abs(np.asarray(back.vertices) - V[source]).max() <= 1e-6 * size
    close(back.uv, uv2, ext)


def test_split_seams_keeps_a_seamless_mesh_as_it_is(mesh_uv):
    mesh, uv = mesh_uv
    T = mesh.faces
    source, F2, uv2 = io.split_seams(mesh.faces, uv, T)
    np.testing.assert_array_equal(source, np.arange(mesh.n_vertices))
    np.testing.assert_array_equal(F2, mesh.faces)
    np.testing.assert_array_equal(uv2, uv)


def test_obj_per_corner_reader_on_handwritten_file(tmp_path):
    """A unit square cut along its diagonal in UV: vertex 1 (index 0-based 0) has two vt."""
    p = tmp_path / "seam.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0.5\n"
                 "f 1/1 2/2 3/3\nf 1/5 3/3 4/4\n")
    m = jp.load(p)
    assert m.uv is None
    np.testing.assert_array_equal(m.uv_faces, [[0, 1, 2], [4, 2, 3]])
    np.testing.assert_array_equal(m.texcoords[4], [0.5, 0.5])
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                 "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    m = jp.load(p)
    np.testing.assert_array_equal(m.uv, [[0, 0], [1, 0], [1, 1], [0, 1]])
    assert m.texcoords is None
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n"
                 "f 1/1 2/2 3/3\nf 1 3 4\n")
    with pytest.warns(UserWarning, match=r"1 of the faces have no vt.*not loaded"):
        assert jp.load(p).uv is None


@pytest.mark.parametrize("names", [("u", "v"), ("s", "t"), ("texture_u", "texture_v")])
def test_ply_uv_property_names(tmp_path, names):
    a, b = names
    p = tmp_path / "n.ply"
    p.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                 f"property float z\nproperty float {a}\nproperty float {b}\nelement face 1\n"
                 "property list uchar int vertex_indices\nend_header\n"
                 "0 0 0 0.25 0.5\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n")
    m = jp.load(p)
    np.testing.assert_array_equal(m.uv, [[0.25, 0.5], [1, 0], [0, 1]])


def test_ply_big_endian_quads_and_face_texcoords(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], ">f4")
    head = ("ply\nformat binary_big_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
            "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
            "property list uchar float texcoord\nend_header\n").encode()
    quad = np.array([4], ">u1").tobytes() + np.array([0, 1, 2, 3], ">i4").tobytes() + \
        np.array([8], ">u1").tobytes() + np.arange(8, dtype=">f4").tobytes()
    tri = np.array([3], ">u1").tobytes() + np.array([1, 4, 2], ">i4").tobytes() + \
        np.array([6], ">u1").tobytes() + (10 + np.arange(6)).astype(">f4").tobytes()
    p = tmp_path / "q.ply"
    p.write_bytes(head + V.tobytes() + quad + tri)
    m = jp.load(p)
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3], [1, 4, 2]])
    assert m.uv is None     # vertex 2 has UVs (4, 5) and (14, 15): a seam
    np.testing.assert_array_equal(m.texcoords[m.uv_faces],
                                  [[[0, 1], [2, 3], [4, 5]], [[0, 1], [4, 5], [6, 7]],
                                   [[10, 11], [12, 13], [14, 15]]])


@pytest.mark.parametrize("name", ["out.stl", "out.xyz", "out", "out.OBJX"])
def test_unknown_extension_is_refused_before_any_work(tmp_path, name):
    with pytest.raises(MeshFileError, match=r"cannot write .*jaxparam writes \.obj, \.ply, \.glb, \.gltf, \.off"):
        io.check_output_format(tmp_path / name)
    with pytest.raises(MeshFileError, match=r"cannot write"):
        jp.save(tmp_path / name, "not a mesh")     # the extension is checked before the mesh
    assert list(tmp_path.iterdir()) == []
    assert io.check_output_format("A.GLB") == ".glb"
    (tmp_path / "d.obj").mkdir()
    with pytest.raises(MeshFileError, match=r"d\.obj: is a folder; give a file path ending in one of \.obj"):
        io.check_output_format(tmp_path / "d.obj")


def test_arguments_in_the_wrong_order_are_refused_with_the_right_call(tmp_path, mesh_uv):
    """``jp.save(mesh, path)`` (trimesh's ``mesh.export(path)`` order) and ``jp.load(mesh)``
    raised pathlib's TypeError ("expected str, bytes or os.PathLike object, not TriMesh")."""
    mesh, _ = mesh_uv
    with pytest.raises(MeshFileError, match=r"save: the file must be given by its path .*got TriMesh; "
                                            r"the path comes first: jp\.save\('out\.obj', mesh, uv\)"):
        jp.save(mesh, tmp_path / "out.obj")
    with pytest.raises(MeshFileError, match=r"load: .*got TriMesh; a mesh in memory needs no loading"):
        jp.load(mesh)
    with pytest.raises(MeshFileError, match=r"reading a point file: .*got NoneType"):
        jp.load_points(None)
    assert list(tmp_path.iterdir()) == []


def test_glb_with_embedded_checker_texture(tmp_path, mesh_uv):
    mesh, uv = mesh_uv
    img = io.checker_texture(64, 8)
    assert img.shape == (64, 64, 3) and img.dtype == np.uint8
    assert np.array_equal(img[0, 0], img[0, 16]) and not np.array_equal(img[0, 0], img[0, 8])
    jp.save(tmp_path / "c.glb", mesh, (uv + 1) / 4, texture=img)
    scene = trimesh.load(tmp_path / "c.glb", process=False)
    geom = list(scene.geometry.values())[0]
    tex = np.asarray(geom.visual.material.baseColorTexture.convert("RGB"))
    np.testing.assert_array_equal(tex, img)
    close(np.asarray(geom.visual.uv), (uv + 1) / 4, ".glb")
    with pytest.raises(MeshFileError, match=r"texture image is embedded only in \.glb or \.gltf"):
        jp.save(tmp_path / "c.obj", mesh, uv, texture=img)
    with pytest.raises(MeshError, match=r"texture must be an \(H, W, 3\) uint8"):
        jp.save(tmp_path / "c.glb", mesh, uv, texture=np.zeros((4, 4)))


def test_bad_uv_shapes(tmp_path, mesh_uv):
    mesh, uv = mesh_uv
    with pytest.raises(MeshError, match=r"uv must have shape .*per-corner UVs: pass"):
        jp.save(tmp_path / "a.ply", mesh, uv[:5])
    with pytest.raises(MeshError, match=r"uv_faces index .* outside the uv table of 5 rows"):
        jp.save(tmp_path / "a.obj", mesh, uv[:5], uv_faces=mesh.faces)
    with pytest.raises(MeshError, match=r"uv_faces must be"):
        jp.save(tmp_path / "a.obj", mesh, uv, uv_faces=mesh.faces[:2])
    assert list(tmp_path.iterdir()) == []


def test_trimesh_with_per_corner_uvs_is_a_pytree(mesh_uv):
    import jax
    import jax.numpy as jnp

    mesh, _ = mesh_uv
    tex, T = seamed(mesh)
    m = jp.TriMesh(mesh.vertices, mesh.faces, texcoords=tex, uv_faces=T)
    f = jax.jit(lambda mm: jnp.sum(mm.texcoords[mm.uv_faces]) + jnp.sum(mm.vertices))
    assert np.isclose(f(m), tex[T].sum() + np.sum(mesh.vertices))
    leaves, tree = jax.tree_util.tree_flatten(m)
    back = jax.tree_util.tree_unflatten(tree, leaves)
    np.testing.assert_array_equal(back.uv_faces, T)
    assert m.with_vertices(np.asarray(mesh.vertices) * 2).uv_faces is m.uv_faces
    with pytest.raises(MeshError, match=r"need both texcoords"):
        jp.TriMesh(mesh.vertices, mesh.faces, uv_faces=T)
    with pytest.raises(MeshError, match=r"uv_faces rows 0, 1, .*\(96 in all\) point outside texcoords \(row 0 = \(0, 1, 2\), 2 texcoords\)"):
        jp.TriMesh(mesh.vertices, mesh.faces, texcoords=tex[:2], uv_faces=T)


@pytest.mark.parametrize("name", ["camelhead.off", "lilium.obj"])
def test_real_mesh_every_format(tmp_path, name):
    from conftest import data_path

    src = data_path("meshes", name)
    mesh = jp.load(src)
    uv = np.asarray(mesh.vertices)[:, :2]
    for ext in [".obj", ".ply", ".glb"]:
        jp.save(tmp_path / f"r{ext}", mesh, uv)
        t = trimesh.load(tmp_path / f"r{ext}", process=False, force="mesh")
        assert t.vertices.shape == (mesh.n_vertices, 3) and np.array_equal(t.faces, mesh.faces), ext
        close(np.asarray(t.visual.uv), uv, ext)


@pytest.mark.parametrize("ext", [".ply", ".glb"])
def test_cli_flatten_writes_the_named_format(tmp_path, ext):
    """The issue's "done when": ``jaxparam flatten X -o x.ply`` writes a PLY trimesh reads with
    its UVs (and the same for GLB)."""
    from jaxparam.cli import main

    mesh = jp.shapes.disk(3, seed=2, height=0.2)
    src = tmp_path / "in.obj"
    jp.save(src, mesh)
    out = tmp_path / f"x{ext}"
    assert main(["flatten", str(src), "-o", str(out)]) == 0
    t = trimesh.load(out, process=False, force="mesh")
    np.testing.assert_array_equal(t.faces, mesh.faces)
    back = jp.load(out)
    assert back.uv is not None
    close(np.asarray(t.visual.uv), back.uv, ext)
    assert jp.distortion(back, back.uv).flips == 0


@pytest.mark.parametrize("ext", [".obj", ".ply", ".glb"])
def test_per_corner_uvs_read_by_trimesh(tmp_path, mesh_uv, ext):
    """trimesh holds one UV per vertex, so it splits our seamed files' vertices; corner by
    corner it reads the same positions and UVs."""
    mesh, _ = mesh_uv
    tex, T = seamed(mesh)
    p = tmp_path / f"s{ext}"
    jp.save(p, mesh, tex, uv_faces=T)
    t = trimesh.load(p, process=False, force="mesh")
    assert len(t.faces) == mesh.n_faces
    close(np.asarray(t.vertices)[t.faces], np.asarray(mesh.vertices)[mesh.faces], ext)
    close(np.asarray(t.visual.uv)[t.faces], tex[T], ext)


def _line_by_line_off(path, monkeypatch):
    from jaxparam.io import off

    with monkeypatch.context() as m:
        m.setattr(off, "fast_off", lambda text: None)
        return off.read_off(path)


@pytest.mark.parametrize("body, fast", [
    ("OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", True),
    ("OFF\n# a comment\n4 2 0\n\n0 0 0  # origin\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", True),
    ("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n", False),            # a quad
    ("OFF\n4 2 0\n0 0 0 9\n1 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", False),     # same total
    ("OFF 4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", False),      # counts on line 1
    ("OFF\n4 2 0\n0 0 0 1 1 1\n1 0 0 1 1 1\n1 1 0 1 1 1\n0 1 0 1 1 1\n3 0 1 2\n3 0 2 3\n", False),
])
def test_the_vectorized_off_reader_equals_the_line_reader(tmp_path, monkeypatch, body, fast):
    from jaxparam.io import off
    from jaxparam.io.files import read_text

    path = tmp_path / "m.off"
    path.write_text(body)
    assert (off.fast_off(read_text(path)) is not None) == fast
    if "1 0\n1 1 0" in body:            # a two-number vertex line: both refuse it, naming line 4
        for read in (off.read_off, lambda p: _line_by_line_off(p, monkeypatch)):
            with pytest.raises(MeshFileError, match="line 4"):
                read(path)
        return
    V, F = off.read_off(path)
    V2, F2 = _line_by_line_off(path, monkeypatch)
    assert np.array_equal(V, V2) and np.array_equal(F, F2) and F.dtype == np.int64


def test_an_out_of_range_index_is_still_named_with_its_line(tmp_path):
    path = tmp_path / "m.off"
    path.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
    with pytest.raises(MeshFileError, match="line 6: vertex index 7 is out of range"):
        io.read_off(path)


def test_written_rows_equal_savetxt_digit_for_digit():
    import io as pyio

    from jaxparam.io.files import write_rows

    rng = np.random.default_rng(3)
    X = np.concatenate([rng.normal(size=(70001, 3)) * 10.0 ** rng.integers(-300, 300, (70001, 1)),
                        [[np.pi, -0.0, 1e-320]]])
    a, b = pyio.StringIO(), pyio.StringIO()
    write_rows(a, "v %.17g %.17g %.17g\n", X)
    np.savetxt(b, X, fmt="v %.17g %.17g %.17g")
    assert a.getvalue() == b.getvalue()
    F = rng.integers(0, 10 ** 9, (1000, 6))
    a, b = pyio.StringIO(), pyio.StringIO()
    write_rows(a, "f %d/%d %d/%d %d/%d\n", F)
    np.savetxt(b, F, fmt="f %d/%d %d/%d %d/%d")
    assert a.getvalue() == b.getvalue()
    assert np.array_equal(np.loadtxt(pyio.StringIO(a.getvalue().replace("f ", "").replace("/", " "))), F)


def test_obj_faces_may_refer_to_vertices_defined_further_down(tmp_path):
    # Found in QA: an OBJ with its 'f' lines before its 'v' lines (libigl and trimesh read it)
    # was refused ("index 1 refers to element 1 but only 0 are defined before this line").
    p = tmp_path / "faces_first.obj"
    p.write_text("f 1 2 3\nf 1 3 4\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n")
    mesh = jp.load(p)
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]] and mesh.n_vertices == 4
    p.write_text("f 1 2 5\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n")
    with pytest.raises(MeshFileError, match=r"line 1: index 5 is out of range: the file defines only 4"):
        jp.load(p)
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n")
    with pytest.raises(MeshFileError, match=r"line 4: index 0 is not valid"):
        jp.load(p)


def test_obj_backslash_continues_a_line(tmp_path):
    # Found in QA: the OBJ format's line continuation (a backslash at the end of a line, read
    # by libigl and trimesh) was refused as "cannot read a coordinate from '\\'".
    p = tmp_path / "continued.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 \\\n 0\nv 1 1 0\nf 1 2 3\nf 2 4 \\\n3\n")
    mesh = jp.load(p)
    assert mesh.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]
    assert mesh.faces.tolist() == [[0, 1, 2], [1, 3, 2]]
    trimesh = pytest.importorskip("trimesh")            # the oracle reads the same
    other = trimesh.load(p, process=False)
    assert np.array_equal(other.vertices, mesh.vertices) and np.array_equal(other.faces, mesh.faces)
    p.write_text("v 0 0 0\nv 1 0 \\\n x\nv 0 1 0\nf 1 2 3\n")   # errors name the first line
    with pytest.raises(MeshFileError, match=r"line 2: cannot read a coordinate from 'x'"):
        jp.load(p)


def test_a_utf8_byte_order_mark_is_not_part_of_the_first_line(tmp_path):
    # Found in QA: an OBJ saved by a Windows editor (BOM first) lost its first 'v' line without
    # a word (tag '\ufeffv' unknown), shifting every index; an .xyz's first point was refused.
    bom = b"\xef\xbb\xbf"
    p = tmp_path / "bom.obj"
    p.write_bytes(bom + b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n")
    mesh = jp.load(p)
    assert mesh.n_vertices == 4 and mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    q = tmp_path / "bom.xyz"
    q.write_bytes(bom + b"1 0 0\n0 1 0\n0 0 1\n1 1 1\n")
    np.testing.assert_array_equal(jp.load_points(q)[0], [1.0, 0.0, 0.0])


def test_save_refuses_nan_uvs_at_the_vertices_of_faces(tmp_path):
    # Found in QA: jp.save wrote an all-nan map as UVs of 0 (a file of collapsed triangles,
    # silently); nan stays allowed, and written as 0, only at vertices in no face.
    mesh = jp.shapes.graph_surface(4)
    uv = np.asarray(jp.convex_map(mesh))
    bad = uv.copy()
    bad[[3, 7]] = np.nan
    with pytest.raises(MeshError, match=r"uv is not finite at vertices 3, 7 \(2 in all\)"):
        jp.save(tmp_path / "bad.obj", mesh, bad)
    assert not (tmp_path / "bad.obj").exists()
    stray = jp.TriMesh(np.vstack([mesh.vertices, [[9.0, 9.0, 9.0]]]), mesh.faces)
    jp.save(tmp_path / "ok.obj", stray, np.vstack([uv, [[np.nan, np.nan]]]))
    np.testing.assert_allclose(jp.load(tmp_path / "ok.obj").uv[:-1], uv)


def _write_polygon_mesh(path, V, polys):
    """``V`` and the polygon list ``polys`` (0-based) as an OBJ, OFF or ASCII PLY file."""
    ext = path.suffix
    if ext == ".obj":
        text = "".join(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in V)
        text += "".join("f " + " ".join(str(i + 1) for i in p) + "\n" for p in polys)
    elif ext == ".off":
        text = f"OFF\n{len(V)} {len(polys)} 0\n" + "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in V)
        text += "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys)
    else:
        text = (f"ply\nformat ascii 1.0\nelement vertex {len(V)}\nproperty double x\nproperty double y\n"
                f"property double z\nelement face {len(polys)}\nproperty list uchar int vertex_indices\n"
                "end_header\n" + "".join(f"{x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in V)
                + "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys))
    path.write_text(text)


@pytest.mark.parametrize("ext", [".obj", ".off", ".ply"])
def test_triangles_written_as_degenerate_polygons_load_as_those_triangles(tmp_path, ext):
    """Found in QA: `f a b c c` (exporters' triangles in a quad format) gave 'faces 1, 3, 5, ...
    repeat a vertex', numbers of the fan's triangles the user cannot find in the file."""
    grid = jp.shapes.plane_grid(4, 4)
    V, F = np.asarray(grid.vertices), np.asarray(grid.faces)
    polys = [list(f) + [f[2]] if i % 3 == 0 else list(f) + [f[0]] if i % 3 == 1 else
             [f[0], f[0], f[1], f[2], f[2]] if i % 2 else list(f) for i, f in enumerate(F)]
    p = tmp_path / f"degquads{ext}"
    _write_polygon_mesh(p, V, polys)
    mesh = jp.load(p)
    np.testing.assert_array_equal(np.asarray(mesh.faces), F)


def test_repeated_corners_keep_their_per_corner_uvs(tmp_path):
    p = tmp_path / "q.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 0.5 0.5\n"
                 "f 1/4 1/1 2/2 3/3 3/3\n")
    V, F, tex, T, _ = io.obj.parse_obj(p)
    np.testing.assert_array_equal(F, [[0, 1, 2]])
    np.testing.assert_array_equal(T, [[3, 1, 2]])    # a run keeps its first corner, with its vt


def star_polygon(n=5, tilt=0.7):
    """A concave 2n-gon (a star, counter-clockwise about +z) rotated about the x axis by
    ``tilt``: ``(V (2n, 3), normal (3,), area)``."""
    a = np.pi * np.arange(2 * n) / n
    r = np.where(np.arange(2 * n) % 2 == 0, 1.0, 0.4)
    P = np.stack([r * np.cos(a), r * np.sin(a)], 1)
    area = 0.5 * np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])
    c, s = np.cos(tilt), np.sin(tilt)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    V = np.c_[P, np.zeros(2 * n)] @ R.T + np.array([3.0, -1.0, 2.0])
    return V, R @ np.array([0.0, 0, 1]), area


@pytest.mark.parametrize("ext", [".obj", ".off", ".ply"])
@pytest.mark.parametrize("start", [0, 1])              # the fan from a tip, or from a notch
def test_a_concave_polygon_is_split_without_folds(tmp_path, ext, start):
    """Found in QA: a concave 10-gon split by a fan gave 2 triangles of negative area in its
    plane, and flatten ran on folded geometry.  Now: ear clipping in the polygon's plane."""
    V, normal, area = star_polygon()
    order = list(np.roll(np.arange(10), -start))
    p = tmp_path / f"star{ext}"
    _write_polygon_mesh(p, V, [order])
    mesh = jp.load(p)
    F = np.asarray(mesh.faces)
    assert F.shape == (8, 3) and set(F.ravel()) == set(range(10))
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    assert np.all(cross @ normal > 0)                              # no triangle folds back
    np.testing.assert_allclose(0.5 * np.linalg.norm(cross, axis=1).sum(), area, rtol=1e-12)


def test_convex_and_nonplanar_polygons_keep_the_fan(tmp_path):
    """Convex polygons (and a warped quad) are split exactly as before: a fan from corner 0."""
    t = 2 * np.pi * np.arange(6) / 6
    V = np.vstack([np.c_[np.cos(t), np.sin(t), np.zeros(6)],
                   [[3, 0, 0], [4, 0, 0.3], [4, 1, 0], [3, 1, 0.3]]])
    p = tmp_path / "convex.obj"
    _write_polygon_mesh(p, V, [list(range(6)), [6, 7, 8, 9]])
    np.testing.assert_array_equal(np.asarray(jp.load(p).faces),
                                  [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [6, 7, 8], [6, 8, 9]])


def test_polygons_of_several_sizes_keep_the_file_order():
    from jaxparam.io.polygons import triangulate

    V, _, _ = star_polygon()
    V = np.vstack([V, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]])
    polys = [[10, 11, 12], list(range(10)), [11, 13, 12, 12], [10, 11, 13, 12]]
    poly, pick = triangulate(V, polys, lambda i: f"polygon {i}")
    assert list(poly) == [0] + [1] * 8 + [2] + [3, 3]
    np.testing.assert_array_equal(pick[0], [0, 1, 2])
    np.testing.assert_array_equal(pick[9], [0, 1, 2])
    np.testing.assert_array_equal(pick[10:], [[0, 1, 2], [0, 2, 3]])
