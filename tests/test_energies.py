import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import jaxparam as jp
from jaxparam import energies as E
from jaxparam import geometry as G

DEFORMATION = ["condition_2", "mips", "condition_2_squared", "condition_f_squared", "angle"]
SV_FORMS = {
    "condition_2": lambda s1, s2: s1 / s2,
    "mips": lambda s1, s2: s1 / s2 + s2 / s1,
    "condition_2_squared": lambda s1, s2: (s1 / s2) ** 2,
    "condition_f_squared": lambda s1, s2: (s1 / s2) ** 2 + (s2 / s1) ** 2,
    "symmetric_dirichlet": lambda s1, s2: s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2,
    "arap": lambda s1, s2: (s1 - 1) ** 2 + (s2 - 1) ** 2,
    "conformal": lambda s1, s2: 0.5 * (s1 - s2) ** 2,
    "dirichlet": lambda s1, s2: 0.5 * (s1 ** 2 + s2 ** 2),
    "green_lagrange": lambda s1, s2: (s1 ** 2 - 1) ** 2 + (s2 ** 2 - 1) ** 2,
}


def triangle(seed):
    rng = np.random.default_rng(seed)
    V = rng.standard_normal((3, 3))
    return np.asarray(G.local_frames(V, np.array([[0, 1, 2]])))[0]


def image(frame, A, t=(0.0, 0.0)):
    return frame @ np.asarray(A).T + np.asarray(t)


@pytest.mark.parametrize("name", sorted(SV_FORMS))
def test_density_matches_numpy_svd(name):
    frame = triangle(0)
    A = np.array([[1.3, 0.4], [-0.2, 0.8]])
    s = np.linalg.svd(A, compute_uv=False)
    got = float(E.ENERGIES[name].density(frame, image(frame, A)))
    assert got == pytest.approx(SV_FORMS[name](s[0], s[1]), rel=1e-12)


def test_mips_proposition_2_agrees():
    for seed in range(5):
        frame = triangle(seed)
        A = np.random.default_rng(seed + 10).standard_normal((2, 2))
        if np.linalg.det(A) < 0:
            A[0] *= -1
        q = image(frame, A)
        assert float(E.mips_prop2(frame, q)) == pytest.approx(float(E.ENERGIES["mips"].density(frame, q)), rel=1e-10)


def test_barrier_is_infinite_on_inverted_triangle_with_finite_gradient():
    frame = triangle(1)
    q = image(frame, [[1.0, 0], [0, -1.0]])
    for name in ["mips", "symmetric_dirichlet", "condition_2", "angle"]:
        d = E.ENERGIES[name].density
        assert np.isinf(float(d(frame, q)))
        g = jax.grad(lambda qq: d(frame, qq))(jnp.asarray(q))
        assert not np.any(np.isnan(np.asarray(g)))


@settings(max_examples=25, deadline=None)
@given(theta=st.floats(0, 6.28), scale=st.floats(0.1, 10), tx=st.floats(-5, 5), ty=st.floats(-5, 5),
       a=st.floats(0.3, 3), b=st.floats(-1, 1), d=st.floats(0.3, 3), seed=st.integers(0, 20))
def test_deformation_functionals_are_similarity_invariant(theta, scale, tx, ty, a, b, d, seed):
    frame = triangle(seed)
    A = np.array([[a, b], [0.0, d]])
    R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    q = image(frame, A)
    q2 = image(frame, scale * R @ A, (tx, ty))
    # A reflection reverses orientation, so it is applied to the triangle as well (mirror both).
    M = np.diag([1.0, -1.0])
    fr_m, q_m = frame @ M, q @ M
    for name in DEFORMATION:
        dens = E.ENERGIES[name].density
        e0 = float(dens(frame, q))
        assert float(dens(frame, q2)) == pytest.approx(e0, rel=1e-8)
        assert float(dens(fr_m[[0, 2, 1]], q_m[[0, 2, 1]])) == pytest.approx(e0, rel=1e-8)


