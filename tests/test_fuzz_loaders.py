"""Hypothesis-generated OBJ/OFF/PLY text and bytes: the loaders raise MeshFileError (malformed
file) or a MeshError subclass (a well-formed file holding an invalid mesh), never anything else."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

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


@pytest.mark.parametrize("ext", ["obj", "off", "ply"])
@SETTINGS
@given(data=st.binary(max_size=300))
def test_bytes_never_crash(tmp_path, ext, data):
    check(tmp_path, f"b.{ext}", data)


@SETTINGS
@given(cut=st.integers(0, 400))
def test_truncated_valid_files(tmp_path, cut):
    mesh = jp.shapes.plane_grid(3, 3)
    p = tmp_path / "full.obj"
    jp.save(p, mesh)
    check(tmp_path, "cut.obj", p.read_bytes()[:cut])
