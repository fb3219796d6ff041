import json
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial import cKDTree

import jaxparam as jp
from jaxparam import points as PT
from jaxparam import weights as wts
from jaxparam.points.graph import drop_steep_pairs, knn_graph, tangent_frames
from jaxparam.points.meshless import map_points
from jaxparam.points.triangulation import delaunay, flip_towards_3d_delaunay, peel_ears
from jaxparam.topology import half_edge_twins
from jaxparam.triangles import orient
from jaxparam.errors import MeshFileError, PointCloudError
from conftest import data_path


@pytest.fixture(scope="module")
def surface_points():
    """Vertices of a generated graph surface, shuffled; and the mesh they came from."""
    mesh = jp.shapes.graph_surface(24, jitter=0.3, seed=1)   # jittered: a unique Delaunay triangulation
    perm = np.random.default_rng(0).permutation(mesh.n_vertices)
    return np.asarray(mesh.vertices)[perm], perm, mesh


@pytest.mark.parametrize("kind", PT.WEIGHTS)
def test_weights_positive_and_sum_to_one(surface_points, kind):
    P, _, _ = surface_points
    g = PT.point_graph(P, 10)
    bnd = PT.detect_boundary(P, g)
    fixed = np.zeros(len(P), bool)
    fixed[bnd] = True
    E = wts.fan_entries(g.indptr, g.indices, fixed)
    w = np.asarray(wts.fan_weights(jnp.asarray(P), E, kind))
    assert w.min() > 0
    lam = w / np.bincount(E.row, weights=w)[E.row]
    np.testing.assert_allclose(np.bincount(E.row, weights=lam), 1.0, atol=1e-12)


def test_boundary_detection_precision_recall(surface_points):
    P, perm, mesh = surface_points
    uv, bnd = jp.meshless_map(P)
    true = set(np.flatnonzero(np.isin(perm, mesh.topology.boundary_loops[0])).tolist())
    found = set(bnd.tolist())
    precision = len(true & found) / len(found)
    recall = len(true & found) / len(true)
    assert precision >= 0.95 and recall >= 0.9, (precision, recall)


def test_map_is_one_to_one_reconstruction_recovers_edges(surface_points):
    P, perm, mesh = surface_points
    rec = jp.reconstruct_surface(P)
    assert rec.mesh.topology.is_disk and jp.distortion(rec.mesh, rec.uv).flips == 0
    used = rec.mesh.topology.referenced.mean()
    assert used >= 0.98
    E0 = {tuple(e) for e in np.sort(np.argsort(perm)[mesh.topology.edges], 1).tolist()}
    E1 = {tuple(e) for e in rec.mesh.topology.edges.tolist()}
    # Measured 77 %: Delaunay of the meshless UVs flips some of the source mesh's diagonals.
    assert len(E0 & E1) / len(E0) >= 0.75
    # Every reconstructed face lies on the source surface: within 1% of the diagonal.
    src = mesh
    from scipy.spatial import cKDTree
    cent = np.asarray(rec.mesh.vertices)[rec.mesh.faces].mean(1)
    dense = jp.shapes.refine(src, 2)
    d, _ = cKDTree(np.asarray(dense.vertices)).query(cent)
    diag = np.linalg.norm(np.ptp(P, axis=0))
    assert d.max() / diag < 0.01


def test_noisy_points_still_one_to_one():
    mesh = jp.shapes.graph_surface(20)
    P = np.asarray(mesh.vertices) + np.random.default_rng(2).normal(0, 0.002, (mesh.n_vertices, 3))
    uv, bnd = jp.meshless_map(P, weights="shape_preserving")
    rec = jp.reconstruct_surface(P)
    assert jp.distortion(rec.mesh, rec.uv).flips == 0


