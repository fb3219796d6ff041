"""jaxparam.sparse: every backend against dense solves, adjoint gradients against finite
differences, the factorization cache, PARDISO's shared Cholesky analysis, and the errors."""
import gc

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import scipy.sparse as sp  # noqa: E402

from jaxparam import sparse as S  # noqa: E402
from jaxparam.errors import SolverError  # noqa: E402

N = 50
BACKENDS = S.available_backends()
GENERAL_BACKENDS = [b for b in BACKENDS if b != "cholespy"]     # CHOLMOD is Cholesky only


def random_system(n=N, symmetric=False, seed=0):
    """A diagonally dominant matrix on a random sparse graph plus the diagonal (SPD when
    symmetric): its pattern, values and dense form."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.08, random_state=rng, format="csr",
                  data_rvs=lambda k: rng.uniform(-1, 1, k))
    if symmetric:
        A = A + A.T
    A = (A + sp.identity(n) * (abs(A).sum(1).max() + 1)).tocsr()
    A.sum_duplicates()
    A.sort_indices()
    return S.Pattern(A.indptr, A.indices, n), A.data.copy(), A.toarray()


def symmetric_direction(P, dv):
    """dv made symmetric on P's pattern (entries (i, j) and (j, i) moved alike)."""
    M = sp.csr_matrix((dv, P.indices, P.indptr), shape=(P.n, P.n))
    M = (M + M.T).tocsr()
    M.sort_indices()
    assert np.array_equal(M.indices, P.indices)
    return M.data


def test_available_backends():
    assert BACKENDS[-1] == "scipy" and set(BACKENDS) <= {"pardiso", "cholespy", "scipy"}


