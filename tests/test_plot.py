"""jp.plot: Figures returned (no backend forced), saved when given a path at 150 dpi, round
spheres, per-pixel checker textures, robust colour limits, flipped and degenerate faces
counted apart."""
import matplotlib
import matplotlib.image as mpimg
import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure

import jaxparam as jp
from jaxparam.plot import face_states, raster, robust_limits


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


@pytest.fixture(scope="module")
def grid():
    mesh = jp.shapes.graph_surface(8)
    return mesh, np.asarray(jp.convex_map(mesh, boundary="circle"))


def image_of(fig) -> np.ndarray:
    """The RGBA image a rasterized picture shows (its first image artist)."""
    return np.asarray(fig.axes[0].images[0].get_array())


def mask_box(rgba) -> tuple[int, int]:
    """(width, height) in pixels of the covered part of a picture."""
    ys, xs = np.nonzero(rgba[..., 3] > 0.5)
    return xs.max() - xs.min() + 1, ys.max() - ys.min() + 1


def test_no_backend_forced_and_figures_returned(grid, monkeypatch, tmp_path):
    mesh, uv = grid
    before = matplotlib.get_backend()

    def refuse(*a, **k):
        raise AssertionError("jaxparam.plot must not choose matplotlib's backend")

    monkeypatch.setattr(matplotlib, "use", refuse)
    figs = [jp.plot.plot_uv(mesh, uv, size=2), jp.plot.plot_checkerboard(mesh, uv, size=2),
            jp.plot.plot_isocurves(jp.fit_surface(mesh, uv), lines=4, resolution=20, size=2),
            jp.plot.plot_remesh(jp.remesh(mesh, uv, levels=1, base_faces=4), size=2)]
    assert all(isinstance(f, Figure) for f in figs)
    assert matplotlib.get_backend() == before
    # pyplot manages them, so plt.show() and Jupyter display them
    assert all(plt.fignum_exists(f.number) for f in figs)
    assert not any(tmp_path.iterdir())               # nothing saved without a path


def test_saves_png_at_150_dpi(grid, tmp_path):
    mesh, uv = grid
    p = tmp_path / "sub" / "uv.png"
    fig = jp.plot.plot_checkerboard(mesh, uv, p, size=4.0)
    assert fig.dpi == 150
    img = mpimg.imread(p)
    # 4 inches at 150 dpi on the longer side of the picture (bbox_inches="tight" crops a little)
    assert 540 <= max(img.shape[:2]) <= 640, img.shape


@pytest.mark.parametrize("elev,azim", [(30, -60), (75, 10), (0, 90)])
def test_sphere_is_round_and_fills_the_frame(elev, azim):
    sphere = jp.shapes.sphere(2)
    uv = np.asarray(sphere.vertices)[:, :2]
    rgba = image_of(jp.plot.plot_checkerboard(sphere, uv, elev=elev, azim=azim, size=2.0))
    w, h = mask_box(rgba)
    assert abs(w / h - 1) < 0.02, (w, h)
    assert max(w, h) >= 0.94 * max(rgba.shape[:2])        # the mesh fills the frame


def test_ellipsoid_keeps_its_proportions():
    """One scale on both screen axes: an ellipsoid 2:1 seen from the side is 2:1."""
    s = jp.shapes.sphere(2)
    V = np.asarray(s.vertices) * np.array([1.0, 1.0, 2.0])
    mesh = jp.TriMesh(V, s.faces)
    rgba = image_of(jp.plot.plot_checkerboard(mesh, V[:, :2], elev=0, azim=0, size=2.0))
    w, h = mask_box(rgba)
    # a polyhedron inscribed in the ellipsoid: its silhouette ratio is near 2 but not exact
    assert abs(h / w - 2) < 0.06, (w, h)


