import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import MeshError, TopologyError
from conftest import data_path


def similarity_residual(uv, xy):
    """Max distance between uv and xy after the best similarity (least squares, may reflect)."""
    A = np.column_stack([uv, np.ones(len(uv))])
    X, *_ = np.linalg.lstsq(A, xy, rcond=None)
    # A similarity has X[:2] = s * rotation: check it and return the fit residual.
    M = X[:2]
    assert np.allclose(M.T @ M, np.eye(2) * (M.T @ M)[0, 0], atol=1e-8)
    return np.abs(A @ X - xy).max()


def plane_coordinates(V):
    """Coordinates of the (planar) points ``V`` in their plane: an isometry, computed here with
    numpy's SVD, independently of the library's boundary maps."""
    X = np.asarray(V, np.float64) - np.mean(V, axis=0)
    _, sv, Vt = np.linalg.svd(X, full_matrices=False)
    assert sv[2] <= 1e-12 * sv[0], "the points are not planar"
    return X @ Vt[:2].T


@pytest.mark.parametrize("kind", ["shape_preserving", "mean_value", "harmonic"])
def test_linear_precision(kind):
    # Eq. (6): a planar mesh with boundary="plane" is reproduced up to a similarity.
    mesh = jp.shapes.plane_grid(9, 9, jitter=0.3, seed=3, tilt=True)
    uv = np.asarray(jp.convex_map(mesh, weights=kind, boundary="plane"))
    flat = plane_coordinates(mesh.vertices)                            # the plane's own coordinates
    assert similarity_residual(uv, flat) < 1e-9


def test_uniform_has_no_linear_precision():
    mesh = jp.shapes.plane_grid(9, 9, jitter=0.3, seed=3, tilt=True)
    uv = np.asarray(jp.convex_map(mesh, weights="uniform", boundary="plane"))
    flat = plane_coordinates(mesh.vertices)
    A = np.column_stack([uv, np.ones(len(uv))])
    X, *_ = np.linalg.lstsq(A, flat, rcond=None)
    assert np.abs(A @ X - flat).max() > 1e-3


def grid_corner_positions(mesh, n=12):
    """Loop positions of the ``n x n`` grid's four corner vertices, the loop's first vertex first.

    Pinning the square's corners there puts no dividing edge of the grid (the two corner
    triangles' diagonals) along a side of the square."""
    loop = mesh.topology.boundary_loops[0]
    pos = sorted(int(np.flatnonzero(loop == c)[0]) for c in (0, n - 1, n * n - n, n * n - 1))
    assert pos[0] == 0, "the grid's boundary loop no longer starts at a corner"
    return pos


@pytest.mark.parametrize("kind", jp.weights.KINDS)
@pytest.mark.parametrize("boundary", ["circle", "square"])
def test_convex_map_one_to_one(grid_mesh, kind, boundary):
    """Theorem 1 on the grid: its conditions hold (except the harmonic weights' sign) and the map
    has no flipped face and no boundary overlap.  On the square the corners sit on the grid's
    corners, so that no dividing edge lies along a side (the default corners put one there:
    see test_theorem1_catches_dividing_edge_on_square_side)."""
    corners = grid_corner_positions(grid_mesh) if boundary == "square" else None
    uv = jp.convex_map(grid_mesh, weights=kind, boundary=boundary, corners=corners)
    rep = jp.distortion(grid_mesh, uv, weights=kind)
    cert = rep.theorem1
    assert cert.convex_boundary and cert.dividing_edges_ok and not cert.dividing_edges_on_boundary
    if kind == "harmonic":
        # Cotangent weights are negative across obtuse angles: Theorem 1 does not apply, and the
        # certificate must say so rather than promise a one-to-one map.
        assert cert.positive_weights is False and cert.negative_weights > 0 and not cert.holds
    else:
        assert cert.positive_weights is True and cert.negative_weights == 0 and cert.holds
    assert rep.flips == 0 and rep.degenerate == 0 and rep.boundary_overlaps == 0
    assert np.all(np.asarray(jp.geometry.signed_areas(uv, grid_mesh.faces)) > 0)
    if kind == "harmonic":
        # Without Theorem 1's guarantee, pin the map itself: the discrete harmonic map is
        # libigl's harmonic function (cotangent Laplacian) with the same boundary values.
        igl = pytest.importorskip("igl")
        loop = grid_mesh.topology.boundary_loops[0]
        U = np.asarray(uv)
        ref = igl.harmonic(np.asarray(grid_mesh.vertices, np.float64), np.asarray(grid_mesh.faces, np.int64),
                           loop.astype(np.int64), np.ascontiguousarray(U[loop]), 1)
        np.testing.assert_allclose(U, ref, atol=1e-10)