@pytest.mark.parametrize("kind, rtol", [("inverse_distance", 1e-6), ("mean_value", 1e-4)])
def test_gradient_through_meshless_map(surface_points, kind, rtol):
    P, _, _ = surface_points
    g = PT.point_graph(P, 10)
    bnd = PT.detect_boundary(P, g)
    c = np.random.default_rng(0).standard_normal((len(P), 2))

    def loss(X):
        uv, _ = jp.meshless_map(X, graph=g, boundary_indices=bnd, weights=kind)
        return jnp.sum(c * uv)

    grad = np.asarray(jax.grad(loss)(jnp.asarray(P)))
    d = np.random.default_rng(1).standard_normal(P.shape)
    h = 1e-6
    fd = (loss(jnp.asarray(P + h * d)) - loss(jnp.asarray(P - h * d))) / (2 * h)
    # Tolerance: mean-value weights have large second derivatives (tan of half angles).
    assert abs(np.sum(grad * d) - fd) <= rtol * max(1.0, abs(fd))


def test_point_errors(tmp_path):
    P = np.random.default_rng(0).random((50, 3))
    with pytest.raises(PointCloudError, match="too few"):
        jp.meshless_map(P[:3])
    with pytest.raises(PointCloudError, match=r"points 50 .*duplicate"):
        jp.meshless_map(np.vstack([P, P[:1]]))
    with pytest.raises(PointCloudError, match="collinear"):
        jp.meshless_map(np.outer(np.arange(20.0), [1, 2, 3]))
    with pytest.raises(PointCloudError, match="coincident|duplicate"):
        jp.meshless_map(np.zeros((20, 3)))
    with pytest.raises(PointCloudError, match="k = 60"):
        jp.meshless_map(P, k=60)
    with pytest.raises(PointCloudError, match="non-finite"):
        jp.meshless_map(np.vstack([P, [[np.nan, 0, 0]]]))
    with pytest.raises(PointCloudError, match="unknown weights"):
        jp.meshless_map(P, weights="cot")
    uv, bnd = jp.meshless_map(np.vstack([P, P[:2]]), merge_duplicates=True)
    assert uv.shape == (52, 2)            # input numbering: a copy gets its first point's UV
    np.testing.assert_array_equal(np.asarray(uv)[50:], np.asarray(uv)[:2])
    with pytest.raises(PointCloudError, match=r"points 50, 51 .*point 50 equals point 7"):
        jp.meshless_map(np.vstack([P, P[[7, 7]]]))
    # near copies (1e-12 away, distinct in a file) left triangles collapsed to segments
    # (session 22): refused the same way, and merged on request
    near = np.vstack([P, P[:3] + 1e-12])
    with pytest.raises(PointCloudError, match=r"points 50, 51, 52 .*point 50 is 1\.\d+e-12 from point 0"):
        jp.meshless_map(near)
    uv, _ = jp.meshless_map(near, merge_duplicates=True)
    np.testing.assert_array_equal(np.asarray(uv)[50:], np.asarray(uv)[:3])
    with pytest.raises(PointCloudError, match="boundary must be 'circle' or 'square'"):
        jp.meshless_map(P, boundary="plane")
    with pytest.raises(PointCloudError, match="unknown spacing"):
        jp.meshless_map(P, spacing="arc")
    with pytest.raises(PointCloudError, match=r"unknown options \['kk'\]"):
        jp.reconstruct_surface(P, kk=3)
    with pytest.raises(PointCloudError, match="boundary_indices must be >= 3 distinct"):
        jp.reconstruct_surface(P, boundary_indices=[0, 1, 1])


def test_unreachable_cluster_is_reported():
    mesh = jp.shapes.graph_surface(12)
    P = np.asarray(mesh.vertices)
    far = P[:12] + 50.0                    # an island that cannot reach the boundary
    Q = np.vstack([P, far])
    g = PT.point_graph(Q, 6)
    bnd = mesh.topology.boundary_loops[0]
    with pytest.raises(PointCloudError, match=r"12 points cannot reach the boundary .*\(e.g. point 1\d\d at \(50, 50, 5\d"):
        jp.meshless_map(Q, k=6, graph=g, boundary_indices=bnd)
    # a second piece as large as the first: named as a piece to reconstruct on its own
    Q2 = np.vstack([P, P + [5.0, 0.0, 0.0]])
    g2 = PT.point_graph(Q2, 6)
    with pytest.raises(PointCloudError, match=r"they are 144 of the 288 points: a separate piece.*raise k"):
        jp.meshless_map(Q2, k=6, graph=g2, boundary_indices=bnd)


