"""One gradient-check grid over the public differentiable functions of jaxparam (issue 12, item 7).

Every case compares ``jax.grad(loss)(x) . d`` with the central difference
``(L(x + h d) - L(x - h d)) / (2 h)`` (truncation ``O(h^2)``: below 1e-8 relative at the steps
used) along 3 random directions ``d`` (standard normal entries), on two meshes:

- ``generic``: ``jp.shapes.disk(3, seed=1, height=0.3)`` (37 vertices, interior jittered, lifted
  by a saddle) with every vertex moved by ``0.01 N(0, 1)``: nothing symmetric, no two
  neighbours collinear, no boundary vertex at a corner's arc length;
- ``regular``: ``jp.shapes.graph_surface(6)`` (36 vertices, the unjittered grid, lifted).

Where the output does not depend on the input at all (uniform weights with a ``user`` or
uniformly spaced circle boundary) the gradient must be exactly 0.

The loss is ``sum(c * out)`` for a fixed random ``c`` (or a rigid-motion-invariant one where
the output is defined up to a rigid motion).  Steps are in units of the bounding-box diagonal
(about 2 for both meshes) and are stated per case with the tolerance; "smooth" cases ask
``1e-6`` relative (measured errors are far below: see each comment).  The error is
``|g.d - fd| / max(|fd|, FLOOR * ||g|| ||d||)``: the floor keeps a direction along which the
loss happens to be stationary from asking for relative accuracy in rounding noise.

The always-on part is one or two cases of each function; the full product (every weight x
every boundary x both meshes, every solver x fixed/free x both meshes, every energy on both
meshes, ...) is marked ``slow``.  Where a function is not differentiable it must refuse a
traced input with a library error that names the reason and the route: those are tested at
the end.

Documented kinks are not in the grid (they have one-sided tests of their own):
``boundary="square"``/polygon corners at a vertex's arc length (tests/test_boundary_gradients.py;
the regular mesh's grid corners sit exactly there, so there it takes ``corners=``),
the fan weights' unsigned angle at collinear neighbours and the polar-map switch of
shape-preserving weights (tests/test_weight_kinks.py; on the regular grid opposite neighbours
are collinear, so meshless mean-value / shape-preserving maps run on the generic points only).
"""
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import MeshError, PointCloudError
from jaxparam.optimize import SOLVERS, UnconvergedGradientWarning

RTOL = 1e-6          # smooth cases
FLOOR = 1e-9         # relative to ||g|| ||d||: see the module docstring
N_DIRS = 3


# ---------------------------------------------------------------------------------------------
# helpers

def fd(f, x, d, h) -> float:
    return (float(f(x + h * d)) - float(f(x - h * d))) / (2 * h)


def directions(x, seed, n=N_DIRS, mask=None):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        d = rng.standard_normal(np.shape(x))
        if mask is not None:
            d = d * mask
        out.append(jnp.asarray(d))
    return out


def check(f, x, h, rtol=RTOL, seed=0, mask=None, grad=None, jit=False):
    """Assert ``grad f . d`` matches :func:`fd` along 3 random directions (``jit``: one
    compilation of ``f`` and one of its gradient, shared by the evaluations); returns the worst
    relative error (for the record in the comments)."""
    x = jnp.asarray(x, jnp.float64)
    if grad is None:
        grad = jax.grad(f)
    if jit:
        f, grad = jax.jit(f), jax.jit(grad)
    g = grad(x)
    assert np.all(np.isfinite(np.asarray(g))), "non-finite gradient"
    worst = 0.0
    for d in directions(x, seed, mask=mask):
        got = float(jnp.vdot(g, d))
        want = fd(f, x, d, h)
        scale = max(abs(want), FLOOR * float(jnp.linalg.norm(g)) * float(jnp.linalg.norm(d)))
        # scale 0: the output does not depend on x (uniform weights with a fixed boundary):
        # then the gradient must be exactly 0 too.
        err = abs(got - want) / scale if scale > 0 else abs(got - want)
        worst = max(worst, err)
        assert err <= rtol, (got, want, err)
    print(f"worst relative error {worst:.1e} (h = {h:g}, rtol = {rtol:g})")
    return worst


def weighted_sum(shape, seed):
    c = jnp.asarray(np.random.default_rng(seed).standard_normal(shape))
    return lambda out: jnp.sum(c * jnp.nan_to_num(out))


def edge_loss(faces_mesh, uv, seed=3):
    """Invariant under rigid motions of the UVs: a random combination of squared edge lengths."""
    E = faces_mesh.topology.edges
    w = np.random.default_rng(seed).standard_normal(E.shape[0])
    return jnp.sum(w * jnp.sum((uv[E[:, 0]] - uv[E[:, 1]]) ** 2, axis=1))


def _generic():
    m = jp.shapes.disk(3, seed=1, height=0.3)
    V = np.asarray(m.vertices) + 0.01 * np.random.default_rng(0).standard_normal(m.vertices.shape)
    return jp.TriMesh(V, m.faces)


