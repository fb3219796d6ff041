"""Derivatives of jaxparam.manifold: ManifoldParameterization.with_vertices re-solves the charts
for new positions with the discrete choices (base domain, paths, surface triangles, charts'
connectivity, point location) held fixed, so the remesh is differentiable in the positions."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import MeshError
from jaxparam.manifold import ManifoldParameterization, manifold_map


@pytest.fixture(scope="module")
def sphere():
    mesh = jp.shapes.sphere(2)                       # 162 vertices, 320 faces
    base, param = manifold_map(mesh, 8, method="paths")   # the route whose charts are solved
    return mesh, base, param


# The always-on tests take conftest's torus(40, 20) over 40 base faces by the same route,
# shared with test_manifold.py (since session 29: the sphere's map took 5-10 s of its own;
# the slow gradient test below keeps it).
def test_with_vertices_at_the_input_positions_is_the_parameterization(torus_paths_map):
    mesh, base, param = torus_paths_map
    for V0 in (np.asarray(mesh.vertices), jnp.asarray(mesh.vertices)):
        again = param.with_vertices(V0)
        assert isinstance(again, ManifoldParameterization) and again.structure is param.structure
        for f in ("base_vertices", "base_faces", "region", "vertex_face"):
            assert getattr(again, f) is getattr(param, f)
        for f in ("face_uv", "vertex_bary"):
            np.testing.assert_array_equal(np.asarray(getattr(again, f)), np.asarray(getattr(param, f)))
        np.testing.assert_array_equal(np.asarray(again.mesh.vertices), np.asarray(param.mesh.vertices))
        np.testing.assert_array_equal(again.mesh.faces, param.mesh.faces)
        np.testing.assert_array_equal(np.asarray(again.remesh(2).mesh.vertices),
                                      np.asarray(param.remesh(2).mesh.vertices))
    # The refined mesh's first vertices are the input's; the rest their midpoints/centroids.
    np.testing.assert_array_equal(np.asarray(param.mesh.vertices)[:mesh.n_vertices], np.asarray(mesh.vertices))
    # Under jit (the traced, differentiable solve) the same to rounding; a pytree out.
    jitted = jax.jit(param.with_vertices)(jnp.asarray(mesh.vertices))
    assert isinstance(jitted, ManifoldParameterization)
    np.testing.assert_allclose(np.asarray(jitted.face_uv), param.face_uv, atol=1e-12)
    np.testing.assert_allclose(np.asarray(jitted.vertex_bary), param.vertex_bary, atol=1e-12)


@pytest.mark.slow
def test_remesh_gradient_matches_central_differences(sphere):
    mesh, base, param = sphere
    V0 = jnp.asarray(mesh.vertices)
    rng = np.random.default_rng(0)
    n_remesh = param.remesh(2).mesh.n_vertices
    target = jnp.asarray(rng.standard_normal((n_remesh, 3)))

    def loss(V):
        X = param.with_vertices(V).remesh(levels=2).mesh.vertices
        return jnp.sum(target * X) + jnp.sum(X ** 2 * target[:, ::-1])

    g = jax.jit(jax.grad(loss))(V0)
    assert np.all(np.isfinite(np.asarray(g)))
    eps = 1e-5
    for _ in range(2):
        D = jnp.asarray(rng.standard_normal(V0.shape))
        fd = (loss(V0 + eps * D) - loss(V0 - eps * D)) / (2 * eps)
        an = jnp.sum(g * D)
        assert abs(float(fd - an)) <= 1e-6 * abs(float(an)), (float(fd), float(an))
    # The charts move with the positions (not only the lift): d(face_uv) is not zero.
    J = jax.jit(jax.grad(lambda V: jnp.sum(param.with_vertices(V).face_uv[:, :, 0] ** 2)))(V0)
    assert float(jnp.abs(J).max()) > 1e-3


def test_manifold_map_under_tracing_names_the_route(torus_paths_map):
    mesh, base, param = torus_paths_map

    def through_map(V):
        _, p = manifold_map(jp.TriMesh(V, mesh.faces, validate=False), 40)
        return p.remesh(1).mesh.vertices.sum()

    with pytest.raises(MeshError, match=r"traced.*with_vertices"):
        jax.grad(through_map)(jnp.asarray(mesh.vertices))
    with pytest.raises(MeshError, match=r"shape \(800, 3\)"):
        param.with_vertices(np.asarray(param.mesh.vertices))
    hand = ManifoldParameterization(param.mesh, param.base_vertices, param.base_faces, param.region,
                                    param.face_uv, param.vertex_face, param.vertex_bary)
    with pytest.raises(MeshError, match="no structure"):
        hand.with_vertices(np.asarray(mesh.vertices))
    np.testing.assert_allclose(np.asarray(hand.remesh(1).mesh.vertices),
                               np.asarray(param.remesh(1).mesh.vertices), atol=1e-14)
