"""Hypothesis-generated OBJ/OFF/PLY text and bytes: the loaders raise MeshFileError (malformed
file) or a MeshError subclass (a well-formed file holding an invalid mesh), never anything else."""
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings, strategies as st

import jaxparam as jp
from jaxparam.errors import MeshError, MeshFileError

tokens = st.sampled_from(["v", "f", "vt", "vn", "#", "OFF", "3", "4", "0", "1", "2", "-1", "7",
                          "1e999", "nan", "inf", "-0", "0.5", "1/1", "2//3", "x", "", "999999999999",
                          "ply", "format", "ascii", "element", "vertex", "face", "end_header"])
lines = st.lists(st.lists(tokens, max_size=6).map(" ".join), max_size=12).map("\n".join)
SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                              HealthCheck.function_scoped_fixture])


def check(tmp_path, name, data: bytes):
    p = tmp_path / name
    p.write_bytes(data)
    try:
        m = jp.load(p)
    except (MeshFileError, MeshError):
        return
    assert m.n_faces >= 1 and np.all(np.isfinite(np.asarray(m.vertices)))


@pytest.mark.parametrize("ext", ["obj", "off"])
@SETTINGS
@given(text=lines)
def test_text_never_crashes(tmp_path, ext, text):
    check(tmp_path, f"f.{ext}", text.encode())


@pytest.mark.parametrize("ext", ["obj", "off", "ply", "stl"])
@SETTINGS
@given(data=st.binary(max_size=300))
def test_bytes_never_crash(tmp_path, ext, data):
    check(tmp_path, f"b.{ext}", data)


PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n"
            "property float z\nelement face {nf}\nproperty list uchar int vertex_indices\nend_header\n")
counts = st.sampled_from(["0", "1", "3", "4", "-1", "1e999", "nan", "99999999999", "x", ""])


@SETTINGS
@given(nv=counts, nf=counts, body=lines)
@example(nv="0", nf="1", body="1e999")   # an infinite list count (was an OverflowError)
@example(nv="0", nf="1", body="nan")
def test_headers_with_random_counts_never_crash(tmp_path, nv, nf, body):
    check(tmp_path, "h.ply", (PLY_HEAD.format(nv=nv, nf=nf) + body).encode())
    check(tmp_path, "h.off", f"OFF\n{nv} {nf} 0\n{body}".encode())


@pytest.mark.parametrize("name, data", [
    ("huge.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\n"
                 b"property float y\nproperty float z\nend_header\n\x00\x00"),
    ("huge.off", b"OFF\n4000000000 1 0\n0 0 0\n"),
])
def test_huge_counts_are_refused_without_allocating(tmp_path, name, data):
    p = tmp_path / name
    p.write_bytes(data)
    with pytest.raises(MeshFileError, match=r"truncated|unexpected length|cannot read"):
        jp.load(p)


@pytest.mark.parametrize("name, text, cls, match", [
    ("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", MeshError, r"vertices 0 .*non-finite"),
    ("rep.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 1\n", MeshError, r"repeat a vertex"),
    ("bow.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv -1 -1 0\nv -1 0 0\nf 1 2 3\nf 1 4 5\n", MeshError, r"bowtie"),
])
def test_well_formed_files_with_invalid_meshes_raise_mesh_errors(tmp_path, name, text, cls, match):
    """The documented split: a file we can parse but whose mesh is invalid gives a MeshError
    (never a MeshFileError), so callers can tell a broken file from a broken mesh."""
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(cls, match=match) as e:
        jp.load(p)
    assert not isinstance(e.value, MeshFileError)


@SETTINGS
@given(cut=st.integers(0, 400))
def test_truncated_valid_files(tmp_path, cut):
    mesh = jp.shapes.plane_grid(3, 3)
    p = tmp_path / "full.obj"
    jp.save(p, mesh)
    check(tmp_path, "cut.obj", p.read_bytes()[:cut])


PLY_UV_HEAD = ("ply\nformat {fmt} 1.0\nelement vertex {nv}\nproperty double x\nproperty double y\n"
               "property double z\nproperty float u\nproperty float v\nelement face {nf}\n"
               "property list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n")


@SETTINGS
@given(fmt=st.sampled_from(["ascii", "binary_little_endian", "binary_big_endian", "binary_middle"]),
       nv=st.sampled_from(["0", "1", "3", "4", "-2", "x"]), nf=st.sampled_from(["0", "1", "2", "-1"]),
       body=st.binary(max_size=200))
def test_ply_with_uvs_and_random_bodies_never_crash(tmp_path, fmt, nv, nf, body):
    """jaxparam's own PLY reader (vertex u/v, face texcoord lists) on random data after a
    valid header."""
    check(tmp_path, "u.ply", PLY_UV_HEAD.format(fmt=fmt, nv=nv, nf=nf).encode() + body)


@SETTINGS
@given(text=lines)
def test_ascii_ply_with_uvs_never_crashes(tmp_path, text):
    check(tmp_path, "a.ply", (PLY_UV_HEAD.format(fmt="ascii", nv=3, nf=1) + text).encode())


@SETTINGS
@given(cut=st.integers(0, 2000), ext=st.sampled_from(["ply", "glb", "obj"]))
def test_truncated_files_of_every_written_format(tmp_path, cut, ext):
    mesh = jp.shapes.plane_grid(3, 3)
    p = tmp_path / f"full.{ext}"
    jp.save(p, mesh, np.asarray(mesh.vertices)[:, :2])
    check(tmp_path, f"cut.{ext}", p.read_bytes()[:cut])
