"""jaxparam.sparse.solve under every JAX transformation: forward mode (jvp, jacfwd) and reverse
mode (grad, vjp, jacrev) from its one custom_linear_solve definition, against central finite
differences and each other; second derivatives; jit; vmap over right-hand sides and over matrices
against Python loops; the number of factorizations and solves each costs; and jacfwd == jacrev
through a whole convex map."""
import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import scipy.sparse as sp  # noqa: E402

import jaxparam as jp  # noqa: E402
from jaxparam import sparse as S  # noqa: E402
from jaxparam.sparse import differentiable  # noqa: E402

N = 30
H = 1e-6                        # central-difference step (relative to entries of size ~1)
BACKENDS = S.available_backends()
GENERAL_BACKENDS = [b for b in BACKENDS if b != "cholespy"]     # CHOLMOD is Cholesky only
CASES = ([(False, b) for b in GENERAL_BACKENDS] + [(True, b) for b in BACKENDS])
CASE_IDS = [f"{'spd' if s else 'unsym'}-{b}" for s, b in CASES]


def random_system(symmetric: bool, seed: int = 0, n: int = N):
    """A diagonally dominant matrix on a random sparse mask plus the diagonal (symmetric
    positive definite when ``symmetric``): ``(pattern, values, dense, rng)``."""
    rng = np.random.default_rng(seed)
    mask = rng.random((n, n)) < 0.12
    if symmetric:
        mask |= mask.T
    M = np.where(mask, rng.uniform(-1, 1, (n, n)), 0.0)
    if symmetric:
        M = (M + M.T) / 2
    np.fill_diagonal(M, np.abs(M).sum(1) + 1 + rng.random(n))
    A = sp.csr_matrix(M)
    A.sort_indices()
    assert A.nnz > 2 * n and (np.allclose(M, M.T) == symmetric)
    return S.Pattern(A.indptr, A.indices, n), A.data.copy(), M, rng


def transpose_positions(P) -> np.ndarray:
    """For each entry ``(i, j)`` of the (structurally symmetric) pattern, the position of ``(j, i)``."""
    T = sp.csr_matrix((np.arange(P.nnz, dtype=np.float64) + 1, P.indices, P.indptr), shape=(P.n, P.n)).T.tocsr()
    T.sort_indices()
    assert np.array_equal(T.indices, P.indices)
    return T.data.astype(np.int64) - 1


def direction(P, dv, symmetric: bool) -> np.ndarray:
    """``dv``, made symmetric on the pattern when the matrix is (``symmetric=True`` promises
    ``A = A^T`` and the Cholesky backends read one triangle, so finite differences must keep it)."""
    return (dv + dv[transpose_positions(P)]) / 2 if symmetric else dv


def unit_directions(P, symmetric: bool) -> np.ndarray:
    """``(nnz, m)``: the unit directions of the entries, or of the symmetric pairs of entries."""
    if not symmetric:
        return np.eye(P.nnz)
    t = transpose_positions(P)
    keep = np.flatnonzero(np.arange(P.nnz) <= t)
    D = np.zeros((P.nnz, keep.size))
    D[keep, np.arange(keep.size)] = 1
    D[t[keep], np.arange(keep.size)] = 1
    return D


