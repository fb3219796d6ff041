import numpy as np
import pytest

import jaxparam as jp
from jaxparam import topology as T
from jaxparam.errors import DegenerateFaceError, MeshError, NonManifoldError


def ring(t, v):
    return t.ring_idx[t.ring_ptr[v]:t.ring_ptr[v + 1]].tolist()


def test_single_triangle_loop_and_rings():
    t = T.build(np.array([[0, 1, 2]]))
    assert [l.tolist() for l in t.boundary_loops] == [[0, 1, 2]]
    assert ring(t, 0) == [1, 2]
    assert t.euler == 1 and t.genus == 0 and t.n_components == 1


def test_fan_ring_is_anticlockwise():
    # Vertex 0 at the centre of a hexagon fan.
    k = 6
    F = np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)])
    t = T.build(F)
    r = ring(t, 0)
    start = r.index(1)
    assert r[start:] + r[:start] == [1, 2, 3, 4, 5, 6]
    assert t.interior.tolist() == [0]
    assert t.boundary_loops[0].tolist() == [1, 2, 3, 4, 5, 6]
    # Boundary vertex 1: from the neighbour across its outgoing boundary edge to the incoming one.
    assert ring(t, 1) == [2, 0, 6]


def test_grid_counts(grid_mesh):
    t = grid_mesh.topology
    n = 12
    assert t.n_vertices == n * n
    assert len(t.boundary_loops) == 1 and len(t.boundary_loops[0]) == 4 * (n - 1)
    assert t.euler == 1 and t.genus == 0
    # Every interior vertex's ring closes: consecutive neighbours share a face with it.
    faces = {tuple(sorted(f)) for f in t.faces.tolist()}
    for v in t.interior[:20]:
        r = ring(t, v)
        for a, b in zip(r, r[1:] + r[:1]):
            assert tuple(sorted((v, a, b))) in faces


def test_boundary_loop_follows_face_orientation(grid_mesh):
    t = grid_mesh.topology
    loop = t.boundary_loops[0]
    directed = {(a, b) for f in t.faces.tolist() for a, b in zip(f, f[1:] + f[:1])}
    for a, b in zip(loop, np.roll(loop, -1)):
        assert (int(a), int(b)) in directed


def test_closed_and_torus_genus():
    assert jp.shapes.sphere(1).topology.genus == 0
    assert jp.shapes.sphere(1).topology.is_closed
    assert jp.shapes.torus().topology.genus == 1


def test_dividing_edges():
    # Two triangles sharing edge (0, 2); all vertices on the boundary, so (0, 2) divides.
    t = T.build(np.array([[0, 1, 2], [0, 2, 3]]))
    assert t.dividing_edges.tolist() == [[0, 2]]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dividing_edges_and_edge_faces_match_their_definitions(seed):
    """Read from the boundary rings and scattered by sorted position (not by a test over every
    edge): checked against the definitions on a strip, whose every interior edge divides, and on
    holed, shuffled grids, two components and an unreferenced vertex among them."""
    rng = np.random.default_rng(seed)
    grid = jp.shapes.plane_grid(9, 2 + seed).faces
    hole = jp.shapes.plane_grid(8, 8).faces
    hole = hole[~np.any(np.isin(hole, rng.choice(64, 3, replace=False)), axis=1)]
    F = np.r_[grid, hole + grid.max() + 2]
    F = F[rng.permutation(len(F))][:, np.roll([0, 1, 2], seed)]
    try:
        t = T.build(F)
    except NonManifoldError:     # a removed vertex left a bowtie: take the grid alone
        t = T.build(grid)
        F = grid
    n_faces = np.zeros(t.n_edges, int)
    for f, (i, j, k) in enumerate(t.faces):
        for u, v in ((i, j), (j, k), (k, i)):
            e = np.flatnonzero((t.edges[:, 0] == min(u, v)) & (t.edges[:, 1] == max(u, v)))[0]
            assert t.edge_faces[e, int(u > v)] == f        # side 0: the face running lo -> hi
            n_faces[e] += 1
    assert np.array_equal((t.edge_faces >= 0).sum(axis=1), n_faces)
    want = t.edges[t.is_boundary[t.edges[:, 0]] & t.is_boundary[t.edges[:, 1]] & (n_faces == 2)]
    assert len(want) > 0
    np.testing.assert_array_equal(t.dividing_edges, want)


