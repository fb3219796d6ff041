"""jaxparam.distance: exact point-to-mesh distances against brute force and trimesh."""
import numpy as np
import pytest
import trimesh

import jaxparam as jp

from jaxparam.distance import (
    bounding_diagonal, closest_points_on_triangles, compiled_nearest_faces, face_grid_points,
    point_triangle_distance,
    sample_surface,
    surface_distance,
)


def _brute(P, V, F):
    rows = np.repeat(np.arange(len(P)), len(F))
    cand = np.tile(np.arange(len(F)), len(P))
    q = closest_points_on_triangles(P[rows], V[F[cand, 0]], V[F[cand, 1]], V[F[cand, 2]])
    return np.linalg.norm(q - P[rows], axis=1).reshape(len(P), len(F)).min(axis=1)


def test_exact_against_brute_force_for_any_k():
    rng = np.random.default_rng(0)
    V = rng.normal(size=(30, 3))
    F = rng.integers(0, 30, (40, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    P = rng.normal(size=(400, 3)) * 1.5
    oracle = _brute(P, V, F)
    for k, compiled in ((1, False), (3, False), (8, False), (len(F), False), (8, True)):
        d, face, q = point_triangle_distance(P, V, F, k=k, compiled=compiled)
        np.testing.assert_allclose(d, oracle, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(q - P, axis=1), d, atol=1e-12)


def test_slivers_are_exact_and_searched_through_their_boxes():
    # a mesh of revolution of slivers (aspect ~300) and a soup stretched 1000 : 1 : 0.01: the
    # ball around a sliver's centroid holds its whole neighbourhood (session 19: 139 s for
    # 20,000 samples of a 20,000-sliver lathe, and out of memory at aspect 1,600); the AABB
    # tree keeps the search local, and the answer exact
    from jaxparam.aabb_tree import AABBTree

    rng = np.random.default_rng(19)
    lathe = jp.shapes.revolution(600, 3)
    V, F = np.asarray(lathe.vertices), np.asarray(lathe.faces)
    soup = rng.random((120, 3)) * [1000, 1, 0.01]
    G = rng.integers(0, 120, (200, 3))
    G = G[(G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 0] != G[:, 2])]
    for V, F in ((V, F), (soup, G)):
        lo, hi = V.min(0), V.max(0)
        P = lo - 0.1 * (hi - lo) + 1.2 * (hi - lo) * rng.random((500, 3))
        oracle = _brute(P, V, F)
        for compiled in (False, True):
            d, face, q = point_triangle_distance(P, V, F, compiled=compiled)
            np.testing.assert_allclose(d, oracle, atol=1e-12 * np.ptp(V))
            np.testing.assert_allclose(np.linalg.norm(q - P, axis=1), d, atol=1e-12 * np.ptp(V))
        # the tree's search: every face nearer than the bound is among the pairs it returns
        tree = AABBTree(V, F, leaf=4)
        bound = 1.5 * oracle
        rows, cand = tree.within(P, bound, chunk=97)
        near = (np.repeat(np.arange(len(P)), len(F)), np.tile(np.arange(len(F)), len(P)))
        T = V[F]
        dist = np.linalg.norm(closest_points_on_triangles(P[near[0]], *(T[near[1], c] for c in range(3)))
                              - P[near[0]], axis=1)
        want = set(zip(near[0][dist <= bound[near[0]]].tolist(), near[1][dist <= bound[near[0]]].tolist()))
        assert want <= set(zip(rows.tolist(), cand.tolist()))
        assert rows.size < 0.5 * len(P) * len(F)          # and it is a search, not all pairs


def test_compiled_nearest_faces_give_numpys_distances_on_degenerate_faces():
    # the optional point-cloud-utils search (the fast extra) on a soup with repeated corners,
    # a collinear face and a one-point face (its barycentric coordinates there are NaN: only
    # its face is taken), a single point and no point at all
    pytest.importorskip("point_cloud_utils", reason="the fast extra is not installed")
    rng = np.random.default_rng(26)
    V = rng.normal(size=(30, 3))
    F = rng.integers(0, 30, (60, 3))
    F[:5, 1] = F[:5, 0]
    V[29] = 0.5 * (V[27] + V[28])
    F[5], F[6] = [27, 28, 29], [3, 3, 3]
    P = rng.normal(size=(3000, 3)) * 2
    d0, _, _ = point_triangle_distance(P, V, F, compiled=False)
    d1, face, q = point_triangle_distance(P, V, F)
    assert np.isfinite(q).all()
    np.testing.assert_allclose(d1, d0, rtol=0, atol=1e-15 * bounding_diagonal(V))
    np.testing.assert_allclose(np.linalg.norm(q - P, axis=1), d1, atol=1e-14)
    np.testing.assert_allclose(_brute(P[:200], V, F), d1[:200], atol=1e-14)
    assert compiled_nearest_faces(P[:1], V, F).shape == (1,)
    assert point_triangle_distance(P[:0], V, F)[0].shape == (0,)


def test_the_kept_tree_answers_for_its_own_mesh_only(monkeypatch):
    # libigl's tree is kept between queries of one mesh (the closed meshes' finish stage asks
    # ~40 times); a mesh with the same shape but other positions or faces gets its own tree,
    # and every answer is numpy's search's
    igl = pytest.importorskip("igl", reason="the fast extra is not installed")
    import jaxparam.distance as dist
    built = []

    class Counted(igl.AABB):
        def init(self, V, F):
            built.append(len(V))
            return super().init(V, F)

    monkeypatch.setattr(igl, "AABB", Counted)
    monkeypatch.setattr(dist, "_TREES", {})
    mesh = jp.shapes.sphere(2)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    P = np.random.default_rng(3).normal(size=(500, 3))
    meshes = [(V, F), (V.copy(), F), (V + 0.1, F), (V, F[:, [0, 2, 1]]), (V, F)]
    counts = []
    for V_, F_ in meshes:
        d, _, _ = point_triangle_distance(P, V_, F_)
        counts.append(len(built))
        d0, _, _ = point_triangle_distance(P, V_, F_, compiled=False)
        np.testing.assert_allclose(d, d0, rtol=0, atol=1e-15 * bounding_diagonal(V_))
    # the copy reuses the first tree; the last mesh was pushed out by the two before it
    assert counts == [1, 1, 2, 3, 4]
    assert len(dist._TREES) == dist._TREES_KEPT


def test_closest_point_is_never_beaten_by_samples_of_the_triangle():
    rng = np.random.default_rng(1)
    A, B, C = (rng.normal(size=(200, 3)) for _ in range(3))
    C[:20] = A[:20]                                    # degenerate triangles (an edge)
    C[20:30] = B[20:30] = A[20:30]                     # a point
    P = rng.normal(size=(200, 3)) * 2
    q = closest_points_on_triangles(P, A, B, C)
    d = np.linalg.norm(q - P, axis=1)
    w = rng.dirichlet([1, 1, 1], size=500)
    S = w[None, :, 0, None] * A[:, None] + w[None, :, 1, None] * B[:, None] + w[None, :, 2, None] * C[:, None]
    assert (np.linalg.norm(S - P[:, None], axis=2).min(axis=1) >= d - 1e-12).all()


def test_agrees_with_trimesh_proximity():
    m = trimesh.creation.icosphere(2)
    rng = np.random.default_rng(2)
    P = rng.normal(size=(300, 3))
    d, face, q = point_triangle_distance(P, m.vertices, m.faces)
    q_t, d_t, _ = trimesh.proximity.closest_point_naive(m, P)
    np.testing.assert_allclose(d, d_t, atol=1e-10)


def test_surface_distance_of_a_scaled_sphere():
    m = trimesh.creation.icosphere(3)
    sd = surface_distance(m.vertices, m.faces, 1.01 * m.vertices, m.faces, samples=5000)
    diag = bounding_diagonal(m.vertices)
    # the vertices of the scaled sphere are 0.01 out; chord midpoints of the unit sphere lie
    # inside it, so a sample is between 0.01 minus the sagitta and 0.01 from the other surface
    assert sd.diagonal == pytest.approx(diag)
    assert 0.009 / diag < sd.rms_ab < 0.0105 / diag
    assert sd.hausdorff == pytest.approx(0.0101 / diag, rel=0.02)
    assert surface_distance(m.vertices, m.faces, m.vertices, m.faces, samples=2000).hausdorff < 1e-12


def test_sample_surface_is_area_weighted_and_reproducible():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [3, 0, 0], [3, 3, 0]], float)
    F = np.array([[0, 1, 2], [1, 3, 4]])              # areas 0.5 and 3
    P, face = sample_surface(V, F, 20000, seed=5)
    assert np.mean(face == 1) == pytest.approx(3 / 3.5, abs=0.01)
    P2, _ = sample_surface(V, F, 20000, seed=5)
    np.testing.assert_array_equal(P, P2)
    d, _, _ = point_triangle_distance(P, V, F)
    assert d.max() < 1e-12