MESHES = {"generic": _generic, "regular": lambda: jp.shapes.graph_surface(6)}


@pytest.fixture(scope="module")
def meshes():
    return {k: f() for k, f in MESHES.items()}


def grid_corners(mesh):
    """Loop positions of the regular grid's 4 corners (the square boundary's kink-free route)."""
    loop = list(mesh.topology.boundary_loops[0])
    V = np.asarray(mesh.vertices)
    ext = [int(np.argmin(V[:, 0] + V[:, 1])), int(np.argmax(V[:, 0] - V[:, 1])),
           int(np.argmax(V[:, 0] + V[:, 1])), int(np.argmax(V[:, 1] - V[:, 0]))]
    pos = sorted(loop.index(v) for v in ext)
    assert pos[0] == 0, pos          # the grid's loop starts at a corner
    return tuple(pos)


# ---------------------------------------------------------------------------------------------
# convex_map and least_squares_map: every weight x every boundary

WEIGHTS = jp.weights.KINDS
BOUNDARIES = ("circle", "square", "plane", "polygon", "user", "circle_uniform_spacing")
PENTAGON = [[np.cos(a), np.sin(a)] for a in 2 * np.pi * np.arange(5) / 5]


def map_kwargs(mesh, name, boundary):
    """Keyword arguments of ``convex_map`` for a boundary case; ``user`` boundary UVs are a
    constant circle (the gradient then flows through the interior solve only)."""
    if boundary == "circle_uniform_spacing":
        return dict(boundary="circle", spacing="uniform")
    if boundary == "polygon":
        return dict(boundary={"polygon": PENTAGON})
    if boundary == "user":
        k = mesh.topology.boundary_loops[0].size
        a = 2 * np.pi * np.arange(k) / k
        return dict(boundary=np.column_stack([np.cos(a), np.sin(a)]))
    if boundary == "square" and name == "regular":
        return dict(boundary="square", corners=None)    # replaced below by the grid's corners
    return dict(boundary=boundary)


def convex_case(meshes, name, weights, boundary):
    mesh = meshes[name]
    kw = map_kwargs(mesh, name, boundary)
    if name == "regular" and boundary in ("square", "polygon"):
        # The regular grid's loop is symmetric: boundary vertices sit exactly at the default
        # corner arc lengths (the documented kink).  Pin the corners to loop vertices instead:
        # the grid's 4 corners (square), loop positions 0, 3, 8, 12, 16 (pentagon).
        pos = grid_corners(mesh)
        if boundary == "square":
            kw["corners"] = pos
        else:
            k = mesh.topology.boundary_loops[0].size
            kw["corners"] = (0, 3, 8, 12, 16)
            assert kw["corners"][-1] < k
    F = mesh.faces
    L = weighted_sum((mesh.n_vertices, 2), 1)
    return lambda V: L(jp.convex_map(jp.TriMesh(V, F), weights=weights, **kw)), mesh


CONVEX_FAST = [("generic", "mean_value", "circle"), ("regular", "uniform", "square")]
CONVEX_ALL = [(n, w, b) for n in MESHES for w in WEIGHTS for b in BOUNDARIES
              if (n, w, b) not in CONVEX_FAST]


def _convex(meshes, name, weights, boundary):
    f, mesh = convex_case(meshes, name, weights, boundary)
    # h = 1e-5 (5e-6 of the diagonal); 1e-6 asked.
    check(f, mesh.vertices, 1e-5, seed=sum(map(ord, weights + boundary)))


@pytest.mark.parametrize("name,weights,boundary", CONVEX_FAST)
def test_convex_map(meshes, name, weights, boundary):
    _convex(meshes, name, weights, boundary)


@pytest.mark.slow
@pytest.mark.parametrize("name,weights,boundary", CONVEX_ALL)
def test_convex_map_full_grid(meshes, name, weights, boundary):
    _convex(meshes, name, weights, boundary)


@pytest.mark.parametrize("name", [pytest.param("generic"), pytest.param("regular", marks=pytest.mark.slow)])
def test_least_squares_map(meshes, name):
    """In the vertices (default mu = 1/|v - w|) and in user edge weights ``mu``; h = 1e-5
    (vertices) and 1e-5 (mu ~ 1); 1e-6 asked."""
    mesh = meshes[name]
    F, E = mesh.faces, mesh.topology.edges
    L = weighted_sum((mesh.n_vertices, 2), 2)
    check(lambda V: L(jp.least_squares_map(jp.TriMesh(V, F))), mesh.vertices, 1e-5, seed=3)
    mu0 = 1.0 + 0.5 * np.random.default_rng(4).random(E.shape[0])
    check(lambda mu: L(jp.least_squares_map(mesh, mu=mu, boundary="square"
                                            if name == "generic" else "circle")), mu0, 1e-5, seed=5)


# ---------------------------------------------------------------------------------------------
# distortion scalars (jp.metrics.face_distortion) and every energy

