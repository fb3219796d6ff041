"""Wavelet multiresolution of meshes with subdivision connectivity (jaxparam.wavelets, §7)."""
import jax
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import MeshError
from jaxparam.subdivision import dyadic_hierarchy
from jaxparam.wavelets import Coefficients, Compressed, analyze, compress, synthesize


@pytest.fixture(scope="module")
def semi():
    mesh = jp.shapes.graph_surface(12)
    return jp.remesh(mesh, jp.convex_map(mesh, weights="mean_value"), levels=3)


@pytest.mark.parametrize("wavelet", ["lazy", "lifted"])
def test_synthesis_inverts_analysis(semi, wavelet):
    c = analyze(semi, wavelet=wavelet)
    assert c.base.shape == (7, 3) and c.count == semi.mesh.n_vertices - 7
    np.testing.assert_allclose(np.asarray(synthesize(c)), np.asarray(semi.mesh.vertices), atol=1e-13)
    for level, n in enumerate(semi.hierarchy.counts):
        assert synthesize(c, level=level).shape == (n, 3)


def test_lazy_levels_are_subsamplings(semi):
    c = analyze(semi, wavelet="lazy")
    for level, n in enumerate(semi.hierarchy.counts):
        np.testing.assert_allclose(np.asarray(synthesize(c, level=level)),
                                   np.asarray(semi.mesh.vertices)[:n], atol=1e-13)


def test_an_affine_surface_has_no_details():
    # A tilted plane remeshed over its own coordinates with the square's corners: the
    # inverse map is affine and every new vertex is its parents' midpoint.
    mesh = jp.shapes.plane_grid(9, 9, tilt=True)
    uv = np.asarray(jp.shapes.plane_grid(9, 9).vertices)[:, :2]
    loop = list(mesh.topology.boundary_loops[0])
    corners = sorted(loop.index(v) for v in (0, 8, 72, 80))
    semi = jp.remesh(mesh, uv, levels=3, corners=corners)
    for wavelet in ("lazy", "lifted"):
        c = analyze(semi, wavelet=wavelet)
        assert max(float(np.abs(np.asarray(d)).max()) for d in c.details) < 1e-13


def test_the_lifted_coarse_levels_keep_the_mean_on_a_regular_mesh():
    # A torus triangulation is valence 6 everywhere, and stays so under refinement.
    torus = jp.shapes.torus(8, 6)
    H = dyadic_hierarchy(torus.faces, torus.n_vertices, 2)
    X = np.random.default_rng(0).normal(size=(H.counts[-1], 3))
    mesh = jp.TriMesh(X, H.faces[-1], validate=False)
    lifted, lazy = analyze(mesh, wavelet="lifted", hierarchy=H), analyze(mesh, wavelet="lazy", hierarchy=H)
    np.testing.assert_allclose(np.asarray(lifted.base).mean(0), X.mean(0), atol=1e-12)
    assert np.abs(np.asarray(lazy.base).mean(0) - X.mean(0)).max() > 1e-3


@pytest.mark.parametrize("wavelet", ["lazy", "lifted"])
def test_compression_error_falls_as_more_coefficients_are_kept(semi, wavelet):
    V, n = np.asarray(semi.mesh.vertices), semi.mesh.n_vertices
    errors = []
    for keep in (0.0, 0.05, 0.2, 0.5, 1.0):
        small = compress(semi, keep, wavelet=wavelet)
        assert isinstance(small, Compressed) and small.hierarchy is semi.hierarchy
        np.testing.assert_array_equal(small.mesh.faces, semi.mesh.faces)
        assert small.mesh.uv is semi.uv                            # the parameter points stay
        assert small.kept == round(keep * (n - 7))
        assert small.stored_fraction == pytest.approx((7 + small.kept) / n)
        errors.append(np.sqrt(np.mean(np.sum((np.asarray(small.mesh.vertices) - V) ** 2, 1))))
    assert errors[-1] < 1e-13 and errors[0] > 1e-3
    assert all(a >= b for a, b in zip(errors, errors[1:]))


def test_bad_wavelet_input_is_named(semi):
    with pytest.raises(MeshError, match="unknown wavelet 'haar'"):
        analyze(semi, wavelet="haar")
    with pytest.raises(MeshError, match=r"keep must be a fraction in \[0, 1\], got 2"):
        compress(semi, 2)
    with pytest.raises(MeshError, match=r"level must be in \[0, 3\]"):
        synthesize(analyze(semi), level=4)
    with pytest.raises(MeshError, match="subdivision connectivity"):
        analyze(jp.shapes.graph_surface(5))
    with pytest.raises(MeshError, match="hierarchy= is for a TriMesh"):
        analyze(semi, hierarchy=semi.hierarchy)
    with pytest.raises(MeshError, match="hierarchy must be a Hierarchy of the mesh's 25 vertices"):
        analyze(jp.shapes.graph_surface(5), hierarchy=semi.hierarchy)
    with pytest.raises(MeshError, match="expected a Remesh"):
        analyze(np.zeros((7, 3)))


def test_a_mesh_read_back_and_its_explicit_hierarchy_give_the_remesh_s_coefficients(semi, tmp_path):
    jp.save(tmp_path / "semi.obj", semi.mesh)
    back = jp.load(tmp_path / "semi.obj")                       # a TriMesh: hierarchy from its faces
    for c in (analyze(back), analyze(back, hierarchy=semi.hierarchy)):
        np.testing.assert_allclose(np.asarray(c.base), np.asarray(analyze(semi).base), atol=1e-15)
    small = compress(back, 0.1)
    np.testing.assert_allclose(np.asarray(small.mesh.vertices),
                               np.asarray(compress(semi, 0.1).mesh.vertices), atol=1e-15)
    # A compressed result can be analysed again, with its own hierarchy.
    assert analyze(small).count == analyze(semi).count


def test_results_survive_pytree_round_trips(semi):
    small = compress(semi, 0.1)
    back = jax.tree_util.tree_map(lambda x: x, small)
    assert isinstance(back, Compressed) and back.hierarchy is small.hierarchy
    assert (back.kept, back.stored_fraction) == (small.kept, small.stored_fraction)
    np.testing.assert_array_equal(np.asarray(back.mesh.vertices), np.asarray(small.mesh.vertices))
    np.testing.assert_array_equal(np.asarray(back.mesh.uv), np.asarray(small.mesh.uv))
    c = analyze(semi)
    c2 = jax.tree_util.tree_map(lambda x: x, c)
    assert isinstance(c2, Coefficients) and c2.hierarchy is c.hierarchy and c2.wavelet == c.wavelet
    # Synthesis under jit, the coefficients passed whole.
    X = jax.jit(synthesize)(c)
    np.testing.assert_allclose(np.asarray(X), np.asarray(semi.mesh.vertices), atol=1e-13)
