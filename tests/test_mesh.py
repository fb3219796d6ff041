import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import DegenerateFaceError, MeshError, MeshFileError


def test_trimesh_validates_coordinates():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [np.nan, 1, 0]])
    with pytest.raises(MeshError, match=r"vertices 2 .*non-finite"):
        jp.TriMesh(V, [[0, 1, 2]])


def test_trimesh_zero_area_face():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    with pytest.raises(DegenerateFaceError, match=r"faces 0 .*zero area"):
        jp.TriMesh(V, [[0, 1, 2], [1, 0, 3]])


def test_trimesh_is_a_pytree(grid_mesh):
    f = jax.jit(lambda m: jnp.sum(m.vertices ** 2))
    assert np.isclose(f(grid_mesh), np.sum(np.asarray(grid_mesh.vertices) ** 2))
    g = jax.grad(lambda V: jnp.sum(jp.TriMesh(V, grid_mesh.faces).vertices))(jnp.asarray(grid_mesh.vertices))
    assert g.shape == grid_mesh.vertices.shape


def test_obj_roundtrip_keeps_order(tmp_path, grid_mesh):
    uv = np.random.default_rng(0).random((grid_mesh.n_vertices, 2))
    p = tmp_path / "m.obj"
    jp.save(p, grid_mesh, uv)
    text = p.read_text()
    assert "f 1/1 " in text or "/" in text.split("\nf ")[1]
    m2 = jp.load(p)
    np.testing.assert_array_equal(m2.faces, grid_mesh.faces)
    np.testing.assert_allclose(m2.vertices, grid_mesh.vertices, rtol=0, atol=0)
    np.testing.assert_allclose(m2.uv, uv, rtol=0, atol=0)


def test_off_reader(tmp_path):
    p = tmp_path / "q.off"
    p.write_text("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    m = jp.load(p)
    assert m.faces.tolist() == [[0, 1, 2], [0, 2, 3]]


@pytest.mark.parametrize("ext", ["ply", "stl"])
def test_trimesh_formats(tmp_path, ext, grid_mesh):
    import trimesh
    p = tmp_path / f"m.{ext}"
    trimesh.Trimesh(np.asarray(grid_mesh.vertices), grid_mesh.faces, process=False).export(p)
    m = jp.load(p)
    assert m.n_faces == grid_mesh.n_faces
    if ext == "ply":
        np.testing.assert_allclose(m.vertices, grid_mesh.vertices)


@pytest.mark.parametrize("text, match", [
    ("OFF\n4 2 0\n0 0 0\n1 0 0\n", r"truncated"),
    ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", r"line 6.*out of range"),
    ("XYZ\n", r"line 1.*header"),
])
def test_off_errors(tmp_path, text, match):
    p = tmp_path / "bad.off"
    p.write_text(text)
    with pytest.raises(MeshFileError, match=match):
        jp.load(p)


def test_obj_errors(tmp_path):
    p = tmp_path / "bad.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1\nf 1 2 3\n")
    with pytest.raises(MeshFileError, match=r"line 3.*three coordinates"):
        jp.load(p)
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")
    with pytest.raises(MeshFileError, match=r"line 4.*only 3"):
        jp.load(p)


def test_missing_and_empty_files(tmp_path):
    with pytest.raises(MeshFileError, match="no such file"):
        jp.load(tmp_path / "nope.obj")
    (tmp_path / "e.off").write_text("")
    with pytest.raises(MeshFileError, match="empty"):
        jp.load(tmp_path / "e.off")
    assert isinstance(MeshFileError("x"), OSError)


def test_save_is_atomic(tmp_path, grid_mesh):
    p = tmp_path / "out.obj"
    with pytest.raises(MeshError):
        jp.save(p, grid_mesh, np.zeros((3, 2)))
    assert not p.exists()
    assert list(tmp_path.iterdir()) == []


def test_io_package_holds_the_readers_and_writers(tmp_path, grid_mesh):
    import jaxparam.io as io
    import jaxparam.mesh as mesh_module

    assert jp.load is io.load and jp.save is io.save and jp.load_points is io.load_points
    assert jp.points.load_points is io.load_points
    assert not hasattr(mesh_module, "load") and not hasattr(mesh_module, "atomic_write")
    p = tmp_path / "g.obj"
    io.save(p, grid_mesh)
    V, F, uv = io.read_obj(p)
    np.testing.assert_array_equal(F, grid_mesh.faces)
    assert uv is None and V.shape == (grid_mesh.n_vertices, 3)
    io.atomic_write(tmp_path / "t.bin", lambda f: f.write(b"\x00\x01"), mode="wb")
    assert (tmp_path / "t.bin").read_bytes() == b"\x00\x01"


def test_load_points_refuses_a_folder(tmp_path):
    with pytest.raises(MeshFileError, match=r": is a folder, not a point file"):
        jp.load_points(tmp_path)
