"""Differentiable pipeline (issue 12 item 4): ``wavelets.compress``, ``remesh`` through the
parameterization, ``fit_surface`` (spline and Clough–Tocher), each with its discrete choices held
fixed (kept-coefficient mask; located faces and boundary segments; knots, zero columns and rank;
triangulation and containing triangles).

Each gradient is checked against central finite differences along a random direction, with the
tolerance stated per case; the forward values are checked against fingerprints recorded from
the code before this change (``BEFORE``: a weighted sum of each array, its size and its number
of ``nan``; recorded with the cases built as in ``_remesh_cases`` / ``_fit_cases``).
"""
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.interpolate import CloughTocher2DInterpolator, LSQBivariateSpline
from scipy.spatial import Delaunay

import jaxparam as jp
from jaxparam.errors import MeshError

# Recorded from the code before the change (remesh/compress: jaxparam at HEAD, re-recorded under
# issue 15 when remesh began snapping boundary samples onto the input's boundary vertices; fit: SciPy's
# LSQBivariateSpline and CloughTocher2DInterpolator as fit_surface called them).
BEFORE = {
    'remesh/g12_circle_l3/X': (1.0793041550929787, 651, 0),
    'remesh/disk5_l3/X': (3.2269274820158227, 651, 0),
    'remesh/disk5_l2_b5/X': (3.1611862285664962, 153, 0),
    'remesh/g8_l3/X': (1.064726226999871, 651, 0),
    'remesh/ex5_square/X': (5.581266198817979, 123, 0),
    'compress/g12_circle_l3/lazy/0.02/X': (1.3666773383787953, 651, 0),
    'compress/g12_circle_l3/lazy/0.1/X': (1.1067695171692924, 651, 0),
    'compress/g12_circle_l3/lazy/0.37/X': (1.1547725094074233, 651, 0),
    'compress/g12_circle_l3/lifted/0.02/X': (1.1668656639406083, 651, 0),
    'compress/g12_circle_l3/lifted/0.1/X': (0.9232191486302108, 651, 0),
    'compress/g12_circle_l3/lifted/0.37/X': (1.1004464982859885, 651, 0),
    'compress/disk5_l3/lazy/0.02/X': (2.624082452671033, 651, 0),
    'compress/disk5_l3/lazy/0.1/X': (2.973417081777792, 651, 0),
    'compress/disk5_l3/lazy/0.37/X': (3.2170239453768295, 651, 0),
    'compress/disk5_l3/lifted/0.02/X': (2.744728368809199, 651, 0),
    'compress/disk5_l3/lifted/0.1/X': (3.0553968210846696, 651, 0),
    'compress/disk5_l3/lifted/0.37/X': (3.2031822235975493, 651, 0),
    'compress/disk5_l2_b5/lazy/0.02/X': (2.903027997988679, 153, 0),
    'compress/disk5_l2_b5/lazy/0.1/X': (3.275095242817149, 153, 0),
    'compress/disk5_l2_b5/lazy/0.37/X': (3.26396501261455, 153, 0),
    'compress/disk5_l2_b5/lifted/0.02/X': (3.23518295158855, 153, 0),
    'compress/disk5_l2_b5/lifted/0.1/X': (3.4038140464454836, 153, 0),
    'compress/disk5_l2_b5/lifted/0.37/X': (3.244377354722382, 153, 0),
    'compress/g8_l3/lazy/0.02/X': (0.9675770092837095, 651, 0),
    'compress/g8_l3/lazy/0.1/X': (1.1369673163197387, 651, 0),
    'compress/g8_l3/lazy/0.37/X': (1.1455131177499414, 651, 0),
    'compress/g8_l3/lifted/0.02/X': (1.1150568128853386, 651, 0),
    'compress/g8_l3/lifted/0.1/X': (1.0014776845176565, 651, 0),
    'compress/g8_l3/lifted/0.37/X': (1.1045383124504682, 651, 0),
    'compress/ex5_square/lazy/0.02/X': (5.091269450903831, 123, 0),
    'compress/ex5_square/lazy/0.1/X': (5.58126619881799, 123, 0),
    'compress/ex5_square/lazy/0.37/X': (5.581266198817995, 123, 0),
    'compress/ex5_square/lifted/0.02/X': (5.068656563801924, 123, 0),
    'compress/ex5_square/lifted/0.1/X': (5.314259879637661, 123, 0),
    'compress/ex5_square/lifted/0.37/X': (5.581266198817996, 123, 0),
    'fit/g25/spline/None/eval': (-3.7412544758558717, 1056, 6),
    'fit/g25/spline/None/sampleX': (5.549349698564786, 675, 0),
    'fit/g25/spline/6/eval': (-3.7311150886775093, 1056, 6),
    'fit/g25/spline/6/sampleX': (5.519084751348626, 675, 0),
    'fit/g25/spline/2/eval': (-3.8120398655880026, 1056, 6),
    'fit/g25/spline/2/sampleX': (5.528434911974971, 675, 0),
    'fit/g25/clough_tocher/None/eval': (-3.746051958713495, 1056, 6),
    'fit/g25/clough_tocher/None/sampleX': (-8.669954236206124, 669, 0),
    'fit/ex5/spline/None/eval': (13.933418503370643, 1056, 6),
    'fit/ex5/spline/None/sampleX': (58.18307867159612, 675, 0),
    'fit/ex5/spline/6/eval': (13.933418503370643, 1056, 6),
    'fit/ex5/spline/6/sampleX': (58.18307867159612, 675, 0),
    'fit/ex5/spline/2/eval': (16.61968165458476, 1056, 6),
    'fit/ex5/spline/2/sampleX': (48.14076063352192, 675, 0),
    'fit/ex5/clough_tocher/None/eval': (18.684716877060772, 1056, 12),
    'fit/ex5/clough_tocher/None/sampleX': (20.892859251771725, 663, 0),
    'fit/disk5/spline/None/eval': (-1.7640991346672088, 1056, 6),
    'fit/disk5/spline/None/sampleX': (-8.971817236010203, 675, 0),
    'fit/disk5/spline/6/eval': (346.3512629635957, 1056, 6),
    'fit/disk5/spline/6/sampleX': (213.54168121007353, 675, 0),
    'fit/disk5/spline/2/eval': (-1.4776571593584253, 1056, 6),
    'fit/disk5/spline/2/sampleX': (-9.366108702901677, 675, 0),
    'fit/disk5/clough_tocher/None/eval': (5.637215325053287, 1056, 228),
    'fit/disk5/clough_tocher/None/sampleX': (-1.244802421432604, 435, 0),
}


