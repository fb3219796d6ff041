"""Remeshing with subdivision connectivity (jaxparam.remesh, survey §7)."""
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.cli import main
from jaxparam.errors import MeshError, TopologyError
from jaxparam.remesh import Remesh, area_aware_map, base_domain, refine_domain
from jaxparam.subdivision import (CHILDREN, dyadic_hierarchy, dyadic_refine, hierarchy_from_faces,
                                  midpoint_refine, split_corner_values)
from jaxparam.triangles import locate


def area2(U, F):
    a, b, c = U[F[:, 0]], U[F[:, 1]], U[F[:, 2]]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


@pytest.fixture(scope="module")
def surface():
    mesh = jp.shapes.graph_surface(12)
    return mesh, np.asarray(jp.convex_map(mesh, weights="mean_value", boundary="circle"))


@pytest.fixture(scope="module")
def semi(surface):
    mesh, uv = surface
    return jp.remesh(mesh, uv, levels=3)


def test_dyadic_refinement_splits_each_triangle_into_four_at_the_midpoints():
    U = np.array([[0.0, 0], [1, 0], [0, 1], [1, 1]])
    F = np.array([[0, 1, 2], [1, 3, 2]])
    F1, parents, on_bnd = dyadic_refine(F, 4)
    assert F1.shape == (8, 3) and parents.shape == (5, 2)          # 5 edges, 5 new vertices
    assert on_bnd.sum() == 4                                       # the diagonal is interior
    U1 = np.concatenate([U, U[parents].mean(1)])
    A = area2(U1, F1)
    assert np.all(A > 0)
    np.testing.assert_allclose(A.reshape(2, 4), np.repeat(area2(U, F)[:, None] / 4, 4, 1))
    t = jp.TriMesh(U1, F1).topology
    assert t.is_disk and t.n_vertices == 9


def test_locate_agrees_with_a_brute_force_search_and_rejects_outside_points(disk_mesh):
    U = np.asarray(jp.convex_map(disk_mesh, weights="uniform"))
    F = disk_mesh.faces
    rng = np.random.default_rng(0)
    r, t = np.sqrt(rng.random(300)) * 0.95, 2 * np.pi * rng.random(300)
    Q = np.column_stack([r * np.cos(t), r * np.sin(t)])
    face, bary = locate(U, F, Q)
    np.testing.assert_allclose(np.einsum("kc,kcd->kd", bary, U[F[face]]), Q, atol=1e-12)
    assert np.all(bary >= 0)
    with pytest.raises(MeshError, match="outside the parameter domain"):
        locate(U, F, np.array([[0.0, 0.0], [1.5, 0.0]]))


def test_remesh_has_subdivision_connectivity_and_lies_on_the_surface(surface, semi):
    mesh, uv = surface
    H, out = semi.hierarchy, semi.mesh
    assert isinstance(semi, Remesh) and semi.uv is out.uv and semi.levels == 3
    assert H.levels == 3 and out.n_faces == 6 * 4 ** 3 and H.counts[-1] == out.n_vertices
    assert out.topology.is_disk
    np.testing.assert_array_equal(semi.base_faces, H.faces[0])
    assert np.all(area2(np.asarray(semi.uv), out.faces) > 0)       # T^j is a triangulation
    # eq. (11): every vertex is psi^{-1} of its parameter point, i.e. on the input's faces.
    face, bary = locate(uv, mesh.faces, np.asarray(semi.uv))
    X = np.einsum("kc,kcd->kd", bary, np.asarray(mesh.vertices)[mesh.faces[face]])
    np.testing.assert_allclose(np.asarray(out.vertices), X, atol=1e-12)
    # Boundary vertices lie on the parameter domain's boundary polygon (so on the surface's
    # boundary): distance to the polygon's segments.
    loop = mesh.topology.boundary_loops[0]
    A, B = uv[loop], uv[np.roll(loop, -1)]
    Q = np.asarray(semi.uv)[out.topology.boundary]
    t = np.clip(np.einsum("qsd,sd->qs", Q[:, None] - A[None], B - A) / np.sum((B - A) ** 2, 1), 0, 1)
    d = np.linalg.norm(Q[:, None] - (A[None] + t[..., None] * (B - A)[None]), axis=2).min(1)
    assert d.max() < 1e-12
    # Nested vertex sets: the first n_l vertices are T^l's, with its faces.
    for level in range(H.levels + 1):
        assert H.faces[level].max() == H.counts[level] - 1


