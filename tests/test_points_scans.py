"""Scan-like point sets (survey §8, issue 14): noise, uneven density and outliers.

Always-on tests sample the height field ``z = h(x, y)`` over the unit square (the vertical
distance to it bounds the true distance from above); the slow ones sample shared disk meshes
and score against them with libigl.
"""
import numpy as np
import pytest

import jaxparam as jp
from jaxparam import points as PT
from jaxparam.errors import PointCloudError
from jaxparam.points.defaults import BRIDGE_FACTOR
from jaxparam.points.graph import knn_graph, robust_frames, tangent_frames
from conftest import data_path


def height(x, y):
    return 0.2 * np.sin(2 * np.pi * x) * np.cos(2 * np.pi * y) + 0.3 * x ** 2


def true_normal(x, y):
    hx = 0.4 * np.pi * np.cos(2 * np.pi * x) * np.cos(2 * np.pi * y) + 0.6 * x
    hy = -0.4 * np.pi * np.sin(2 * np.pi * x) * np.sin(2 * np.pi * y)
    n = np.column_stack([-hx, -hy, np.ones_like(x)])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def scan(n, *, noise=0.0, outliers=0.0, density=1.0, notch=False, seed=0):
    """``n`` points of the height field: Gaussian noise of ``noise`` times the diagonal (RMS),
    density rising ``density``-fold along x, a share ``outliers`` moved 3-10 % of the
    diagonal up or down, ``notch``: the domain is a C (no points in x in [0.3, 0.7], y > 0.3).
    **Returns:** ``(P (n, 3), outlier indices, diagonal)``."""
    rng = np.random.default_rng(seed)
    xy = rng.random((16 * n, 2))
    xy = xy[rng.random(len(xy)) < (1 + (density - 1) * xy[:, 0]) / density]
    if notch:
        xy = xy[~((xy[:, 0] > 0.3) & (xy[:, 0] < 0.7) & (xy[:, 1] > 0.3))]
    xy = xy[:n]
    P = np.column_stack([xy, height(xy[:, 0], xy[:, 1])])
    diag = float(np.linalg.norm(np.ptp(P, axis=0)))
    P = P + rng.normal(0, noise * diag, P.shape)
    out = np.sort(rng.choice(n, int(outliers * n), replace=False))
    P[out, 2] += rng.choice([-1, 1], out.size) * rng.uniform(0.03, 0.1, out.size) * diag
    return P, out, diag


def face_samples(P, F):
    """Centroids and edge midpoints of the faces ``F`` over ``P``."""
    X = P[F]
    return np.concatenate([X.mean(1), (X[:, 0] + X[:, 1]) / 2, (X[:, 1] + X[:, 2]) / 2,
                           (X[:, 2] + X[:, 0]) / 2])


def check_scan_result(rec, P, out, diag, *, tol=0.01):
    """The issue's quality goal on a height-field scan: vertices are the input points, in
    order; planted outliers out of the faces; >= 99 % of the others used; faces within
    ``tol`` of the diagonal (vertical distance); one manifold disk; no flipped UV."""
    F = np.asarray(rec.mesh.faces)
    np.testing.assert_array_equal(np.asarray(rec.mesh.vertices), P)
    inlier = np.ones(len(P), bool)
    inlier[out] = False
    used = np.zeros(len(P), bool)
    used[rec.points_used] = True
    assert used[inlier].mean() >= 0.99
    S = face_samples(P, F)
    assert np.abs(S[:, 2] - height(S[:, 0], S[:, 1])).max() <= tol * diag
    assert rec.mesh.topology.is_disk and len(rec.mesh.topology.boundary_loops) == 1
    assert jp.distortion(rec.mesh, rec.uv).flips == 0
    assert np.all(np.isfinite(np.asarray(rec.uv)))


