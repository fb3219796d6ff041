"""The maps' reverse pass (issue 12): the adjoint solve's residual check, which a derivative
solve skips only with a factor that has passed it (and never for a non-finite solution); the
blocked transposed LU solve; and ``combination.solve_weights``, whose hand-written derivative
must give the values of assemble + solve bitwise and the derivatives JAX takes of them."""
import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import scipy.sparse as sp  # noqa: E402

import jaxparam as jp  # noqa: E402
from jaxparam import combination as comb  # noqa: E402
from jaxparam import linear  # noqa: E402
from jaxparam import sparse as S  # noqa: E402
from jaxparam import weights as wts  # noqa: E402

N = 40


def random_matrix(seed: int, n: int = N, symmetric: bool = False):
    """A diagonally dominant sparse matrix: ``(pattern, values, dense)``."""
    rng = np.random.default_rng(seed)
    mask = rng.random((n, n)) < 0.15
    M = np.where(mask | mask.T, rng.uniform(-1, 1, (n, n)), 0.0)
    if symmetric:
        M = (M + M.T) / 2
    np.fill_diagonal(M, np.abs(M).sum(1) + 1 + rng.random(n))
    A = sp.csr_matrix(M)
    A.sort_indices()
    return S.Pattern(A.indptr, A.indices, n), A.data.copy(), M


@pytest.mark.parametrize("symmetric", [False, True], ids=["lu", "spd"])
def test_derivative_solve_skips_the_check_only_after_a_passed_one(symmetric):
    P, v, M = random_matrix(1, symmetric=symmetric)
    b = np.random.default_rng(2).standard_normal((N, 2))
    fac = S.factorize(P, v, symmetric=symmetric)
    assert not fac.verified
    before = S.stats["checks_skipped"]
    # an unverified factor is checked even when the caller trusts checks
    x = fac.solve_transpose(b, trust_checked=True)
    assert fac.verified and S.stats["checks_skipped"] == before
    np.testing.assert_allclose(x, np.linalg.solve(M.T, b), atol=1e-12)
    y = fac.solve_transpose(b, trust_checked=True)
    assert S.stats["checks_skipped"] == before + 1
    np.testing.assert_array_equal(x, y)
    fac.solve(b)                                   # untrusted solves are always checked
    assert S.stats["checks_skipped"] == before + 1


def test_a_non_finite_trusted_solve_gets_the_check_and_the_fallback():
    P, v, M = random_matrix(3)
    b = np.random.default_rng(4).standard_normal(N)
    fac = S.factorize(P, v)
    fac.solve(b)
    assert fac.verified
    if fac.backend == "scipy":
        pytest.skip("the fallback is SuperLU itself")
    fac._impl.solve = lambda rhs, transpose: np.full(np.shape(rhs), np.nan)   # a broken factor
    fallbacks = S.stats["fallbacks"]
    x = fac.solve_transpose(b, trust_checked=True)
    assert S.stats["fallbacks"] == fallbacks + 1 and fac._fallback is not None
    np.testing.assert_allclose(x, np.linalg.solve(M.T, b), atol=1e-12)


def test_grad_skips_exactly_the_adjoint_check():
    P, v, M = random_matrix(5)
    b, w = np.random.default_rng(6).standard_normal((2, N, 2))
    loss = jax.jit(jax.grad(lambda vals, rhs: jnp.sum(w * S.solve(P, vals, rhs)), argnums=(0, 1)))
    solves, skipped = S.stats["solves"], S.stats["checks_skipped"]
    gv, gb = loss(v, b)
    assert S.stats["solves"] == solves + 2 and S.stats["checks_skipped"] == skipped + 1
    lam = np.linalg.solve(M.T, w)
    np.testing.assert_allclose(gb, lam, atol=1e-12)
    x = np.linalg.solve(M, b)
    np.testing.assert_allclose(gv, -np.sum(lam[P.rows] * x[P.indices], 1), atol=1e-12)
    # transposing the solve alone (no forward solve of fresh values first) checks the adjoint
    P2, v2, M2 = random_matrix(7)
    skipped = S.stats["checks_skipped"]
    (lam2,) = jax.linear_transpose(lambda r: S.solve(P2, jnp.asarray(v2), r), jnp.zeros(N))(jnp.ones(N))
    assert S.stats["checks_skipped"] == skipped
    np.testing.assert_allclose(lam2, np.linalg.solve(M2.T, np.ones(N)), atol=1e-12)


@pytest.mark.skipif("pardiso" not in S.available_backends(), reason="needs PARDISO")
def test_blocked_transposed_lu_solve_is_reproducible_and_right():
    P, v, M = random_matrix(8, n=200)
    b = np.random.default_rng(9).standard_normal((200, 3))
    fac = S.factorize(P, v, backend="pardiso")
    x = fac.solve_transpose(b)
    for _ in range(3):
        np.testing.assert_array_equal(fac.solve_transpose(np.array(b)), x)
    np.testing.assert_allclose(x, np.linalg.solve(M.T, b), rtol=0, atol=1e-12 * np.abs(x).max())
    cols = np.stack([fac.solve_transpose(b[:, j]) for j in range(3)], 1)
    np.testing.assert_allclose(x, cols, rtol=0, atol=1e-13 * np.abs(x).max())


def _system(kind, seed=0):
    mesh = jp.shapes.disk(rings=5, seed=seed, height=0.3)
    t = mesh.topology
    Sy = linear.interior_system(t)
    V = jnp.asarray(mesh.vertices)
    w = wts.entry_weights(V, t, kind)[0]
    ang = np.linspace(0, 2 * np.pi, t.boundary.size, endpoint=False)
    u = jnp.asarray(np.stack([np.cos(ang), np.sin(ang)], 1))
    return Sy, w, u, kind in wts.SYMMETRIC_KINDS, comb.normalizes(kind)