def fingerprint(x):
    x = np.asarray(x, float).ravel()
    fin = np.isfinite(x)
    w = np.cos(np.arange(x.size) * 0.7 + 0.3)
    return float(np.sum(np.where(fin, x, 0) * w)), x.size, int((~fin).sum()), float(np.sum(np.abs(x[fin])))


def _remesh_cases():
    m1 = jp.shapes.graph_surface(12)
    yield "g12_circle_l3", m1, jp.convex_map(m1, weights="mean_value", boundary="circle"), dict(levels=3)
    m2 = jp.shapes.disk(5, seed=1, height=0.3)
    uv2 = jp.convex_map(m2)
    yield "disk5_l3", m2, uv2, dict(levels=3)
    yield "disk5_l2_b5", m2, uv2, dict(levels=2, base_faces=5)
    m3 = jp.shapes.graph_surface(8)
    yield "g8_l3", m3, jp.convex_map(m3), dict(levels=3)
    m4 = jp.shapes.example5(9)
    loop = list(m4.topology.boundary_loops[0])
    corners = [loop.index(v) for v in sorted([0, 8, 72, 80], key=loop.index)]
    yield "ex5_square", m4, jp.convex_map(m4, boundary="square", corners=corners), dict(levels=2, corners=corners)


def _fit_cases():
    rng = np.random.default_rng(0)
    for name, mesh, w in (("g25", jp.shapes.graph_surface(25), dict(weights="shape_preserving", boundary="square")),
                          ("ex5", jp.shapes.example5(20), dict(weights="uniform", boundary="square")),
                          ("disk5", jp.shapes.disk(5, seed=1, height=0.3), {})):
        uv = np.asarray(jp.convex_map(mesh, **w))
        lo, hi = uv.min(0), uv.max(0)
        Q = np.concatenate([lo + (hi - lo) * rng.random((300, 2)), uv[:50],
                            [[lo[0] - 1, lo[1]], [hi[0] + 0.5, hi[1] + 0.5]]])
        yield name, mesh, uv, Q