def test_outliers_are_found_reported_and_left_out():
    P, out, diag = scan(3000, noise=0.002, outliers=0.01, seed=1)
    rec = jp.reconstruct_surface(P)
    found = np.isin(out, rec.outliers)
    assert found.mean() >= 0.9, f"{found.sum()} of {out.size} outliers found"
    false = np.setdiff1d(rec.outliers, out)
    assert false.size <= 0.005 * len(P)
    assert np.all(np.diff(rec.outliers) > 0)
    assert not np.isin(rec.outliers, rec.points_used).any()
    check_scan_result(rec, P, out, diag)
    # A removed outlier's UV is that of its nearest kept point (found from its own neighbour
    # list; brute force here).  Removed: an outlier whose UV repeats another point's (the late
    # ones, found after the map, keep their own).
    uv = np.asarray(rec.uv)
    same = np.all(uv[rec.outliers][:, None, :] == uv[None, :, :], axis=2).sum(1) > 1
    removed = rec.outliers[same]
    assert removed.size >= 0.8 * out.size
    kept = np.setdiff1d(np.arange(len(P)), removed)
    D = np.linalg.norm(P[removed][:, None, :] - P[kept][None, :, :], axis=2)
    np.testing.assert_array_equal(uv[removed], uv[kept[np.argmin(D, axis=1)]])
    # Turned off, the outliers are meshed and pull faces far off the surface.
    rec0 = jp.reconstruct_surface(P, outliers=False)
    assert rec0.outliers.size == 0
    S = face_samples(P, np.asarray(rec0.mesh.faces))
    assert np.abs(S[:, 2] - height(S[:, 0], S[:, 1])).max() > 0.02 * diag


def test_noisy_uneven_scan_is_one_disk_near_the_surface():
    P, out, diag = scan(3000, noise=0.002, density=8.0, seed=2)
    rec = jp.reconstruct_surface(P)
    check_scan_result(rec, P, out, diag)


def test_sparse_boundary_faces_are_not_peeled_as_ears(monkeypatch):
    # Eightfold density: the sparse side's boundary zigzags, and its outer faces look like ears
    # (wide apex, no neighbour inside) on bases longer than the spacing; they cover the square.
    P, out, diag = scan(3000, noise=0.002, density=8.0, seed=2)

    def covered(rec):
        X = P[np.asarray(rec.mesh.faces)][:, :, :2]
        u, v = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
        return 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).sum()

    kept = covered(jp.reconstruct_surface(P))
    from jaxparam.points import reconstruct as rmod
    from jaxparam.points.triangulation import peel_ears
    monkeypatch.setattr(rmod, "peel_ears", lambda F, P_, g, **kw: peel_ears(F, P_, g, max_base=np.inf, **kw))
    every = covered(jp.reconstruct_surface(P))
    assert kept >= 0.96 and kept > every + 0.01, (kept, every)   # measured 0.966 and 0.950


def test_no_bridging_triangles_over_a_notch_of_a_noisy_scan():
    # A C-shaped domain: the parameter-plane Delaunay closes the notch with long triangles.
    P, out, diag = scan(3000, noise=0.002, notch=True, seed=3)
    rec = jp.reconstruct_surface(P)
    check_scan_result(rec, P, out, diag)
    F = np.asarray(rec.mesh.faces)
    C = P[F].mean(1)
    spacing = np.median(np.sort(np.linalg.norm(P[F] - P[F][:, [1, 2, 0]], axis=2), axis=1)[:, 0])
    inside = (C[:, 0] > 0.3 + 2 * spacing) & (C[:, 0] < 0.7 - 2 * spacing) & (C[:, 1] > 0.3 + 2 * spacing)
    assert not inside.any(), f"{inside.sum()} faces bridge the notch"
    L = np.linalg.norm(P[F] - P[F][:, [1, 2, 0]], axis=2).max(1)
    assert L.max() <= 2 * BRIDGE_FACTOR * np.median(L)


