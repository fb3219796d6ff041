"""A split round's large pieces start from their parent's map, as a problem of their own, and
stop where a cold start would (`jaxparam.atlas.flatten.warm_charts`, issue 18, session 35)."""
import numpy as np

import jaxparam as jp
from jaxparam.atlas import build
from jaxparam.atlas import flatten as fl


def test_which_charts_start_warm():
    # parent 0 has 10 faces, parent 1 has 4; the corner UVs are counterclockwise unless turned
    parent = np.array([0] * 10 + [1] * 4)
    chart = np.array([0] * 6 + [1] * 3 + [2] + [2] + [3] * 3)
    ccw = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    corner_uv = np.repeat(ccw[None], parent.size, 0)
    warm = fl.warm_charts(chart, corner_uv, parent, np.bincount(parent))
    # 6 of parent 0's 10 faces: warm; 3 of 10: cold; faces of two parents: cold; 3 of 4: warm
    assert warm.tolist() == [True, False, False, True]
    corner_uv[12] = ccw[[0, 2, 1]]                      # one turned triangle in chart 3
    assert fl.warm_charts(chart, corner_uv, parent, np.bincount(parent)).tolist() == [True, False, False, False]
    assert fl.warm_charts(chart, corner_uv, parent, np.bincount(parent), min_share=0.7).tolist() == [False] * 4


def test_a_split_charts_large_piece_starts_warm_and_ends_where_a_cold_start_does(monkeypatch):
    g = jp.shapes.graph_surface(16)
    V, F = np.asarray(g.vertices, float).copy(), g.faces
    # a tall bump: far from developable, so a conformal start is far from the minimum
    V[:, 2] = 0.8 * np.exp(-((V[:, 0] - 0.6) ** 2 + (V[:, 1] - 0.5) ** 2) / 0.03)
    mesh = jp.TriMesh(V, F)
    en = jp.energies.get("symmetric_dirichlet")
    every = np.arange(F.shape[0])
    chart = np.zeros(F.shape[0], np.int64)
    corner_uv, _, q0 = build._flatten_subset(V, F, chart, every, en, "conformal", "shape_preserving",
                                             "newton", 200)
    assert q0["flips"].sum() == 0
    # peel a sliver off one end, as a split round does: a large remainder and a small piece
    x = V[F].mean(1)[:, 0]
    small = np.flatnonzero(x <= np.quantile(x, 0.06))
    assert fl.WARM_MIN_SHARE * F.shape[0] > small.size
    split = chart.copy()
    split[small] = 1
    steps = []
    real = fl.minimize_charts

    def counted(cm, *a, **k):
        uv, res = real(cm, *a, **k)
        steps.append((k.get("cold") is not None, cm.n_charts, res.iterations))
        return uv, res

    monkeypatch.setattr(fl, "minimize_charts", counted)
    warm_uv, labels, qw = build._flatten_subset(V, F, split, every, en, "conformal", "shape_preserving",
                                                "newton", 200, prev=(corner_uv, chart))
    warm_steps = steps[:]
    steps.clear()
    cold_uv, _, qc = build._flatten_subset(V, F, split, every, en, "conformal", "shape_preserving",
                                           "newton", 200)
    # two problems with a parent's map (the large piece warm, the small one cold), one without
    assert [(w, n) for w, n, _ in warm_steps] == [(True, 1), (False, 1)]
    assert [(w, n) for w, n, _ in steps] == [(False, 2)]
    assert warm_steps[0][2] < steps[0][2]                # measured 7 Newton steps against 13
    assert qw["flips"].sum() == 0 and qw["overlaps"][0] == 0
    assert np.array_equal(qw["overlaps"], qc["overlaps"])    # the cold piece's are its own
    # the same minimum: the energies per chart agree to 1e-6 (4 at an isometry)
    np.testing.assert_allclose(qw["sym_dirichlet"], qc["sym_dirichlet"], rtol=1e-6)