def check(key, x, rtol):
    s, n, nans, l1 = fingerprint(x)
    s0, n0, nans0 = BEFORE[key]
    assert (n, nans) == (n0, nans0), key
    assert abs(s - s0) <= rtol * l1, (key, s, s0, abs(s - s0) / l1)


# (20-30 s on a 2-core AMD EPYC: with the slow tests since session 27, when the always-on suite
# took 877 s there; the gradient and jit tests of remesh and compress stay always on)
@pytest.mark.slow
def test_remesh_and_compress_values_are_unchanged():
    # Bitwise in practice (concrete UVs take the numpy path as before; the mask is the same
    # stable ranking); 1e-14 of the L1 norm leaves room for summation order only.
    for name, mesh, uv, kw in _remesh_cases():
        semi = jp.remesh(mesh, uv, **kw)
        check(f"remesh/{name}/X", semi.mesh.vertices, 1e-14)
        for wavelet in ("lazy", "lifted"):
            for keep in (0.02, 0.1, 0.37):
                check(f"compress/{name}/{wavelet}/{keep}/X",
                      jp.wavelets.compress(semi, keep, wavelet=wavelet).mesh.vertices, 1e-14)


def test_fit_surface_values_are_unchanged():
    # Clough–Tocher: SciPy's values, bitwise.  Spline: FITPACK's least-squares solution, now
    # solved in JAX/NumPy: 1e-9 of the L1 norm (measured <= 3e-10 relative, the worst the
    # rank-deficient disk5 / 6 knots case with more coefficients than points).
    # (The spline's keys went in session 20: its default is now a penalized fit, defined on
    # the parameters' hull; test_spline_matches_fitpack_on_the_same_knots compares its
    # smoothing=0 with LSQBivariateSpline directly.)
    for name, mesh, uv, Q in _fit_cases():
        for kind, knots in (("clough_tocher", None),):
            s = jp.fit_surface(mesh, uv, kind=kind, knots=knots)
            rtol = 1e-15 if kind == "clough_tocher" else 1e-9
            check(f"fit/{name}/{kind}/{knots}/eval", s.evaluate(Q), rtol)
            check(f"fit/{name}/{kind}/{knots}/sampleX", s.sample(15).vertices, rtol)


# ---------------------------------------------------------------------------------------------
# Finite differences


def directional(f, x, d, h, g=None):
    """``(grad f . d, central difference of f along d)`` (``g``: ``grad f`` at ``x`` if known)."""
    g = jax.grad(f)(x) if g is None else g
    return float(jnp.sum(g * d)), (float(f(x + h * d)) - float(f(x - h * d))) / (2 * h)


def assert_fd(f, x, d, h, rtol, g=None):
    g, fd = directional(f, x, d, h, g)
    assert abs(g - fd) <= rtol * abs(fd), (g, fd, abs(g - fd) / abs(fd))


def generic(mesh, seed=7, size=0.01):
    """The mesh's vertices moved by ``size`` at random: the generated disks and grids are
    symmetric, which puts some remesh sample points exactly on a boundary-polygon vertex (e.g.
    the base corner at half the arc length), where the remesh is only one-sided differentiable."""
    return jnp.asarray(mesh.vertices) + size * np.random.default_rng(seed).normal(size=mesh.vertices.shape)


