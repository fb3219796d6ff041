"""The relaxed samples of a closed remesh (jaxparam/manifold/relax.py, issue 13): edge midpoints
land where the dyadic grid puts them however their ends are recorded, a point on a base edge
is the same point from either side, a triangle through the three faces at a base vertex of
valence 3 is found, and no level-4 triangle turns over in the base domain where its relaxed
level-3 parent does not."""
import numpy as np
import pytest

import jaxparam as jp
from conftest import data_path
from jaxparam.manifold import manifold_map
from jaxparam.manifold.parameterization import _dyadic_samples
from jaxparam.manifold.relax import BaseDomain, around_a_vertex, relax_samples
from jaxparam.subdivision import dyadic_hierarchy

# An irregular tetrahedron: every base vertex has valence 3 and an angle sum far from 2 pi,
# so unfolding around a vertex the wrong way lands a point in the wrong place.
B = np.array([[0.0, 0.0, 0.0], [1.3, 0.1, 0.0], [0.2, 1.1, 0.1], [0.4, 0.3, 0.9]])
F0 = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def across(r: np.ndarray, b: np.ndarray):
    """``(has, g, b')``: points ``(r, b)`` on an edge of the tetrahedron written in the face
    across it (found by its vertices, independently of the library)."""
    has = (b > 1e-12).sum(1) == 2
    g, bg = r.copy(), b.copy()
    for k in np.flatnonzero(has):
        ends = F0[r[k]][b[k] > 1e-12]
        g[k] = next(f for f in range(4) if f != r[k] and set(ends) <= set(F0[f]))
        bg[k] = [b[k][F0[r[k]] == v].sum() for v in F0[g[k]]]
    return has, g, bg


def turned_over(D: BaseDomain, G: np.ndarray, r: np.ndarray, b: np.ndarray):
    """``(turned (m,) bool, decided (m,) bool)``: the triangles ``G`` over samples ``(r, b)``
    whose corners can all be drawn in one base face's chart without unfolding around a base
    vertex (each corner in that face, the face across the base edge it lies on, or a face
    sharing an edge with it; a base vertex in any face at it), and whose area there is not
    positive."""
    pinned = (b > 1e-12).sum(1) == 1
    vertex = D.F0[r, np.argmax(b, 1)]
    has, g_alt, b_alt = D.other_side(r, b)

    def drawn_in(f, v, unfold):
        rv, bv = r[v].copy(), b[v].copy()
        alt = has[v] & (g_alt[v] == f)
        rv[alt], bv[alt] = f[alt], b_alt[v][alt]
        at = D.F0[f] == vertex[v][:, None]
        pv = pinned[v] & at.any(1)
        rv[pv], bv[pv] = f[pv], at[pv].astype(np.float64)
        ok = (rv == f) | (unfold & (D.across[f] == rv[:, None]).any(1))
        return ok, D.carry(f, rv, bv)[1]

    # One face holding every corner first; then, for triangles without a base vertex, one
    # face and the faces across its edges.  (A triangle at a base vertex with its other
    # corners in faces around it can be drawn around the vertex either way, and the sectors
    # around it need not close up; one through the three faces at a base vertex of valence 3
    # goes around it, which relax_samples allows: those are left undecided.)
    turned, decided = np.zeros(G.shape[0], bool), np.zeros(G.shape[0], bool)
    at_vertex = pinned[G].any(1) | around_a_vertex(D, G, r, b)
    for unfold, c in ((u, c) for u in (False, True) for c in range(3)):
        for f in (r[G[:, c]], g_alt[G[:, c]]):
            oks, p = zip(*(drawn_in(f, G[:, k], unfold) for k in range(3)))
            ok = oks[0] & oks[1] & oks[2] & ~decided & ~(unfold & at_vertex)
            d1, d2 = p[1] - p[0], p[2] - p[0]
            area = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
            turned |= ok & ~(area > 0)
            decided |= ok
    return turned, decided


def test_edge_midpoints_land_where_the_dyadic_grid_puts_them_however_their_ends_are_recorded():
    """Every sample on a base edge recorded in the face across it: a midpoint drawn in one
    end's face with the other end unfolded around a base vertex landed in the wrong sector
    (cow: a triangle at a base vertex of valence 3 turned over)."""
    D = BaseDomain(B, F0)
    H = dyadic_hierarchy(F0, 4, 3)
    r, b = _dyadic_samples(F0, H, 2)
    has, g, bg = across(r, b)
    assert has.sum() > 0.3 * r.size
    r2, b2 = np.where(has, g, r), np.where(has[:, None], bg, b)
    rm, bm = relax_samples(D, None, H.faces[2], H.parents[-1], r2, b2, iterations=0)
    r3, b3 = _dyadic_samples(F0, H, 3)
    np.testing.assert_allclose(np.einsum("kc,kcd->kd", bm, B[F0[rm]]),
                               np.einsum("kc,kcd->kd", b3, B[F0[r3]]), atol=1e-12)