def test_load_points_formats(tmp_path):
    P = np.random.default_rng(0).random((20, 3))
    np.savetxt(tmp_path / "p.xyz", P)
    np.save(tmp_path / "p.npy", P)
    np.testing.assert_allclose(jp.load_points(tmp_path / "p.xyz"), P)
    np.testing.assert_allclose(jp.load_points(tmp_path / "p.npy"), P)
    (tmp_path / "bad.xyz").write_text("0 0 0\n1 2\n")
    with pytest.raises(MeshFileError, match="line 2"):
        jp.load_points(tmp_path / "bad.xyz")
    with pytest.raises(MeshFileError, match="no such file"):
        jp.load_points(tmp_path / "none.xyz")


def test_cli_meshless_and_fit(tmp_path, surface_points):
    from jaxparam.cli import main
    P, _, _ = surface_points
    np.savetxt(tmp_path / "p.xyz", P)
    rep = tmp_path / "r.json"
    assert main(["meshless", str(tmp_path / "p.xyz"), "-o", str(tmp_path / "rec.obj"),
                 "--report", str(rep), "--plot", str(tmp_path / "rec.png")]) == 0
    r = json.loads(rep.read_text())
    assert r["flips"] == 0 and r["points_used"] >= 0.98 * len(P)
    m = jp.load(tmp_path / "rec.obj")
    np.testing.assert_allclose(np.asarray(m.vertices), P, rtol=1e-15)
    assert main(["fit", str(tmp_path / "rec.obj"), "-o", str(tmp_path / "fit.obj"),
                 "--surface", "clough-tocher", "--resolution", "30"]) == 0
    assert jp.load(tmp_path / "fit.obj").n_faces > 100
    jp.save(tmp_path / "nouv.obj", jp.shapes.plane_grid(4, 4))
    assert main(["fit", str(tmp_path / "nouv.obj"), "-o", str(tmp_path / "x.obj")]) == 3


@pytest.mark.data
def test_bump_domain_half_points():
    P = jp.load_points(data_path("points", "bump-domain-half.xyz"))
    rec = jp.reconstruct_surface(P)
    assert jp.distortion(rec.mesh, rec.uv).flips == 0
    # Measured: 72 % of the points end up in the disk (the rest are peeled off with bridging
    # triangles); issue 4 keeps this open.
    assert rec.mesh.topology.referenced.mean() > 0.7


def _non_delaunay_3d(F, P, U):
    """Interior edges that the 3D flip pass would still flip (excess angle, UVs kept valid)."""
    again = flip_towards_3d_delaunay(F, P, U, 1)
    return int(np.any(again != F, axis=1).sum())


def test_3d_flips_keep_a_one_to_one_triangulation_and_bring_faces_to_the_surface():
    # Random points on a strongly curved patch (a half cylinder of radius 1): the Delaunay
    # triangulation of the parameter points has many edges that are not Delaunay in 3D.
    rng = np.random.default_rng(4)
    t, h = rng.uniform(0, np.pi, 900), rng.uniform(0, 2.0, 900)
    P = np.column_stack([np.cos(t), h, np.sin(t)])
    rec0 = jp.reconstruct_surface(P, flip_rounds=0)
    rec = jp.reconstruct_surface(P)
    U = np.asarray(rec.uv)
    assert rec.mesh.topology.is_disk and jp.distortion(rec.mesh, rec.uv).flips == 0
    F0 = delaunay(U)
    F1 = flip_towards_3d_delaunay(F0, P, U, 100)
    assert len(F1) == len(F0) and orient(U, *F1.T).min() > 0
    assert jp.TriMesh(P, F1).topology.is_disk
    assert _non_delaunay_3d(F0, P, U) > 0 and _non_delaunay_3d(F1, P, U) == 0
    # Distance of face points to the cylinder, before and after.
    def worst(m):
        X = np.asarray(m.vertices)[m.faces]
        S = np.concatenate([X.mean(1), (X[:, 0] + X[:, 1]) / 2, (X[:, 1] + X[:, 2]) / 2, (X[:, 2] + X[:, 0]) / 2])
        return np.abs(1 - np.hypot(S[:, 0], S[:, 2])).max()
    assert worst(rec.mesh) < worst(rec0.mesh)