def test_face_distortion_scalars(meshes):
    """The differentiable per-face quantities behind ``jp.distortion``: the area-weighted
    symmetric Dirichlet and the mean of ``s1 / s2 + s2 / s1`` (MIPS), in the UVs and in the
    vertices; h = 2e-6 (a direction along which the MIPS term barely changes, 5e-3, shows
    the O(h^2) truncation: 9e-7 at h = 1e-5, 7e-8 at 3e-6), 1e-6 asked.  Only symmetric functions of ``(s1, s2)`` are smooth:
    ``s1`` and ``s2`` alone kink where a face is conformal (``R = |(F, G)| = 0`` in
    :func:`jaxparam.geometry.singular_values`); the generic convex map's most nearly
    conformal face has ``s1 - s2 = 2.8e-3``, and ``sum(s1)`` differenced at h = 1e-4 is
    4e-4 off (right at h = 1e-6)."""
    for name, mesh in meshes.items():
        F = mesh.faces
        uv0 = jnp.asarray(jp.convex_map(mesh))

        def scalars(V, uv):
            q = jp.metrics.face_distortion(jp.TriMesh(V, F, validate=False), uv)
            w = q["area3d"] / jnp.sum(q["area3d"])
            s1, s2 = q["s1"], q["s2"]
            return jnp.sum(w * (s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2)) + jnp.sum(w * (s1 / s2 + s2 / s1))

        check(lambda uv: scalars(jnp.asarray(mesh.vertices), uv), uv0, 2e-6, seed=6, jit=True)
        check(lambda V: scalars(V, uv0), mesh.vertices, 2e-6, seed=7, jit=True)


ENERGY_FAST = ("symmetric_dirichlet",)
#: Not symmetric in (s1, s2): kinked at a conformal face (none is: the most nearly conformal
#: faces have s1 - s2 = 2.8e-3 (generic) and 0.09 (regular)), so a smaller step.
KINKED = ("condition_2", "condition_2_squared")


def _energy(meshes, name, en):
    mesh = meshes[name]
    F = mesh.faces
    uv0 = jnp.asarray(jp.convex_map(mesh))
    E = jp.ENERGIES[en]
    # In the UVs and in the vertices; h = 2e-6 (as for face_distortion); 1e-6 asked.  The
    # condition numbers s1/s2 kink at a conformal face (jaxparam.energies, "Kinks"); near the
    # generic map's most nearly conformal face (s1 - s2 = 2.8e-3) their O(h^2) term is large
    # (measured 6e-5 at h = 1e-5, 2.6e-6 at 2e-6, 5e-9 at 1e-7): h = 1e-7 for them.
    h = 1e-7 if en in KINKED else 2e-6
    check(lambda uv: E(mesh, uv), uv0, h, seed=8, jit=True)
    check(lambda V: E(jp.TriMesh(V, F, validate=False), uv0), mesh.vertices, h, seed=9, jit=True)


@pytest.mark.parametrize("en", ENERGY_FAST)
def test_energy(meshes, en):
    _energy(meshes, "generic", en)


@pytest.mark.slow
@pytest.mark.parametrize("name,en", [(n, e) for n in MESHES for e in jp.ENERGIES
                                     if (n, e) not in [("generic", f) for f in ENERGY_FAST]])
def test_energy_full_grid(meshes, name, en):
    _energy(meshes, name, en)


def test_energy_parameters(meshes):
    """``jp.energy(f, params)``'s value in its parameters (a pytree); h = 1e-5; 1e-6 asked."""
    mesh = meshes["generic"]
    uv0 = jnp.asarray(jp.convex_map(mesh))

    def f(s1, s2, p):
        return p["a"] * (s1 ** 2 + s2 ** 2) + p["b"] * (s1 ** -2 + s2 ** -2) + p["a"] * p["b"] * s1 / s2

    check(lambda ab: jp.energy(f, {"a": ab[0], "b": ab[1]})(mesh, uv0), jnp.asarray([1.0, 0.7]),
          1e-5, seed=10, jit=True)


# ---------------------------------------------------------------------------------------------
# minimize: every solver, fixed and free boundary

TIGHT = dict(energy_rtol=1e-15, grad_rtol=1e-13, max_iters=300, verbose=False)


def traced(f):
    """``f`` as the differentiated function evaluates it (the forward pass of a VJP: the
    optimum is polished to a stationary point before differentiating)."""
    return lambda x: jax.vjp(f, x)[0]