def test_the_hierarchy_is_recovered_from_the_faces_alone(semi, tmp_path):
    p = tmp_path / "semi.obj"
    jp.save(p, semi.mesh)                                      # the parameter points as vt
    back = jp.load(p)
    H = hierarchy_from_faces(back.faces, back.n_vertices)
    assert H.counts == semi.hierarchy.counts
    for a, b in zip(H.parents, semi.hierarchy.parents):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(MeshError, match="subdivision connectivity"):
        hierarchy_from_faces(jp.shapes.graph_surface(5).faces, 25)


def test_a_square_map_with_its_corners_is_covered_exactly():
    mesh = jp.shapes.example5(9)
    loop = list(mesh.topology.boundary_loops[0])
    at_corner = sorted([0, 8, 72, 80], key=loop.index)          # the grid's corners, in loop order
    assert loop[0] == at_corner[0]
    corners = [loop.index(v) for v in at_corner]               # positions in the loop
    uv = np.asarray(jp.convex_map(mesh, boundary="square", corners=corners))
    lo, hi = uv.min(0), uv.max(0)
    assert all(np.all(np.isclose(uv[v], lo) | np.isclose(uv[v], hi)) for v in at_corner)
    semi = jp.remesh(mesh, uv, levels=2, corners=corners)
    assert semi.mesh.n_faces == 4 * 16
    total = 0.5 * area2(np.asarray(semi.uv), semi.mesh.faces).sum()
    np.testing.assert_allclose(total, np.prod(hi - lo), rtol=1e-12)


def test_remesh_is_differentiable_in_the_vertex_positions(surface):
    mesh, uv = surface
    faces = mesh.faces

    def loss(V):
        s = jp.remesh(jp.TriMesh(V, faces, validate=False), uv, levels=2)
        return jnp.sum(s.mesh.vertices[:, 2] ** 2) + jnp.sum(jp.wavelets.analyze(s).details[-1] ** 2)

    V0 = jnp.asarray(mesh.vertices)
    g = jax.grad(loss)(V0)
    D = np.random.default_rng(1).normal(size=V0.shape)
    h = 1e-6
    fd = (loss(V0 + h * D) - loss(V0 - h * D)) / (2 * h)
    np.testing.assert_allclose(float(jnp.sum(g * D)), float(fd), rtol=1e-6)


def test_bad_remesh_input_is_named(surface):
    mesh, uv = surface
    with pytest.raises(MeshError, match="levels must be an integer"):
        jp.remesh(mesh, uv, levels=-1)
    with pytest.raises(MeshError, match=r"uv must be a finite \(144, 2\)"):
        jp.remesh(mesh, uv[:10], levels=1)
    with pytest.raises(MeshError, match=r"levels are the third argument: jp.remesh\(mesh, levels=3\)"):
        jp.remesh(mesh, 3)                                     # levels where uv goes
    bad = uv.copy()
    bad[:, 0] *= -1                                            # mirrored: every face flipped
    with pytest.raises(MeshError, match="not one-to-one: faces 0, 1"):
        jp.remesh(mesh, bad, levels=1)
    with pytest.raises(MeshError, match="at least 3 corners"):
        jp.remesh(mesh, uv, levels=1, corners=2)
    with pytest.raises(MeshError, match="at least 3 corners"):
        jp.remesh(mesh, uv, levels=1, base_faces=2)
    with pytest.raises(MeshError, match="base_faces or corners, not both"):
        jp.remesh(mesh, uv, levels=1, base_faces=5, corners=6)
    with pytest.raises(MeshError, match="base_faces must be an integer.*corners="):
        jp.remesh(mesh, uv, levels=1, base_faces=[0, 11, 22])
    with pytest.raises(MeshError, match=r"increasing positions in the boundary loop of 44 vertices.*\[0, 11, 50\]"):
        jp.remesh(mesh, uv, levels=1, corners=[0, 11, 50])
    with pytest.raises(TopologyError, match="closed"):
        sphere = jp.shapes.sphere(1)
        jp.remesh(sphere, np.zeros((sphere.n_vertices, 2)), levels=1)


def test_refined_boundary_vertices_go_halfway_along_the_boundary():
    # The unit circle's 64-gon, a 4-corner base: level-1 boundary vertices sit at the arc
    # midpoints, i.e. at 45, 135, 225 and 315 degrees, not at the chords' midpoints.
    t = 2 * np.pi * np.arange(64) / 64
    U = np.column_stack([np.cos(t), np.sin(t)])
    uv0, F0, s0, curve = base_domain(U, np.arange(64), 4)
    uv1, H = refine_domain(uv0, F0, s0, curve, 1)
    new_on_circle = np.abs(np.linalg.norm(uv1[H.counts[0]:], axis=1) - 1) < 1e-12
    ang = np.sort(np.degrees(np.arctan2(uv1[H.counts[0]:][new_on_circle, 1],
                                        uv1[H.counts[0]:][new_on_circle, 0])) % 360)
    np.testing.assert_allclose(ang, [45, 135, 225, 315], atol=1e-9)