def test_flips_keep_the_half_edge_twins_up_to_date():
    rng = np.random.default_rng(4)
    t, h = rng.uniform(0, np.pi, 900), rng.uniform(0, 2.0, 900)
    P = np.column_stack([np.cos(t), h, np.sin(t)])
    U = np.column_stack([np.cos(t), h])        # the side view: far from 3D Delaunay
    F0 = delaunay(U)
    F1, twin = flip_towards_3d_delaunay(F0, P, U, 100, return_twin=True)
    np.testing.assert_array_equal(F1, flip_towards_3d_delaunay(F0, P, U, 100))
    assert not np.array_equal(F1, F0)
    np.testing.assert_array_equal(twin, half_edge_twins(F1, len(P)))


@pytest.mark.parametrize("kind", PT.WEIGHTS)
def test_host_map_matches_the_jax_map(surface_points, kind):
    P, _, _ = surface_points
    g = PT.point_graph(P, 10)
    bnd = PT.detect_boundary(P, g)
    opts = dict(weights=kind, boundary="circle", spacing="chord",
                symmetric=kind in ("uniform", "inverse_distance"))
    U = np.asarray(map_points(P, g, bnd, **opts))
    Uh = map_points(P, g, bnd, host=True, **opts)
    assert isinstance(Uh, np.ndarray)
    np.testing.assert_allclose(Uh, U, rtol=0, atol=1e-13)


def test_delaunay_fallback_without_triangle_matches(monkeypatch):
    import sys
    U = np.random.default_rng(5).random((400, 2))
    F = delaunay(U)
    monkeypatch.setitem(sys.modules, "triangle", None)          # import triangle -> ImportError
    G = delaunay(U)
    key = lambda T: {tuple(sorted(f)) for f in T.tolist()}
    assert key(F) == key(G) and orient(U, *G.T).min() > 0


def test_point_graph_does_not_depend_on_the_input_order(surface_points):
    P, _, _ = surface_points
    perm = np.random.default_rng(7).permutation(len(P))
    inv = np.argsort(perm)
    a, b = PT.point_graph(P, 10), PT.point_graph(P[perm], 10)
    np.testing.assert_allclose(a.normal, b.normal[inv], atol=1e-12)
    np.testing.assert_allclose(a.gap, b.gap[inv], atol=1e-12)
    np.testing.assert_allclose(a.detect_gap, b.detect_gap[inv], atol=1e-12)
    for v in range(0, len(P), 17):
        fan_a = a.indices[a.indptr[v]:a.indptr[v + 1]]
        fan_b = perm[b.indices[b.indptr[inv[v]]:b.indptr[inv[v] + 1]]]
        # The same cyclic order (anticlockwise about the same normal), maybe from another start.
        assert fan_b.tolist() in [np.roll(fan_a, s).tolist() for s in range(fan_a.size)]


