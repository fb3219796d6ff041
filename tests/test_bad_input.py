"""The catalogue of bad inputs (docs/errors.md): each gets our own error, naming what and where."""
import json
import re

import numpy as np
import pytest
from conftest import data_path

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
    (TRI, [[0, 1, 2], [0, 1, 2]], NonManifoldError, r"faces 0, 1 .*duplicate faces .*\(0, 1, 2\)"),
    (TRI, [[0, 1, 2], [1, 3, 2], [2, 1, 0]], NonManifoldError, r"faces 0, 2 .*duplicate faces"),
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
    torus = jp.shapes.torus(8, 6)
    with pytest.raises(TopologyError, match=r"genus 1 with 1 boundary loops.*cut the handles"):
        jp.convex_map(jp.TriMesh(torus.vertices, torus.faces[1:]))


def test_minimize_refuses_a_flipped_start(grid_mesh):
    uv = np.asarray(jp.convex_map(grid_mesh)) * np.array([1.0, -1.0])
    with pytest.raises(jp.SolverError, match=r"not injective: \d+ of \d+ triangles .*first: face 0.*convex_map") as e:
        jp.minimize(grid_mesh, "mips", init=uv)
    assert e.value.stage == "init" and isinstance(e.value, RuntimeError)


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
    with pytest.raises(MeshError, match=r"not form a convex .*turns clockwise at corners 1 .*convex hull"):
        jp.convex_map(grid_mesh, boundary={"polygon": [[0, 0], [1, 1], [2, 0], [1, 3]]})
    with pytest.raises(MeshError, match=r"the corners run clockwise"):
        jp.convex_map(grid_mesh, boundary={"polygon": [[0, 0], [0, 1], [1, 1], [1, 0]]})
    with pytest.raises(MeshError, match=r"corners 1 and 2 coincide"):
        jp.convex_map(grid_mesh, boundary={"polygon": [[0, 0], [1, 0], [1, 0], [0, 1]]})
    with pytest.raises(MeshError, match=r"unknown weights 'cot'; use one of"):
        jp.convex_map(grid_mesh, weights="cot")
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