@pytest.mark.parametrize("name", ["condition_2", "mips", "condition_2_squared", "condition_f_squared"])
def test_depends_only_on_ratio_and_increases(name):
    frame = triangle(3)
    dens = E.ENERGIES[name].density
    rhos = np.linspace(1.0, 5.0, 9)
    vals = [float(dens(frame, image(frame, np.diag([r * 2.0, 2.0])))) for r in rhos]
    # Same ratio, other singular values: the same value (Theorem 2).
    for r, v in zip(rhos, vals):
        assert float(dens(frame, image(frame, np.diag([r * 0.3, 0.3])))) == pytest.approx(v, rel=1e-10)
    assert np.all(np.diff(vals) > 0)  # proper (Corollary 1)


def test_green_lagrange_is_not_a_deformation_functional():
    frame = triangle(4)
    gl = E.ENERGIES["green_lagrange"].density
    assert float(gl(frame, image(frame, np.eye(2)))) == pytest.approx(0.0, abs=1e-14)
    assert float(gl(frame, image(frame, 2 * np.eye(2)))) > 1.0   # a uniform scaling changes it


def test_user_energy_from_singular_values_and_jacobian():
    frame = triangle(5)
    q = image(frame, [[1.2, 0.3], [0.1, 0.9]])
    u1 = jp.energy(lambda s1, s2: s1 / s2 + s2 / s1)
    u2 = jp.energy(lambda J: jnp.sum(J ** 2) / jnp.linalg.det(J))
    ref = float(E.ENERGIES["mips"].density(frame, q))
    assert float(u1.density(frame, q)) == pytest.approx(ref, rel=1e-12)
    assert float(u2.density(frame, q)) == pytest.approx(ref, rel=1e-12)
    with pytest.raises(jp.MeshError, match="takes \\(s1, s2\\) or \\(J\\)"):
        jp.energy(lambda a, b, c: a)
    with pytest.raises(jp.MeshError, match="unknown energy 'foo'"):
        E.get("foo")


def test_mesh_energy_gradient_finite_differences():
    mesh = jp.shapes.graph_surface(6)
    uv = np.asarray(jp.convex_map(mesh))
    en = E.ENERGIES["symmetric_dirichlet"]
    f = lambda U: en(mesh, U)
    g = np.asarray(jax.grad(f)(jnp.asarray(uv)))
    d = np.random.default_rng(0).standard_normal(uv.shape) * 1e-3
    h = 1e-4
    fd = (f(jnp.asarray(uv + h * d)) - f(jnp.asarray(uv - h * d))) / (2 * h)
    assert abs(np.sum(g * d) - fd) <= 1e-7 * max(1.0, abs(fd))


def test_energy_equality_is_by_value():
    f = lambda s1, s2: s1 / s2 + s2 / s1
    a, b = jp.energy(f), jp.energy(f)
    assert a == b and hash(a) == hash(b) and a is not b
    assert a.of_J is not None and a.of_sv is f
    assert jp.energy(f, name="other") != a
    assert jp.energy(f, scale_invariant=True) != a
    assert jp.energy(lambda s1, s2: s1 / s2 + s2 / s1) != a     # another function object
    assert E.get(f) == a and E.get("mips") is E.ENERGIES["mips"]
    J = jp.energy(lambda J: jnp.sum(J ** 2))
    assert J.of_J is not None and J.of_sv is None
    assert E.ENERGIES["angle"].of_J is None and E.ENERGIES["arap"].of_sv is None


def test_equal_energies_share_compiled_code():
    import functools

    @functools.partial(jax.jit, static_argnames="en")
    def mean_density(frames, Q, *, en):
        return E.total(en, frames, jnp.ones(frames.shape[0]), Q)

    frame = triangle(6)
    frames, Q = frame[None], image(frame, [[1.1, 0.2], [0.0, 0.9]])[None]
    f = lambda s1, s2: s1 ** 2 + s2 ** 2
    a = mean_density(frames, Q, en=jp.energy(f))
    n = mean_density._cache_size()
    b = mean_density(frames, Q, en=jp.energy(f))            # a fresh, equal energy: no compile
    assert mean_density._cache_size() == n and float(a) == float(b)
    mean_density(frames, Q, en=jp.energy(lambda s1, s2: s1 ** 2 + s2 ** 2))
    assert mean_density._cache_size() == n + 1               # another function: its own code