def test_steep_neighbour_pairs_across_a_thin_fold_are_dropped():
    # Two parallel layers as far apart as the point spacing, joined by a half-cylinder fold at
    # x = 1: many of the 10 nearest neighbours lie on the other layer.
    rng = np.random.default_rng(6)
    t = 0.03
    xy = rng.random((2000, 2))
    top = np.column_stack([xy[:1000], np.full(1000, t)])
    bottom = np.column_stack([xy[1000:], np.zeros(1000)])
    a, y = rng.uniform(-np.pi / 2, np.pi / 2, 200), rng.random(200)
    fold = np.column_stack([1 + 0.5 * t * np.cos(a), y, 0.5 * t + 0.5 * t * np.sin(a)])
    P = np.concatenate([top, bottom, fold])
    layer = np.concatenate([np.ones(1000), np.zeros(1000), np.full(200, -1)])

    def across(g):
        rows = g.rows
        far = (P[rows, 0] < 0.9) & (P[g.indices, 0] < 0.9)
        return far & (layer[rows] >= 0) & (layer[g.indices] >= 0) & (layer[rows] != layer[g.indices])

    g1, g = PT.point_graph(P, 10, max_slope=1.0), PT.point_graph(P, 10)
    assert across(g).sum() < 0.75 * across(g1).sum()
    # Every pair kept leaves both tangent planes by at most the slope (or joins a point that
    # would otherwise keep fewer than three neighbours).
    rows = g.rows
    d = P[g.indices] - P[rows]
    slope = np.maximum(np.abs(np.sum(d * g.normal[rows], 1)), np.abs(np.sum(d * g.normal[g.indices], 1)))
    slope /= np.linalg.norm(d, axis=1)
    # ... and joins two consistently oriented normals at most 90 degrees apart.
    ok = (slope <= PT.defaults.MAX_SLOPE) & (
        np.sum(g.normal[rows] * g.normal[g.indices], 1) >= PT.defaults.MIN_NORMAL_DOT)
    weak = np.bincount(rows[ok], minlength=len(P)) < 3     # kept all their pairs
    assert np.all(ok | weak[rows] | weak[g.indices])
    # Symmetric still.
    pairs = set(zip(rows.tolist(), g.indices.tolist()))
    assert all((w, v) in pairs for v, w in pairs)


def test_normals_are_oriented_consistently_round_a_curved_sheet():
    # Three quarters of a cylinder: turned towards the best-fit normal, a third of the normals
    # point inwards (measured 0.67 agree); propagated along the spanning tree, all agree.
    rng = np.random.default_rng(3)
    t, z = rng.uniform(0, 1.5 * np.pi, 3000), rng.uniform(0, 2, 3000)
    P = np.column_stack([np.cos(t), np.sin(t), z])
    outward = np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
    g = PT.point_graph(P, 10)
    agree = np.sum(g.normal * outward, 1) > 0
    assert max(agree.mean(), 1 - agree.mean()) == 1.0
    raw = np.sum(tangent_frames(P, g.indptr, g.indices)[0] * outward, 1) > 0
    assert max(raw.mean(), 1 - raw.mean()) < 0.9
    # The fans stay symmetric graphs with unit normals.
    np.testing.assert_allclose(np.linalg.norm(g.normal, axis=1), 1.0, atol=1e-12)


def test_pairs_with_opposed_normals_are_dropped():
    # A flat grid whose right half has its normals flipped: the pairs across x = 0.5 join
    # opposed normals and leave the graph; the others stay.
    x, y = np.meshgrid(np.linspace(0, 1, 20), np.linspace(0, 1, 20))
    P = np.column_stack([x.ravel(), y.ravel(), np.zeros(400)])
    ip, ix = knn_graph(P, 8)
    n = np.tile([0.0, 0.0, 1.0], (400, 1))
    n[P[:, 0] > 0.5] *= -1
    ptr, idx = drop_steep_pairs(P, ip, ix, n, 0.6, min_dot=0.0)
    rows = np.repeat(np.arange(400), np.diff(ptr))
    assert not np.any((P[rows, 0] > 0.5) != (P[idx, 0] > 0.5))
    rows0 = np.repeat(np.arange(400), np.diff(ip))
    same = (P[rows0, 0] > 0.5) == (P[ix, 0] > 0.5)
    assert idx.size == same.sum() and np.any(~same)


