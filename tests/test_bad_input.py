"""The catalogue of bad inputs (docs/errors.md): each gets our own error, naming what and where."""
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.cli import main
from jaxparam.errors import (DegenerateFaceError, JaxparamError, MeshError, MeshFileError,
                             NonManifoldError, TopologyError)

TRI = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])


@pytest.mark.parametrize("vertices, faces, cls, match", [
    (np.zeros((0, 3)), np.zeros((0, 3), int), MeshError, r"no faces"),
    (TRI[:3] * np.array([1, 1, np.nan]), [[0, 1, 2]], MeshError, r"vertices 0, 1, 2 .*non-finite"),
    (np.array([[np.inf, 0, 0], [1, 0, 0], [0, 1, 0]]), [[0, 1, 2]], MeshError, r"vertices 0 .*non-finite"),
    (TRI, [[0, 1, 7]], MeshError, r"faces 0 .*outside \[0, 4\)"),
    (TRI, [[0, -1, 2]], MeshError, r"faces 0 .*outside"),
    (TRI, [[0, 1, 1]], DegenerateFaceError, r"faces 0 .*repeat a vertex"),
    (np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), [[0, 1, 2]], DegenerateFaceError, r"zero area"),
    (TRI, [[0, 1, 2], [0, 1, 2]], NonManifoldError, r"duplicate faces"),
    (np.vstack([TRI, [[0.5, -1, 0]]]), [[0, 1, 2], [1, 0, 3], [0, 1, 4]], NonManifoldError,
     r"edges \(0, 1\) .*more than two faces"),
    (np.vstack([TRI, [[-1, -1, 0], [-1, 0, 0]]]), [[0, 1, 2], [0, 4, 5]], NonManifoldError,
     r"vertices 0 .*bowtie"),
    (TRI, [[0, 1, 2], [1, 2, 3]], NonManifoldError, r"edges \(1, 2\) .*same direction.*inconsistent"),
    (TRI, [[0, 1, 2, 3]], MeshError, r"shape \(m, 3\)"),
    (TRI, [[0.5, 1, 2]], MeshError, r"integer"),
])
def test_mesh_construction_errors(vertices, faces, cls, match):
    with pytest.raises(cls, match=match) as e:
        jp.TriMesh(vertices, np.asarray(faces))
    assert isinstance(e.value, JaxparamError) and isinstance(e.value, ValueError)


def test_one_triangle_maps_to_its_boundary(single_triangle):
    uv = np.asarray(jp.convex_map(single_triangle))
    np.testing.assert_allclose(np.linalg.norm(uv, axis=1), 1.0)
    assert jp.distortion(single_triangle, uv).flips == 0


def test_unreferenced_vertices_reported(grid_mesh):
    V = np.vstack([np.asarray(grid_mesh.vertices), [[5.0, 5, 5]]])
    mesh = jp.TriMesh(V, grid_mesh.faces)
    assert mesh.topology.summary()["unreferenced_vertices"] == 1
    assert np.isnan(np.asarray(jp.convex_map(mesh))[-1]).all()


def test_topology_errors_for_disk_methods():
    with pytest.raises(TopologyError, match=r"closed .*no boundary.*manifold_map"):
        jp.convex_map(jp.shapes.sphere(1))
    with pytest.raises(TopologyError, match=r"closed"):
        jp.minimize(jp.shapes.torus(8, 6), "mips")
    a = jp.shapes.plane_grid(3, 3)
    two = jp.TriMesh(np.vstack([np.asarray(a.vertices)] * 2) + np.repeat([[0, 0, 0], [3, 0, 0]], 9, 0),
                     np.vstack([a.faces, a.faces + 9]))
    with pytest.raises(TopologyError, match=r"2 connected components .*split"):
        jp.convex_map(two)


def test_several_boundary_loops_documented_fill(grid_mesh):
    F = grid_mesh.faces[~np.any(grid_mesh.faces == 50, axis=1)]
    holed = jp.TriMesh(grid_mesh.vertices, F)
    assert len(holed.topology.boundary_loops) == 2
    uv = jp.convex_map(holed)
    assert jp.distortion(holed, uv).flips == 0


def test_user_boundary_errors(grid_mesh):
    k = len(grid_mesh.topology.boundary_loops[0])
    with pytest.raises(MeshError, match=rf"shape \({k}, 2\)"):
        jp.convex_map(grid_mesh, boundary=np.zeros((k - 1, 2)))
    with pytest.raises(MeshError, match=r"not form a convex"):
        jp.convex_map(grid_mesh, boundary={"polygon": [[0, 0], [1, 1], [2, 0], [1, 3]]})
    with pytest.raises(MeshError, match=r"unknown boundary 'disc'"):
        jp.convex_map(grid_mesh, boundary="disc")
    with pytest.raises(MeshError, match=r"unknown spacing"):
        jp.convex_map(grid_mesh, spacing="arc")


def test_user_weights_of_wrong_sign(grid_mesh):
    mu = -np.ones(grid_mesh.topology.n_edges)
    with pytest.raises(MeshError, match=r"mu must be positive; edges \(\d+, \d+\)"):
        jp.least_squares_map(grid_mesh, mu=mu)
    with pytest.raises(MeshError, match=r"shape \(\d+,\)"):
        jp.least_squares_map(grid_mesh, mu=np.ones(3))


@pytest.mark.parametrize("name, content, match", [
    ("trunc.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", r"line 4"),
    ("counts.off", b"OFF\n5 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", r"truncated|counts"),
    ("junk.obj", bytes(range(256)) * 4, r"binary"),
    ("empty.off", b"", r"empty"),
    ("noface.obj", b"v 0 0 0\nv 1 0 0\n", r"no faces"),
    ("badnum.obj", b"v 0 0 x\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", r"line 1.*'x'"),
    ("junk.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n0 0\n", r".ply|PLY|read"),
])
def test_malformed_files(tmp_path, name, content, match):
    p = tmp_path / name
    p.write_bytes(content)
    with pytest.raises(MeshFileError, match=match) as e:
        jp.load(p)
    assert isinstance(e.value, OSError)
    assert main(["flatten", str(p), "-o", str(tmp_path / "o.obj")]) == 3
    assert not (tmp_path / "o.obj").exists()


def test_missing_file_and_folder(tmp_path, capsys):
    with pytest.raises(MeshFileError, match="no such file"):
        jp.load(tmp_path / "nope.off")
    with pytest.raises(MeshFileError, match="folder"):
        jp.load(tmp_path)
    assert main(["info", str(tmp_path / "nope.off")]) == 3
    assert "no such file" in capsys.readouterr().err


def test_cli_exit_codes_for_bad_meshes(tmp_path, capsys):
    p = tmp_path / "bow.off"
    p.write_text("OFF\n5 2 0\n0 0 0\n1 0 0\n0 1 0\n-1 -1 0\n-1 0 0\n3 0 1 2\n3 0 3 4\n")
    assert main(["flatten", str(p), "-o", str(tmp_path / "o.obj")]) == 3
    assert "bowtie" in capsys.readouterr().err