def _minimize(meshes, name, solver, free):
    mesh = meshes[name]
    F = mesh.faces
    L = weighted_sum((mesh.n_vertices, 2), 11)

    def loss(V):
        m = jp.TriMesh(V, F)
        uv = jp.minimize(m, "symmetric_dirichlet", solver=solver, free_boundary=free, **TIGHT).uv
        return edge_loss(m, uv) if free else L(uv)

    with warnings.catch_warnings():
        warnings.simplefilter("error", UnconvergedGradientWarning)
        # h = 3e-6 (the optimum is the same one, polished by Newton steps before
        # differentiating, whichever solver found it).  The difference is O(h^2)-limited: on
        # the regular mesh, fixed boundary, one direction is off by 1.5e-6, 1.4e-7, 1.5e-8,
        # 1.3e-9 at h = 1e-4, 3e-5, 1e-5, 3e-6); 1e-6 asked.
        return check(traced(loss), mesh.vertices, 3e-6, seed=12, grad=jax.grad(loss))


MIN_FAST = [("generic", "newton", False)]


@pytest.mark.parametrize("name,solver,free", MIN_FAST)
def test_minimize(meshes, name, solver, free):
    _minimize(meshes, name, solver, free)


#: jaxopt's L-BFGS with a free boundary on the regular mesh cannot be checked by differences of
#: its own forward values: they are off the optimum by up to 1.3e-8 in the loss at some
#: nearby positions (along the grid's second direction, at V - h d with h = 3e-6 and 3e-5,
#: while at V + h d it agrees with Newton's to 1e-16), so the difference is off by 6e-4 at
#: h = 3e-6 and 6e-5 at h = 3e-5 (error ~ 1/h: noise in the values, not in the slope).
#: The implicit gradient depends only on the (polished) minimizer and the true Hessian there,
#: not on which solver found it, so it is checked against Newton's at the same mesh: measured
#: 1.7e-15 relative; and Newton's own gradient against finite differences
#: (``regular-newton-True`` in this grid: at most 1.1e-9 at h = 3e-6 along the same three
#: directions).
#: The same holds for our own L-BFGS there since the Newton Hessian's pull-back is written out
#: entry by entry (issue 17, session 9: rounding-level changes in the polishing steps): its
#: difference quotient is off by 2.4e-3 at h = 3e-6, while its gradient agrees with Newton's
#: to 1e-10 and Newton's with finite differences (both checked here).
FORWARD_NOISY = {("regular", "jaxopt_lbfgs", True), ("regular", "lbfgs", True)}


def _minimize_against_newton(meshes, name, solver, free):
    mesh = meshes[name]
    F = mesh.faces

    def loss(V, solver):
        m = jp.TriMesh(V, F)
        uv = jp.minimize(m, "symmetric_dirichlet", solver=solver, free_boundary=free, **TIGHT).uv
        return edge_loss(m, uv)

    V = jnp.asarray(mesh.vertices)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnconvergedGradientWarning)
        ours = traced(lambda V: loss(V, solver))(V)
        ref = traced(lambda V: loss(V, "newton"))(V)
        g = np.asarray(jax.grad(lambda V: loss(V, solver))(V))
        g_ref = np.asarray(jax.grad(lambda V: loss(V, "newton"))(V))
    assert abs(float(ours) - float(ref)) <= 1e-12 * abs(float(ref))      # the same minimizer
    assert np.all(np.isfinite(g)) and np.linalg.norm(g_ref) > 0
    err = np.linalg.norm(g - g_ref) / np.linalg.norm(g_ref)
    assert err <= 1e-10, err


@pytest.mark.slow
@pytest.mark.parametrize("name,solver,free", [
    (n, s, f) for n in MESHES for s in SOLVERS for f in (False, True) if (n, s, f) not in MIN_FAST])
def test_minimize_full_grid(meshes, name, solver, free):
    if (name, solver, free) in FORWARD_NOISY:
        _minimize_against_newton(meshes, name, solver, free)
    else:
        _minimize(meshes, name, solver, free)


# ---------------------------------------------------------------------------------------------
# meshless_map

MESHLESS_FAST = [("generic", "mean_value")]
MESHLESS_ALL = [(n, w) for n in MESHES for w in jp.points.WEIGHTS
                if (n, w) not in MESHLESS_FAST
                and not (n == "regular" and w in ("mean_value", "shape_preserving"))]


def _meshless(meshes, name, weights):
    P0 = np.asarray(meshes[name].vertices)
    graph = jp.points.point_graph(P0, 8)
    _, bnd = jp.meshless_map(P0, k=8, weights=weights, graph=graph)
    L = weighted_sum((P0.shape[0], 2), 13)

    def loss(P):
        return L(jp.meshless_map(P, k=8, weights=weights, graph=graph, boundary_indices=bnd)[0])

    # h = 1e-5; 1e-6 asked.
    check(loss, P0, 1e-5, seed=14)


@pytest.mark.parametrize("name,weights", MESHLESS_FAST)
def test_meshless_map(meshes, name, weights):
    _meshless(meshes, name, weights)


@pytest.mark.slow
@pytest.mark.parametrize("name,weights", MESHLESS_ALL)
def test_meshless_map_full_grid(meshes, name, weights):
    _meshless(meshes, name, weights)