def test_checkerboard_is_per_pixel_with_straight_squares():
    """Two triangles textured with 8 x 8 squares: per-face colours could show 2 colours, a
    per-pixel texture shows 8 squares along every row and column, edges straight."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    mesh = jp.TriMesh(V, F)
    rgba = image_of(jp.plot.plot_checkerboard(mesh, V[:, :2], squares=8, elev=90, azim=-90,
                                              size=2.0))
    ys, xs = np.nonzero(rgba[..., 3] > 0.5)
    inner = rgba[ys.min() + 2:ys.max() - 1, xs.min() + 2:xs.max() - 1, :3]
    orange = inner[..., 0] > inner[..., 2]
    for line in (orange[inner.shape[0] // 3], orange[:, inner.shape[1] // 2]):
        assert np.count_nonzero(line[1:] != line[:-1]) == 7
    # straight: every column of pixels changes colour at the same rows (up to anti-aliasing)
    cols = orange[:, 5:-5:7]
    changes = [np.flatnonzero(c[1:] != c[:-1]) for c in cols.T]
    assert all(len(c) == 7 for c in changes)
    assert np.ptp(np.stack(changes), axis=0).max() <= 1


def test_robust_limits_ignore_outliers():
    v = np.concatenate([np.linspace(0, 1, 990), np.full(10, 1e6)])
    lim = robust_limits(v, percentile=98, floor=0)
    assert lim.vmin == 0 and 0.97 < lim.vmax <= 1.0
    assert lim.above == pytest.approx(0.01 + 0.01, abs=0.002) and lim.extend == "max"
    assert "2 % of faces beyond the scale" in lim.label("log2(σ1/σ2)")
    sym = robust_limits(np.array([-3.0, -1, 0, 1, 2, 50]), percentile=50, symmetric=True)
    assert sym.vmin == -sym.vmax
    # a heavy tail above the bulk (slivers): the far fence, not the percentile, sets the top
    tail = np.concatenate([np.linspace(0, 1, 950), np.linspace(3, 30, 50)])
    lim = robust_limits(tail, percentile=98, floor=0)
    q1, q3 = np.percentile(tail, [25, 75])
    assert lim.vmax == pytest.approx(q3 + 3 * (q3 - q1)) and lim.vmax < 3


def test_plot_uv_colour_limits_come_from_percentiles(grid):
    mesh, uv = grid
    bad = uv.copy()
    inner = np.setdiff1d(np.arange(mesh.n_vertices), mesh.topology.boundary_loops[0])
    v = inner[0]
    bad[v] = bad[v] + 0.3 * (bad[inner[1]] - bad[v])          # squeeze one fan: outliers
    fig = jp.plot.plot_uv(mesh, bad)
    coll = fig.axes[0].collections[0]
    fd = jp.metrics.face_distortion(mesh, bad)
    aspect = np.log2(np.asarray(fd["s1"]) / np.abs(np.asarray(fd["s2"])))
    good = np.isfinite(aspect) & (np.asarray(fd["area_uv"]) > 0)
    assert coll.norm.vmax < aspect[good].max()
    q1, q3 = np.percentile(aspect[good], [25, 75])
    expect = min(np.percentile(aspect[good], 98), q3 + 3 * (q3 - q1))
    assert coll.norm.vmax == pytest.approx(expect)
    assert "beyond the scale" in fig.axes[1].get_ylabel()


def test_flipped_and_degenerate_counted_apart():
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [0.5, 0.4, 0]], float)
    F = np.array([[0, 1, 5], [1, 2, 5], [2, 3, 5], [3, 0, 5], [1, 4, 2]])
    mesh = jp.TriMesh(V, F)
    uv = V[:, :2].copy()
    uv[4] = [1.0, 0.5]                       # face 4 (1, 4, 2) collinear in UV: degenerate
    uv[5] = [0.5, -0.2]                      # face 0 (0, 1, 5) turned over: flipped
    st = face_states(mesh, uv)
    assert st.flipped.tolist() == [True, False, False, False, False]
    assert st.degenerate.tolist() == [False, False, False, False, True]
    assert jp.plot.plot_uv(mesh, uv).texts[0].get_text().endswith("1 flipped, 1 degenerate")


def test_square_boundary_corner_faces_are_degenerate_not_flipped():
    mesh = jp.shapes.graph_surface(8)
    uv = np.asarray(jp.convex_map(mesh, boundary="square"))
    st = face_states(mesh, uv)
    assert st.flipped.sum() == 0
    assert st.degenerate.sum() == jp.distortion(mesh, uv).flips   # the ones the metric counts


def test_rasterizer_nearest_face_wins():
    """Two parallel squares: the one nearer the camera covers the other."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                  [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    F = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    r = raster.rasterize(V, F, elev=90, azim=-90, pixels=40)
    assert set(np.unique(r.face[r.mask])) <= {2, 3}
    r = raster.rasterize(V, F, elev=-90, azim=-90, pixels=40)
    assert set(np.unique(r.face[r.mask])) <= {0, 1}
    assert r.mask.mean() > 0.9
