import jax
import jax.numpy as jnp
import numpy as np

from jaxparam import geometry as G


def test_singular_values_match_numpy():
    rng = np.random.default_rng(0)
    J = rng.standard_normal((200, 2, 2))
    s1, s2 = G.singular_values(jnp.asarray(J))
    s = np.linalg.svd(J, compute_uv=False)
    np.testing.assert_allclose(np.asarray(s1), s[:, 0], rtol=1e-12)
    np.testing.assert_allclose(np.abs(np.asarray(s2)), s[:, 1], rtol=1e-10, atol=1e-14)
    np.testing.assert_array_equal(np.asarray(s2) < 0, np.linalg.det(J) < 0)


def test_symmetric_function_gradient_finite_at_equal_singular_values():
    J = jnp.array([[2.0, 0.0], [0.0, 2.0]])

    def f(J):
        s1, s2 = G.singular_values(J)
        return s1 ** 2 + s2 ** 2

    g = jax.grad(f)(J)
    np.testing.assert_allclose(np.asarray(g), 2 * np.asarray(J), rtol=1e-12)


def test_jacobian_of_isometry_is_rotation():
    rng = np.random.default_rng(1)
    V = rng.standard_normal((3, 3))
    F = np.array([[0, 1, 2]])
    fr = np.asarray(G.local_frames(V, F))[0]
    th = 0.3
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    uv = fr @ R.T + 5.0
    J = np.asarray(G.jacobians(V, F, uv))[0]
    np.testing.assert_allclose(J, R, atol=1e-12)
    np.testing.assert_allclose(G.face_areas(V, F), 0.5 * np.linalg.norm(np.cross(V[1] - V[0], V[2] - V[0])))


def test_max_step_stops_before_inversion():
    uv = jnp.array([[0.0, 0], [1, 0], [0, 1]])
    F = np.array([[0, 1, 2]])
    d = jnp.array([[0.0, 0], [0, 0], [0, -1.0]])  # vertex 2 moves down: inverts at t = 1
    t = G.max_step(uv, d, F, safety=1.0)
    np.testing.assert_allclose(t, 1.0)
    assert np.isinf(G.max_step(uv, -d, F))
    assert G.signed_areas(uv + 0.99 * d, F)[0] > 0


def test_corner_angles_sum_to_pi():
    V = np.random.default_rng(2).standard_normal((30, 3))
    F = np.arange(30).reshape(10, 3)
    np.testing.assert_allclose(np.asarray(G.corner_angles(V, F)).sum(1), np.pi)


def test_dot_is_the_coordinate_sum_and_differentiates_like_it():
    """``geometry.dot`` (the written-out sum that keeps XLA's slow YNNPACK reduce away, issue 17)
    against ``jnp.sum(a * b, -1)``: values to rounding, and its custom_jvp's forward and reverse
    derivatives to rounding too, for 2 and 3 coordinates and a batch axis."""
    import jax
    import jax.numpy as jnp
    from jaxparam.geometry import dot

    rng = np.random.default_rng(3)
    for shape in ((50, 3), (7, 5, 2)):
        a, b = (jnp.asarray(rng.standard_normal(shape)) for _ in range(2))
        ref = lambda a, b: jnp.sum(a * b, -1)            # noqa: E731
        np.testing.assert_allclose(dot(a, b), ref(a, b), rtol=1e-14, atol=1e-14)
        ta, tb = (jnp.asarray(rng.standard_normal(shape)) for _ in range(2))
        np.testing.assert_allclose(jax.jvp(dot, (a, b), (ta, tb))[1],
                                   jax.jvp(ref, (a, b), (ta, tb))[1], rtol=1e-13, atol=1e-13)
        ct = jnp.asarray(rng.standard_normal(shape[:-1]))
        for x, y in zip(jax.vjp(dot, a, b)[1](ct), jax.vjp(ref, a, b)[1](ct)):
            np.testing.assert_allclose(x, y, rtol=1e-13, atol=1e-13)
            assert float(jnp.max(jnp.abs(y))) > 0
