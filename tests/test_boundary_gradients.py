"""Boundary maps as functions of the loop's positions: continuity, gradients, refusals, kinks.

Issue 12, items 3 and 6: ``boundary="plane"`` is continuous under tiny perturbations (no 180°
turn, no mirror image), has finite and correct gradients (also for a circular planar loop),
refuses a loop whose projection crosses itself; ``square`` and ``polygon`` have a documented
kink where a vertex sits on a corner, and JAX returns the derivative of the side after it.
"""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam import boundary as B
from jaxparam.errors import MeshError
from jaxparam.geometry import signed_areas
from conftest import data_path


def loop_of(mesh):
    loop = mesh.topology.boundary_loops[0]
    return loop, np.asarray(mesh.vertices)[loop]


def svd_plane(X):
    """The former rule (principal axes, flipped to counter-clockwise): it jumps under 1e-10."""
    X = X - X.mean(axis=0)
    uv = X @ np.linalg.svd(X, full_matrices=False)[2][:2].T
    area = np.sum(uv[:, 0] * np.roll(uv[:, 1], -1) - np.roll(uv[:, 0], -1) * uv[:, 1])
    return uv * np.array([1.0, -1.0 if area < 0 else 1.0])


CONTINUITY_MESHES = {
    "graph_surface": lambda: jp.shapes.graph_surface(12),
    # a nearly planar, nearly circular boundary: the regular 48-gon lifted by z = 1e-6 (x^2 - y^2),
    # whose two in-plane singular values are equal
    "near_circle": lambda: jp.shapes.disk(8, height=1e-6),
}


@pytest.mark.parametrize("name", sorted(CONTINUITY_MESHES))
def test_plane_continuous_under_tiny_perturbations(name):
    mesh = CONTINUITY_MESHES[name]()
    loop, X = loop_of(mesh)
    rng = np.random.default_rng(0)
    uv0 = np.asarray(B.plane(X))
    jumps, svd_jumps = [], []
    for _ in range(10):
        Xe = X + 1e-10 * rng.standard_normal(X.shape)
        jumps.append(np.abs(np.asarray(B.plane(Xe)) - uv0).max())
        svd_jumps.append(np.abs(svd_plane(Xe) - svd_plane(X)).max())
    assert max(jumps) < 1e-8, max(jumps)
    assert max(svd_jumps) > 0.1      # the test has teeth: principal axes turn or mirror here
    # the first loop vertex on +u, counter-clockwise
    assert uv0[0, 0] > 0 and abs(uv0[0, 1]) < 1e-12
    area = np.sum(uv0[:, 0] * np.roll(uv0[:, 1], -1) - np.roll(uv0[:, 0], -1) * uv0[:, 1])
    assert area > 0


@pytest.mark.parametrize("name", sorted(CONTINUITY_MESHES))
def test_plane_convex_map_continuous_and_not_mirrored(name):
    mesh = CONTINUITY_MESHES[name]()
    uv0 = np.asarray(jp.convex_map(mesh, weights="mean_value", boundary="plane"))
    V = np.asarray(mesh.vertices) + 1e-10 * np.random.default_rng(1).standard_normal(mesh.vertices.shape)
    uv1 = np.asarray(jp.convex_map(jp.TriMesh(V, mesh.faces), weights="mean_value", boundary="plane"))
    assert np.abs(uv1 - uv0).max() < 1e-8
    # laid out counter-clockwise like the faces: no face is mirrored
    assert np.asarray(signed_areas(uv0, mesh.faces)).min() > 0