def rel_err(a, b) -> float:
    """Norm-wise relative error ``|a - b| / |b|``."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def central(f, x, d, h=H):
    """The central difference of ``f`` at ``x`` along ``d`` (numpy arrays)."""
    return (np.asarray(f(x + h * d)) - np.asarray(f(x - h * d))) / (2 * h)


def clear_cache():
    with differentiable.cache_lock:
        differentiable.cache.clear()


@pytest.mark.parametrize(("symmetric", "backend"), CASES, ids=CASE_IDS)
@pytest.mark.parametrize("k", [None, 2], ids=["vector-rhs", "matrix-rhs"])
def test_jvp_against_central_differences(symmetric, backend, k):
    P, v, D, rng = random_system(symmetric, seed=1)
    b = rng.standard_normal(N if k is None else (N, k))
    dv, db = direction(P, rng.standard_normal(v.shape), symmetric), rng.standard_normal(b.shape)

    def f(vals, rhs):
        return S.solve(P, vals, rhs, symmetric=symmetric, backend=backend)

    x, dx = jax.jvp(f, (v, b), (dv, db))
    np.testing.assert_allclose(x, np.linalg.solve(D, b), rtol=0, atol=1e-12)
    # each input alone, then both together
    _, dx_v = jax.jvp(lambda vals: f(vals, b), (v,), (dv,))
    _, dx_b = jax.jvp(lambda rhs: f(v, rhs), (b,), (db,))
    assert rel_err(dx_v, central(lambda vals: f(vals, b), v, dv)) < 1e-6
    assert rel_err(dx_b, central(lambda rhs: f(v, rhs), b, db)) < 1e-6
    fd_both = (np.asarray(f(v + H * dv, b + H * db)) - np.asarray(f(v - H * dv, b - H * db))) / (2 * H)
    assert rel_err(dx, fd_both) < 1e-6
    # and the closed form dx = A^{-1} (db - dA x)
    dA = sp.csr_matrix((dv, P.indices, P.indptr), shape=(N, N)).toarray()
    np.testing.assert_allclose(dx, np.linalg.solve(D, db - dA @ np.asarray(x)), rtol=0, atol=1e-10)


@pytest.mark.parametrize(("symmetric", "backend"), CASES, ids=CASE_IDS)
def test_jacfwd_against_central_differences_and_jacrev(symmetric, backend):
    P, v, _, rng = random_system(symmetric, seed=2)
    b = rng.standard_normal(N)

    def f(vals, rhs):
        return S.solve(P, vals, rhs, symmetric=symmetric, backend=backend)

    Jv_fwd, Jb_fwd = jax.jacfwd(f, argnums=(0, 1))(v, b)
    Jv_rev, Jb_rev = jax.jacrev(f, argnums=(0, 1))(v, b)
    assert Jv_fwd.shape == (N, P.nnz) and Jb_fwd.shape == (N, N)
    # every column of the Jacobians against a central difference along that coordinate (for a
    # symmetric matrix: along each symmetric pair of entries)
    E = unit_directions(P, symmetric)
    fd_v = np.stack([central(lambda vals: f(vals, b), v, e) for e in E.T], 1)
    fd_b = np.stack([central(lambda rhs: f(v, rhs), b, e) for e in np.eye(N)], 1)
    assert rel_err(Jv_fwd @ E, fd_v) < 1e-6 and rel_err(Jb_fwd, fd_b) < 1e-6
    np.testing.assert_allclose(Jv_fwd, Jv_rev, rtol=0, atol=1e-10 * np.abs(Jv_rev).max())
    np.testing.assert_allclose(Jb_fwd, Jb_rev, rtol=0, atol=1e-10 * np.abs(Jb_rev).max())


@pytest.mark.parametrize(("symmetric", "backend"), CASES, ids=CASE_IDS)
def test_grad_under_jit_and_vjp(symmetric, backend):
    P, v, D, rng = random_system(symmetric, seed=3)
    b, w = rng.standard_normal((N, 2)), rng.standard_normal((N, 2))

    def loss(vals, rhs):
        return jnp.sum(w * S.solve(P, vals, rhs, symmetric=symmetric, backend=backend))

    gv, gb = jax.jit(jax.grad(loss, argnums=(0, 1)))(v, b)
    gv_eager, gb_eager = jax.grad(loss, argnums=(0, 1))(v, b)
    np.testing.assert_array_equal(gv, gv_eager)
    np.testing.assert_array_equal(gb, gb_eager)
    # the adjoint formulas: lam = A^-T w, d b = lam, d A_ij = -lam_i . x_j
    x = np.linalg.solve(D, b)
    lam = np.linalg.solve(D.T, w)
    np.testing.assert_allclose(gb, lam, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gv, -np.sum(lam[P.rows] * x[P.indices], 1), rtol=0, atol=1e-12)
    # vjp agrees with grad, and with central differences of the loss
    _, pull = jax.vjp(lambda vals, rhs: S.solve(P, vals, rhs, symmetric=symmetric, backend=backend), v, b)
    pv, pb = pull(jnp.asarray(w))
    np.testing.assert_allclose(pv, gv, rtol=0, atol=1e-13)
    np.testing.assert_allclose(pb, gb, rtol=0, atol=1e-13)
    dv = direction(P, rng.standard_normal(v.shape), symmetric)
    fd = float(central(lambda vals: loss(vals, b), v, dv))
    assert abs(float(gv @ dv) - fd) <= 1e-6 * abs(fd)


# PARDISO's two cases (10-15 s each) with the slow tests since session 27; SciPy's stay on.
# Each derivative is jitted (one compilation each, kept by the persistent cache): eagerly the
# second-order transforms dispatched op by op, 8 s of SciPy's cases; the same custom_linear_solve
# rules are transformed either way.
@pytest.mark.parametrize(("symmetric", "backend"), [
    pytest.param(s, b, id=i, marks=pytest.mark.slow) if b == "pardiso" else pytest.param(s, b, id=i)
    for (s, b), i in zip(CASES, CASE_IDS)])
def test_second_derivatives_against_differences_of_the_gradient(symmetric, backend):
    P, v, _, rng = random_system(symmetric, seed=4)
    b = rng.standard_normal(N)

    def loss(vals, rhs):
        x = S.solve(P, vals, rhs, symmetric=symmetric, backend=backend)
        return jnp.sum(x ** 2) + jnp.sum(x[:3]) ** 3

    g = jax.grad(loss, argnums=(0, 1))
    du, db = direction(P, rng.standard_normal(v.shape), symmetric), rng.standard_normal(b.shape)
    # grad of grad: grad_z <g(z), d> = H d, against (g(z + h d) - g(z - h d)) / 2h
    Hd = jax.jit(jax.grad(lambda vals, rhs: sum(jnp.vdot(gi, di) for gi, di in zip(g(vals, rhs), (du, db))),
                          argnums=(0, 1)))(v, b)
    g_jit = jax.jit(g)
    gp, gm = g_jit(v + H * du, b + H * db), g_jit(v - H * du, b - H * db)
    for i in range(2):
        assert rel_err(Hd[i], (np.asarray(gp[i]) - np.asarray(gm[i])) / (2 * H)) < 1e-5
    # mixed modes: forward-over-reverse (jax.hessian) == reverse-over-reverse
    Hv_fr = jax.jit(jax.hessian(loss))(v, b)
    Hv_rr = jax.jit(jax.jacrev(jax.grad(loss)))(v, b)
    np.testing.assert_allclose(Hv_fr, Hv_rr, rtol=0, atol=1e-10 * np.abs(Hv_rr).max())
    np.testing.assert_allclose(Hv_fr, Hv_fr.T, rtol=0, atol=1e-10 * np.abs(Hv_fr).max())
    np.testing.assert_allclose(Hv_fr @ du, Hd[0] - jax.jit(jax.jacfwd(jax.grad(loss), argnums=1))(v, b) @ db,
                               rtol=0, atol=1e-9 * np.abs(Hd[0]).max())


@pytest.mark.parametrize(("symmetric", "backend"), CASES, ids=CASE_IDS)
def test_vmap_over_rhs_and_over_values_equals_a_loop(symmetric, backend):
    P, v, _, rng = random_system(symmetric, seed=5)
    B = rng.standard_normal((5, N, 2))
    Vs = v * rng.uniform(0.8, 1.2, (4, P.nnz))
    if symmetric:   # keep each member symmetric
        Vs = np.stack([direction(P, vv, True) for vv in Vs])

    def f(vals, rhs):
        return S.solve(P, vals, rhs, symmetric=symmetric, backend=backend)

    loop = lambda pairs: np.stack([np.asarray(S.factorize(P, vv, symmetric=symmetric, backend=backend)
                                              .solve(bb)) for vv, bb in pairs])
    clear_cache()
    s0 = dict(S.stats)
    over_rhs = jax.vmap(lambda rhs: f(v, rhs))(B)
    assert S.stats["factorizations"] - s0["factorizations"] == 1     # one matrix, one factorization
    np.testing.assert_allclose(over_rhs, loop((v, bb) for bb in B), rtol=0, atol=1e-13)
    over_vals = jax.vmap(lambda vals: f(vals, B[0]))(Vs)
    np.testing.assert_array_equal(over_vals, loop((vv, B[0]) for vv in Vs))
    both = jax.jit(jax.vmap(f))(Vs, B[:4])
    np.testing.assert_array_equal(both, loop(zip(Vs, B[:4])))
    # vector right-hand sides, nested vmap (values outside, rhs inside), and in_axes on axis 1
    nested = jax.vmap(lambda vals: jax.vmap(lambda rhs: f(vals, rhs))(B[:, :, 0]))(Vs)
    np.testing.assert_allclose(nested, np.stack([loop((vv, bb) for bb in B[:, :, 0]) for vv in Vs]),
                               rtol=0, atol=1e-13)
    ax1 = jax.vmap(lambda rhs: f(v, rhs), in_axes=1, out_axes=1)(np.moveaxis(B, 0, 1))
    np.testing.assert_allclose(np.moveaxis(np.asarray(ax1), 1, 0), over_rhs, rtol=0, atol=1e-13)
    # gradients through vmap, per member
    gv = jax.vmap(jax.grad(lambda vals, rhs: jnp.sum(f(vals, rhs))))(Vs, B[:4])
    for i in range(4):
        np.testing.assert_allclose(gv[i], jax.grad(lambda vals: jnp.sum(f(vals, B[i])))(Vs[i]),
                                   rtol=0, atol=1e-13)


def test_cost_one_factorization_per_matrix():
    """Reverse mode costs one extra solve (A^T), forward mode one extra solve per tangent
    batch; neither factorizes again."""
    P, v, _, rng = random_system(False, seed=6)
    b = rng.standard_normal((N, 2))
    f = jax.jit(lambda vals, rhs: S.solve(P, vals, rhs))

    def cost(fn):
        clear_cache()
        s0 = dict(S.stats)
        jax.block_until_ready(fn())
        return {k: S.stats[k] - s0[k] for k in ("factorizations", "solves")}

    loss = lambda vals, rhs: jnp.sum(f(vals, rhs))
    jax.block_until_ready(f(v, b))
    assert cost(lambda: f(v, b)) == {"factorizations": 1, "solves": 1}
    assert cost(lambda: jax.grad(loss, argnums=(0, 1))(v, b)) == {"factorizations": 1, "solves": 2}
    assert cost(lambda: jax.jvp(f, (v, b), (v, b))) == {"factorizations": 1, "solves": 2}
    # jacfwd: all nnz tangents in one batched solve
    assert cost(lambda: jax.jacfwd(loss)(v, b)) == {"factorizations": 1, "solves": 2}


def test_jacfwd_equals_jacrev_through_convex_map():
    mesh = jp.shapes.disk(4, seed=1, height=0.3)
    F = mesh.faces

    def total(V):
        return jnp.sum(jp.convex_map(jp.TriMesh(V, F), weights="mean_value"))

    V = jnp.asarray(mesh.vertices)
    fwd, rev = jax.jacfwd(total)(V), jax.jacrev(total)(V)
    assert fwd.shape == V.shape and np.all(np.isfinite(rev)) and np.abs(rev).max() > 1e-3
    np.testing.assert_allclose(fwd, rev, rtol=0, atol=1e-9)
