import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp

from jaxparam import sparse as S
from jaxparam.errors import SolverError


def random_system(n=50, symmetric=False, seed=0):
    A = sp.random(n, n, density=0.08, random_state=seed, format="csr")
    if symmetric:
        A = A + A.T
    A = (A + sp.identity(n) * (np.abs(A).sum(1).max() + 1)).tocsr()
    A.sort_indices()
    return S.Pattern(A.indptr, A.indices, n), A.data.copy(), A.toarray()


@pytest.mark.parametrize("backend", S.available_backends())
@pytest.mark.parametrize("symmetric", [False, True])
def test_factorize_against_dense(backend, symmetric):
    P, vals, D = random_system(symmetric=symmetric)
    fac = S.factorize(P, vals, symmetric=symmetric, backend=backend)
    assert fac.backend == backend
    b = np.random.default_rng(1).standard_normal((50, 3))
    np.testing.assert_allclose(fac.solve(b), np.linalg.solve(D, b), atol=1e-12)
    np.testing.assert_allclose(fac.solve(b[:, 0]), np.linalg.solve(D, b[:, 0]), atol=1e-12)
    np.testing.assert_allclose(fac.solve_transpose(b), np.linalg.solve(D.T, b), atol=1e-12)


@pytest.mark.parametrize("symmetric", [False, True])
def test_solve_gradient_finite_differences(symmetric):
    P, vals, D = random_system(symmetric=symmetric, seed=3)
    b = np.random.default_rng(2).standard_normal((50, 2))

    def f(v, rhs):
        return jnp.sum(jnp.sin(S.solve(P, v, rhs, symmetric=symmetric)))

    gv, gb = jax.grad(f, argnums=(0, 1))(jnp.asarray(vals), jnp.asarray(b))
    rng = np.random.default_rng(4)
    dv = rng.standard_normal(vals.shape)
    if symmetric:  # keep A symmetric: perturb entry (i, j) and (j, i) alike
        M = sp.csr_matrix((dv, P.indices, P.indptr), shape=(50, 50))
        M = (M + M.T).tocsr()
        M.sort_indices()
        dv = M.data
    db = rng.standard_normal(b.shape)
    h = 1e-6
    fd = (f(vals + h * dv, b + h * db) - f(vals - h * dv, b - h * db)) / (2 * h)
    an = np.sum(np.asarray(gv) * dv) + np.sum(np.asarray(gb) * db)
    assert abs(an - fd) <= 1e-6 * max(1.0, abs(fd))


def test_solve_under_jit_and_cache():
    P, vals, D = random_system(seed=5)
    b = np.ones((50, 2))
    f = jax.jit(lambda v: jnp.sum(S.solve(P, v, b) ** 2))
    before = S.stats["factorizations"]
    g = jax.grad(f)(jnp.asarray(vals))
    assert np.all(np.isfinite(g))
    # The backward pass reuses the forward factorization.
    assert S.stats["factorizations"] - before == 1
    x = np.linalg.solve(D, b)
    np.testing.assert_allclose(f(jnp.asarray(vals)), np.sum(x ** 2), rtol=1e-12)


@pytest.mark.parametrize("backend", S.available_backends())
def test_singular_matrix_raises(backend):
    n = 4
    A = sp.csr_matrix(np.array([[1.0, 1, 0, 0], [1, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    P = S.Pattern(A.indptr, A.indices, n)
    with pytest.raises(SolverError, match="singular"):
        S.factorize(P, A.data, backend=backend).solve(np.arange(4.0))


def test_shape_errors():
    P, vals, _ = random_system()
    with pytest.raises(SolverError, match=r"values must have shape \(\d+,\)"):
        S.solve(P, vals[:-1], np.ones((50, 2)))
    with pytest.raises(SolverError, match=r"rhs must have shape \(50,\)"):
        S.solve(P, vals, np.ones((49, 2)))
    with pytest.raises(SolverError, match="not available"):
        S.factorize(P, vals, backend="cholmod")


def test_pattern_reuse_refactorizes_stale_factorization():
    P, vals, D = random_system(seed=7)
    f1 = S.factorize(P, vals)
    f2 = S.factorize(P, vals * 2.0)
    b = np.ones(50)
    np.testing.assert_allclose(f1.solve(b), np.linalg.solve(D, b), atol=1e-12)
    np.testing.assert_allclose(f2.solve(b), np.linalg.solve(2 * D, b), atol=1e-12)