def _binary_ply(faces: int, tail: bytes = b"") -> bytes:
    """A little-endian PLY of 4 vertices and 2 triangles whose header promises ``faces``."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], "<f4")
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
            "property float y\nproperty float z\nelement face %d\n"
            "property list uchar int vertex_indices\nend_header\n" % faces).encode()
    tri = [np.array([3], "<u1").tobytes() + np.array(f, "<i4").tobytes() for f in ([0, 1, 2], [1, 3, 2])]
    return head + V.tobytes() + b"".join(tri) + tail


# Found in QA (session 20): a binary PLY whose header promises fewer faces than it holds lost
# the rest silently.
@pytest.mark.parametrize("target", ["mesh", "points"])
def test_binary_ply_with_data_after_the_promised_elements(tmp_path, target):
    p = tmp_path / "lessb.ply"
    p.write_bytes(_binary_ply(1))
    load = jp.load if target == "mesh" else jp.load_points
    with pytest.raises(MeshFileError, match=r"lessb\.ply, byte 230: binary data goes on after the 1 "
                       r"face elements the header promises: 13 more bytes .*fix the count in the "
                       r"header \(line 7: 'element face 1'\) or cut the file at byte 230"):
        load(p)
    p.write_bytes(_binary_ply(2, b"\r\n"))       # a line end after the data is harmless
    assert load(p).shape[0] == 4 if target == "points" else load(p).n_faces == 2


@pytest.mark.parametrize("name, content, match", [
    ("trunc.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", r"line 4: index 4 .*only 3"),
    ("counts.off", b"OFF\n5 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", r"promises 5 vertices and 2 faces .*truncated"),
    ("junk.obj", bytes(range(256)) * 4, r"looks binary"),
    ("empty.off", b"", r": the file is empty"),
    ("noface.obj", b"v 0 0 0\nv 1 0 0\n", r"no faces"),
    ("badnum.obj", b"v 0 0 x\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", r"line 1.*'x'"),
    # Found in QA: "a face with 2 vertices but 2 indices given".
    ("twogon.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n", r"line 6: a face needs at least 3 vertices, this one has 2"),
    ("junk.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n0 0\n", r"cannot read the file as \.ply \(.+\); check the format"),
    # Found in QA: a header promising fewer faces than the file holds dropped the rest silently.
    ("lessf.off", b"OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n",
     r"lessf\.off, line 8: data goes on after the 1 faces the header promises: 1 more line .*2 face "
     r"lines in all.* fix the face count in the header \(line 2: '4 1 0'\)"),
    ("lessv.off", b"OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n",
     r"line 6: the header promises 3 vertices and 2 faces, but the file holds 4 vertex lines and "
     r"then 2 face lines; fix the counts"),
    ("lessf.ply", b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                  b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                  b"end_header\n0 0 0\n1 0 0\n0 1 0\n\n1 1 0\n3 0 1 2\n3 1 3 2\n",
     r"lessf\.ply, line 16: data goes on after the 1 face elements the header promises: 1 more line "
     r".*\(2 face lines in all.*fix the count in the header \(line 7: 'element face 1'\) or remove"),
])
def test_malformed_files(tmp_path, name, content, match):
    p = tmp_path / name
    p.write_bytes(content)
    with pytest.raises(MeshFileError, match=match) as e:
        jp.load(p)
    assert isinstance(e.value, OSError)
    assert main(["flatten", str(p), "-o", str(tmp_path / "o.obj")]) == 3
    assert not (tmp_path / "o.obj").exists()


@pytest.mark.parametrize("name, content, cls, match", [
    ("deg.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 4 4\n", DegenerateFaceError,
     r"deg\.obj, line 6: the polygon with vertices \(2, 4, 4, 4\) has only 2 distinct corner"),
    ("twice.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 1 3\n", DegenerateFaceError,
     r"line 5: the polygon with vertices \(1, 2, 1, 3\) visits vertex 1 twice"),
    ("deg.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n5 0 1 1 0 0\n", DegenerateFaceError,
     r"deg\.off, line 7: the polygon with vertices \(0, 1, 1, 0, 0\) has only 2 distinct"),
    # a pentagram: its fan folds, and no split into triangles keeps it
    ("star5.obj", "".join(f"v {np.cos(a):.17g} {np.sin(a):.17g} 0\n" for a in
                          2 * np.pi * np.arange(0, 10, 2) / 5) + "# a comment\nf 1 2 3 4 5\n",
     MeshError, r"star5\.obj, line 7: the polygon with vertices \(1, 2, 3, 4, 5\) crosses itself "
                r"\(its edges .* meet in its plane\).*split it into simple polygons"),
])
def test_polygons_that_cannot_be_triangulated_name_their_line(tmp_path, capsys, name, content, cls,
                                                              match):
    """A polygon is cleaned of repeated corners and split before the mesh's checks, so its
    problems are named by file line, not by the numbers of the triangles it became."""
    p = tmp_path / name
    p.write_text(content)
    with pytest.raises(cls, match=match) as e:
        jp.load(p)
    assert not isinstance(e.value, MeshFileError)      # a well-formed file with a bad face
    assert main(["flatten", str(p), "-o", str(tmp_path / "o.obj")]) == 3
    assert re.search(match, capsys.readouterr().err)


def test_missing_file_and_folder(tmp_path, capsys):
    with pytest.raises(MeshFileError, match="no such file"):
        jp.load(tmp_path / "nope.off")
    (tmp_path / "d.off").mkdir()
    for folder in [tmp_path, tmp_path / "d.off"]:          # no extension (trimesh route), .off
        with pytest.raises(MeshFileError, match=r": is a folder, not a mesh file"):
            jp.load(folder)
    assert main(["info", str(tmp_path / "nope.off")]) == 3
    assert "no such file" in capsys.readouterr().err


def test_cli_exit_codes_for_bad_meshes(tmp_path, capsys):
    p = tmp_path / "bow.off"
    p.write_text("OFF\n5 2 0\n0 0 0\n1 0 0\n0 1 0\n-1 -1 0\n-1 0 0\n3 0 1 2\n3 0 3 4\n")
    assert main(["flatten", str(p), "-o", str(tmp_path / "o.obj")]) == 3
    assert "bowtie" in capsys.readouterr().err


@pytest.mark.data
def test_halftunnel_holes_filled_no_flips_for_every_positive_weight(tmp_path):
    """Several boundary loops: the longest goes to the circle, the other two are filled virtually."""
    path = data_path("meshes", "halftunnel.off")
    mesh = jp.load(path)
    assert [len(l) for l in mesh.topology.boundary_loops] == [48, 32, 16]
    for kind in ["uniform", "inverse_distance", "shape_preserving", "mean_value"]:
        uv = np.asarray(jp.convex_map(mesh, weights=kind))
        rep = jp.distortion(mesh, uv, weights=kind)
        assert rep.flips == 0 and np.isfinite(uv).all(), kind
        assert rep.theorem1.holds, kind
    out, rep = tmp_path / "h.obj", tmp_path / "h.json"
    assert main(["flatten", str(path), "-o", str(out), "--report", str(rep)]) == 0
    r = json.loads(rep.read_text())
    assert r["holes_filled"] == 2 and r["flips"] == 0


def test_holes_filled_key_is_always_in_the_report(tmp_path):
    p, rep = tmp_path / "g.obj", tmp_path / "r.json"
    jp.save(p, jp.shapes.graph_surface(6))
    assert main(["flatten", str(p), "-o", str(tmp_path / "o.obj"), "--report", str(rep)]) == 0
    assert json.loads(rep.read_text())["holes_filled"] == 0


def write_off(path, V, F):
    path.write_text(f"OFF\n{len(V)} {len(F)} 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in V)
                    + "".join(f"3 {a} {b} {c}\n" for a, b, c in F))


@pytest.mark.parametrize("name, V, F, match", [
    ("nan.off", [[0, 0, "nan"], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], r"vertices 0 .*non-finite"),
    ("flat.off", [[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], r"faces 0 .*zero area"),
    ("dup.off", TRI.tolist(), [[0, 1, 2], [0, 1, 2]], r"duplicate faces"),
    ("edge3.off", np.vstack([TRI, [[0.5, -1, 0]]]).tolist(), [[0, 1, 2], [1, 0, 3], [0, 1, 4]],
     r"edges \(0, 1\) .*more than two faces"),
    ("orient.off", TRI.tolist(), [[0, 1, 2], [1, 2, 3]], r"inconsistent"),
    ("two.off", np.vstack([TRI, TRI + 5]).tolist(), [[0, 1, 2], [1, 3, 2], [4, 5, 6], [5, 7, 6]],
     r"2 connected components"),
    ("closed.off", np.asarray(jp.shapes.sphere(0).vertices).tolist(), jp.shapes.sphere(0).faces.tolist(),
     r"closed \(no boundary"),
    # a small mesh far from the origin, as float32 keeps it: every vertex on one point
    ("float32.off", (np.float32(5e3) + np.float32(1e-4) * np.asarray(jp.shapes.graph_surface(4).vertices,
                                                                    np.float32)).astype(float).tolist(),
     jp.shapes.graph_surface(4).faces.tolist(), r"zero area.*only 1 distinct position.*float32"),
])
def test_cli_exit_3_names_the_problem(tmp_path, capsys, name, V, F, match):
    p = tmp_path / name
    write_off(p, V, F)
    out = tmp_path / "o.obj"
    assert main(["flatten", str(p), "-o", str(out), "--report", str(tmp_path / "r.json")]) == 3
    err = capsys.readouterr().err
    assert err.startswith("jaxparam flatten: ") and len(err.strip().splitlines()) == 1
    assert re.search(match, err), err
    assert list(tmp_path.iterdir()) == [p]                 # nothing written


def test_cli_exit_3_for_an_unwritable_output_and_for_points(tmp_path, capsys):
    p = tmp_path / "g.obj"
    jp.save(p, jp.shapes.graph_surface(5))
    (tmp_path / "taken").mkdir()
    assert main(["flatten", str(p), "-o", str(tmp_path / "taken")]) == 3
    assert "is a folder" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "taken")]) == 3
    assert "is a folder, not a mesh file" in capsys.readouterr().err
    pts = tmp_path / "few.xyz"
    pts.write_text("0 0 0\n1 0 0\n0 1 0\n")
    assert main(["meshless", str(pts), "-o", str(tmp_path / "m.obj")]) == 3
    assert "too few" in capsys.readouterr().err
    assert not (tmp_path / "m.obj").exists()


@pytest.mark.parametrize("content", ["", "# a scan header only\n\n"])
def test_cli_meshless_names_a_point_file_with_no_points(tmp_path, capsys, content):
    # Found in QA: an empty .xyz gave a raw numpy ValueError ("zero-size array to reduction").
    pts = tmp_path / "empty.xyz"
    pts.write_text(content)
    with pytest.raises(MeshFileError, match="holds no points"):
        jp.load_points(pts)
    assert main(["meshless", str(pts), "-o", str(tmp_path / "m.obj")]) == 3
    assert "holds no points" in capsys.readouterr().err
    with pytest.raises(jp.errors.PointCloudError, match="0 points are too few"):
        jp.meshless_map(np.zeros((0, 3)))


@pytest.mark.parametrize("k", [0, -1, 2.5])
def test_meshless_k_must_be_a_positive_integer(k):
    # Found in QA: --k 0 raised ZeroDivisionError, k=-1 a scipy ValueError, k=2.5 a TypeError.
    P = jp.shapes.graph_surface(6).vertices
    with pytest.raises(jp.errors.PointCloudError, match=r"k \(neighbours per point\) must be a positive integer"):
        jp.meshless_map(P, k=k)
    with pytest.raises(jp.errors.PointCloudError, match="must be a positive integer"):
        jp.reconstruct_surface(P, k=k)


def test_a_triangle_soup_is_named_as_such():
    # Found in QA on a triangle-soup OBJ (every face with its own three vertices, as STL
    # exporters write): the error only said "1653 connected components ... parameterize each
    # on its own", where the remedy is to merge the coincident vertices.
    mesh = jp.shapes.graph_surface(4)
    F = np.asarray(mesh.faces)
    soup = jp.TriMesh(np.asarray(mesh.vertices)[F.reshape(-1)], np.arange(F.size).reshape(-1, 3))
    with pytest.raises(TopologyError, match=r"18 connected components.*vertices \d+ and \d+ "
                       r"coincide but lie in different components.*triangle soup.*merge"):
        jp.convex_map(soup)
    two = jp.TriMesh(np.vstack([mesh.vertices, mesh.vertices + 5.0]),
                     np.vstack([F, F + mesh.n_vertices]))
    with pytest.raises(TopologyError, match="2 connected components") as e:
        jp.convex_map(two)
    assert "soup" not in str(e.value)


def test_distortion_counts_nan_faces_and_names_a_wrong_shape(grid_mesh):
    # Found in QA: jp.distortion of an all-nan map said flips=0, degenerate=0 (nan <= 0 is
    # False), and a (5, 2) uv gave a raw IndexError.
    uv = np.asarray(jp.convex_map(grid_mesh))
    bad = uv.copy()
    bad[0] = np.nan
    n_bad = int(np.any(grid_mesh.faces == 0, axis=1).sum())
    rep = jp.distortion(grid_mesh, bad)
    assert rep.flips == n_bad and rep.degenerate == n_bad
    assert jp.metrics.flips(grid_mesh, bad) == n_bad
    assert jp.distortion(grid_mesh, uv).flips == 0
    with pytest.raises(MeshError, match=r"distortion: uv must have shape \(\d+, 2\).*got \(5, 2\)"):
        jp.distortion(grid_mesh, uv[:5])


def _npy_bytes(a) -> bytes:
    import io as _io
    buf = _io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


@pytest.mark.parametrize("name, make, match", [
    # Found in QA: an .npz quoted its zip bytes ("cannot read numbers from 'PK\x03\x04...'"),
    # an .off mesh said "line 1: expected 'x y z', got 'OFF'".
    ("p.npz", lambda p: np.savez(p, a=np.zeros((5, 3))),
     r"p\.npz: a NumPy \.npz archive, not a point file; points are read from \.xyz/\.txt/\.csv .*"
     r"\.npy .*\.ply .*np\.save\('points\.npy', array\)"),
    ("m.off", lambda p: p.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
     r"m\.off: an OFF mesh file \(\.off\), not a point file; points are read .* from \.xyz.*"
     r"jaxparam flatten.*np\.save\('points\.npy', jp\.load\('.*m\.off'\)\.vertices\)"),
    ("m.obj", lambda p: p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
     r"an OBJ mesh file \(\.obj\), not a point file"),
    ("m.xyz", lambda p: p.write_text("# exported\nOFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
     r"m\.xyz: an OFF mesh file \(its first line is 'OFF'\).* Rename it to m\.off first\..*"
     r"jp\.load\('.*m\.off'\)"),
    ("m.txt", lambda p: p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\n"),
     r"an OBJ mesh file \(it has 'v' lines\).*Rename it to m\.obj first"),
    ("blob.bin", lambda p: p.write_bytes(b"\x01\x02\x00\x00" * 64), r"binary data, not a point file"),
    ("arr.dat", lambda p: p.write_bytes(_npy_bytes(np.zeros((5, 3)))),
     r"a \.npy array under the extension '\.dat'; rename the file to end in \.npy"),
])
def test_point_files_of_another_kind_are_refused_with_the_formats(tmp_path, capsys, name, make, match):
    p = tmp_path / name
    make(p)
    with pytest.raises(MeshFileError, match=match):
        jp.load_points(p)
    assert main(["-q", "meshless", str(p), "-o", str(tmp_path / "o.obj")]) == 3
    assert re.search(match, capsys.readouterr().err)
    assert not (tmp_path / "o.obj").exists()


def test_csv_points_are_still_read(tmp_path):
    p = tmp_path / "p.csv"
    np.savetxt(p, np.arange(12.0).reshape(4, 3), delimiter=",")
    np.testing.assert_array_equal(jp.load_points(p), np.arange(12.0).reshape(4, 3))


# Found in QA (session 21, the Python API): these reached TypeErrors deep in the driver or
# numpy, or were taken silently ("no" as a free boundary ran a free-boundary minimization).
@pytest.mark.parametrize("call, match", [
    (lambda m: jp.minimize(m, max_iters="5"), r"minimize: max_iters must be an integer >= 0, got '5'"),
    (lambda m: jp.minimize(m, max_iters=2.5), r"max_iters must be an integer >= 0, got 2\.5"),
    (lambda m: jp.minimize(m, max_iters=True), r"max_iters must be an integer >= 0, got True"),
    (lambda m: jp.minimize(m, energy_rtol="1e-3"), r"energy_rtol must be a number >= 0, got '1e-3'"),
    (lambda m: jp.minimize(m, free_boundary="no"), r"free_boundary must be True or False, got 'no'"),
    (lambda m: jp.least_squares_map(m, mu="uniform"), r"least_squares_map: mu must be None .*got 'uniform'"),
    (lambda m: jp.convex_map(m, host="no"), r"convex_map: host must be True or False, got 'no'"),
    (lambda m: jp.energy("mips"), r"energy: fn must be a function .*jp\.ENERGIES\['mips'\]"),
    (lambda m: jp.plot.plot_uv(m, np.zeros((5, 2))), r"plot_uv: uv must have shape \(\d+, 2\)"),
    (lambda m: jp.plot.plot_checkerboard(m, jp.convex_map(m), squares="8"),
     r"plot_checkerboard: squares must be an integer >= 1, got '8'"),
])
def test_api_options_of_the_wrong_type_are_named(grid_mesh, call, match):
    with pytest.raises(MeshError, match=match):
        call(grid_mesh)


def test_plots_take_a_vertices_faces_pair_and_a_manifold_map_prints_one_line(tmp_path, torus_map):
    m = jp.shapes.graph_surface(6)
    pair = (np.asarray(m.vertices), np.asarray(m.faces))
    uv = np.asarray(jp.convex_map(m))
    jp.plot.plot_uv(pair, uv, tmp_path / "uv.png")
    jp.plot.plot_checkerboard(pair, uv, tmp_path / "c.png")
    assert (tmp_path / "uv.png").stat().st_size > 0 and (tmp_path / "c.png").stat().st_size > 0
    param = torus_map[2]                  # conftest's map (sphere(1) at 8 before session 29)
    assert repr(param) == ("ManifoldParameterization(mesh=" + repr(param.mesh) + ", 40 base faces "
                           f"over {len(param.base_vertices)} base vertices, method='maps')")


# Found in QA (session 22, arguments swapped or of the wrong kind): a mesh passed where points
# go reached float() deep in numpy; energy(uv, mesh) an AttributeError; energy(mesh, uv) with
# too few UV rows returned a number (JAX clamps out-of-range gathers), silently wrong.
@pytest.mark.parametrize("call, kind, match", [
    (lambda m, uv: jp.meshless_map(m), jp.ArgumentTypeError,
     r"meshless_map: points must be an \(N, 3\) array, got a mesh \(TriMesh\); pass its vertices"),
    (lambda m, uv: jp.reconstruct_surface(m), jp.ArgumentTypeError, r"pass its vertices \(mesh\.vertices\)"),
    (lambda m, uv: jp.meshless_map([[0, 1, "a"]] * 5), jp.ArgumentTypeError,
     r"points must be an \(N, 3\) array of numbers, got list"),
    (lambda m, uv: jp.ENERGIES["mips"](uv, m), jp.ArgumentTypeError,
     r"energy 'mips' \(called as energy\(mesh, uv\)\): expected a jaxparam TriMesh"),
    (lambda m, uv: jp.ENERGIES["mips"](m, uv[:5]), MeshError,
     r"energy 'mips': uv must have shape \(\d+, 2\), one row per vertex of the mesh, got \(5, 2\)"),
    (lambda m, uv: jp.distortion(uv, m), TypeError, r"distortion: expected a jaxparam TriMesh"),
    (lambda m, uv: jp.atlas(np.asarray(m.vertices)), jp.JaxparamError, r"atlas: expected a jaxparam TriMesh"),
])
def test_arguments_of_the_wrong_kind_get_the_library_s_error(grid_mesh, call, kind, match):
    uv = np.asarray(jp.convex_map(grid_mesh))
    with pytest.raises(kind, match=match) as info:
        call(grid_mesh, uv)
    assert isinstance(info.value, jp.JaxparamError)


def test_remesh_and_manifold_map_refuse_zero_area_faces_kept_with_validate_false():
    """Found by session 22's held-out sweep: a disk (or closed mesh) kept with validate=False
    whose one face is flat remeshed 27 % of its diagonal off, silently (1.5 % without it)."""
    m = jp.shapes.graph_surface(6)
    V = np.asarray(m.vertices).copy()
    a, b, c = m.faces[20]
    V[c] = 0.5 * (V[a] + V[b])
    flat = jp.TriMesh(V, m.faces, validate=False)
    with pytest.raises(DegenerateFaceError, match=r"remesh: faces 20 \(1 in all\) have zero area.*"
                                                  r"nondegenerate_faces"):
        jp.remesh(flat, levels=1)
    s = jp.shapes.sphere(1)
    W = np.asarray(s.vertices).copy()
    a, b, c = s.faces[5]
    W[c] = 0.5 * (W[a] + W[b])
    with pytest.raises(DegenerateFaceError, match=r"manifold_map: faces .*zero area"):
        jp.manifold_map(jp.TriMesh(W, s.faces, validate=False), 8)
