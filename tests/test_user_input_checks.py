"""What a notebook user hands the Python API by mistake, refused early with the library's own
errors (the held-out sweep of session 28): boundary UVs that no map can use, an energy that is
not finite on valid triangles, parameters JAX cannot hold, complex coordinates."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import MeshError, SolverError


@pytest.fixture(scope="module")
def small_disk():
    return jp.shapes.disk(3, seed=0, height=0.3)


def _circle(mesh):
    k = len(jp.boundary_loop(mesh))
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    return np.c_[np.cos(t), np.sin(t)]


def test_boundary_uvs_that_turn_every_triangle_over_are_refused(small_disk):
    circle = _circle(small_disk)
    with pytest.raises(MeshError, match=r"run clockwise \(signed area -3\.\d+\): mirror them"):
        jp.convex_map(small_disk, boundary=circle * np.array([1.0, -1.0]))
    for flat in (np.zeros_like(circle), np.c_[circle[:, 0], 0 * circle[:, 0]]):
        with pytest.raises(MeshError, match="enclose no area"):
            jp.convex_map(small_disk, boundary=flat)
    broken = circle.copy()
    broken[[0, 4], 1] = np.nan
    with pytest.raises(MeshError, match=r"not finite in rows 0, 4 \(2 in all\)"):
        jp.convex_map(small_disk, boundary=broken)
    # the same refusal through a mapping {vertex: uv}
    loop = np.asarray(jp.boundary_loop(small_disk))
    with pytest.raises(MeshError, match="run clockwise"):
        jp.convex_map(small_disk, boundary={int(v): (u, -w) for v, (u, w) in zip(loop, circle)})


def test_counter_clockwise_boundary_uvs_still_map_and_differentiate(small_disk):
    circle = _circle(small_disk)
    uv = np.asarray(jp.convex_map(small_disk, boundary=circle))
    F = small_disk.faces
    e1, e2 = uv[F[:, 1]] - uv[F[:, 0]], uv[F[:, 2]] - uv[F[:, 0]]
    assert np.all(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0)
    # traced boundary UVs are not checked (their values are unknown) and the gradient flows
    g = jax.grad(lambda b: jnp.sum(jp.convex_map(small_disk, boundary=b) ** 2))(jnp.asarray(circle))
    assert g.shape == circle.shape and np.all(np.isfinite(np.asarray(g))) and float(jnp.abs(g).max()) > 0


def test_an_energy_that_is_not_finite_on_valid_triangles_is_named_as_the_cause(small_disk):
    # log(s1 s2 - 1) is NaN wherever the start shrinks a triangle: the start is flip-free
    bad = jp.energy(lambda s1, s2: s1 ** 2 + s2 ** 2 + jnp.log(s1 * s2 - 1.0) ** 2)
    with pytest.raises(SolverError, match=r"energy \(<lambda>\) is NaN on faces \d+.*positive.*"
                                          r"the energy itself is not finite") as e:
        jp.minimize(small_disk, bad, verbose=False)
    assert e.value.stage == "init"


def test_energy_params_that_are_not_numbers_are_refused_when_the_energy_is_made():
    with pytest.raises(MeshError, match=r"params must be a pytree of real numbers.*got 'abc' at params"):
        jp.energy(lambda s1, s2, a: a * s1 + 1 / s2, "abc")
    with pytest.raises(MeshError, match=r"got 'x' at \['b'\]"):
        jp.energy(lambda s1, s2, p: p["a"] * s1 + 1 / s2, {"a": 1.0, "b": "x"})
    ok = jp.energy(lambda s1, s2, p: p["a"] * (s1 ** 2 + s1 ** -2) + s2 ** 2 + s2 ** -2,
                   {"a": 1.0, "b": (2, np.ones(3))})
    assert ok.name == "<lambda>"


def test_complex_vertices_are_refused(small_disk):
    with pytest.raises(MeshError, match=r"real numbers, got dtype complex128.*V\.real"):
        jp.TriMesh(np.asarray(small_disk.vertices) + 1j, small_disk.faces)
    # faces given as floats with integral values are taken as integers (docs/errors.md)
    m = jp.TriMesh(small_disk.vertices, small_disk.faces.astype(np.float64))
    assert m.faces.dtype == np.int64 and np.array_equal(m.faces, small_disk.faces)
