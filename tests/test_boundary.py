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


def test_plane_first_vertex_on_u_axis(loop):
    uv = np.asarray(B.plane(loop))
    assert uv[0, 0] > 0 and abs(uv[0, 1]) < 1e-12
    # reversing the loop flips the normal, not the layout's orientation: still counter-clockwise
    uv_r = np.asarray(B.plane(loop[::-1]))
    area = 0.5 * np.sum(uv_r[:, 0] * np.roll(uv_r[:, 1], -1) - np.roll(uv_r[:, 0], -1) * uv_r[:, 1])
    assert area > 0
    _, E = B.plane_frame(loop)
    _, E_r = B.plane_frame(loop[::-1])
    np.testing.assert_allclose(np.asarray(E_r)[2], -np.asarray(E)[2], atol=1e-12)


def test_plane_check_can_be_skipped_for_point_sets():
    mesh = __import__("jaxparam").shapes.plane_grid(9, 9, jitter=0.3, seed=3, tilt=True)
    V = np.asarray(mesh.vertices)            # raster order: not a loop, its polygon crosses itself
    with pytest.raises(MeshError, match="crosses itself"):
        B.plane(V)
    flat = np.asarray(B.plane(V, check=False))
    d_uv = np.linalg.norm(flat[:, None] - flat[None], axis=-1)
    d_3 = np.linalg.norm(V[:, None] - V[None], axis=-1)
    np.testing.assert_allclose(d_uv, d_3, atol=1e-12)     # the mesh is planar: an isometry


def brute_crossings(P):
    """O(k^2) reference for crossing_edges."""
    k = len(P)
    A, Bq = P, np.roll(P, -1, axis=0)

    def o(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    out = []
    for i in range(k):
        for j in range(i + 1, k):
            if (j - i) % k in (1, k - 1):
                d1, d2 = (Bq[i] - A[i], Bq[j] - A[j]) if j == i + 1 else (Bq[j] - A[j], Bq[i] - A[i])
                if d1[0] * d2[1] - d1[1] * d2[0] == 0 and d1 @ d2 < 0:
                    out.append((i, j))
                continue
            p1, p2, q1, q2 = A[i], Bq[i], A[j], Bq[j]
            if np.all(np.maximum(np.minimum(p1, p2), np.minimum(q1, q2))
                      <= np.minimum(np.maximum(p1, p2), np.maximum(q1, q2))):
                if o(p1, p2, q1) * o(p1, p2, q2) <= 0 and o(q1, q2, p1) * o(q1, q2, p2) <= 0:
                    out.append((i, j))
    return np.array(out, np.int64).reshape(-1, 2)


def test_crossing_edges_matches_brute_force():
    rng = np.random.default_rng(0)
    for trial in range(150):
        k = int(rng.integers(3, 30))
        P = rng.standard_normal((k, 2))
        if trial % 3 == 0:
            P = np.round(P * 2) / 2          # collinear overlaps, touching vertices, repeats
        np.testing.assert_array_equal(B.crossing_edges(P), brute_crossings(P), err_msg=str(trial))
    # chunked: the same pairs a few at a time
    P = rng.standard_normal((60, 2))
    np.testing.assert_array_equal(B.crossing_edges(P, chunk=7), brute_crossings(P))


def test_crossing_edges_fast_on_large_simple_boundary():
    import time

    rng = np.random.default_rng(1)
    k = 10_000
    t = np.sort(rng.uniform(0, 2 * np.pi, k))
    r = 1 + 0.3 * np.sin(7 * t)
    P = np.column_stack([r * np.cos(t), r * np.sin(t)])
    t0 = time.perf_counter()
    assert B.crossing_edges(P).shape == (0, 2)
    P[[3000, 3005]] = P[[3005, 3000]]        # swap two vertices: two pairs of edges cross
    np.testing.assert_array_equal(B.crossing_edges(P), [[2999, 3005], [3000, 3004]])
    assert time.perf_counter() - t0 < 5.0   # ~0.2 s; all 5e7 pairs would take minutes


def test_plane_refuses_repeated_projected_vertex():
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    with pytest.raises(MeshError, match=r"consecutive vertices \(7, 8\) \(1 in all\) project to the same "
                                        r"point.*boundary=\"circle\""):
        B.check_plane_boundary(sq, np.array([3, 7, 8, 9, 4]))
    with pytest.raises(MeshError, match=r"consecutive loop positions \(1, 2\)"):
        B.plane(sq)
