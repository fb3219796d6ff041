"""Wavelet multiresolution of meshes with subdivision connectivity (jaxparam.wavelets, §7)."""
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import MeshError
from jaxparam.remesh import Hierarchy, dyadic_refine
from jaxparam.wavelets import analyze, compress, synthesize


@pytest.fixture(scope="module")
def semi():
    mesh = jp.shapes.graph_surface(12)
    return jp.remesh(mesh, jp.convex_map(mesh, weights="mean_value"), levels=3)


@pytest.mark.parametrize("wavelet", ["lazy", "lifted"])
def test_synthesis_inverts_analysis(semi, wavelet):
    c = analyze(semi, wavelet=wavelet)
    assert c.base.shape == (7, 3) and c.count == semi.n_vertices - 7
    np.testing.assert_allclose(np.asarray(synthesize(c)), np.asarray(semi.vertices), atol=1e-13)
    for level, n in enumerate(semi.hierarchy.counts):
        assert synthesize(c, level=level).shape == (n, 3)


def test_lazy_levels_are_subsamplings(semi):
    c = analyze(semi, wavelet="lazy")
    for level, n in enumerate(semi.hierarchy.counts):
        np.testing.assert_allclose(np.asarray(synthesize(c, level=level)),
                                   np.asarray(semi.vertices)[:n], atol=1e-13)


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
    F, n = torus.faces, torus.n_vertices
    counts, parents, faces = [n], [], [F]
    for _ in range(2):
        F, par, _ = dyadic_refine(F, counts[-1])
        counts.append(counts[-1] + par.shape[0])
        parents.append(par)
        faces.append(F)
    H = Hierarchy(tuple(counts), tuple(parents), tuple(faces))
    X = np.random.default_rng(0).normal(size=(counts[-1], 3))
    mesh = jp.TriMesh(X, F, validate=False)
    mesh.hierarchy = H
    lifted, lazy = analyze(mesh, wavelet="lifted"), analyze(mesh, wavelet="lazy")
    np.testing.assert_allclose(np.asarray(lifted.base).mean(0), X.mean(0), atol=1e-12)
    assert np.abs(np.asarray(lazy.base).mean(0) - X.mean(0)).max() > 1e-3


@pytest.mark.parametrize("wavelet", ["lazy", "lifted"])
def test_compression_error_falls_as_more_coefficients_are_kept(semi, wavelet):
    V = np.asarray(semi.vertices)
    errors = []
    for keep in (0.0, 0.05, 0.2, 0.5, 1.0):
        small = compress(semi, keep, wavelet=wavelet)
        np.testing.assert_array_equal(small.faces, semi.faces)
        assert small.kept == round(keep * (semi.n_vertices - 7))
        assert small.stored_fraction == pytest.approx((7 + small.kept) / semi.n_vertices)
        errors.append(np.sqrt(np.mean(np.sum((np.asarray(small.vertices) - V) ** 2, 1))))
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
