import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam import weights as W

POSITIVE = ["uniform", "inverse_distance", "shape_preserving", "mean_value"]


@pytest.mark.parametrize("kind", W.KINDS)
def test_weights_sum_to_one(grid_mesh, kind):
    lam = np.asarray(W.convex_weights(grid_mesh, kind))
    R = W.ring_entries(grid_mesh.topology)
    sums = np.bincount(R.row, weights=lam)
    np.testing.assert_allclose(sums, 1.0, atol=1e-12)
    if kind in POSITIVE:
        assert lam.min() > 0


@pytest.mark.parametrize("kind", ["shape_preserving", "mean_value", "harmonic"])
def test_weights_reproduce_planar_vertex(planar_mesh, kind):
    # Eq. (6): in a plane, v = sum lambda_vw w.
    lam = np.asarray(W.convex_weights(planar_mesh, kind))
    R = W.ring_entries(planar_mesh.topology)
    V = np.asarray(planar_mesh.vertices)
    recon = np.zeros((R.n_rows, 3))
    np.add.at(recon, R.row, lam[:, None] * V[R.nbr])
    np.testing.assert_allclose(recon, V[planar_mesh.topology.interior], atol=1e-12)


def test_uniform_does_not_reproduce(planar_mesh):
    lam = np.asarray(W.convex_weights(planar_mesh, "uniform"))
    R = W.ring_entries(planar_mesh.topology)
    V = np.asarray(planar_mesh.vertices)
    recon = np.zeros((R.n_rows, 3))
    np.add.at(recon, R.row, lam[:, None] * V[R.nbr])
    assert np.abs(recon - V[planar_mesh.topology.interior]).max() > 1e-3


def test_harmonic_single_ring_cotangents():
    # Regular hexagon fan: every angle is 60 degrees, cot = 1/sqrt(3), mu = (cot + cot)/2.
    k = 6
    t = 2 * np.pi * np.arange(k) / k
    V = np.vstack([[0, 0, 0], np.column_stack([np.cos(t), np.sin(t), np.zeros(k)])])
    F = np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)])
    mesh = jp.TriMesh(V, F)
    mu, sym = W.entry_weights(mesh.vertices, mesh.topology, "harmonic")
    assert sym
    np.testing.assert_allclose(mu, 1 / np.sqrt(3), rtol=1e-12)


def test_mean_value_formula_on_square_ring():
    # Four neighbours at distance 1, right angles: tan(45/2) * 2 / 1, equal weights 1/4.
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]])
    lam = np.asarray(W.convex_weights(jp.TriMesh(V, F), "mean_value"))
    np.testing.assert_allclose(lam, 0.25, rtol=1e-12)


def test_shape_preserving_nonplanar_positive(disk_mesh):
    lam = np.asarray(W.convex_weights(disk_mesh, "shape_preserving"))
    assert lam.min() > 0


@pytest.mark.parametrize("kind", ["shape_preserving", "mean_value", "harmonic", "inverse_distance"])
def test_weights_gradient_finite_differences(disk_mesh, kind):
    V0 = np.asarray(disk_mesh.vertices)
    rng = np.random.default_rng(0)
    c = rng.standard_normal(W.ring_entries(disk_mesh.topology).entry.size)

    def f(V):
        return jnp.sum(c * W.convex_weights(disk_mesh.with_vertices(V), kind))

    g = np.asarray(jax.grad(f)(jnp.asarray(V0)))
    d = rng.standard_normal(V0.shape)
    h = 1e-6
    fd = (f(jnp.asarray(V0 + h * d)) - f(jnp.asarray(V0 - h * d))) / (2 * h)
    assert abs(fd - np.sum(g * d)) <= 1e-6 * max(1.0, abs(fd))


def test_unknown_kind(grid_mesh):
    with pytest.raises(jp.MeshError, match="unknown weights 'cot'"):
        W.convex_weights(grid_mesh, "cot")
