"""The cheap paths of one-off calls (issue 17, item 4): NumPy twins of the JAX kernels.

With concrete inputs the weights, the eq. (4) assembly, the scatter and the report's per-face
quantities are computed in NumPy (no tracing or compilation).  Each must equal the JAX path:
bounds below are measured with margin (``uniform`` is bitwise; the rest differ where XLA's and
libm's transcendental functions round differently).  Under ``jax.grad`` the JAX path is used.
"""
import inspect

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam import combination as comb
from jaxparam import host
from jaxparam import linear
from jaxparam import metrics
from jaxparam import weights as wts
from jaxparam.cli import pipeline

KINDS = wts.KINDS
BOUNDARIES = ("circle", "square", "plane")


@pytest.fixture(scope="module")
def meshes():
    """Small disks with uneven valences: a jittered grid, a lifted disk, a graph surface with a
    hole (filled virtually by convex_map)."""
    g = jp.shapes.graph_surface(9, jitter=0.3, seed=1)
    d = jp.shapes.disk(5, seed=3, height=0.2)
    holed = jp.shapes.plane_grid(8, 8, jitter=0.2, seed=2)
    centre = int(np.argmin(np.linalg.norm(holed.vertices[:, :2] - [0.5, 0.5], axis=1)))
    keep = ~np.any(holed.faces == centre, axis=1)   # the faces around one vertex: an inner hole
    holed = jp.TriMesh(holed.vertices, holed.faces[keep])
    return {"graph": g, "disk": d, "holed": holed}


@pytest.mark.parametrize("kind", KINDS)
def test_host_weights_equal_jax_kernel(meshes, kind):
    for name, mesh in meshes.items():
        work, _ = linear.fill_holes(mesh)
        a = np.asarray(wts.entry_weights(work.vertices, work.topology, kind)[0])
        b, sym = wts.entry_weights(work.vertices, work.topology, kind, host=True)
        assert isinstance(b, np.ndarray) and sym == (kind in wts.SYMMETRIC_KINDS)
        np.testing.assert_allclose(b, a, rtol=1e-13, atol=1e-13, err_msg=f"{name} {kind}")
        if kind == "uniform":
            assert np.array_equal(a, b)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("boundary", BOUNDARIES)
def test_host_convex_map_equals_jax_path(meshes, kind, boundary):
    for name in ("graph", "holed"):
        mesh = meshes[name]
        a = np.asarray(jp.convex_map(mesh, weights=kind, boundary=boundary))
        b = jp.convex_map(mesh, weights=kind, boundary=boundary, host=True)
        assert isinstance(b, np.ndarray) and b.shape == a.shape
        assert np.array_equal(np.isnan(a), np.isnan(b)), name
        scale = np.nanmax(np.abs(a))
        assert np.nanmax(np.abs(a - b)) <= 1e-12 * scale, f"{name} {kind} {boundary}"


def test_host_assembly_equals_jax_kernel(meshes):
    mesh = meshes["graph"]
    t = mesh.topology
    S = linear.interior_system(t)
    w = wts.host_entry_weights(mesh.vertices, t, "mean_value")
    uv_b = np.random.default_rng(0).normal(size=(t.boundary.size, 2))
    for normalize in (False, True):
        va, ra = comb.assemble(S, jnp.asarray(w), jnp.asarray(uv_b), normalize=normalize)
        vb, rb = comb.assemble(S, w, uv_b, normalize=normalize, host=True)
        assert isinstance(vb, np.ndarray) and isinstance(rb, np.ndarray)
        vc, _ = comb.assemble(S, w, uv_b, normalize=normalize)        # default: the JAX kernel
        assert np.array_equal(np.asarray(vc), np.asarray(va))
        np.testing.assert_allclose(vb, np.asarray(va), rtol=1e-15, atol=1e-15)
        np.testing.assert_allclose(rb, np.asarray(ra), rtol=1e-14, atol=1e-15)


def test_host_path_needs_no_compilation(meshes):
    """A new mesh size through the host path compiles at most the small boundary kernel, and
    nothing with the default circle boundary."""
    mesh = jp.shapes.graph_surface(13, jitter=0.25, seed=5)    # a size no other test uses
    names = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda n, s, **kw: names.append(n) if n == "/jax/core/compile/backend_compile_duration"
        else None)
    before = len(names)
    jp.convex_map(mesh, weights="shape_preserving", boundary="square", host=True)
    host_compiles = len(names) - before
    before = len(names)
    jp.convex_map(mesh, weights="shape_preserving", boundary="square")
    jax_compiles = len(names) - before
    assert host_compiles <= 1 < jax_compiles
    before = len(names)
    jp.convex_map(jp.shapes.graph_surface(14, jitter=0.25, seed=5), host=True)   # circle
    assert len(names) == before