# (the disk, 20 s, with the slow tests since session 20; the graph surface, 39 s cold on a
# 2-core AMD EPYC, since session 27: test_remesh.py::test_remesh_is_differentiable_in_the_
# vertex_positions stays always on)
@pytest.mark.slow
@pytest.mark.parametrize("name", ["disk", "graph"])
def test_remesh_gradient_follows_the_sample_points_through_convex_map(name):
    mesh = jp.shapes.disk(5, seed=1, height=0.3) if name == "disk" else jp.shapes.graph_surface(8)
    F, V0 = mesh.faces, generic(mesh)
    n = jp.remesh(mesh, jp.convex_map(mesh), levels=3).mesh.n_vertices
    W = jnp.asarray(np.random.default_rng(2).normal(size=(n, 3)))

    def loss(V, uv=None):
        m = jp.TriMesh(V, F)
        return jnp.sum(W * jp.remesh(m, jp.convex_map(m) if uv is None else uv, levels=3).mesh.vertices)

    D = jnp.asarray(np.random.default_rng(1).normal(size=V0.shape))
    assert_fd(loss, V0, D, 1e-6, 1e-6)               # measured ~6e-10 (disk), ~8e-10 (graph)
    # With the UVs held (the derivative before this change) the chain is far off.
    uv0 = np.asarray(jp.convex_map(jp.TriMesh(V0, F)))
    g_held = float(jnp.sum(jax.grad(lambda V: loss(V, uv0))(V0) * D))
    fd = directional(loss, V0, D, 1e-6)[1]
    assert abs(g_held - fd) > 0.1 * abs(fd)         # measured 0.54 (disk), 0.84 (graph)


@pytest.mark.slow
def test_traced_remesh_matches_the_concrete_one_and_moves_with_the_uvs():
    for name, mesh, uv, kw in _remesh_cases():
        ref = jp.remesh(mesh, uv, **kw)
        uv = jnp.asarray(uv)
        (X, q), (dX, dq) = jax.jvp(lambda u: (lambda s: (s.mesh.vertices, s.uv))(jp.remesh(mesh, u, **kw)),
                                   (uv,), (jnp.ones_like(uv),))
        np.testing.assert_allclose(np.asarray(X), np.asarray(ref.mesh.vertices), rtol=0, atol=1e-14)
        np.testing.assert_allclose(np.asarray(q), np.asarray(ref.uv), rtol=0, atol=1e-14)
        # A translation of the UVs moves every sample point with it and no remesh vertex.
        np.testing.assert_allclose(np.asarray(dq), 1.0, atol=1e-12)
        np.testing.assert_allclose(np.asarray(dX), 0.0, atol=1e-12)


def test_remesh_under_jit_needs_concrete_uvs():
    mesh = jp.shapes.graph_surface(8)
    uv = jp.convex_map(mesh)
    with pytest.raises(MeshError, match="remesh: the UVs are traced without a value.*outside jax.jit"):
        jax.jit(lambda u: jp.remesh(mesh, u, levels=1).mesh.vertices)(uv)
    # Traced vertices with concrete UVs compile.
    f = jax.jit(lambda V: jp.remesh(jp.TriMesh(V, mesh.faces, validate=False), uv, levels=2).mesh.vertices)
    np.testing.assert_allclose(np.asarray(f(jnp.asarray(mesh.vertices))),
                               np.asarray(jp.remesh(mesh, uv, levels=2).mesh.vertices), atol=1e-15)