def _four_gather_fan_weights(P, E, kind):
    """The fan weights as they were computed before issue 12's session 8 (four gathered
    3-vectors per entry, each angle twice): the oracle for jaxparam.weights.fan_weights."""
    from jaxparam import weights as wts
    from jaxparam.geometry import safe_norm

    def angle(a, b):
        return jnp.arctan2(safe_norm(jnp.cross(a, b)), jnp.sum(a * b, -1))

    x = P[E.center]
    d = P[E.nbr] - x
    return wts.weights_from_angles(
        kind, angle(d, P[E.next] - x), angle(P[E.prev] - x, d), safe_norm(d), E.row, E.row_start,
        E.row_end, E.degree, n_rows=E.n_rows,
        max_degree=wts.loop_bound(int(E.degree.max())) if kind == "shape_preserving" else 0)


@pytest.mark.parametrize("name", MESHES)
@pytest.mark.parametrize("weights", jp.points.WEIGHTS)
def test_fan_weights_match_the_four_gather_formula(meshes, name, weights):
    """jaxparam.weights.fan_weights (one gather per direction, each angle once) against the
    four-gather formula: values to 1e-13 relative per entry (bitwise on camelhead; on these
    small sets XLA's fusions sum the 3-term dot products in another order, 1.3e-15), reverse
    and forward derivatives to 1e-10 relative (measured about 1e-15)."""
    from jaxparam import weights as wts

    P0 = jnp.asarray(meshes[name].vertices)
    graph = jp.points.point_graph(np.asarray(P0), 8)
    _, bnd = jp.meshless_map(np.asarray(P0), k=8, graph=graph)
    fixed = np.zeros(P0.shape[0], bool)
    fixed[bnd] = True
    E = wts.fan_entries(graph.indptr, graph.indices, fixed)
    ref = jax.jit(lambda P: _four_gather_fan_weights(P, E, weights))
    new = lambda P: wts.fan_weights(P, E, weights)     # noqa: E731
    np.testing.assert_allclose(np.asarray(new(P0)), np.asarray(ref(P0)), rtol=1e-13, atol=0)
    rng = np.random.default_rng(21)
    ct = jnp.asarray(rng.standard_normal(E.row.size))
    g_ref, g_new = jax.vjp(ref, P0)[1](ct)[0], jax.vjp(new, P0)[1](ct)[0]
    d = jnp.asarray(rng.standard_normal(P0.shape))
    t_ref, t_new = jax.jvp(ref, (P0,), (d,))[1], jax.jvp(new, (P0,), (d,))[1]
    for a, b in ((g_new, g_ref), (t_new, t_ref)):
        a, b = np.asarray(a), np.asarray(b)
        assert np.all(np.isfinite(b))
        assert np.max(np.abs(a - b)) <= 1e-10 * max(np.max(np.abs(b)), 1e-300)
    if weights == "uniform":
        assert np.max(np.abs(np.asarray(g_ref))) == 0.0
    else:                  # the check can fail: the derivative is not trivially zero
        assert np.max(np.abs(np.asarray(g_ref))) > 0.0


def test_hand_written_weight_derivatives_match_jax_own():
    """The custom_jvp pieces of the weights (issue 12: the mean-value formula, whose tangent
    reuses the primal's tan, and Floater's shape-preserving weights, whose tangent is written
    out from the forward's polar points, edges and areas) against JAX's derivative of the plain
    formulas: values bitwise, reverse and forward derivatives to 1e-12 relative per entry, on
    random angles and at the degenerate ones (mean value: 0, and pi where tan(pi/2) is about
    1.6e16: finite coefficients either way; shape-preserving: a fan with an angle of pi or
    more, where the centre lies on an edge from p_k, and a zero angle)."""
    import functools

    from jaxparam import weights as wts

    rng = np.random.default_rng(5)
    k = 200
    angle = jnp.asarray(np.concatenate([rng.uniform(0.05, 3.0, k - 2), [0.0, np.pi]]))
    prev = jnp.asarray(rng.permutation(np.asarray(angle)))
    r = jnp.asarray(rng.uniform(0.1, 2.0, k))
    plain_mv = lambda a, p, l: (jnp.tan(0.5 * p) + jnp.tan(0.5 * a)) / l     # noqa: E731

    # point fans of degrees 3..12; row 0 has an angle above pi, row 1 a zero angle
    degree = rng.integers(3, 13, 40)
    row = np.repeat(np.arange(degree.size), degree)
    starts = np.concatenate([[0], np.cumsum(degree)])
    row_start, row_end = starts[row], starts[row + 1]
    delta = rng.uniform(0.2, 1.0, row.size)
    delta[:starts[1]] = 0.3
    delta[0] = 3.6          # above pi once scaled by 2 pi / sum: p lies on an edge from p_k
    delta[starts[1] + 1] = 0.0
    lengths = rng.uniform(0.1, 2.0, row.size)
    ints = (row, row_start, row_end, degree)
    sizes = dict(n_rows=int(degree.size), max_degree=wts.loop_bound(int(degree.max())))
    new_sp = lambda d, l: wts.shape_preserving_weights(d, l, *ints, **sizes)       # noqa: E731
    plain_sp = lambda d, l: functools.partial(wts._shape_preserving_primal, **sizes)(  # noqa: E731
        d, l, *ints)

    # compiled: eager dispatch of the fans' loops took 10-27 s (the values are compared
    # bitwise, both sides compiled the same way; the mean-value pair too, 2 s eagerly)
    for new, ref, args in ((jax.jit(wts._mean_value), jax.jit(plain_mv), (angle, prev, r)),
                           (jax.jit(new_sp), jax.jit(plain_sp),
                            (jnp.asarray(delta), jnp.asarray(lengths)))):
        out, vjp_new = jax.vjp(new, *args)
        out_ref, vjp_ref = jax.vjp(ref, *args)
        assert np.array_equal(np.asarray(out), np.asarray(out_ref))
        ct = jnp.asarray(rng.standard_normal(out.shape))
        tan_in = tuple(jnp.asarray(rng.standard_normal(a.shape)) for a in args)
        pairs = list(zip(vjp_new(ct), vjp_ref(ct)))
        pairs.append((jax.jvp(new, args, tan_in)[1], jax.jvp(ref, args, tan_in)[1]))
        for a, b in pairs:
            a, b = np.asarray(a), np.asarray(b)
            assert np.all(np.isfinite(b)) and np.max(np.abs(b)) > 0
            # relative per entry (the pole's coefficients are about 1e32), with a floor for
            # entries that cancel to far below their terms
            floor = 1e-3 * np.median(np.abs(b))
            assert np.max(np.abs(a - b) / np.maximum(np.abs(b), floor)) <= 1e-12