def test_report_face_quantities_equal_jax(meshes):
    for mesh in meshes.values():
        uv = np.asarray(jp.convex_map(mesh, weights="mean_value"))
        a = metrics.face_distortion(mesh, uv)
        b = host.face_quantities(np.asarray(mesh.vertices), mesh.faces, uv)
        for key in ("J", "s1", "s2", "area3d", "area_uv"):
            np.testing.assert_allclose(b[key], np.asarray(a[key]), rtol=1e-12, atol=1e-14,
                                       err_msg=key)
        rep = metrics.distortion(mesh, uv, weights="mean_value")
        s1, s2, w = np.asarray(a["s1"]), np.asarray(a["s2"]), np.asarray(a["area3d"])
        w = w / w.sum()
        sd = np.sum(w * (s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2))
        assert abs(rep.sym_dirichlet - sd) <= 1e-12 * sd
        assert rep.flips == metrics.flips(mesh, uv) == int(np.sum(np.asarray(a["area_uv"]) <= 0))
        assert rep.theorem1.positive_weights is True and rep.theorem1.holds


def test_report_counts_a_flip():
    mesh = jp.shapes.plane_grid(4, 4)
    uv = np.asarray(mesh.vertices[:, :2]).copy()
    inner = mesh.topology.interior[0]
    uv[inner] += 5.0                              # drags one vertex across its ring
    rep = metrics.distortion(mesh, uv)
    assert rep.flips > 0 and rep.flips == metrics.flips(mesh, uv)
    assert rep.sym_dirichlet == float("inf")


def test_grad_still_takes_the_jax_path(meshes):
    """host=True is ignored under jax.grad: the gradient equals the default path's."""
    mesh = meshes["graph"]
    V0 = jnp.asarray(mesh.vertices)

    def f(V, host):
        m = jp.TriMesh(V, mesh.faces, validate=False)
        return jnp.sum(jp.convex_map(m, weights="mean_value", host=host) ** 2)

    g0 = jax.grad(f)(V0, False)
    g1 = jax.grad(f)(V0, True)
    assert np.array_equal(np.asarray(g0), np.asarray(g1))
    assert np.all(np.isfinite(np.asarray(g1))) and np.abs(np.asarray(g1)).max() > 0


def test_cli_flatten_defaults_mirror_minimize():
    """flatten_mesh spells minimize's defaults out (to keep the optimize stack unimported)."""
    from jaxparam.optimize import minimize

    sig = inspect.signature(pipeline.flatten_mesh).parameters
    for name in ("free_boundary", "solver", "max_iters"):
        assert sig[name].default == jp.options.default_of(minimize, name), name


@pytest.mark.parametrize("spacing", ["chord", "uniform"])
def test_host_circle_equals_boundary_circle(meshes, spacing):
    mesh = meshes["disk"]
    loop = mesh.topology.boundary_loops[0]
    P = np.asarray(mesh.vertices)[loop]
    np.testing.assert_allclose(host.circle(P, spacing),
                               np.asarray(jp.boundary.circle(jnp.asarray(P), spacing=spacing)),
                               rtol=0, atol=1e-15)


def test_host_areas_equal_geometry(meshes):
    """The minimizer's start checks use NumPy areas: equal to the JAX ones to rounding."""
    from jaxparam import geometry as geo
    for m in meshes.values():
        uv = np.asarray(jp.convex_map(m))
        np.testing.assert_allclose(host.signed_areas(uv, m.faces),
                                   np.asarray(geo.signed_areas(jnp.asarray(uv), m.faces)),
                                   rtol=1e-13, atol=1e-17)
        for V in (np.asarray(m.vertices), uv):
            np.testing.assert_allclose(host.face_areas(V, m.faces),
                                       np.asarray(geo.face_areas(jnp.asarray(V), m.faces)),
                                       rtol=1e-13, atol=1e-17)
    flipped = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
    assert host.signed_areas(flipped, np.array([[0, 1, 2]]))[0] == -0.5