def test_smoothing_cuts_the_noise_and_the_default_keeps_the_points():
    P, out, diag = scan(3000, noise=0.002, seed=4)
    err = lambda V: np.sqrt(np.mean((V[:, 2] - height(V[:, 0], V[:, 1])) ** 2))   # noqa: E731
    rec = jp.reconstruct_surface(P)
    np.testing.assert_array_equal(np.asarray(rec.mesh.vertices), P)
    for how, factor in (("mls", 0.6), ("plane", 0.8)):
        sm = jp.reconstruct_surface(P, smooth=how)
        V = np.asarray(sm.mesh.vertices)
        assert err(V) < factor * err(P), how
        assert sm.mesh.topology.is_disk and jp.distortion(sm.mesh, sm.uv).flips == 0
    with pytest.raises(PointCloudError, match="smooth must be one of"):
        jp.reconstruct_surface(P, smooth="laplace")


def test_robust_frames_tilt_less_than_the_fan_pca_under_noise():
    P, _, diag = scan(4000, noise=0.003, seed=5)
    n_true = true_normal(P[:, 0], P[:, 1])
    near = PT.graph.nearest_neighbours(P, 24)[1]
    robust = robust_frames(P, near).normal
    plain = tangent_frames(P, *knn_graph(P, 10, nearest=near))[0]
    ang = lambda N: np.degrees(np.arccos(np.minimum(np.abs(np.sum(N * n_true, 1)), 1)))   # noqa: E731
    assert np.median(ang(robust)) < 0.7 * np.median(ang(plain))
    assert np.all(robust[:, 2] > 0)                      # all turned the same way (upwards)


def test_user_boundary_points_are_never_outliers():
    P, out, diag = scan(2000, seed=6)
    rec = jp.reconstruct_surface(P)
    P2 = P.copy()
    P2[rec.boundary[0], 2] += 0.05 * diag              # a boundary point lifted off the surface
    auto = jp.reconstruct_surface(P2)
    assert rec.boundary[0] in auto.outliers
    given = jp.reconstruct_surface(P2, boundary_indices=rec.boundary)
    assert rec.boundary[0] not in given.outliers
    np.testing.assert_array_equal(given.boundary, rec.boundary)


# --- shared meshes (slow): the quality goal -----------------------------------------

