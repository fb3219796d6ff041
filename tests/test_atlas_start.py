"""The atlas's conformal start (jaxparam.atlas.lscm): exact where a chart is developable,
flip-free everywhere, the convex start where the conformal map folds."""
import numpy as np
import pytest

import jaxparam as jp
from jaxparam import host
from jaxparam.atlas import flatten as fl, lscm
from jaxparam.optimize import problem as pb


def charts_of(*meshes, offset=3.0):
    """Disjoint meshes side by side as one chart mesh, one chart each."""
    V = np.vstack([np.asarray(m.vertices) + [offset * i, 0.0, 0.0] for i, m in enumerate(meshes)])
    starts = np.cumsum([0] + [m.n_vertices for m in meshes[:-1]])
    F = np.vstack([m.faces + s for m, s in zip(meshes, starts)])
    chart = np.concatenate([np.full(m.n_faces, i) for i, m in enumerate(meshes)])
    return fl.chart_mesh(V, F, chart)


def sym_dirichlet(cm, uv):
    q = host.face_quantities(np.asarray(cm.mesh.vertices), cm.mesh.faces, uv)
    s1, s2, a = q["s1"], q["s2"], q["area3d"]
    sd = s1 ** 2 + s2 ** 2 + s1 ** -2.0 + s2 ** -2.0
    return np.bincount(cm.chart, weights=sd * a) / np.bincount(cm.chart, weights=a)


@pytest.fixture(scope="module")
def developable():
    """A jittered plane and a rolled-up cylinder patch (3/4 of a turn): both isometric to
    the plane, so each chart's conformal map is an isometry up to scale."""
    return charts_of(jp.shapes.plane_grid(9, 7, jitter=0.3, seed=2), jp.shapes.cylinder_patch(14, 8))


def test_conformal_start_unrolls_developable_charts(developable):
    cm = developable
    uv = lscm.conformal_start(cm)
    np.testing.assert_allclose(sym_dirichlet(cm, uv), 4.0, rtol=0, atol=1e-7)
    circle = sym_dirichlet(cm, fl.convex_start(cm))
    assert np.all(circle > 4.1)                     # the circle start is far from it


def test_pins_are_two_boundary_vertices_of_each_chart(developable):
    cm = developable
    a, b = lscm.pinned_pairs(cm)
    rim = np.concatenate(cm.mesh.topology.boundary_loops)
    assert np.isin(a, rim).all() and np.isin(b, rim).all() and np.all(a != b)
    np.testing.assert_array_equal(cm.uv_chart[a], [0, 1])
    np.testing.assert_array_equal(cm.uv_chart[b], [0, 1])
    V = np.asarray(cm.mesh.vertices)
    for k in (0, 1):                                # b is the farthest from a in its chart
        on = rim[cm.uv_chart[rim] == k]
        d = np.linalg.norm(V[on] - V[a[k]], axis=1)
        assert np.linalg.norm(V[b[k]] - V[a[k]]) == pytest.approx(d.max())


def test_conformal_map_shares_the_minimization_pattern(developable):
    """The normal matrix is assembled on the Newton Hessian's pattern: the minimization that
    follows finds it in the cache."""
    cm = developable
    lscm.conformal_map(cm)
    before = pb.hessian_pattern.cache_info()
    prob = pb.Problem(cm.mesh, jp.energies.get("symmetric_dirichlet"), True, fl.convex_start(cm))
    prob.hessian_pattern
    after = pb.hessian_pattern.cache_info()
    assert after.hits == before.hits + 1 and after.misses == before.misses


@pytest.mark.parametrize("defect", ["mirrored", "folded", "nan"])
def test_conformal_start_mirrors_or_falls_back(developable, monkeypatch, defect):
    """A chart whose conformal map came out clockwise is mirrored; one that folds or is not
    finite gets its convex start; the other chart keeps its conformal map."""
    cm = developable
    good = lscm.conformal_map(cm)
    bad = good.copy()
    on = cm.uv_chart == 1
    if defect == "mirrored":
        bad[on, 1] *= -1
    elif defect == "folded":
        idx = np.flatnonzero(on)
        bad[idx[: idx.size // 3], 0] *= -1          # a third of the chart turned over
    else:
        bad[np.flatnonzero(on)[5]] = np.nan
    monkeypatch.setattr(lscm, "conformal_map", lambda cm_: bad.copy())
    uv = lscm.conformal_start(cm)
    assert np.all(host.signed_areas(uv, cm.mesh.faces) > 0)
    ref = fl.rescale(cm, good)
    np.testing.assert_allclose(uv[~on], ref[~on], rtol=0, atol=1e-12)
    want = ref if defect == "mirrored" else fl.convex_start(cm)
    np.testing.assert_allclose(uv[on], want[on], rtol=0, atol=1e-9)


def test_self_crossing_conformal_map_falls_back(monkeypatch):
    """A conformal map whose boundary crosses itself (flip-free, but the minimization would
    keep the fold) starts on a circle instead."""
    cm = charts_of(jp.shapes.plane_grid(8, 8), jp.shapes.plane_grid(8, 8))
    good = lscm.conformal_map(cm)
    # chart 1 turned into a spiral strip: flip-free, but its outline overlaps itself
    on = cm.uv_chart == 1
    U = np.asarray(cm.mesh.vertices)[on, :2]
    U = U - U.min(0)
    r, th = 1.0 + 0.25 * U[:, 1] / U[:, 1].max(), 3.0 * np.pi * U[:, 0] / U[:, 0].max()
    swirl = good.copy()
    swirl[on] = np.stack([r * np.cos(th), r * np.sin(th)], 1)
    if np.any(host.signed_areas(swirl, cm.mesh.faces) < 0):
        swirl[on, 1] *= -1
    assert np.all(host.signed_areas(swirl, cm.mesh.faces) > 0)
    assert fl.self_overlaps(cm, swirl).tolist()[1] > 0
    monkeypatch.setattr(lscm, "conformal_map", lambda cm_: swirl.copy())
    uv = lscm.conformal_start(cm)
    assert fl.self_overlaps(cm, uv).tolist() == [0, 0]
    np.testing.assert_allclose(uv[on], fl.convex_start(cm)[on], rtol=0, atol=1e-9)


@pytest.mark.parametrize("start", ["conformal", "convex"])
def test_both_starts_give_valid_atlases(start):
    mesh = jp.shapes.torus(16, 8)
    a = jp.atlas(mesh, start=start, compact=0.0, verbose=False)
    assert a.stats.flips == 0 and a.stats.overlaps == 0
    assert a.stats.sym_dirichlet < 4.2


def test_cli_start_option(tmp_path, capsys):
    """``jaxparam atlas --start``: the two names, and a wrong one refused by the parser
    before any work, naming the choices."""
    from jaxparam.cli import main
    src = tmp_path / "t.obj"
    jp.save(src, jp.shapes.torus(12, 6))
    with pytest.raises(SystemExit) as e:
        main(["atlas", str(src), "-o", str(tmp_path / "o.obj"), "--start", "circle"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "conformal" in err and "convex" in err
    with pytest.raises(SystemExit):
        main(["atlas", "--help"])
    assert "--start" in capsys.readouterr().out