def test_cli_remesh_then_compress(tmp_path):
    src, semi, small = tmp_path / "g.obj", tmp_path / "semi.obj", tmp_path / "small.obj"
    rep, rep2, png = tmp_path / "r.json", tmp_path / "c.json", tmp_path / "p.png"
    jp.save(src, jp.shapes.graph_surface(10))
    assert main(["remesh", str(src), "-o", str(semi), "--levels", "3", "--base-faces", "5",
                 "--report", str(rep), "--plot", str(png)]) == 0
    r = json.loads(rep.read_text())
    assert r["faces"] == 5 * 64 and r["flips"] == 0 and r["levels"] == 3 and png.stat().st_size > 1000
    assert main(["compress", str(semi), "-o", str(small), "--keep", "0.1", "--report", str(rep2)]) == 0
    c = json.loads(rep2.read_text())
    a, b = jp.load(semi), jp.load(small)
    np.testing.assert_array_equal(a.faces, b.faces)
    assert c["coefficients_kept"] == round(0.1 * (a.n_vertices - 6)) and 0 < c["max_error"] < 0.1
    assert main(["compress", str(src), "-o", str(small), "--keep", "0.1"]) == 3   # not semi-regular


def test_holes_and_non_convex_domains_are_refused_with_a_remedy():
    grid = jp.shapes.plane_grid(9, 9)
    F = grid.faces[~np.any(grid.faces == 40, axis=1)]            # a hole around the centre
    keep = np.unique(F)
    holed = jp.TriMesh(np.asarray(grid.vertices)[keep], np.searchsorted(keep, F))
    with pytest.raises(MeshError, match="2 boundary loops; remeshing needs a disk"):
        jp.remesh(holed, np.asarray(holed.vertices)[:, :2], levels=1)
    # A domain with a deep notch in its top side: the base fan reaches outside it.
    x, y = np.asarray(grid.vertices)[:, 0], np.asarray(grid.vertices)[:, 1]
    uv = np.column_stack([x, y * (1 - 0.8 * np.exp(-((x - 0.5) / 0.12) ** 2))])
    with pytest.raises(MeshError, match="convex boundary map"):
        jp.remesh(grid, uv, levels=2, corners=8)


def test_base_faces_names_the_fan_and_corners_stays_its_alias(surface, semi):
    mesh, uv = surface
    for kw in ({"base_faces": 5}, {"corners": 5}):
        s = jp.remesh(mesh, uv, levels=1, **kw)
        assert s.base_faces.shape == (5, 3) and s.mesh.n_faces == 5 * 4
    same = jp.remesh(mesh, uv, levels=3, base_faces=6)             # the default is 6
    np.testing.assert_array_equal(np.asarray(same.mesh.vertices), np.asarray(semi.mesh.vertices))


def test_a_remesh_survives_pytree_round_trips(semi):
    back = jax.tree_util.tree_map(lambda x: x, semi)
    assert isinstance(back, Remesh) and back.hierarchy is semi.hierarchy
    np.testing.assert_array_equal(np.asarray(back.mesh.vertices), np.asarray(semi.mesh.vertices))
    np.testing.assert_array_equal(np.asarray(back.uv), np.asarray(semi.uv))
    np.testing.assert_array_equal(back.mesh.faces, semi.mesh.faces)
    jitted = jax.jit(lambda r: r.with_vertices(2.0 * r.mesh.vertices))(semi)
    assert isinstance(jitted, Remesh) and jitted.hierarchy is semi.hierarchy
    np.testing.assert_allclose(np.asarray(jitted.mesh.vertices), 2 * np.asarray(semi.mesh.vertices))
    moved = semi.mesh.with_vertices(semi.mesh.vertices + 1.0)      # the mesh keeps its UVs
    assert moved.uv is semi.uv and moved.topology is semi.mesh.topology
    # What wavelets need travels with it: analysing the round trip gives the same coefficients.
    a, b = jp.wavelets.analyze(semi), jp.wavelets.analyze(back)
    np.testing.assert_array_equal(np.asarray(a.base), np.asarray(b.base))