def test_fan_angle_derivative_matches_jax_own():
    """The fan angles' hand-written tangent (``weights._fan_angles``, issue 12) against JAX's
    derivative of the plain formula ``atan2(|u x v|, u.v)``, ``|u|``: values to rounding,
    reverse and forward derivatives to 1e-12 relative per entry, on random fans with two
    degenerate pairs, one neighbour on the ray of the previous one (angle 0) and one on the
    opposite ray (angle pi), where both take the mean of the one-sided derivatives (0 for the
    angle)."""
    from jaxparam import weights as wts
    from jaxparam.geometry import safe_norm

    rng = np.random.default_rng(8)
    degree = rng.integers(3, 9, 30)
    row = np.repeat(np.arange(degree.size), degree)
    starts = np.concatenate([[0], np.cumsum(degree)])
    e = np.arange(row.size)
    nxt = np.where(e + 1 < starts[row + 1], e + 1, starts[row])
    d = rng.standard_normal((row.size, 3))
    d[1] = 2.0 * d[0]                  # same ray: |u x v| = 0 (or rounding)
    d[4] = -2.0 * d[3]                 # opposite rays
    d = jnp.asarray(d)

    def plain(d, nxt):
        b = d[nxt]
        return jnp.arctan2(safe_norm(jnp.cross(d, b)), jnp.sum(d * b, -1)), safe_norm(d)

    # compiled, both sides the same way (eagerly each primitive of the forward, the transposed
    # and the tangent passes dispatched on its own: 3-4 s)
    new = jax.jit(lambda d: wts._fan_angles(d, nxt))      # noqa: E731
    ref = jax.jit(lambda d: plain(d, nxt))                # noqa: E731
    out, vjp_new = jax.vjp(new, d)
    out_ref, vjp_ref = jax.vjp(ref, d)
    for a, b in zip(out, out_ref):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-15, atol=1e-15)
    assert abs(float(out[0][0])) < 1e-15 and float(out[0][3]) == pytest.approx(np.pi)
    cts = tuple(jnp.asarray(rng.standard_normal(o.shape)) for o in out)
    tan_in = jnp.asarray(rng.standard_normal(d.shape))
    pairs = [(vjp_new(cts)[0], vjp_ref(cts)[0])]
    pairs += list(zip(jax.jvp(new, (d,), (tan_in,))[1], jax.jvp(ref, (d,), (tan_in,))[1]))
    for a, b in pairs:
        a, b = np.asarray(a), np.asarray(b)
        assert np.all(np.isfinite(b)) and np.max(np.abs(b)) > 0
        floor = 1e-3 * np.median(np.abs(b))
        assert np.max(np.abs(a - b) / np.maximum(np.abs(b), floor)) <= 1e-12


# ---------------------------------------------------------------------------------------------
# fit_surface, remesh, wavelets, manifold_map