def test_harmonic_one_to_one_when_cotangent_weights_positive():
    """With no obtuse angle pair (all cotangent weights positive) the harmonic map is a convex
    combination map and Theorem 1 applies: the certificate holds and nothing flips."""
    mesh = jp.shapes.disk(5)                   # flat, near-equilateral rings: all cot weights > 0
    for boundary in ["circle", "square"]:
        uv = jp.convex_map(mesh, weights="harmonic", boundary=boundary)
        rep = jp.distortion(mesh, uv, weights="harmonic")
        assert rep.theorem1.positive_weights is True and rep.theorem1.holds, boundary
        assert rep.flips == 0 and rep.boundary_overlaps == 0, boundary


def test_theorem1_catches_dividing_edge_on_square_side(grid_mesh):
    """With the square's corners at quarter arc length, one corner misses the grid corner 11: its
    triangle's diagonal (10, 23) lies along a side, the certificate names exactly that edge, and
    exactly the triangle it cuts off (10, 11, 23) collapses onto the side; no other face flips."""
    assert grid_mesh.topology.dividing_edges.tolist() == [[10, 23], [120, 133]]
    for kind in jp.weights.KINDS:
        uv = jp.convex_map(grid_mesh, weights=kind, boundary="square")
        rep = jp.distortion(grid_mesh, uv, weights=kind)
        assert rep.theorem1.convex_boundary and not rep.theorem1.dividing_edges_ok, kind
        assert not rep.theorem1.holds and rep.theorem1.dividing_edges_on_boundary == [(10, 23)], kind
        areas = np.asarray(jp.geometry.signed_areas(uv, grid_mesh.faces))
        ear = np.flatnonzero(np.all(np.isin(grid_mesh.faces, [10, 11, 23]), axis=1))
        assert ear.size == 1, kind
        assert abs(areas[ear[0]]) <= 1e-12, kind               # collapsed onto the square's side
        assert np.all(np.delete(areas, ear) > 0), kind          # and nothing else flips
        assert rep.boundary_overlaps == 0, kind


def test_interior_vertices_are_convex_combinations(grid_mesh):
    uv = np.asarray(jp.convex_map(grid_mesh, weights="mean_value"))
    lam = np.asarray(jp.weights.convex_weights(grid_mesh, "mean_value"))
    R = jp.weights.ring_entries(grid_mesh.topology)
    recon = np.zeros((R.n_rows, 2))
    np.add.at(recon, R.row, lam[:, None] * uv[R.nbr])
    np.testing.assert_allclose(recon, uv[grid_mesh.topology.interior], atol=1e-12)


def test_orientation_kept(disk_mesh):
    uv = jp.convex_map(disk_mesh)
    assert np.all(np.asarray(jp.geometry.signed_areas(uv, disk_mesh.faces)) > 0)


def test_least_squares_map_matches_weights(grid_mesh):
    E = grid_mesh.topology.edges
    V = np.asarray(grid_mesh.vertices)
    mu = 1.0 / np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    uv1 = np.asarray(jp.least_squares_map(grid_mesh, mu=mu))
    uv2 = np.asarray(jp.convex_map(grid_mesh, weights="inverse_distance"))
    np.testing.assert_allclose(uv1, uv2, atol=1e-12)
    with pytest.raises(MeshError, match=r"mu must be positive.*edges"):
        jp.least_squares_map(grid_mesh, mu=-mu)


def test_gradient_through_convex_map_finite_differences(disk_mesh):
    V0 = np.asarray(disk_mesh.vertices)
    F = disk_mesh.faces
    rng = np.random.default_rng(0)
    c = rng.standard_normal((disk_mesh.n_vertices, 2))

    def loss(V, kind):
        uv = jp.convex_map(jp.TriMesh(V, F), weights=kind)
        return jnp.sum(c * uv)

    d = rng.standard_normal(V0.shape)
    h = 1e-6
    for kind in ["shape_preserving", "harmonic", "mean_value"]:
        g = np.asarray(jax.grad(loss)(jnp.asarray(V0), kind))
        fd = (loss(jnp.asarray(V0 + h * d), kind) - loss(jnp.asarray(V0 - h * d), kind)) / (2 * h)
        assert abs(np.sum(g * d) - fd) <= 1e-6 * max(1.0, abs(fd)), kind


def test_gradient_wrt_boundary_uvs(grid_mesh):
    loop = grid_mesh.topology.boundary_loops[0]
    b0 = np.asarray(jp.boundary.circle(jnp.asarray(grid_mesh.vertices)[loop]))
    c = np.random.default_rng(1).standard_normal((grid_mesh.n_vertices, 2))

    def loss(b):
        return jnp.sum(c * jp.convex_map(grid_mesh, weights="mean_value", boundary=b))

    g = np.asarray(jax.grad(loss)(jnp.asarray(b0)))
    d = np.random.default_rng(2).standard_normal(b0.shape)
    h = 1e-6
    fd = (loss(jnp.asarray(b0 + h * d)) - loss(jnp.asarray(b0 - h * d))) / (2 * h)
    assert abs(np.sum(g * d) - fd) <= 1e-6 * max(1.0, abs(fd))


