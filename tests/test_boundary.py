import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxparam import boundary as B
from jaxparam.errors import MeshError


@pytest.fixture
def loop():
    t = np.sort(np.random.default_rng(0).uniform(0, 2 * np.pi, 40))
    return np.column_stack([2 * np.cos(t), np.sin(t), 0.1 * np.sin(3 * t)])


def test_circle_is_ccw_and_on_circle(loop):
    uv = np.asarray(B.circle(loop))
    np.testing.assert_allclose(np.linalg.norm(uv, axis=1), 1.0)
    assert B.is_convex_polygon(uv)
    np.testing.assert_allclose(uv[0], [1, 0])


def test_chord_spacing_proportional(loop):
    t = np.asarray(B.arc_parameters(loop, "chord"))
    seg = np.linalg.norm(np.roll(loop, -1, 0) - loop, axis=1)
    np.testing.assert_allclose(np.diff(t), seg[:-1] / seg.sum())
    np.testing.assert_allclose(B.arc_parameters(loop, "uniform"), np.arange(40) / 40)


def test_square_corners_quarter_arclength(loop):
    uv = np.asarray(B.square(loop, spacing="uniform"))
    np.testing.assert_allclose(uv[[0, 10, 20, 30]], [[0, 0], [1, 0], [1, 1], [0, 1]], atol=1e-12)
    assert B.is_convex_polygon(uv)


def test_square_user_corners(loop):
    uv = np.asarray(B.square(loop, corners=[0, 5, 17, 33]))
    np.testing.assert_allclose(uv[[0, 5, 17, 33]], [[0, 0], [1, 0], [1, 1], [0, 1]], atol=1e-12)
    with pytest.raises(MeshError, match="corner positions"):
        B.square(loop, corners=[0, 17, 5, 33])


def test_polygon_and_convexity(loop):
    tri = np.array([[0, 0], [2, 0], [1, 1.5]])
    uv = np.asarray(B.polygon(loop, tri))
    assert B.is_convex_polygon(uv)
    with pytest.raises(MeshError, match="convex"):
        B.polygon(loop, np.array([[0, 0], [1, 1], [2, 0], [1, 3]]))


def test_plane_projection_of_planar_loop_is_isometric(loop):
    flat = loop.copy()
    flat[:, 2] = 0
    R = np.linalg.qr(np.random.default_rng(1).standard_normal((3, 3)))[0]
    uv = np.asarray(B.plane(flat @ R.T))
    d_uv = np.linalg.norm(uv[:, None] - uv[None], axis=-1)
    d_3 = np.linalg.norm(flat[:, None] - flat[None], axis=-1)
    np.testing.assert_allclose(d_uv, d_3, atol=1e-12)
    area = 0.5 * np.sum(uv[:, 0] * np.roll(uv[:, 1], -1) - np.roll(uv[:, 0], -1) * uv[:, 1])
    assert area > 0


def test_user_uv_shape(loop):
    with pytest.raises(MeshError, match=r"shape \(40, 2\)"):
        B.boundary_uv(loop, np.zeros((39, 2)))
    with pytest.raises(MeshError, match="unknown boundary 'disc'"):
        B.boundary_uv(loop, "disc")


def test_chord_circle_differentiable(loop):
    g = jax.grad(lambda X: jnp.sum(B.circle(X)[:, 0] ** 3))(jnp.asarray(loop))
    assert np.all(np.isfinite(g)) and np.abs(g).max() > 0