@pytest.mark.parametrize("wavelet", ["lazy", "lifted"])
def test_compress_gradient_with_the_mask_held(wavelet):
    mesh = jp.shapes.disk(5, seed=1, height=0.3)
    semi = jp.remesh(mesh, jp.convex_map(mesh), levels=3)
    # Generic positions: the disk's symmetry gives equal scores, a tie at the cut.
    X0 = generic(semi.mesh, seed=9, size=1e-3)
    W = jnp.asarray(np.random.default_rng(3).normal(size=X0.shape))
    D = jnp.asarray(np.random.default_rng(4).normal(size=X0.shape))

    def loss(X):
        return jnp.sum(W * jp.wavelets.compress(semi.with_vertices(X), 0.1, wavelet=wavelet).mesh.vertices)

    g = jax.grad(loss)(X0)                           # (once for both checks: 1-3 s eagerly)
    assert_fd(loss, X0, D, 1e-6, 1e-8, g)            # linear for a fixed mask: measured ~1e-11
    # Not the identity: the dropped coefficients carry no derivative.
    assert float(jnp.abs(g - W).max()) > 1e-3
    # Under jit: the same mask (top_k on the same scores), the same values.
    small = jp.wavelets.compress(semi.with_vertices(X0), 0.1, wavelet=wavelet)
    jitted = jax.jit(lambda X: jp.wavelets.compress(semi.with_vertices(X), 0.1, wavelet=wavelet).mesh.vertices)
    np.testing.assert_allclose(np.asarray(jitted(X0)), np.asarray(small.mesh.vertices), atol=1e-14)


# (18-23 s on a 2-core AMD EPYC, an eager gradient through every step: with the slow tests
# since the always-on suite took 678 s; its pieces stay always on: tests/test_gradients.py::
# test_convex_map (vertices -> convex_map), tests/test_remesh_faithful.py::test_boundary_
# samples_snap_onto_the_input_boundary_corners (remesh of traced UVs: the values and a
# translation's tangent), tests/test_remesh.py::test_remesh_is_differentiable_in_the_vertex_
# positions (remesh -> wavelets in the positions) and test_compress_gradient_with_the_mask_held
# above (compress))
@pytest.mark.slow
def test_the_whole_pipeline_is_differentiable():
    # vertices -> convex_map -> remesh -> compress -> loss: every step's derivative composed.
    # (Two levels since session 29: three compiled about a fifth more eager kernels, 454
    # against 376, for the same chain; the always-on check of traced UVs through remesh.)
    mesh = jp.shapes.disk(5, seed=1, height=0.3)
    F, V0 = mesh.faces, generic(mesh)
    n = jp.remesh(mesh, jp.convex_map(mesh), levels=2).mesh.n_vertices
    W = jnp.asarray(np.random.default_rng(5).normal(size=(n, 3)))

    def loss(V):
        m = jp.TriMesh(V, F)
        semi = jp.remesh(m, jp.convex_map(m), levels=2)
        return jnp.sum(W * jp.wavelets.compress(semi, 0.2).mesh.vertices)

    assert_fd(loss, V0, jnp.asarray(np.random.default_rng(6).normal(size=V0.shape)), 1e-6, 1e-6)


# ---------------------------------------------------------------------------------------------
# fit_surface


def _knots(U, nk):
    lo, hi = U.min(0), U.max(0)
    eps = 1e-9 * max(hi[0] - lo[0], hi[1] - lo[1])
    return (np.linspace(lo[0], hi[0], nk + 2)[1:-1], np.linspace(lo[1], hi[1], nk + 2)[1:-1],
            [lo[0] - eps, hi[0] + eps, lo[1] - eps, hi[1] + eps])


@pytest.mark.parametrize("name,knots", [("g25_square", None), ("g25_circle", None), ("g25_circle", 6),
                                        ("g60_circle", None), ("disk5", None), ("disk5", 6), ("ex5", 6)])