@pytest.mark.data
@pytest.mark.peer
def test_camelhead_points_dropping_steep_pairs_brings_faces_to_the_surface():
    """camelhead.xyz: steep neighbour pairs join the two sides of the ears and the map
    squeezes them; without those pairs the reconstruction lies closer to camelhead.off
    (RMS distance of face centroids and edge midpoints 0.038 % -> 0.027 % of the diagonal)."""
    igl = pytest.importorskip("igl")
    P = jp.load_points(data_path("points", "camelhead.xyz"))
    src = jp.load(data_path("meshes", "camelhead.off"))
    V = np.asarray(src.vertices)
    diag = np.linalg.norm(np.ptp(V, axis=0))

    def distances(rec):
        X = P[rec.mesh.faces]
        S = np.concatenate([X.mean(1), (X[:, 0] + X[:, 1]) / 2, (X[:, 1] + X[:, 2]) / 2,
                            (X[:, 2] + X[:, 0]) / 2])
        d2 = igl.point_mesh_squared_distance(S, V, src.faces)[0]
        return np.sqrt(d2.mean()) / diag, np.sqrt(d2.max()) / diag

    rms1, max1 = distances(jp.reconstruct_surface(P, max_slope=1.0))
    rec = jp.reconstruct_surface(P)
    rms, mx = distances(rec)
    assert rms < 0.9 * rms1 and mx <= max1 * (1 + 1e-9)
    assert rec.mesh.topology.is_disk and jp.distortion(rec.mesh, rec.uv).flips == 0


def test_an_ear_over_a_missed_boundary_point_is_peeled():
    # A 21 x 21 grid whose top-middle point sits in a notch of a densely sampled boundary (two
    # extra points halve the top row's spacing there): the Delaunay hull bridges the notch with
    # one face whose apex angle (~102 degrees) covers empty space, on a base of one spacing.
    g = np.linspace(0, 1, 21)
    xy = np.column_stack([a.ravel() for a in np.meshgrid(g, g)])
    xy = np.vstack([xy, [[0.475, 1.0], [0.525, 1.0]]])
    apex = int(np.flatnonzero(np.all(np.isclose(xy, [0.5, 1.0]), axis=1))[0])
    xy[apex] = [0.5, 0.98]
    P = np.column_stack([xy, 0.1 * np.sin(3 * xy[:, 0])])
    F = delaunay(xy)
    graph = PT.point_graph(P, 10)
    G = peel_ears(F, P, graph)
    gone = {tuple(f) for f in np.sort(F, 1).tolist()} - {tuple(f) for f in np.sort(G, 1).tolist()}
    assert len(gone) == 1 and apex in next(iter(gone))
    t = jp.TriMesh(P, G).topology
    assert t.is_disk and apex in t.boundary_loops[0]
    # Without the two extra points the ear's base is two spacings: a sparse boundary, whose
    # face covers the surface (the square), so it stays; allowing long bases peels it.
    xy2 = np.delete(xy, [len(xy) - 2, len(xy) - 1], axis=0)
    P2 = np.column_stack([xy2, 0.1 * np.sin(3 * xy2[:, 0])])
    F2 = delaunay(xy2)
    graph2 = PT.point_graph(P2, 10)
    assert len(peel_ears(F2, P2, graph2)) == len(F2)
    assert len(peel_ears(F2, P2, graph2, max_base=np.inf)) == len(F2) - 1


def test_a_user_boundary_survives_merging_duplicates(surface_points):
    """With merge_duplicates, boundary_indices (input numbering) are used, not re-detected;
    uv and the returned boundary are both in the input's numbering."""
    P, perm, mesh = surface_points
    bnd_in = np.argsort(perm)[mesh.topology.boundary_loops[0]]   # the true boundary, as indices into P
    copies = np.array([int(bnd_in[0]), 5, 17])
    Q = np.vstack([P, P[copies]])                                # points N, N+1, N+2 repeat earlier ones
    n = len(P)
    # The user names one boundary point by its later copy.
    user = bnd_in.copy()
    user[0] = n
    uv, bnd = jp.meshless_map(Q, boundary_indices=user, merge_duplicates=True)
    ref_uv, ref_bnd = jp.meshless_map(P, boundary_indices=bnd_in)
    assert uv.shape == (n + 3, 2)
    np.testing.assert_array_equal(bnd, bnd_in)                  # the copy is named by its first point
    np.testing.assert_allclose(np.asarray(uv)[:n], np.asarray(ref_uv), atol=1e-12)
    np.testing.assert_array_equal(np.asarray(uv)[n:], np.asarray(uv)[copies])
    # The same for the reconstruction: the mesh spans all input points, copies unused.
    rec = jp.reconstruct_surface(Q, boundary_indices=user, merge_duplicates=True)
    np.testing.assert_array_equal(rec.boundary, bnd_in)
    assert rec.mesh.n_vertices == n + 3 and not rec.mesh.topology.referenced[n:].any()
    with pytest.raises(PointCloudError, match="once duplicates are merged"):
        jp.meshless_map(Q, boundary_indices=[int(bnd_in[0]), 1, n], merge_duplicates=True)