@pytest.mark.slow      # 20 s; the always-on fit gradients are in tests/test_pipeline_gradients.py
@pytest.mark.parametrize("kind", ["spline", "clough_tocher"])
def test_fit_surface(meshes, kind):
    """In the points (linear for fixed parameters) and in the evaluation places; h = 1e-5.
    Spline: 1e-6 asked.  Clough–Tocher: 1e-5 asked, as documented in ``fit_surface``: the
    values are SciPy's (vertex gradients from a Gauss–Seidel iteration stopped at 1e-6), the
    derivative that of the same interpolant with the gradients solved exactly (measured 1.2e-6
    in the points)."""
    mesh = meshes["generic"]
    U = np.asarray(jp.convex_map(mesh))
    rng = np.random.default_rng(15)
    r = 0.6 * np.sqrt(rng.random(40))
    a = 2 * np.pi * rng.random(40)
    Q = jnp.asarray(np.column_stack([r * np.cos(a), r * np.sin(a)]))
    L = weighted_sum((40, 3), 16)
    rtol = RTOL if kind == "spline" else 1e-5
    check(lambda X: L(jp.fit_surface(X, U, kind=kind).evaluate(Q)), mesh.vertices, 1e-5, rtol, seed=17)
    s = jp.fit_surface(mesh, U, kind=kind)
    check(lambda q: L(s.evaluate(q)), Q, 1e-5, rtol, seed=18)


@pytest.mark.slow      # 70 s; the always-on remesh gradients are in tests/test_pipeline_gradients.py
def test_remesh_through_convex_map(meshes):
    """V -> convex_map -> remesh (levels=2), the sample points moving in the domain; h = 1e-5;
    1e-6 asked.  Generic mesh only: on the regular grid the symmetric base domain puts sample
    points exactly on boundary-polygon vertices, where the remesh is one-sided differentiable
    (measured 3.5e-2 off there; see tests/test_pipeline_gradients.py)."""
    mesh = meshes["generic"]
    F = mesh.faces
    n = jp.remesh(mesh, jp.convex_map(mesh), levels=2).mesh.n_vertices
    L = weighted_sum((n, 3), 19)

    def loss(V):
        m = jp.TriMesh(V, F)
        return L(jp.remesh(m, jp.convex_map(m, weights="mean_value"), levels=2).mesh.vertices)

    check(loss, mesh.vertices, 1e-5, seed=20)


@pytest.fixture(scope="module")
def semi(meshes):
    mesh = meshes["generic"]
    return jp.remesh(mesh, jp.convex_map(mesh), levels=2)


@pytest.mark.parametrize("wavelet", [pytest.param("lazy", marks=pytest.mark.slow), "lifted"])
def test_wavelets(semi, wavelet):
    """analyze (every coefficient), synthesize (in the coefficients) and compress (in the
    positions, mask held): all linear, h = 1e-5, 1e-6 asked.  compress is piecewise linear:
    a step of 1e-3 changes which coefficients are kept (measured 0.9 off), 1e-5 does not."""
    X0 = semi.mesh.vertices + 1e-3 * np.random.default_rng(21).standard_normal(semi.mesh.vertices.shape)
    L = weighted_sum(X0.shape, 22)
    c0 = jp.wavelets.analyze(semi.with_vertices(X0), wavelet=wavelet)

    def analysed(X):
        c = jp.wavelets.analyze(semi.with_vertices(X), wavelet=wavelet)
        return L(jnp.concatenate((c.base,) + tuple(c.details)))

    def synthesized(base):
        return L(jp.wavelets.synthesize(jp.wavelets.Coefficients(base, c0.details, c0.hierarchy, wavelet)))

    def compressed(X):
        return L(jp.wavelets.compress(semi.with_vertices(X), 0.3, wavelet=wavelet).mesh.vertices)

    check(analysed, X0, 1e-5, seed=23, jit=True)
    check(synthesized, c0.base, 1e-5, seed=24, jit=True)
    check(compressed, X0, 1e-5, seed=25, jit=True)


@pytest.mark.slow
def test_manifold_map_with_vertices():
    """A closed mesh: ``ManifoldParameterization.with_vertices(V).remesh(1)``, the charts
    re-solved for new positions; h = 1e-5, 1e-6 asked."""
    mesh = jp.shapes.sphere(1)
    V0 = np.asarray(mesh.vertices) * (1 + 0.02 * np.random.default_rng(26).standard_normal((mesh.n_vertices, 1)))
    mesh = jp.TriMesh(V0, mesh.faces)
    _, param = jp.manifold_map(mesh, 8)
    n = param.remesh(1).mesh.n_vertices
    L = weighted_sum((n, 3), 27)
    check(lambda V: L(param.with_vertices(V).remesh(1).mesh.vertices), V0, 1e-5, seed=28)


# ---------------------------------------------------------------------------------------------
# What is not differentiable refuses traced input, naming the reason and the route

