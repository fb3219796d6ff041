"""Boundary self-crossings through a uniform grid: exact against all pairs."""
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.metrics import boundary_crossings, segment_box_pairs


def brute_box_pairs(lo, hi):
    I, J = np.triu_indices(lo.shape[0], 1)
    m = ((lo[I, 0] <= hi[J, 0]) & (lo[J, 0] <= hi[I, 0]) & (lo[I, 1] <= hi[J, 1])
         & (lo[J, 1] <= hi[I, 1]))
    return set(zip(I[m].tolist(), J[m].tolist()))


def brute_crossings(segments, U):
    A, B = U[segments[:, 0]], U[segments[:, 1]]
    out = 0
    o = lambda p, q, r: np.sign((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))
    for i in range(len(segments)):
        for j in range(i + 1, len(segments)):
            if set(segments[i]) & set(segments[j]):
                continue
            if (o(A[i], B[i], A[j]) * o(A[i], B[i], B[j]) < 0
                    and o(A[j], B[j], A[i]) * o(A[j], B[j], B[i]) < 0):
                out += 1
    return out


@pytest.mark.parametrize("seed", range(6))
def test_box_pairs_equal_all_pairs(seed):
    """Random boxes: sparse, dense, long thin ones, points on a lattice (ties), a NaN box;
    and with pairs formed a few at a time."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(50, 400))
    lo = rng.random((k, 2)) * (1 if seed % 2 else 20)
    hi = lo + rng.random((k, 2)) ** (1 + 3 * (seed % 3)) * (0.3 if seed < 3 else 6)
    lo[::7] = np.round(lo[::7], 1)
    hi[::7] = lo[::7]
    if seed == 5:
        lo[4, 1] = np.nan
    want = brute_box_pairs(lo, hi)
    for max_pairs in (4_000_000, 37):
        i, j = segment_box_pairs(lo, hi, max_pairs=max_pairs)
        got = list(zip(i.tolist(), j.tolist()))
        assert len(got) == len(set(got)) and set(got) == want


def test_crossings_of_a_folded_boundary():
    """A disk whose boundary is folded over itself: the grid finds every crossing the
    all-pairs test finds, and none on the unfolded map."""
    mesh = jp.shapes.graph_surface(7)
    uv = np.asarray(jp.convex_map(mesh)).copy()
    S, pairs = boundary_crossings(mesh, uv)
    assert pairs.shape == (0, 2) and jp.metrics.boundary_overlaps(mesh, uv) == 0
    loop = mesh.topology.boundary_loops[0]
    rng = np.random.default_rng(3)
    uv[loop[::3]] *= -0.6 + 0.1 * rng.random((loop[::3].size, 1))     # pull through the centre
    S, pairs = boundary_crossings(mesh, uv)
    n = brute_crossings(S, uv)
    assert n > 10 and pairs.shape[0] == n == jp.metrics.boundary_overlaps(mesh, uv)
    assert np.all(pairs[:, 0] < pairs[:, 1])


def test_self_overlaps_count_each_chart_alone():
    """The atlas's per-chart count equals each chart's own count, the charts apart."""
    from jaxparam.atlas import flatten as fl
    a, b = jp.shapes.graph_surface(6), jp.shapes.graph_surface(8)
    V = np.vstack([np.asarray(a.vertices), np.asarray(b.vertices)])
    F = np.vstack([a.faces, b.faces + a.n_vertices])
    cm = fl.chart_mesh(V, F, np.r_[np.zeros(a.n_faces, int), np.ones(b.n_faces, int)])
    uv = fl.convex_start(cm)
    on = np.flatnonzero(cm.uv_chart == 1)
    rim = np.intersect1d(on, np.concatenate(cm.mesh.topology.boundary_loops))
    uv[rim[::4]] *= -0.5                      # chart 1 folds over itself; both at the origin
    got = fl.self_overlaps(cm, uv)
    want = [jp.metrics.boundary_overlaps(*(lambda m, ids: (m, uv[ids]))(*fl.sub_mesh(cm, k)))
            for k in (0, 1)]
    assert want[0] == 0 and want[1] > 0 and got.tolist() == want