def test_the_other_side_of_a_base_edge_is_the_same_point():
    D = BaseDomain(B, F0)
    rng = np.random.default_rng(1)
    r = rng.integers(0, 4, 500)
    b = rng.dirichlet(np.ones(3), 500)
    b[np.arange(500), rng.integers(0, 3, 500)] = 0.0                  # on an edge
    b /= b.sum(1, keepdims=True)
    has, g, bg = D.other_side(r, b)
    assert has.all() and np.all(g != r)
    np.testing.assert_array_equal(g, across(r, b)[1])
    np.testing.assert_allclose(np.einsum("kc,kcd->kd", bg, B[F0[g]]), np.einsum("kc,kcd->kd", b, B[F0[r]]),
                               atol=1e-15)
    inside = D.other_side(r[:3], np.full((3, 3), 1 / 3))
    assert not inside[0].any() and np.array_equal(inside[1], r[:3])


def test_a_triangle_through_all_three_faces_at_a_base_vertex_goes_around_it():
    """Tetrahedron vertex 0 has faces 0, 1 and 2 around it: a triangle with a corner inside
    each covers the vertex; one with a corner on a base edge that can be written in a face
    another corner is in, or with the base vertex as a corner, does not need three faces."""
    D = BaseDomain(B, F0)
    near0 = lambda f: np.where(F0[f] == 0, 0.8, 0.1)                 # coordinates near vertex 0
    r = np.array([0, 1, 2, 0, 0, 1])
    b = np.stack([near0(0), near0(1), near0(2), np.eye(3)[list(F0[0]).index(0)],
                  np.where(F0[0] == 0, 0.8, np.where(F0[0] == 1, 0.2, 0.0)), near0(1)])
    # sample 4 lies on edge (0, 1), shared by faces 0 and 1
    tri = np.array([[0, 1, 2], [3, 1, 2], [4, 5, 2], [0, 1, 5]])
    np.testing.assert_array_equal(around_a_vertex(D, tri, r, b), [True, False, False, False])
    b[4] = np.where(F0[0] == 1, 0.5, np.where(F0[0] == 2, 0.5, 0.0))  # on edge (1, 2): faces 0, 3
    np.testing.assert_array_equal(around_a_vertex(D, tri[2:3], r, b), [True])


def _children_turned_over(param):
    """Level 3 relaxed and its edges' midpoints (level 4), as the remesh makes them: how many
    level-4 triangles are turned over in the base domain whose level-3 parent is not, and
    the share of triangles decided (:func:`turned_over`), for a map ``param``."""
    from jaxparam.manifold.finish import lift_with

    S = param.structure
    F0b = np.asarray(param.base_faces, np.int64)
    P = S.positions - 0.5 * (S.positions.min(0) + S.positions.max(0))
    D = BaseDomain(P[param.base_vertices], F0b)
    H = dyadic_hierarchy(F0b, int(F0b.max()) + 1, 4)
    r, b = _dyadic_samples(F0b, H, 3)
    r1, b1 = relax_samples(D, lift_with(S.history, P, np.asarray(param.mesh.faces)), H.faces[3],
                           H.parents[-1], r, b)
    parent, parent_decided = turned_over(D, H.faces[3], r1[:r.size], b1[:r.size])
    child, decided = turned_over(D, H.faces[4], r1, b1)
    ok_parent = np.repeat(parent_decided & ~parent, 4)
    return int(np.sum(child & ok_parent)), decided.mean()


def test_no_midpoint_triangle_turns_over_where_its_parent_does_not(torus_map):
    # conftest's torus(32, 16) at 40 base faces (since session 29; torus(24, 12) made its
    # own map): 0 turned over, 99.7 % decided
    turned, decided = _children_turned_over(torus_map[2])
    assert decided > 0.97
    assert turned == 0


@pytest.mark.slow          # 20 s
def test_no_midpoint_triangle_of_cow_turns_over_where_its_parent_does_not():
    """Cow at level 4 over 100 base faces had level-4 triangles turned over in the base domain
    (7 in its final samples) before the midpoints were drawn in a face both ends share."""
    turned, decided = _children_turned_over(manifold_map(jp.load(data_path("meshes", "cow.off")), 100,
                                                         verbose=False)[1])
    assert decided > 0.97
    assert turned == 0