@pytest.mark.parametrize("backend", GENERAL_BACKENDS)
def test_unsymmetric_against_dense(backend):
    P, vals, D = random_system(seed=1)
    assert not np.allclose(D, D.T)
    fac = S.factorize(P, vals, backend=backend)
    assert fac.backend == backend and fac.n == N
    b = np.random.default_rng(2).standard_normal((N, 3))
    for rhs in (b, b[:, 0]):
        x = fac.solve(rhs)
        assert x.shape == rhs.shape
        np.testing.assert_allclose(x, np.linalg.solve(D, rhs), rtol=0, atol=1e-12)
        np.testing.assert_allclose(fac.solve_transpose(rhs), np.linalg.solve(D.T, rhs), rtol=0, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_symmetric_positive_definite_against_dense(backend):
    P, vals, D = random_system(symmetric=True, seed=3)
    assert np.allclose(D, D.T) and np.linalg.eigvalsh(D).min() > 0
    fac = S.factorize(P, vals, symmetric=True, backend=backend)
    assert fac.backend == backend and fac.symmetric
    b = np.random.default_rng(4).standard_normal((N, 2))
    for rhs in (b, b[:, 1]):
        np.testing.assert_allclose(fac.solve(rhs), np.linalg.solve(D, rhs), rtol=0, atol=1e-12)
        np.testing.assert_allclose(fac.solve_transpose(rhs), np.linalg.solve(D, rhs), rtol=0, atol=1e-12)


def test_auto_backend_choice():
    P, vals, _ = random_system(symmetric=True, seed=5)
    first = "pardiso" if "pardiso" in BACKENDS else None
    assert S.factorize(P, vals).backend == (first or "scipy")
    assert S.factorize(P, vals, symmetric=True).backend == (first or BACKENDS[0])


@pytest.mark.parametrize("jit", [False, True])
@pytest.mark.parametrize("symmetric, backend", [(False, b) for b in GENERAL_BACKENDS]
                         + [(True, b) for b in BACKENDS])
def test_gradient_against_central_differences(symmetric, backend, jit):
    P, vals, _ = random_system(symmetric=symmetric, seed=6)
    b = np.random.default_rng(7).standard_normal((N, 2))

    def f(v, rhs):
        return jnp.sum(jnp.sin(S.solve(P, v, rhs, symmetric=symmetric, backend=backend)))

    grad = jax.grad(f, argnums=(0, 1))
    gv, gb = (jax.jit(grad) if jit else grad)(jnp.asarray(vals), jnp.asarray(b))
    rng = np.random.default_rng(8)
    h = 1e-6
    for _ in range(3):
        dv, db = rng.standard_normal(vals.shape), rng.standard_normal(b.shape)
        if symmetric:      # the promise A = A^T must hold along the path
            dv = symmetric_direction(P, dv)
        fd = (float(f(vals + h * dv, b + h * db)) - float(f(vals - h * dv, b - h * db))) / (2 * h)
        an = float(np.sum(np.asarray(gv) * dv) + np.sum(np.asarray(gb) * db))
        assert abs(an - fd) <= 1e-6 * abs(fd), (an, fd)
    if not symmetric:      # single entries too (a general A has independent entries)
        scale = np.abs(np.asarray(gv)).max()
        for e in rng.choice(P.nnz, 4, replace=False):
            dv = np.zeros_like(vals)
            dv[e] = 1.0
            fd = (float(f(vals + h * dv, b)) - float(f(vals - h * dv, b))) / (2 * h)
            assert abs(float(gv[e]) - fd) <= 1e-6 * scale


def test_gradient_with_vector_rhs_and_vmap():
    P, vals, D = random_system(seed=9)
    b = np.random.default_rng(10).standard_normal(N)
    g = jax.grad(lambda v: jnp.sum(S.solve(P, v, b) ** 2))(jnp.asarray(vals))
    x = np.linalg.solve(D, b)
    lam = np.linalg.solve(D.T, 2 * x)
    np.testing.assert_allclose(g, -lam[P.rows] * x[P.indices], rtol=1e-10, atol=1e-14)
    # vmap over a batch of values and right-hand sides
    V = np.stack([vals, 2 * vals, vals + 0.5 * (P.rows == P.indices)])
    B = np.random.default_rng(11).standard_normal((3, N, 2))
    X = jax.jit(jax.vmap(lambda v, r: S.solve(P, v, r)))(V, B)
    for i in range(3):
        np.testing.assert_allclose(X[i], np.linalg.solve(P.matrix(V[i]).toarray(), B[i]), atol=1e-12)


def test_backward_pass_reuses_the_forward_factorization():
    P, vals, D = random_system(seed=12)
    b = np.ones((N, 2))
    f = jax.jit(lambda v: jnp.sum(S.solve(P, v, b) ** 2))
    before = dict(S.stats)
    g = jax.grad(f)(jnp.asarray(vals))
    assert np.all(np.isfinite(g))
    assert S.stats["factorizations"] - before["factorizations"] == 1
    assert S.stats["cache_hits"] - before["cache_hits"] >= 1
    assert S.stats["solves"] - before["solves"] == 2
    # the same values again: no factorization at all
    np.testing.assert_allclose(f(jnp.asarray(vals)), np.sum(np.linalg.solve(D, b) ** 2), rtol=1e-12)
    assert S.stats["factorizations"] - before["factorizations"] == 1
    # new values: one more
    f(jnp.asarray(vals * 1.5))
    assert S.stats["factorizations"] - before["factorizations"] == 2


@pytest.mark.parametrize("backend", BACKENDS)
def test_singular_matrix_raises(backend):
    D = np.array([[1.0, 1, 0, 0], [1, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    A = sp.csr_matrix(D)
    P = S.Pattern(A.indptr, A.indices, 4)
    sym = backend == "cholespy"
    with pytest.raises(SolverError, match="singular") as e:
        S.factorize(P, A.data, symmetric=sym, backend=backend).solve(np.arange(4.0))
    assert e.value.stage in ("factorize", "solve")
    with pytest.raises(SolverError, match="singular"):        # eager solve raises it itself
        S.solve(P, jnp.asarray(A.data), jnp.ones((4, 1)), symmetric=sym, backend=backend)
    with pytest.raises(Exception, match="singular"):          # under jit, inside JAX's error
        jax.jit(lambda v: S.solve(P, v, jnp.ones((4, 1)), symmetric=sym, backend=backend))(A.data)


def test_empty_row_is_singular():
    P = S.Pattern([0, 1, 1, 2], [0, 2], 3)
    with pytest.raises(SolverError, match=r"singular: rows 1 \(1 in all\) have no entries") as e:
        S.factorize(P, [1.0, 1.0])
    assert e.value.stage == "factorize"


def test_bad_residual_goes_to_superlu_then_raises():
    P, vals, D = random_system(seed=13)
    b = np.ones(N)
    fac = S.factorize(P, vals, backend=BACKENDS[0] if BACKENDS[0] != "cholespy" else "scipy")
    fac._impl.solve = lambda rhs, transpose: np.zeros_like(rhs)       # a broken backend
    if fac.backend != "scipy":
        before = S.stats["fallbacks"]
        np.testing.assert_allclose(fac.solve(b), np.linalg.solve(D, b), atol=1e-12)
        assert S.stats["fallbacks"] == before + 1
    fac = S.factorize(P, vals, backend="scipy")
    fac._impl.solve = lambda rhs, transpose: np.zeros_like(rhs)
    with pytest.raises(SolverError, match=r"50 x 50 system left a relative residual of 1 \(> 1e-08\)") as e:
        fac.solve(b)
    assert e.value.stage == "solve"


def test_shape_and_argument_errors():
    P, vals, _ = random_system()
    with pytest.raises(SolverError, match=rf"values must have shape \({P.nnz},\), got \({P.nnz - 1},\)"):
        S.solve(P, vals[:-1], np.ones((N, 2)))
    with pytest.raises(SolverError, match=r"rhs must have shape \(50,\) or \(50, k\), got \(49, 2\)"):
        S.solve(P, vals, np.ones((49, 2)))
    with pytest.raises(SolverError, match=r"rhs must have shape .*got \(50, 2, 1\)"):
        jax.jit(lambda v: S.solve(P, v, jnp.ones((N, 2, 1))))(vals)
    with pytest.raises(SolverError, match=rf"values must have shape \({P.nnz},\) .*got \(3,\)"):
        S.factorize(P, np.ones(3))
    fac = S.factorize(P, vals)
    with pytest.raises(SolverError, match=r"right-hand side must have shape \(50,\) or \(50, k\), got \(7,\)"):
        fac.solve(np.ones(7))
    with pytest.raises(SolverError, match="non-finite"):
        fac.solve(np.full(N, np.nan))
    bad = vals.copy()
    bad[3] = np.inf
    with pytest.raises(SolverError, match="1 non-finite entries"):
        S.factorize(P, bad)
    with pytest.raises(SolverError, match="unknown backend 'cholmod'"):
        S.factorize(P, vals, backend="cholmod")
    if "cholespy" in BACKENDS:
        with pytest.raises(SolverError, match="only symmetric positive definite"):
            S.factorize(P, vals, backend="cholespy")
    with pytest.raises(TypeError, match="must be a sparse.Pattern"):
        S.solve(sp.csr_matrix(np.eye(2)), np.ones(2), np.ones(2))


def test_pattern_validation():
    P = S.Pattern([0, 2, 3], [0, 1, 1], 2)
    assert (P.n, P.nnz) == (2, 3) and P.rows.tolist() == [0, 0, 1] and hash(P) != hash(S.Pattern([0, 2, 3], [0, 1, 1], 2))
    with pytest.raises(ValueError, match=r"indptr must have shape \(3,\) for n = 2, got \(2,\)"):
        S.Pattern([0, 3], [0, 1, 1], 2)
    with pytest.raises(ValueError, match=r"sorted and unique within each row; rows 0 \(1 in all\)"):
        S.Pattern([0, 2, 3], [1, 0, 1], 2)
    with pytest.raises(ValueError, match=r"sorted and unique"):
        S.Pattern([0, 2, 3], [1, 1, 1], 2)
    with pytest.raises(ValueError, match=r"column indices must lie in \[0, 2\)"):
        S.Pattern([0, 2, 3], [0, 2, 1], 2)
    with pytest.raises(ValueError, match="rise from 0 to nnz = 3"):
        S.Pattern([0, 2, 4], [0, 1, 1], 2)
    with pytest.raises(ValueError):
        P.indices[0] = 1                      # read-only: a pattern never changes


def test_factorizations_of_one_pattern_stay_independent():
    """Many factorizations of one pattern alive at once (PARDISO: more than its Cholesky
    slots, so some are evicted and refactorized) all solve their own matrix, bit for bit
    as when made alone."""
    P, vals, D = random_system(symmetric=True, seed=14)
    scales = 1.0 + np.arange(11)
    facs = [S.factorize(P, s * vals, symmetric=True) for s in scales]
    b = np.random.default_rng(15).standard_normal(N)
    for s, fac in zip(scales[::-1], facs[::-1]):
        np.testing.assert_allclose(fac.solve(b), np.linalg.solve(s * D, b), rtol=0, atol=1e-12)
    alone = S.factorize(S.Pattern(P.indptr, P.indices, N), 3.0 * vals, symmetric=True).solve(b)
    np.testing.assert_array_equal(facs[2].solve(b), alone)
    unsym = [S.factorize(P, vals * s) for s in scales[:3]]
    for s, fac in zip(scales[:3], unsym):
        np.testing.assert_allclose(fac.solve_transpose(b), np.linalg.solve(s * D, b), atol=1e-12)


@pytest.mark.skipif("pardiso" not in BACKENDS, reason="PARDISO not available")
def test_pardiso_frees_a_collected_factor():
    P, vals, _ = random_system(symmetric=True, seed=16)
    facs = [S.factorize(P, s * vals, symmetric=True, backend="pardiso") for s in (1.0, 2.0, 3.0)]
    h = S.pardiso.handles[P]
    assert sum(t is not None for t in h.owner) == 3
    del facs[1]
    gc.collect()
    assert sum(t is not None for t in h.owner) == 2
    np.testing.assert_allclose(facs[1].solve(np.ones(N)), facs[0].solve(np.ones(N)) / 3, atol=1e-13)


def test_pattern_collected_before_a_compiled_solve_runs():
    """The compiled solve finds its pattern by uid; if that pattern is gone it is rebuilt
    from the index arrays that travel as operands."""
    _, vals, D = random_system(seed=17)
    A = sp.csr_matrix(D)
    uids = []

    def make():
        P = S.Pattern(A.indptr, A.indices, N)
        uids.append(P.uid)
        return P

    g = jax.jit(lambda v: S.solve(make(), v, jnp.ones(N)))       # the pattern lives while tracing only
    np.testing.assert_allclose(g(vals), np.linalg.solve(D, np.ones(N)), atol=1e-12)
    with S.differentiable.cache_lock:
        S.differentiable.cache.clear()
    gc.collect()
    assert len(uids) == 1 and uids[0] not in S.pattern.registry
    np.testing.assert_allclose(g(2 * vals), np.linalg.solve(2 * D, np.ones(N)), atol=1e-12)
    assert uids[0] in S.pattern.registry and len(uids) == 1