def mesh_scan(name, kind, n, seed=0, *, outliers=False):
    """``n`` area-weighted samples of a shared mesh: ``noise2`` adds Gaussian noise of 0.2 %
    of the diagonal, ``dens8`` makes the density rise eightfold along the longest axis, ``all``
    both; ``outliers``: 1 % of the points moved 2-10 % of the diagonal in random directions
    (redrawn until at least 1.5 % off the surface, libigl distances), and their indices
    returned last.  With ``kind="all", outliers=True`` this is ``benchmarks/points.py``'s set
    ``all``, draw for draw."""
    ext = {"camelhead": "off", "lilium": "obj", "snail": "obj", "bump-domain": "obj"}[name]
    src = jp.load(data_path("meshes", f"{name}.{ext}"))
    V, F = np.asarray(src.vertices), np.asarray(src.faces)
    rng = np.random.default_rng(seed)
    A = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    f = rng.choice(len(F), 8 * n, p=A / A.sum())
    s, r = np.sqrt(rng.random(8 * n)), rng.random(8 * n)
    P = np.einsum("nk,nkd->nd", np.stack([1 - s, s * (1 - r), s * r], 1), V[F[f]])
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    if kind in ("dens8", "all"):
        ax = int(np.argmax(np.ptp(V, axis=0)))
        t = (P[:, ax] - V[:, ax].min()) / np.ptp(V[:, ax])
        P = P[rng.random(len(P)) < (1 + 7 * t) / 8]
    P = P[:n]
    if kind in ("noise2", "all"):
        P = P + rng.normal(0, 0.002 * diag, P.shape)
    if not outliers:
        return P, V, F, diag
    import igl
    out = np.sort(rng.choice(n, n // 100, replace=False))
    base, amp, todo = P[out].copy(), diag * rng.uniform(0.02, 0.1, (out.size, 1)), np.arange(out.size)
    while todo.size:
        d = rng.normal(size=(todo.size, 3))
        P[out[todo]] = base[todo] + d / np.linalg.norm(d, axis=1, keepdims=True) * amp[todo]
        todo = todo[np.sqrt(igl.point_mesh_squared_distance(P[out[todo]], V, F)[0]) < 0.015 * diag]
    return P, V, F, diag, out


@pytest.mark.slow
@pytest.mark.data
@pytest.mark.peer
@pytest.mark.parametrize("name", ["camelhead", "lilium", "snail", "bump-domain"])
@pytest.mark.parametrize("kind", ["noise2", "dens8"])
def test_shared_mesh_scans_meet_the_quality_goal(name, kind):
    """50k samples: faces within 1 % of the diagonal of the source mesh; the source within 1 %
    of the faces for 99.9 % of its area (the rest is the sparse boundary band, where the
    samples stop short of the true edge: up to 1.7 % on lilium's eightfold set); >= 99 % of
    the points; one disk; no flipped UV."""
    igl = pytest.importorskip("igl")
    P, V, F, diag = mesh_scan(name, kind, 50_000)
    rec = jp.reconstruct_surface(P)
    FR = np.asarray(rec.mesh.faces)
    d1 = np.sqrt(igl.point_mesh_squared_distance(face_samples(P, FR), V, F)[0])
    T = mesh_scan(name, "clean", 100_000, seed=7)[0]
    d2 = np.sqrt(igl.point_mesh_squared_distance(T, P, FR)[0])
    assert d1.max() <= 0.01 * diag
    assert np.quantile(d2, 0.999) <= 0.01 * diag
    assert rec.points_used.size >= 0.99 * len(P)
    assert rec.mesh.topology.is_disk and jp.distortion(rec.mesh, rec.uv).flips == 0


@pytest.mark.slow
@pytest.mark.data
@pytest.mark.peer
def test_noisy_uneven_camelhead_scan_with_outliers_keeps_its_boundary():
    """50k samples of camelhead with 0.2 % noise, eightfold density and 1 % outliers: two
    missed outliers once linked stray boundary candidates into a chain longer than the neck's
    loop, the map collapsed onto that chain and 2,438 points were dropped as lone.  Now the
    boundary is the neck (its points near the source's boundary loop), >= 99 % of the inliers
    are used, and the faces lie within 2 % of the diagonal of the source (1.07 %; 12 % before:
    the excess over 1 % is a sliver under the snout, where session 12 found the mouth's
    bridges, benchmarks/README.md)."""
    igl = pytest.importorskip("igl")
    P, V, F, diag, out = mesh_scan("camelhead", "all", 50_000, outliers=True)
    rec = jp.reconstruct_surface(P)
    loop = np.concatenate(jp.TriMesh(V, F).topology.boundary_loops)
    from scipy.spatial import cKDTree
    assert np.median(cKDTree(V[loop]).query(P[rec.boundary])[0]) <= 0.01 * diag
    inl = np.setdiff1d(np.arange(len(P)), out)
    assert np.isin(inl, rec.points_used).mean() >= 0.99
    FR = np.asarray(rec.mesh.faces)
    assert np.sqrt(igl.point_mesh_squared_distance(face_samples(P, FR), V, F)[0]).max() <= 0.02 * diag
    assert rec.mesh.topology.is_disk and jp.distortion(rec.mesh, rec.uv).flips == 0


@pytest.mark.slow
@pytest.mark.data
@pytest.mark.peer
@pytest.mark.parametrize("name,kind", [("camelhead", "out1"), ("snail", "all")])
def test_clusters_of_outliers_are_found_in_later_rounds(name, kind):
    """Outliers within 2 % of the diagonal of each other hide each other from the outlier test;
    on these two 50k-point scans (1 % outliers; snail with noise and eightfold density) the
    last of a cluster of three took a third round, and with two rounds stayed a vertex 3-5 %
    off the surface.  Now every planted outlier is reported, and the faces lie within 1 %."""
    igl = pytest.importorskip("igl")
    if kind == "out1":              # clean samples with the same outliers as the benchmark's set
        P, V, F, diag, out = mesh_scan(name, "clean", 50_000, outliers=True)
    else:
        P, V, F, diag, out = mesh_scan(name, kind, 50_000, outliers=True)
    rec = jp.reconstruct_surface(P)
    assert np.isin(out, rec.outliers).all()
    FR = np.asarray(rec.mesh.faces)
    assert np.sqrt(igl.point_mesh_squared_distance(face_samples(P, FR), V, F)[0]).max() <= 0.01 * diag


@pytest.mark.slow
@pytest.mark.data
@pytest.mark.peer
def test_clean_camelhead_points_stay_within_half_a_percent():
    igl = pytest.importorskip("igl")
    P = jp.load_points(data_path("points", "camelhead.xyz"))
    src = jp.load(data_path("meshes", "camelhead.off"))
    V = np.asarray(src.vertices)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    rec = jp.reconstruct_surface(P)
    d = np.sqrt(igl.point_mesh_squared_distance(face_samples(P, rec.mesh.faces), V, src.faces)[0])
    assert d.max() <= 0.005 * diag
    assert rec.points_used.size >= 0.99 * len(P)
    assert rec.mesh.topology.is_disk and jp.distortion(rec.mesh, rec.uv).flips == 0


def test_row_blocks_on_threads_give_the_same_bits():
    """The points stack's blocks of rows (frames, fans, gaps: jaxparam.blocks) run on
    ``jp.config.threads`` threads; every row is computed the same way, so one thread and
    three give the same reconstruction, bit for bit (20k noisy points: 5 blocks of frames)."""
    P, _, _ = scan(20000, noise=0.002, outliers=0.01, seed=3)
    runs = []
    try:
        for threads in (1, 3):
            jp.config.threads = threads
            rec = jp.reconstruct_surface(P)
            runs.append((np.asarray(rec.mesh.faces), np.asarray(rec.uv), rec.outliers))
    finally:
        jp.config.threads = None
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    np.testing.assert_array_equal(runs[0][2], runs[1][2])
    for bad in (0, 1.5, "2", True):
        with pytest.raises(ValueError, match="threads must be a whole number"):
            jp.config.threads = bad
    try:
        jp.config.threads = np.int64(2)
        assert jp.config.threads == 2
    finally:
        jp.config.threads = None


def test_boundary_chain_is_not_lengthened_by_stray_points_off_the_surface():
    """Boundary candidates link within three local spacings of the smaller of the two points'
    spacings: a stray point off the surface (large spacing: its neighbours are far) must not
    join clusters of interior candidates into a chain longer than the true boundary.  A
    50k-point camelhead scan (noise, eightfold density, outliers) lost its boundary that way
    to a 17-point chain through two missed outliers, and its map collapsed (2,438 points then
    dropped as lone).  Here: a ring of 50 candidates (radius 0.1, perimeter 0.63) and three
    tight clusters of interior candidates 0.5 apart, each pair bridged by a point of spacing
    0.3; the ring is the boundary."""
    from jaxparam.points.graph import PointGraph
    from jaxparam.points.defaults import K_DETECT
    rng = np.random.default_rng(0)
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    ring = np.column_stack([0.1 * np.cos(t), 0.1 * np.sin(t), np.zeros(50)])
    centres = np.array([[1.0, 0.0], [1.5, 0.0], [2.0, 0.0]])
    clusters = np.concatenate([c + 0.005 * rng.standard_normal((3, 2)) for c in centres])
    bridges = np.array([[1.25, 0.0], [1.75, 0.0]])
    stray = np.column_stack([np.concatenate([clusters, bridges]), np.zeros(11)])
    filler = np.column_stack([rng.uniform(-0.09, 0.09, (400, 2)) * [0.7, 0.7], np.zeros(400)])
    P = np.concatenate([ring, stray, filler])
    n = len(P)
    gap = np.zeros(n)
    gap[:61] = np.pi                                   # the ring, clusters and bridges
    spacing = np.full(n, 0.0126)
    spacing[59:61] = 0.3                               # the bridges: points off the surface
    graph = PointGraph(indptr=np.zeros(n + 1, np.int64), indices=np.zeros(0, np.int64),
                       gap=gap, normal=np.tile([0.0, 0.0, 1.0], (n, 1)), spacing=spacing,
                       detect_k=K_DETECT, detect_gap=gap, detect_spacing=spacing)
    loop = PT.detect_boundary(P, graph)
    assert set(loop.tolist()) == set(range(50))


def test_an_error_in_a_row_block_reaches_the_caller_after_every_block_ran():
    from jaxparam.blocks import for_blocks
    done = np.zeros(10, bool)

    def body(r0, r1):
        done[r0:r1] = True
        if r0 == 0:
            raise ValueError("block 0 failed")

    try:
        jp.config.threads = 2
        with pytest.raises(ValueError, match="block 0 failed"):
            for_blocks(body, 10, 2)
    finally:
        jp.config.threads = None
    assert done.all()


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="no fork on this platform")
@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")   # JAX's, when it is loaded
def test_row_blocks_work_in_a_forked_child():
    """A child forked after the row-block pool has started inherits the pool but not its
    threads; it must make its own instead of waiting for ever."""
    import multiprocessing as mp
    from jaxparam.blocks import for_blocks
    out = np.zeros(8)

    def body(r0, r1):
        out[r0:r1] = 1.0

    try:
        jp.config.threads = 2
        for_blocks(body, 8, 2)                     # the parent's pool exists now
        ctx = mp.get_context("fork")
        child = ctx.Process(target=_fill_in_child)
        child.start()
        child.join(60)
        alive = child.is_alive()
        if alive:
            child.kill()
        assert not alive and child.exitcode == 0
    finally:
        jp.config.threads = None
    assert out.all()


def _fill_in_child():
    from jaxparam.blocks import for_blocks
    jp.config.threads = 2
    got = np.zeros(8)

    def body(r0, r1):
        got[r0:r1] = 1.0

    for_blocks(body, 8, 2)
    raise SystemExit(0 if got.all() else 1)


def test_squeezed_share_counts_faces_squeezed_below_their_share_of_the_area():
    from jaxparam.points.squeeze import squeezed_share
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    assert squeezed_share(F, P, P[:, :2]) == 0.0               # an isometry squeezes nothing
    U = P[:, :2].copy()
    U[3] = [0.5 + 1e-5, 0.5 + 1e-5]                            # the second face nearly flat
    assert squeezed_share(F, P, U) == 0.5
    assert squeezed_share(F[:0], P, U) == 0.0


def test_a_closed_point_set_is_refused_where_the_map_squeezed_it_and_an_open_one_is_not():
    # points on a torus (closed: the boundary detector finds a 3-point chain, and the disk map
    # squeezes 62 % of the triangles; most other samplings of it have no chain at all, which
    # meshless_map refuses) against the noisy height field (open: nothing squeezed).  Refused
    # since session 27 (a camel cut open along a slit whose sides touch, 8k samples: 83 %
    # squeezed, and 1,743 points dropped as "outliers" before); a loop the user gives is
    # trusted: the squeezed map comes back with a warning.
    torus = jp.shapes.torus(32, 16)
    V, F = np.asarray(torus.vertices), np.asarray(torus.faces)
    rng = np.random.default_rng(4)
    f = rng.choice(len(F), 3000)
    w = rng.dirichlet(np.ones(3), 3000)
    P = np.einsum("nk,nkd->nd", w, V[F[f]])
    with pytest.raises(PointCloudError, match=r"squeezed \d+ % .*closed surface.*no mesh is made"):
        jp.reconstruct_surface(P, verbose=False)
    # the user's loop: the 3 points nearest point 0, around it
    near = np.argsort(np.linalg.norm(P - P[0], axis=1))[1:40]
    loop = near[[0, int(np.argmax(np.linalg.norm(P[near] - P[near[0]], axis=1))), 20]]
    with pytest.warns(PT.squeeze.SqueezedMapWarning, match="boundary_indices given"):
        rec = jp.reconstruct_surface(P, boundary_indices=loop, verbose=False)
    assert rec.squeezed > 0.2
    P, _, _ = scan(3000, noise=0.002, seed=4)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", PT.squeeze.SqueezedMapWarning)
        rec = jp.reconstruct_surface(P, verbose=False)
    assert rec.squeezed < 0.05