def test_face_grid_finds_the_farthest_point_that_samples_miss():
    # A flat square against a tent over it: the square's point farthest from the tent is its
    # centre (the midpoint of its diagonal), h / sqrt(1 + h^2) from the tent's faces.  Twenty
    # random samples miss it; a grid of step 1/8 on every face holds it.
    h = 0.5
    square = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    F_sq = np.array([[0, 1, 2], [0, 2, 3]])
    tent = np.vstack([square, [[0, 0, h]]])
    F_tent = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    diag = np.linalg.norm(np.ptp(tent, 0))
    exact = h / np.sqrt(1 + h * h) / diag
    sampled = surface_distance(tent, F_tent, square, F_sq, samples=20, seed=0)
    grid = surface_distance(tent, F_tent, square, F_sq, samples=20, seed=0, face_grid=8)
    assert sampled.hausdorff_ba < 0.95 * exact
    assert grid.hausdorff_ba == pytest.approx(exact, rel=1e-12)
    assert face_grid_points(square, F_sq, 8).shape == (2 * (45 - 3), 3)


def test_unused_vertices_are_not_surface_samples():
    """Found by session 22's held-out sweep: a disk written with unused vertices far off it (a
    sphere's cap cut away) had every remesh level's error measured from those vertices."""
    m = jp.shapes.graph_surface(6)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    far = np.vstack([V, [[0.0, 0.0, 5.0], [3.0, 3.0, 3.0]]])      # two vertices no face uses
    W = V + [0.0, 0.0, 0.01]
    clean = surface_distance(V, F, W, F, samples=2000)
    with_unused = surface_distance(far, F, np.vstack([W, far[-2:]]), F, samples=2000)
    assert with_unused.hausdorff == pytest.approx(clean.hausdorff, rel=1e-12)
    assert with_unused.rms_ab == pytest.approx(clean.rms_ab, rel=1e-12)