def test_spline_matches_fitpack_on_the_same_knots(name, knots):
    # g25/g60 circle: basis functions in the empty corners (zero columns); disk5 with 6 knots:
    # 100 coefficients for 91 points (FITPACK's minimum-norm solution).
    mesh = {"g25": jp.shapes.graph_surface(25), "g60": jp.shapes.graph_surface(60),
            "disk5": jp.shapes.disk(5, seed=1, height=0.3), "ex5": jp.shapes.example5(20)}[name.split("_")[0]]
    boundary = "square" if name.endswith("square") or name == "ex5" else "circle"
    U = np.asarray(jp.convex_map(mesh, boundary=boundary))
    X = np.asarray(mesh.vertices)
    nk = knots if knots is not None else int(np.clip(np.sqrt(len(U)) / 3, 2, 40))
    tu, tv, box = _knots(U, nk)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = [LSQBivariateSpline(U[:, 0], U[:, 1], X[:, c], tu, tv, bbox=box, kx=3, ky=3) for c in range(3)]
    s = jp.fit_surface(mesh, U, kind="spline", knots=knots, smoothing=0)
    lo, hi = U.min(0), U.max(0)
    Q = np.concatenate([U, lo + (hi - lo) * np.random.default_rng(0).random((500, 2))])
    # the surface is defined on the parameters' convex hull (nan outside)
    from scipy.spatial import ConvexHull
    eq = ConvexHull(U).equations
    reach = (Q @ eq[:, :2].T + eq[:, 2]).max(1)          # > 0 outside the hull
    got = s.evaluate(Q)
    assert isinstance(got, np.ndarray)
    assert np.all(np.isnan(got[reach > 1e-6])) and np.all(np.isfinite(got[reach < -1e-6]))
    Q, got = Q[reach < -1e-6], got[reach < -1e-6]
    want = np.column_stack([r.ev(Q[:, 0], Q[:, 1]) for r in ref])
    err = np.abs(got - want).max() / np.abs(want).max()
    # measured <= 1.2e-7 inside the hull (g25_circle, the rank-deficient disk5 / 6 knots; until
    # session 20 the rectangle's corners, where both swing far, were in the denominator: 3.2e-10)
    assert err < 5e-7, err


def _fit_fixture(name):
    mesh = jp.shapes.disk(5, seed=1, height=0.3) if name == "disk" else jp.shapes.graph_surface(8)
    X0 = jnp.asarray(mesh.vertices)
    U0 = jnp.asarray(jp.convex_map(mesh, boundary="circle" if name == "disk" else "square"))
    lo, hi = np.asarray(U0).min(0), np.asarray(U0).max(0)
    rng = np.random.default_rng(8)
    Q = lo + (hi - lo) * (0.1 + 0.8 * rng.random((80, 2)))
    # places inside the parameters' hull, where both surfaces are defined (the disk's circle
    # leaves the rectangle's corners out)
    Q = Q[Delaunay(np.asarray(U0)).find_simplex(Q) >= 0]
    interior = (np.asarray(U0) > lo + 1e-6).all(1) & (np.asarray(U0) < hi - 1e-6).all(1)
    return mesh, X0, U0, Q, interior, rng


SPLINE_CASES = [pytest.param("disk", None, marks=pytest.mark.slow), ("disk", 6),
                pytest.param("graph", None, marks=pytest.mark.slow),
                pytest.param("graph", 6, marks=pytest.mark.slow)]


def _spline_case(name, knots):
    """The fixture, the weights and the directions, drawn in one order for both tests below
    (``rng`` goes on to draw the residual's and the sample's, as before the split)."""
    mesh, X0, U0, Q, interior, rng = _fit_fixture(name)
    W = jnp.asarray(rng.normal(size=(len(Q), 3)))
    dX = jnp.asarray(rng.normal(size=X0.shape))
    dU = jnp.asarray(rng.normal(size=U0.shape) * interior[:, None] * 1e-2)          # bbox points held
    dq = jnp.asarray(rng.normal(size=Q.shape) * 1e-2)
    return X0, U0, jnp.asarray(Q), W, dX, dU, dq, rng