def test_subdivision_numbering_contract():
    # Two triangles: children 4f .. 4f+3 in CHILDREN's order, new vertices in edge order.
    F = np.array([[0, 1, 2], [1, 3, 2]])
    F1, parents, on_bnd = dyadic_refine(F, 4)
    w = np.concatenate([F, F1.reshape(2, 4, 3)[:, 3]], axis=1)     # (v1, v2, v3, w1, w2, w3)
    np.testing.assert_array_equal(F1.reshape(2, 4, 3), w[:, CHILDREN])
    keys = np.sort(parents, axis=1)
    assert np.all(np.diff(keys[:, 0] * 4 + keys[:, 1]) > 0)        # sorted (min, max) pairs
    H = dyadic_hierarchy(F, 4, 2)
    assert H.counts == (4, 9, 25) and H.levels == 2
    np.testing.assert_array_equal(H.faces[1], F1)
    np.testing.assert_array_equal(H.on_boundary[0], on_bnd)
    assert hierarchy_from_faces(H.faces[-1], 25).counts == H.counts
    U = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    V1, G1 = midpoint_refine(U, F)
    np.testing.assert_array_equal(G1, F1)
    np.testing.assert_array_equal(V1[4:], U[parents].mean(1))
    # Corner values carried to the children agree with the vertices' midpoints.
    C = split_corner_values(U[F])
    np.testing.assert_array_equal(C, V1[F1])


def test_unreferenced_vertices_do_not_block_a_remesh():
    # Found in QA on a scan with stray vertices: convex_map gives them nan, and remesh refused
    # the whole mesh ("uv must be a finite (n, 2) array, got shape (n, 2)").
    mesh = jp.shapes.graph_surface(8)
    V = np.vstack([mesh.vertices, [[5.0, 5.0, 5.0], [6.0, 5.0, 5.0]]])
    stray = jp.TriMesh(V, mesh.faces)
    plain = jp.remesh(mesh, levels=2)
    semi = jp.remesh(stray, levels=2)
    assert np.all(np.isfinite(np.asarray(semi.mesh.vertices)))
    np.testing.assert_allclose(np.asarray(semi.mesh.vertices), np.asarray(plain.mesh.vertices),
                               atol=1e-10)
    uv = np.asarray(jp.convex_map(mesh))
    bad = np.vstack([uv, [[np.nan, 0.0], [0.0, 0.0]]])
    bad[3] = np.nan                                   # a vertex of a face: named in the error
    with pytest.raises(MeshError, match="not finite at vertices 3"):
        jp.remesh(stray, bad, levels=1)


def test_flat_faces_of_a_square_boundary_map_get_the_right_remedy():
    # Found in QA (snail refined, jaxparam remesh --boundary square): the error said "use a
    # convex-combination map", which the map was; the cause is faces with all three corners on
    # one side of the square.
    mesh = jp.shapes.cylinder_patch(12, 4)
    uv = jp.convex_map(mesh, boundary="square")
    with pytest.raises(MeshError, match=r"faces \d+, \d+ \(2 in all\) are flipped or degenerate.*"
                       r"one straight side.*use the circle boundary"):
        jp.remesh(mesh, uv, levels=1)


def test_a_mesh_with_no_interior_vertex_is_remeshed_from_its_boundary_map():
    # Found in QA: jaxparam remesh of one triangle (or of an 8 x 2 strip) exited 4 with
    # "minimize: no free vertex ... use free_boundary=True", an option remesh does not have.
    for mesh in (jp.TriMesh(np.eye(3), [[0, 1, 2]]), jp.shapes.plane_grid(8, 2)):
        semi = jp.remesh(mesh, levels=2)
        assert np.all(np.isfinite(np.asarray(semi.mesh.vertices)))
        assert (area2(np.asarray(semi.mesh.uv), semi.mesh.faces) > 0).all()


# Found in QA (session 21): jaxparam remesh --weights harmonic on a noisy disk said only "the
# start has infinite energy (stretch); a degenerate or inverted triangle?".
def test_area_aware_map_names_a_folding_start_and_the_weights_to_use():
    m = jp.shapes.graph_surface(10)
    V = np.asarray(m.vertices).copy()
    inner = m.topology.interior
    V[inner, :2] += np.random.default_rng(1).normal(0, 0.03, (inner.size, 2))
    noisy = jp.TriMesh(V, m.faces)
    assert jp.metrics.flips(noisy, jp.convex_map(noisy, weights="harmonic")) > 0
    with pytest.raises(MeshError, match=r"area_aware_map: the convex map with 'harmonic' weights "
                       r"folds: faces \d+ \(1 in all\).*negative where angles are obtuse.*"
                       r"'shape_preserving' \(the default\) or 'mean_value'"):
        area_aware_map(noisy, weights="harmonic")
    assert jp.metrics.flips(noisy, area_aware_map(noisy)) == 0