def test_planar_mesh_in_plane_frame_keeps_face_orientation():
    mesh = jp.shapes.plane_grid(9, 9, jitter=0.3, seed=3, tilt=True)
    loop, X = loop_of(mesh)
    c, E = (np.asarray(a) for a in B.plane_frame(X))
    np.testing.assert_allclose(E @ E.T, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(np.cross(E[0], E[1]), E[2], atol=1e-14)
    flat = (np.asarray(mesh.vertices) - c) @ E[:2].T
    assert np.asarray(signed_areas(flat, mesh.faces)).min() > 0
    np.testing.assert_allclose(flat[loop], B.plane(X), atol=1e-13)


def generic_loop():
    mesh = jp.shapes.disk(5, seed=1, height=0.3)
    _, X = loop_of(mesh)
    return X + 0.02 * np.random.default_rng(0).standard_normal(X.shape)


def test_plane_gradient_matches_central_differences():
    X = generic_loop()
    rng = np.random.default_rng(1)
    h = 1e-5
    errs = []
    for _ in range(3):
        d = rng.standard_normal(X.shape)
        _, jv = jax.jvp(B.plane, (jnp.asarray(X),), (jnp.asarray(d),))
        fd = (np.asarray(B.plane(X + h * d)) - np.asarray(B.plane(X - h * d))) / (2 * h)
        errs.append(np.abs(fd - np.asarray(jv)).max() / np.abs(np.asarray(jv)).max())
    assert max(errs) <= 1e-6, errs         # measured ~1e-10


def test_plane_gradient_through_convex_map():
    mesh = jp.shapes.disk(5, seed=1, height=0.3)
    V0 = np.asarray(mesh.vertices) + 0.01 * np.random.default_rng(3).standard_normal(mesh.vertices.shape)
    c = np.random.default_rng(0).standard_normal((mesh.n_vertices, 2))

    def loss(V):
        return jnp.sum(c * jp.convex_map(jp.TriMesh(V, mesh.faces), weights="mean_value",
                                         boundary="plane"))

    g = np.asarray(jax.grad(loss)(jnp.asarray(V0)))
    d = np.random.default_rng(2).standard_normal(V0.shape)
    h = 1e-5
    fd = (loss(jnp.asarray(V0 + h * d)) - loss(jnp.asarray(V0 - h * d))) / (2 * h)
    assert abs(np.sum(g * d) - fd) <= 1e-6 * abs(fd)          # measured ~5e-9


def circle_loop(k=48):
    t = 2 * np.pi * np.arange(k) / k
    return np.column_stack([np.cos(t), np.sin(t), np.zeros(k)])


def test_plane_gradient_finite_for_circular_planar_loop():
    # Equal in-plane singular values: the former SVD rule had an undefined axis (NaN gradient).
    X = circle_loop()

    def f(x):
        uv = B.plane(x)
        return jnp.sum(uv ** 3) + jnp.sum(jnp.sin(uv))

    for grad in (jax.grad(f), jax.jit(jax.grad(f))):
        g = np.asarray(grad(jnp.asarray(X)))
        assert np.all(np.isfinite(g)) and np.abs(g).max() > 0
    d = np.random.default_rng(0).standard_normal(X.shape)
    h = 1e-5
    fd = (f(jnp.asarray(X + h * d)) - f(jnp.asarray(X - h * d))) / (2 * h)
    assert abs(np.sum(g * d) - fd) <= 1e-6 * max(1.0, abs(fd))


def test_plane_gradient_finite_when_first_vertex_projects_onto_centre():
    # A notched circle whose first vertex is the mean of the loop: the u axis falls back to the
    # farthest vertex; values and gradient stay finite.
    t = np.linspace(np.pi / 6, 2 * np.pi - np.pi / 6, 30)
    arc = np.column_stack([np.cos(t), np.sin(t), np.zeros(30)])
    X = np.vstack([[arc[:, 0].sum() / 30, 0.0, 0.0], arc])
    assert np.linalg.norm(X[0] - X.mean(axis=0)) < 1e-15
    uv = np.asarray(B.plane(X))
    assert np.all(np.isfinite(uv))
    g = np.asarray(jax.grad(lambda x: jnp.sum(B.plane(x) ** 2))(jnp.asarray(X)))
    assert np.all(np.isfinite(g))


def test_plane_zero_vector_area_refused_but_finite_under_grad():
    t = 2 * np.pi * np.arange(48) / 48
    X = np.column_stack([np.cos(t), np.sin(2 * t), np.zeros(48)])   # figure eight, equal lobes
    with pytest.raises(MeshError, match=r"encloses no area in any plane.*boundary=\"circle\""):
        B.plane(X)
    with pytest.raises(MeshError, match="encloses no area"):
        B.check_plane_boundary(X)
    g = np.asarray(jax.grad(lambda x: jnp.sum(B.plane(x) ** 2))(jnp.asarray(X)))
    assert np.all(np.isfinite(g))


def figure_eight(k=48):
    """A space curve (no self-intersection in 3D) whose best plane shows a figure eight."""
    t = 2 * np.pi * np.arange(k) / k
    return np.column_stack([np.cos(t) + 0.5 * np.cos(t) ** 2, np.sin(2 * t), 0.1 * np.sin(t)])


def test_figure_eight_refused_with_crossing_edges():
    X = figure_eight()
    msg = (r"boundary 'plane': the boundary loop projected onto its plane crosses itself.*"
           r"\(12, 13\) with \(35, 36\) \(1 in all\).*loop positions.*boundary=\"circle\"")
    with pytest.raises(MeshError, match=msg):
        B.plane(X)
    with pytest.raises(MeshError, match=msg):
        B.check_plane_boundary(X)
    with pytest.raises(MeshError, match=msg):
        B.boundary_uv(X, "plane")
    # Under jit or grad the values are tracers: nothing is checked, the map is computed.
    assert np.all(np.isfinite(np.asarray(jax.jit(B.plane)(jnp.asarray(X)))))
    traced = jax.jit(lambda x: (B.check_plane_boundary(x), B.plane(x))[1])(jnp.asarray(X))
    np.testing.assert_allclose(traced, B.plane(X, check=False), atol=1e-12)
    assert np.all(np.isfinite(np.asarray(B.plane(X, check=False))))


def test_figure_eight_mesh_boundary_names_vertices():
    mesh = jp.shapes.disk(4)                     # boundary: the 24 vertices of the outer ring
    loop, X = loop_of(mesh)
    V = np.asarray(mesh.vertices).copy()
    V[loop] = figure_eight(loop.size)
    bad = jp.TriMesh(V, mesh.faces, validate=False)
    L = bad.topology.boundary_loops[0]
    k = L.size
    pairs = B.crossing_edges(np.asarray(B.plane(V[L], check=False)))
    assert pairs.shape[0] >= 1
    i, j = pairs[0]
    named = rf"\({L[i]}, {L[(i + 1) % k]}\) with \({L[j]}, {L[(j + 1) % k]}\)"
    with pytest.raises(MeshError, match=rf"crosses itself.*{named}.*named by its two vertices"):
        B.check_plane_boundary(V[L], L)


def test_cut_open_boundary_refused():
    # camel_b's boundary runs along both sides of its cut: no vector area, no plane.
    mesh = jp.load(data_path("meshes", "camel_b.obj"))
    loop, X = loop_of(mesh)
    with pytest.raises(MeshError, match="encloses no area in any plane"):
        B.check_plane_boundary(X, loop)


# --- kinks of square and polygon (item 6) ------------------------------------------------------

def corner_loop():
    """8 vertices with unit edges around a 2 x 2 square: vertex 2's arc parameter is exactly 1/4
    (so is 4's 1/2 and 6's 3/4): with the default corners they sit on the square's corners."""
    P = np.array([[0, 0], [1, 0], [2, 0], [2, 1], [2, 2], [1, 2], [0, 2], [0, 1]], float)
    return np.column_stack([P, np.zeros(8)])


def one_sided(f, X, d, h=1e-7):
    g0 = np.asarray(f(jnp.asarray(X)))
    right = (np.asarray(f(jnp.asarray(X + h * d))) - g0) / h
    left = (g0 - np.asarray(f(jnp.asarray(X - h * d)))) / h
    _, jv = jax.jvp(f, (jnp.asarray(X),), (jnp.asarray(d),))
    return np.asarray(jv), right, left


def dt_along(X, d):
    return np.asarray(jax.jvp(B.arc_parameters, (jnp.asarray(X),), (jnp.asarray(d),))[1])


def test_square_kink_jax_returns_the_side_after_the_corner():
    X = corner_loop()
    np.testing.assert_array_equal(np.asarray(B.arc_parameters(X))[[2, 4, 6]], [0.25, 0.5, 0.75])
    d = np.zeros_like(X)
    d[2, 0] = 1.0                  # lengthens edge 1: the parameters of vertices 2, 4, 6 increase
    assert np.all(dt_along(X, d)[[2, 4, 6]] > 0)
    jv, right, left = one_sided(B.square, X, d)
    corner = [2, 4, 6]
    # a real kink at the corner vertices: the two one-sided derivatives differ
    assert np.all(np.abs(right[corner] - left[corner]).max(axis=1) > 0.1)
    # t increases: JAX returns the right (forward) difference, along the side after the corner
    np.testing.assert_allclose(jv, right, atol=1e-6)
    np.testing.assert_allclose(jv[2], [0.0, 0.375])      # up the square's side x = 1
    np.testing.assert_allclose(left[2], [0.375, 0.0], atol=1e-6)   # not along y = 0
    # the opposite direction decreases t: JAX returns the left (backward) difference
    jv, right, left = one_sided(B.square, X, -d)
    np.testing.assert_allclose(jv, left, atol=1e-6)
    assert np.abs(jv[corner] - right[corner]).max() > 0.1
    # elsewhere the map is smooth: both one-sided derivatives agree with JAX
    smooth = [1, 3, 5, 7]
    np.testing.assert_allclose(right[smooth], left[smooth], atol=1e-6)


def test_polygon_kink_jax_returns_the_side_after_the_corner():
    tri = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]])   # corner parameters 0, 3/12, 7/12
    X = corner_loop()                                      # vertex 2 at exactly 1/4
    d = np.random.default_rng(0).standard_normal(X.shape)
    dt = dt_along(X, d)[2]
    jv, right, left = one_sided(lambda x: B.polygon(x, tri), X, d)
    after, before = (right, left) if dt > 0 else (left, right)
    np.testing.assert_allclose(jv, after, atol=1e-5)
    assert np.abs(jv[2] - before[2]).max() > 10 * abs(dt)
    # the side after the corner is the one from (3, 0) to (0, 4)
    side = np.array([-3.0, 4.0]) / 5.0
    assert abs(jv[2, 0] * side[1] - jv[2, 1] * side[0]) < 1e-12
    others = [i for i in range(8) if i != 2]
    np.testing.assert_allclose(right[others], left[others], atol=1e-5)


def test_no_kink_with_pinned_corners():
    X = corner_loop()
    d = np.random.default_rng(1).standard_normal(X.shape)
    jv, right, left = one_sided(lambda x: B.square(x, corners=[0, 2, 4, 6]), X, d)
    np.testing.assert_allclose(right, left, atol=1e-5)
    np.testing.assert_allclose(jv, right, atol=1e-5)
    np.testing.assert_array_equal(jv[[0, 2, 4, 6]], 0.0)   # the corner vertices stay put