def test_not_differentiable_refuses_with_a_library_error(meshes):
    mesh = meshes["generic"]
    F = mesh.faces
    V0 = jnp.asarray(mesh.vertices)
    uv0 = jnp.asarray(jp.convex_map(mesh))
    # The distortion report and the counts are numpy floats and integers.
    for fn in (lambda uv: jp.distortion(mesh, uv).sym_dirichlet,
               lambda uv: jp.metrics.flips(mesh, uv) * 1.0,
               lambda uv: jp.metrics.boundary_overlaps(mesh, uv) * 1.0,
               lambda uv: float(jp.metrics.theorem1(mesh, uv).holds)):
        with pytest.raises(MeshError, match=r"not differentiable.*face_distortion"):
            jax.grad(fn)(uv0)
    # manifold_map's discrete choices need concrete positions: the route is with_vertices.
    with pytest.raises(MeshError, match=r"traced.*with_vertices"):
        jax.grad(lambda V: jp.manifold_map(jp.TriMesh(V, F, validate=False), 8)[1]
                 .remesh(1).mesh.vertices.sum())(V0)
    # meshless_map's neighbourhoods are topology: the graph must come from concrete points.
    with pytest.raises(PointCloudError, match=r"graph=jp\.points\.point_graph"):
        jax.grad(lambda P: jp.meshless_map(P)[0].sum())(V0)
    # an energy closing over a tracer: the route is jp.energy(f, params).
    with pytest.raises(MeshError, match=r"jp\.energy\(lambda s1, s2, p: \.\.\., params=p\)"):
        jax.grad(lambda a: jp.minimize(mesh, jp.energy(lambda s1, s2: a * s1 ** 2 + s2 ** -2),
                                       verbose=False).uv.sum())(1.0)
    # the parameter-dependent discrete choices of fit_surface and remesh under jit.
    with pytest.raises(MeshError, match=r"fit_surface: uv is traced without a value"):
        jax.jit(lambda u: jp.fit_surface(V0, u).evaluate(u[:3]))(uv0)
    with pytest.raises(MeshError, match=r"remesh: the UVs are traced without a value"):
        jax.jit(lambda u: jp.remesh(mesh, u, levels=1).mesh.vertices)(uv0)
    # reconstruct_surface is a discrete algorithm (Delaunay, region growing).
    with pytest.raises(PointCloudError, match=r"not differentiable.*meshless_map"):
        jax.grad(lambda P: jp.reconstruct_surface(P).uv.sum())(V0)


def test_unconverged_minimize_warns_when_differentiated(meshes):
    mesh = meshes["generic"]
    start = np.asarray(jp.convex_map(mesh))

    def loss(V):
        return jp.minimize(jp.TriMesh(V, mesh.faces), init=start, max_iters=1, verbose=False).uv.sum()

    with pytest.warns(UnconvergedGradientWarning, match="stopping point"):
        jax.grad(loss)(jnp.asarray(mesh.vertices))


def test_solve_cache_tells_matrices_apart_that_share_a_fingerprint():
    """The factorization cache of jaxparam.sparse.solve is found by a fingerprint of a few
    values and confirmed by an exact comparison of all of them (issue 12: cheaper than hashing
    every value per solve).  Two matrices that agree on the fingerprint's entries but not
    elsewhere must not share a factorization, inside a gradient as well as eagerly."""
    from jaxparam import linear, sparse
    from jaxparam.sparse import differentiable as D

    mesh = jp.shapes.disk(8, seed=1, height=0.3)       # nnz > 2 x the fingerprint's 64 values
    t = mesh.topology
    S = linear.interior_system(t)
    w = np.asarray(jp.weights.entry_weights(mesh.vertices, t, "mean_value")[0])
    vals, rhs = (np.asarray(a) for a in jp.combination.assemble(S, w, np.ones((t.boundary.size, 2)),
                                                                normalize=True))
    step = max(1, vals.size // D._FINGERPRINT)
    off = np.flatnonzero(np.arange(vals.size) % step != 0)
    off = off[off != vals.size - 1]
    diag = set(S.diag_pos.tolist())
    i = int(next(j for j in off if j in diag))             # a diagonal entry off the fingerprint
    vals2 = vals.copy()
    vals2[i] *= 1.5
    assert D._fingerprint(vals) == D._fingerprint(vals2)
    with D.cache_lock:
        D.cache.clear()
    x1 = np.asarray(sparse.solve(S.pattern, vals, rhs))
    x2 = np.asarray(sparse.solve(S.pattern, vals2, rhs))
    A1, A2 = (S.pattern.matrix(v).toarray() for v in (vals, vals2))
    np.testing.assert_allclose(x1, np.linalg.solve(A1, rhs), atol=1e-12)
    np.testing.assert_allclose(x2, np.linalg.solve(A2, rhs), atol=1e-12)
    assert np.abs(x1 - x2).max() > 1e-6
    # Under jax.grad the adjoint solve must use its own matrix's factorization.
    g = jax.jit(jax.grad(lambda v: jnp.sum(sparse.solve(S.pattern, v, rhs) ** 2)))
    for v, A in ((vals, A1), (vals2, A2)):
        x = np.linalg.solve(A, rhs)
        lam = np.linalg.solve(A.T, 2 * x)
        want = -np.einsum("ik,jk->ij", lam, x)[S.pattern.rows, S.pattern.indices]
        np.testing.assert_allclose(np.asarray(g(v)), want, rtol=1e-9, atol=1e-12)