def _reference(Sy, normalize, symmetric):
    def f(w, u):
        vals, rhs = comb.assemble(Sy, w, u, normalize=normalize)
        return S.solve(Sy.pattern, vals, rhs, symmetric=symmetric)
    return f


def _close(a, b):
    for x, y in zip(a, b):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-11 * np.abs(y).max())


def _new(Sy, normalize, symmetric):
    return lambda w, u: comb.solve_weights(Sy, w, u, normalize=normalize, symmetric=symmetric)


def _inputs(Sy, w, u):
    rng = np.random.default_rng(1)
    g = jnp.asarray(rng.standard_normal((Sy.n_free, 2)))
    return g, jnp.asarray(rng.standard_normal(w.shape)), jnp.asarray(rng.standard_normal(u.shape))


@pytest.mark.parametrize("kind", ["mean_value", pytest.param("harmonic", marks=pytest.mark.slow)])
def test_solve_weights_values_and_derivatives_match_assemble_and_solve(kind):
    Sy, w, u, symmetric, normalize = _system(kind)
    ref, new = _reference(Sy, normalize, symmetric), _new(Sy, normalize, symmetric)
    np.testing.assert_array_equal(jax.jit(new)(w, u), jax.jit(ref)(w, u))
    np.testing.assert_array_equal(new(w, u), ref(w, u))
    g, dw, du = _inputs(Sy, w, u)
    loss = lambda f: lambda w, u: jnp.sum(g * f(w, u))  # noqa: E731
    _close(jax.jit(jax.grad(loss(new), argnums=(0, 1)))(w, u), jax.grad(loss(ref), argnums=(0, 1))(w, u))
    _close(jax.jvp(new, (w, u), (dw, du)), jax.jvp(ref, (w, u), (dw, du)))
    # a zero tangent on one input
    _close([jax.jvp(lambda w: new(w, u), (w,), (dw,))[1]], [jax.jvp(lambda w: ref(w, u), (w,), (dw,))[1]])


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["mean_value", "harmonic"])
def test_solve_weights_under_jacfwd_vmap_and_second_order(kind):
    Sy, w, u, symmetric, normalize = _system(kind)
    ref, new = _reference(Sy, normalize, symmetric), _new(Sy, normalize, symmetric)
    g, dw, du = _inputs(Sy, w, u)
    _close(jax.jacfwd(new, argnums=1)(w, u), jax.jacrev(ref, argnums=1)(w, u))
    dws = jnp.stack([dw, 2 * dw, -dw])
    _close(jax.vmap(lambda d: jax.jvp(lambda w: new(w, u), (w,), (d,))[1])(dws),
           jax.vmap(lambda d: jax.jvp(lambda w: ref(w, u), (w,), (d,))[1])(dws))
    hvp = lambda f: jax.jvp(jax.grad(lambda w: jnp.sum(g * f(w, u)) ** 2), (w,), (dw,))[1]  # noqa: E731
    _close([hvp(new)], [hvp(ref)])


def test_convex_map_gradient_against_central_differences_through_solve_weights():
    mesh = jp.shapes.disk(rings=5, seed=2, height=0.3)
    F = mesh.faces
    V = jnp.asarray(mesh.vertices)
    rng = np.random.default_rng(3)
    W = jnp.asarray(rng.standard_normal((mesh.n_vertices, 2)))
    for kind in ("mean_value", "inverse_distance"):
        f = lambda V: jnp.sum(W * jp.convex_map(jp.TriMesh(V, F), weights=kind))  # noqa: E731
        g = jax.grad(f)(V)
        d = jnp.asarray(rng.standard_normal(V.shape))
        h = 1e-6
        fd = (f(V + h * d) - f(V - h * d)) / (2 * h)
        assert abs(float(jnp.sum(g * d)) - float(fd)) <= 1e-6 * abs(float(fd))


def test_eager_gradient_reuses_the_forward_factor_on_an_ill_conditioned_mesh():
    """Under an eager ``jax.grad`` the convex map's forward solve (concrete values, inside the
    custom_jvp) and its adjoint solve (traced) share one cached, checked factor: one
    factorization per gradient, the adjoint's check skipped.  Before, the adjoint factorized
    again and checked its own residual, which a mesh with vertices 1e-9 from a neighbour (mean
    value weights near 1e9) failed at 2.8e-7 after a forward that passed, so the gradient
    raised JAX's runtime error around a SolverError (found by the held-out QA, issue 12)."""
    mesh = jp.shapes.disk(10, seed=0)
    V, F = np.asarray(mesh.vertices).copy(), np.asarray(mesh.faces)
    rng = np.random.default_rng(0)
    for i in rng.choice(mesh.topology.interior, 10, replace=False):
        j = next(x for x in F[np.any(F == i, 1)][0] if x != i)
        V[i] = V[j] + 1e-9 * (V[i] - V[j])
    before = dict(S.stats)
    g = jax.grad(lambda X: jnp.sum(jp.convex_map(jp.TriMesh(X, F), weights="mean_value") ** 2))(
        jnp.asarray(V))
    assert np.all(np.isfinite(np.asarray(g))) and float(jnp.max(jnp.abs(g))) > 0
    assert S.stats["factorizations"] - before["factorizations"] == 1
    assert S.stats["checks_skipped"] - before["checks_skipped"] == 1