def test_closed_mesh_error():
    with pytest.raises(TopologyError, match="closed.*manifold_map"):
        jp.convex_map(jp.shapes.sphere(1))


def test_components_error():
    a = jp.shapes.plane_grid(4, 4)
    V = np.vstack([np.asarray(a.vertices), np.asarray(a.vertices) + 5])
    F = np.vstack([a.faces, a.faces + 16])
    with pytest.raises(TopologyError, match=r"2 connected components"):
        jp.convex_map(jp.TriMesh(V, F))


def test_holes_filled_virtually():
    mesh = jp.shapes.plane_grid(9, 9, jitter=0.2, seed=1)
    F = mesh.faces[~np.any(mesh.faces == 40, axis=1)]
    holed = jp.TriMesh(mesh.vertices, F)
    uv = jp.convex_map(holed, weights="mean_value")
    assert jp.distortion(holed, uv).flips == 0
    assert np.all(np.isfinite(np.asarray(uv)[holed.topology.referenced]))


def test_unreferenced_vertices_are_nan(grid_mesh):
    V = np.vstack([np.asarray(grid_mesh.vertices), [[9.0, 9, 9]]])
    mesh = jp.TriMesh(V, grid_mesh.faces)
    uv = np.asarray(jp.convex_map(mesh))
    assert np.isnan(uv[-1]).all() and np.isfinite(uv[:-1]).all()
    assert jp.distortion(mesh, uv).unreferenced_vertices == 1


@pytest.mark.data
@pytest.mark.parametrize("name", ["camel_b.obj", "bump-domain.obj", "lilium.obj", "snail.obj",
                                  "grid.off", "planexy.off", "camelhead.off", "halftunnel.off"])
def test_no_flips_on_shared_disk_meshes(name):
    mesh = jp.load(data_path("meshes", name))
    for kind in ["shape_preserving", "mean_value", "uniform"]:
        uv = jp.convex_map(mesh, weights=kind)
        assert jp.distortion(mesh, uv).flips == 0, (name, kind)


def test_harmonic_weights_on_a_needle_name_the_face():
    # Found in QA (session 20): a needle triangle (angle 1e-12) left the harmonic system singular
    # and the error said only "singular or badly conditioned".
    from jaxparam.errors import SolverError
    i, j = np.meshgrid(np.arange(11), np.arange(11), indexing="ij")
    V = np.stack([i.ravel() / 10, j.ravel() / 10, np.zeros(121)], 1)
    v = (np.arange(10)[:, None] * 11 + np.arange(10)).ravel()
    F = np.concatenate([np.stack([v, v + 11, v + 12], 1), np.stack([v, v + 12, v + 1], 1)])
    V[60] = 0.5 * (V[49] + V[61]) + [1e-13, -1e-13, 0]      # face (49, 60, 61) a needle
    mesh = jp.TriMesh(V, F)
    with pytest.raises(SolverError, match=r"face \d+ \(vertices 49, 60, 61\) has an angle of .* rad.*"
                                          r"'mean_value' or 'shape_preserving'"):
        jp.convex_map(mesh, weights="harmonic")
    assert np.all(np.isfinite(np.asarray(jp.convex_map(mesh, weights="mean_value"))))


def test_scaled_symmetric_dirichlet_is_the_same_at_every_scale():
    # the held-out sweep (session 26): the report's sym_dirichlet of a convex map was 8.92 for
    # snail and 8.1e12 for snail x 1e6 (the circle's UVs against a larger surface);
    # sym_dirichlet_scaled matches the UV area to the surface's first
    m = jp.shapes.disk(6, seed=0, height=0.3)
    V = np.asarray(m.vertices)
    uv = np.asarray(jp.convex_map(m))
    base = jp.distortion(m, uv)
    for s in (1e-6, 1e6):
        r = jp.distortion(jp.TriMesh(V * s, m.faces), uv)
        assert r.sym_dirichlet_scaled == pytest.approx(base.sym_dirichlet_scaled, rel=1e-9)
        assert r.sym_dirichlet != pytest.approx(base.sym_dirichlet, rel=0.5)
    # and it is the plain value of the UVs scaled to the surface's area
    q = jp.metrics.face_distortion(m, uv)
    a3, auv = np.asarray(q["area3d"]), np.asarray(q["area_uv"])
    scaled = jp.distortion(m, uv * np.sqrt(a3.sum() / auv.sum()))
    assert scaled.sym_dirichlet == pytest.approx(base.sym_dirichlet_scaled, rel=1e-12)
    assert base.sym_dirichlet_scaled >= 4.0