# (the graph surface's default-knot case, 11 s, and Clough-Tocher's, 16 s, run with the slow
# tests since session 20, when the always-on suite reached its 10 minutes; the disk's stay,
# its default knots' 30 s excepted since session 27: the disk with 6 knots stays always on;
# its checks in the UVs, of the residual and of a sampled patch are in test_spline_gradients_
# in_the_uvs_the_residual_and_a_sample below, with the slow tests since the always-on suite
# took 678 s: the same fit's derivative in X and in the evaluation places stays here)
@pytest.mark.parametrize("name,knots", SPLINE_CASES)
def test_spline_gradients(name, knots):
    X0, U0, Qj, W, dX, dU, dq, _ = _spline_case(name, knots)

    def in_X(X):
        return jnp.sum(W * jp.fit_surface(X, U0, kind="spline", knots=knots).evaluate(Qj))

    s0 = jp.fit_surface(X0, U0, kind="spline", knots=knots)

    def in_q(q):
        return jnp.sum(W * s0.evaluate(q))

    assert_fd(in_X, X0, dX, 1e-5, 1e-9)                                               # linear: ~1e-11
    assert_fd(in_q, Qj, dq, 1e-4, 1e-7)                                               # measured <= 3e-9


# (with the slow tests since the always-on suite took 678 s, 6 s of the disk's 16: the fit's
# derivative in X, through the same solve, stays always on in test_spline_gradients[disk-6])
@pytest.mark.slow
@pytest.mark.parametrize("name,knots", SPLINE_CASES)
def test_spline_gradients_in_the_uvs_the_residual_and_a_sample(name, knots):
    X0, U0, Qj, W, dX, dU, dq, rng = _spline_case(name, knots)

    def in_uv(U):                     # the knots stay where the concrete bbox put them
        return jnp.sum(W * jp.fit_surface(X0, U, kind="spline", knots=knots).evaluate(Qj))

    s0 = jp.fit_surface(X0, U0, kind="spline", knots=knots)
    assert_fd(in_uv, U0, dU, 1e-4, 1e-7)                                              # measured <= 3e-9
    # The residual too (where the spline does not interpolate: 6 knots give more coefficients
    # than points; a step well below the residual, which is a norm), and a sampled patch.
    res = float(s0.residual_rms)
    # (graph, 6 knots: 100 coefficients for 81 points nearly interpolate under the default
    # penalty, res 6e-6 of a unit-size surface, where the finite differences are noise)
    if res > 1e-4 * float(jnp.abs(X0).max()):
        assert_fd(lambda X: jp.fit_surface(X, U0, kind="spline", knots=knots).residual_rms, X0,
                  jnp.asarray(rng.normal(size=X0.shape)), 1e-4 * res, 1e-6)
    assert_fd(lambda X: jnp.sum(jp.fit_surface(X, U0, kind="spline", knots=knots).sample(6).vertices ** 2),
              X0, jnp.asarray(rng.normal(size=X0.shape)), 1e-5, 1e-8)


def exact_ct(U, X, q):
    """SciPy's Clough–Tocher with its gradient estimate converged (tol 1e-14): the map whose
    derivative fit_surface returns."""
    f = CloughTocher2DInterpolator(Delaunay(np.asarray(U)), np.asarray(X), tol=1e-14, maxiter=100000)
    return np.asarray(f(np.asarray(q))).reshape(-1, 3)


