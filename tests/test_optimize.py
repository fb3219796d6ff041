import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import SolverError


@pytest.fixture(scope="module")
def mesh():
    return jp.shapes.graph_surface(8)


@pytest.fixture(scope="module")
def start(mesh):
    return np.asarray(jp.convex_map(mesh, weights="uniform"))


@pytest.mark.parametrize("solver", ["newton", "lbfgs", "bfgs", "jaxopt_lbfgs"])
@pytest.mark.parametrize("free", [False, True])
def test_solvers_decrease_energy_without_flips(mesh, start, solver, free):
    res = jp.minimize(mesh, "symmetric_dirichlet", init=start, free_boundary=free, solver=solver,
                      max_iters=40, verbose=False)
    assert res.flips == 0 and jp.distortion(mesh, res.uv).flips == 0
    assert res.history[-1] < res.history[0]
    assert np.all(np.diff(res.history) <= 1e-12)      # monotone
    if not free:
        loop = mesh.topology.boundary_loops[0]
        np.testing.assert_array_equal(res.uv[loop], start[loop])


def test_newton_and_lbfgs_reach_the_same_minimum(mesh, start):
    a = jp.minimize(mesh, "symmetric_dirichlet", init=start, solver="newton", verbose=False)
    b = jp.minimize(mesh, "symmetric_dirichlet", init=start, solver="lbfgs", max_iters=300, verbose=False)
    assert a.converged
    assert b.energy == pytest.approx(a.energy, rel=1e-6)


@pytest.mark.parametrize("name", ["mips", "angle", "arap", "conformal", "green_lagrange",
                                  "condition_f_squared"])
def test_every_named_energy_minimizes(mesh, start, name):
    res = jp.minimize(mesh, name, init=start, free_boundary=True, max_iters=15, verbose=False)
    assert res.flips == 0 and res.energy <= res.history[0]


def test_free_boundary_scale_invariant_is_normalized(mesh, start):
    res = jp.minimize(mesh, "mips", init=start, free_boundary=True, max_iters=20, verbose=False)
    a0 = float(jnp.sum(jp.geometry.signed_areas(start, mesh.faces)))
    a1 = float(jnp.sum(jp.geometry.signed_areas(res.uv, mesh.faces)))
    assert a1 == pytest.approx(a0, rel=1e-9)
    np.testing.assert_allclose(res.uv.mean(0), start.mean(0), atol=1e-9)
    assert res.boundary_overlaps == 0


def test_free_boundary_symmetric_dirichlet_natural_scale(mesh):
    res = jp.minimize(mesh, "symmetric_dirichlet", free_boundary=True, verbose=False)
    # At the optimum of a scale-dependent energy the UV area is near the 3D area.
    a3 = float(jnp.sum(jp.geometry.face_areas(mesh.vertices, mesh.faces)))
    auv = float(jnp.sum(jp.geometry.signed_areas(res.uv, mesh.faces)))
    assert auv == pytest.approx(a3, rel=0.2)
    assert res.energy < 4.2   # an isometry scores 4; the graph surface is nearly developable


def test_user_energy_with_newton_and_lbfgs(mesh, start):
    mine = jp.energy(lambda s1, s2: s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2)
    for solver in ["newton", "lbfgs"]:
        a = jp.minimize(mesh, mine, init=start, solver=solver, max_iters=30, verbose=False)
        b = jp.minimize(mesh, "symmetric_dirichlet", init=start, solver=solver, max_iters=30, verbose=False)
        assert a.energy == pytest.approx(b.energy, rel=1e-6)


def test_non_injective_start_is_refused(mesh, start):
    bad = start.copy()
    i = mesh.topology.interior[5]
    bad[i] = bad[mesh.topology.boundary_loops[0][0]] * 1.5
    with pytest.raises(SolverError, match=r"not injective: \d+ of \d+ triangles are flipped") as e:
        jp.minimize(mesh, "mips", init=bad, verbose=False)
    assert e.value.stage == "init"


def test_max_iters_and_silence(mesh, start, capsys):
    res = jp.minimize(mesh, "mips", init=start, max_iters=2, verbose=False)
    assert res.iterations <= 2 and len(res.history) == res.iterations + 1
    assert capsys.readouterr().err == "" and capsys.readouterr().out == ""
    with pytest.raises(jp.MeshError, match="unknown solver"):
        jp.minimize(mesh, "mips", solver="adam")


def test_implicit_gradient_of_the_optimum():
    mesh = jp.shapes.graph_surface(5)
    F = mesh.faces
    V0 = np.asarray(mesh.vertices)
    init = np.asarray(jp.convex_map(mesh))
    c = np.random.default_rng(0).standard_normal((mesh.n_vertices, 2))

    def loss(V):
        res = jp.minimize(jp.TriMesh(V, F), "symmetric_dirichlet", init=init, verbose=False,
                          energy_rtol=1e-15, grad_rtol=1e-13, max_iters=100)
        return jnp.sum(c * res.uv)

    g = np.asarray(jax.grad(loss)(jnp.asarray(V0)))
    d = np.random.default_rng(1).standard_normal(V0.shape)
    h = 1e-5
    fd = (loss(jnp.asarray(V0 + h * d)) - loss(jnp.asarray(V0 - h * d))) / (2 * h)
    # Tolerance: the optimum is resolved to ~1e-12, central differences to ~h^2.
    assert abs(np.sum(g * d) - float(fd)) <= 1e-4 * max(1.0, abs(float(fd)))


def test_cli_flatten_with_energy(tmp_path, mesh):
    from jaxparam.cli import main
    import json
    p = tmp_path / "m.obj"
    jp.save(p, mesh)
    rep = tmp_path / "r.json"
    code = main(["flatten", str(p), "-o", str(tmp_path / "o.obj"), "--energy", "symmetric-dirichlet",
                 "--free-boundary", "--solver", "newton", "--max-iters", "20", "--report", str(rep)])
    assert code == 0
    r = json.loads(rep.read_text())
    assert r["flips"] == 0 and r["iterations"] >= 1 and r["energy"] < 4.5


@pytest.mark.parametrize("name", ["symmetric_dirichlet", "mips", "condition_f_squared", "condition_2"])
def test_analytic_eigensystem_projection_matches_eigh(name):
    from jaxparam import optimize as O
    en = jp.energies.ENERGIES[name]
    rng = np.random.default_rng(3)
    for _ in range(5):
        J = rng.standard_normal((2, 2))
        if np.linalg.det(J) < 0:
            J[0] *= -1
        H = jax.hessian(lambda v: en.density.of_J(v.reshape(2, 2)))(jnp.asarray(J.reshape(-1)))
        ref = np.asarray(O._psd(H[None]))[0]
        got = np.asarray(O._projected_sv_hessian(jnp.asarray(J), en.density.of_sv))
        np.testing.assert_allclose(got, ref, atol=1e-10 * np.abs(ref).max())
