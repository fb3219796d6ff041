import numpy as np
import pytest

import jaxparam as jp


@pytest.fixture(scope="module")
def mesh_uv():
    mesh = jp.shapes.graph_surface(25)
    return mesh, np.asarray(jp.convex_map(mesh, weights="shape_preserving", boundary="square"))


def test_clough_tocher_interpolates(mesh_uv):
    mesh, uv = mesh_uv
    s = jp.fit_surface(mesh, uv, kind="clough_tocher")
    np.testing.assert_allclose(s.evaluate(uv), np.asarray(mesh.vertices), atol=1e-10)


def test_spline_approximates_and_samples(mesh_uv):
    mesh, uv = mesh_uv
    s = jp.fit_surface(mesh, uv, kind="spline")
    diag = np.linalg.norm(np.ptp(np.asarray(mesh.vertices), 0))
    assert s.residual_rms < 0.01 * diag
    patch = s.sample(20)
    assert patch.n_faces == 2 * 19 * 19 and patch.uv.shape == (400, 2)


def test_better_parameterization_gives_better_spline():
    # Survey Figs. 6 and 8: the spline through a shape-preserving map fits better than uniform.
    mesh = jp.shapes.example5(20)
    res = {w: jp.fit_surface(mesh, np.asarray(jp.convex_map(mesh, weights=w, boundary="square")),
                             kind="spline", knots=6).residual_rms
           for w in ["uniform", "shape_preserving"]}
    assert res["shape_preserving"] < res["uniform"]


def test_isocurve_picture(tmp_path, mesh_uv):
    mesh, uv = mesh_uv
    p = tmp_path / "iso.png"
    fig = jp.plot.plot_isocurves(jp.fit_surface(mesh, uv), p)
    assert fig.axes and p.stat().st_size > 5000


def test_fit_errors(mesh_uv):
    mesh, uv = mesh_uv
    with pytest.raises(jp.MeshError, match="unknown kind"):
        jp.fit_surface(mesh, uv, kind="nurbs")
    with pytest.raises(jp.MeshError, match=r"uv must have shape"):
        jp.fit_surface(mesh, uv[:5])
    # Found in QA: a non-array uv crashed inside NumPy (TypeError), not with the library's error.
    with pytest.raises(jp.MeshError, match=r"uv must be an \(N, 2\) array of parameters, got str"):
        jp.fit_surface(mesh, "uv.txt")


def test_an_atlas_is_refused_with_what_to_do_instead():
    # Found in QA: fit_surface(mesh, atlas) crashed with a TypeError; an atlas's charts lie side
    # by side, so one surface over its square is meaningless: fit one chart at a time.
    torus = jp.shapes.torus(16, 8)
    atlas = jp.atlas(torus)
    assert atlas.stats.charts > 1
    with pytest.raises(jp.MeshError, match=r"got an Atlas.*Fit one chart at a time"):
        jp.fit_surface(torus, atlas)


def test_unused_vertices_do_not_enter_the_fit(mesh_uv):
    """A vertex no face uses (a reconstruction's outlier, given its neighbour's UV) is left out:
    Clough-Tocher still interpolates every used vertex."""
    mesh, uv = mesh_uv
    V = np.vstack([np.asarray(mesh.vertices), np.asarray(mesh.vertices)[:1] + 0.5])
    U = np.vstack([np.asarray(uv), np.asarray(uv)[:1]])            # same place, another value
    with_stray = jp.TriMesh(V, mesh.faces)
    surf = jp.fit_surface(with_stray, U, kind="clough_tocher")
    np.testing.assert_allclose(np.asarray(surf.evaluate(np.asarray(uv))), np.asarray(mesh.vertices),
                               atol=1e-8)