# (36 s cold on a 2-core AMD EPYC: with the slow tests since session 27; Clough-Tocher under
# jit and its values against SciPy's stay always on)
@pytest.mark.slow
@pytest.mark.parametrize("name", ["disk", "graph"])
def test_clough_tocher_gradients(name):
    mesh, X0, U0, Q, interior, rng = _fit_fixture(name)
    s0 = jp.fit_surface(X0, U0, kind="clough_tocher")
    Q = Q[np.isfinite(s0.evaluate(Q)).all(1)]
    Qj = jnp.asarray(Q)
    W = jnp.asarray(rng.normal(size=(len(Q), 3)))
    dX = jnp.asarray(rng.normal(size=X0.shape))
    dU = jnp.asarray(rng.normal(size=U0.shape) * interior[:, None] * 1e-2)
    dq = jnp.asarray(rng.normal(size=Q.shape) * 1e-2)
    cases = [  # (function of the public API, the exactly solved interpolant, point, direction, h)
        (lambda X: jnp.sum(W * jp.fit_surface(X, U0, kind="clough_tocher").evaluate(Qj)),
         lambda X: np.sum(np.asarray(W) * exact_ct(U0, X, Q)), X0, dX, 1e-5),
        (lambda U: jnp.sum(W * jp.fit_surface(X0, U, kind="clough_tocher").evaluate(Qj)),
         lambda U: np.sum(np.asarray(W) * exact_ct(U, X0, Q)), U0, dU, 1e-4),
        (lambda q: jnp.sum(W * s0.evaluate(q)),
         lambda q: np.sum(np.asarray(W) * exact_ct(U0, X0, q)), Qj, dq, 1e-4),
    ]
    for public, exact, x, d, h in cases:
        g = float(jnp.sum(jax.grad(public)(x) * d))
        fd_exact = (exact(x + h * d) - exact(x - h * d)) / (2 * h)
        assert abs(g - fd_exact) <= 1e-7 * abs(fd_exact), (g, fd_exact)         # measured <= ~3e-9
        # Against SciPy's own values (Gauss–Seidel stopped at 1e-6): the gap of the estimate.
        fd = (float(public(x + h * d)) - float(public(x - h * d))) / (2 * h)
        assert abs(g - fd) <= 1e-4 * abs(fd), (g, fd)                             # measured <= 4e-6
    # The forward values under grad are SciPy's.
    val = jax.jvp(lambda X: jp.fit_surface(X, U0, kind="clough_tocher").evaluate(Qj), (X0,), (dX,))[0]
    np.testing.assert_array_equal(np.asarray(val), s0.evaluate(Q))


@pytest.mark.parametrize("kind", ["spline", "clough_tocher"])
def test_fit_surface_under_jit(kind):
    mesh, X0, U0, Q, interior, rng = _fit_fixture("disk")
    Q = np.concatenate([Q, [[5.0, 5.0]]])                    # one place outside: nan
    s0 = jp.fit_surface(X0, U0, kind=kind)
    want = s0.evaluate(Q)
    f = jax.jit(lambda X, q: jp.fit_surface(X, U0, kind=kind).evaluate(q))
    got = np.asarray(f(X0, jnp.asarray(Q)))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
    assert np.isnan(got[-1]).all()
    g = jax.jit(jax.grad(lambda X: jnp.sum(jp.fit_surface(X, U0, kind=kind).evaluate(Q[:-1]) ** 2)))(X0)
    # The jitted gradient against a central difference of the jitted forward ``f`` (compiled
    # above) along a random direction, not against an eager jax.grad (6-8 s of Clough-Tocher's
    # 12; the eager gradients are checked in test_spline_gradients and, with the slow tests,
    # test_clough_tocher_gradients).  The loss is quadratic in X (both fits are linear in X
    # for a fixed triangulation and fixed knots), so the difference is exact but for rounding
    # and, for Clough-Tocher, SciPy's gradient estimate stopped at 1e-6: measured 3e-13
    # (spline), 7.5e-8 (Clough-Tocher).
    loss = lambda X: float(np.sum(np.asarray(f(X, jnp.asarray(Q)))[:-1] ** 2))
    d = jnp.asarray(rng.normal(size=X0.shape))
    h = 1e-3
    fd = (loss(X0 + h * d) - loss(X0 - h * d)) / (2 * h)
    assert abs(float(jnp.vdot(g, d)) - fd) <= 1e-6 * abs(fd), (float(jnp.vdot(g, d)), fd)
    with pytest.raises(MeshError, match="fit_surface: uv is traced without a value.*outside jax.jit"):
        jax.jit(lambda U: jp.fit_surface(X0, U, kind=kind).evaluate(Q))(U0)