def test_components_and_unreferenced():
    F = np.array([[0, 1, 2], [3, 4, 5]])
    t = T.build(F, 7)
    assert t.n_components == 2
    assert t.referenced.tolist() == [True] * 6 + [False]


def test_non_manifold_edge_error():
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(NonManifoldError, match=r"edges \(0, 1\)"):
        T.build(F)


def test_inconsistent_orientation_error():
    F = np.array([[0, 1, 2], [0, 1, 3]])
    with pytest.raises(NonManifoldError, match=r"same direction.*inconsistent"):
        T.build(F)


def test_bowtie_vertex_error():
    F = np.array([[0, 1, 2], [0, 3, 4]])
    with pytest.raises(NonManifoldError, match=r"vertices 0 .*bowtie"):
        T.build(F)


def test_index_errors():
    with pytest.raises(MeshError, match=r"faces 1 .*outside \[0, 3\)"):
        T.check_faces(np.array([[0, 1, 2], [0, 1, 5]]), 3)
    with pytest.raises(MeshError, match=r"outside"):
        T.check_faces(np.array([[0, -1, 2]]), 3)
    with pytest.raises(DegenerateFaceError, match=r"faces 0 .*repeat a vertex"):
        T.check_faces(np.array([[0, 0, 2]]), 3)
    with pytest.raises(MeshError, match=r"shape \(m, 3\)"):
        T.check_faces(np.array([[0, 1, 2, 3]]), 4)
    with pytest.raises(MeshError, match=r"no faces"):
        T.check_faces(np.zeros((0, 3), int), 4)


def test_hole_loops_longest_first():
    mesh = jp.shapes.plane_grid(7, 7)
    # Remove the faces around the centre vertex to make a hole.
    F = mesh.faces
    keep = ~np.any(F == 24, axis=1)
    t = T.build(F[keep], 49)
    assert len(t.boundary_loops) == 2
    assert len(t.boundary_loops[0]) == 24 and len(t.boundary_loops[1]) in (6, 8)
    assert t.genus == 0


@pytest.mark.parametrize("make", [lambda: jp.shapes.disk(6, seed=2), lambda: jp.shapes.torus(10, 6),
                                  lambda: jp.shapes.cylinder_patch(8, 5)])
def test_renumber_equals_a_fresh_build(make):
    mesh = make()
    n = mesh.n_vertices + 3                      # three unreferenced vertices too
    t = T.build(mesh.faces, n)
    new_id = np.random.default_rng(1).permutation(n)
    a, b = T.renumber(t, new_id), T.build(new_id[mesh.faces], n)
    for f in ("faces", "edges", "edge_faces", "ring_ptr", "ring_idx", "ring_prev", "ring_next",
              "ring_row", "ring_wedge", "is_boundary", "referenced", "interior", "boundary", "slot",
              "components", "dividing_edges"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    assert len(a.boundary_loops) == len(b.boundary_loops)
    for la, lb in zip(a.boundary_loops, b.boundary_loops):
        np.testing.assert_array_equal(la, lb)
    assert (a.n_components, a.euler, a.genus) == (b.n_components, b.euler, b.genus)


def test_a_moebius_strip_is_named_not_orientable():
    # Found in QA (session 20): a Moebius strip was told to "orient the faces consistently (e.g.
    # trimesh.repair.fix_winding)", which no winding can do.
    import jaxparam as jp
    from jaxparam.errors import NonManifoldError
    n = 24
    t = 2 * np.pi * np.arange(n) / n
    V = np.concatenate([np.stack([(1 + s * np.cos(t / 2)) * np.cos(t), (1 + s * np.cos(t / 2)) * np.sin(t),
                                  s * np.sin(t / 2)], 1) for s in (-0.3, 0.3)])
    i, j = np.arange(n), (np.arange(n) + 1) % n
    # the strip's two rims swap where it closes: the last quad joins rim 0 to rim 1
    a, b = i, np.where(j == 0, n + 0, j)
    c, d = i + n, np.where(j == 0, 0, j + n)
    F = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    with pytest.raises(NonManifoldError, match="not orientable.*fix_winding cannot help"):
        jp.TriMesh(V, F)
    # an orientable mesh with some faces flipped keeps the fix_winding advice
    m = jp.shapes.graph_surface(6)
    G = np.asarray(m.faces).copy()
    G[:7] = G[:7, ::-1]
    with pytest.raises(NonManifoldError, match="traversed in the same direction.*fix_winding"):
        jp.TriMesh(m.vertices, G)