def test_reconstruction_fields_agree(surface_points):
    P, _, _ = surface_points
    rec = jp.reconstruct_surface(P)
    assert isinstance(rec, PT.Reconstruction)
    assert rec.mesh.uv is rec.uv and rec.uv.shape == (len(P), 2)
    np.testing.assert_array_equal(rec.points_used, np.unique(rec.mesh.faces))
    assert set(rec.seconds) == {"neighbours", "boundary", "weights_and_solve", "delaunay", "flips",
                                "peel_and_topology"}
    # The same polygon as the meshless map's (detected in Morton order: maybe from another start).
    uv, bnd = jp.meshless_map(P, weights="shape_preserving")
    assert rec.boundary.tolist() in [np.roll(bnd, s).tolist() for s in range(bnd.size)]
    assert np.all(rec.mesh.topology.is_boundary[rec.boundary] | ~rec.mesh.topology.referenced[rec.boundary])


def test_points_that_are_all_on_the_boundary_are_mapped_by_the_boundary_map():
    # Found in QA: four points with k=3 (every one on the boundary polygon) raised numpy's
    # "zero-size array to reduction operation maximum" from the fan weights.
    P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.1]])
    uv, bnd = jp.meshless_map(P, k=3)
    assert sorted(np.asarray(bnd).tolist()) == [0, 1, 2, 3]
    np.testing.assert_allclose(np.linalg.norm(np.asarray(uv), axis=1), 1.0)
    rec = jp.reconstruct_surface(P, k=3)
    assert rec.mesh.n_faces == 2 and np.all(np.isfinite(np.asarray(rec.uv)))


def test_point_graph_refuses_a_bad_k_or_shape():
    P = np.random.default_rng(0).random((40, 3))
    with pytest.raises(jp.PointCloudError, match=r"k \(neighbours per point\) must be an integer in \[1, 40\).*got 0"):
        jp.points.point_graph(P, k=0)
    with pytest.raises(jp.PointCloudError, match=r"got 40"):
        jp.points.point_graph(P, k=40)
    with pytest.raises(jp.PointCloudError, match=r"\(N, 3\) array, got shape \(40, 2\)"):
        jp.points.point_graph(P[:, :2])


@pytest.mark.slow
def test_a_moebius_strip_warns_that_it_is_not_orientable():
    """Found by session 22's held-out sweep: points of a Moebius strip reconstructed to a mesh
    that bridges its seam (area 11.6 against 3.78), reported as normal.  The pairs in each
    other's tangent plane with opposed normals mark the seam; a tube (orientable) has none."""
    from jaxparam.points.orientation import NonOrientableWarning
    rng = np.random.default_rng(0)
    t, s = rng.uniform(0, 2 * np.pi, 3000), rng.uniform(-0.3, 0.3, 3000)
    mob = np.column_stack([(1 + s * np.cos(t / 2)) * np.cos(t), (1 + s * np.cos(t / 2)) * np.sin(t),
                           s * np.sin(t / 2)])
    with pytest.warns(NonOrientableWarning, match=r"\d+ neighbour pairs .*opposed normals.*Moebius"):
        jp.reconstruct_surface(mob)
    tube = np.column_stack([np.cos(t), np.sin(t), 2 * s])
    with warnings.catch_warnings():
        warnings.simplefilter("error", NonOrientableWarning)
        jp.reconstruct_surface(tube)
