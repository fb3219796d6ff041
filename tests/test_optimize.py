import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import MeshError, SolverError


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


def test_newton_steps_on_when_its_solve_misses_the_residual(mesh, start):
    # a Hessian whose solve misses the residual bound (camelhead scaled 1000:1:0.01 under the
    # angle energy left 1.45e-6 and stopped with a SolverError) is shifted further and its
    # direction used: with a bound no solve can meet, every step takes that road and reaches
    # the minimum the default reaches
    a = jp.minimize(mesh, "symmetric_dirichlet", init=start, verbose=False)
    b = jp.minimize(mesh, "symmetric_dirichlet", init=start, verbose=False,
                    solver=jp.optimize.Newton(residual_tol=0.0))
    assert a.converged and b.converged and b.flips == 0
    assert b.energy == pytest.approx(a.energy, rel=1e-9)


@pytest.mark.parametrize("name", ["mips", "angle", "arap", "conformal", "green_lagrange",
                                  "condition_f_squared"])
def test_every_named_energy_minimizes(mesh, start, name):
    free = name != "conformal"          # it has no free minimum but a point
    res = jp.minimize(mesh, name, init=start, free_boundary=free, max_iters=15, verbose=False)
    assert res.flips == 0 and res.energy <= res.history[0]


def test_conformal_energy_is_not_scale_invariant_and_has_no_free_minimum(mesh, start):
    """0.5 (s1 - s2)^2 is quadratic in the UVs: it was marked scale-invariant, so a free
    boundary's iterates were rescaled to the start's area, a constrained optimum that Newton
    did not reach and whose implicit gradient was 42x off (session 22)."""
    en = jp.ENERGIES["conformal"]
    assert not en.scale_invariant
    assert float(en(mesh, 2 * start)) == pytest.approx(4 * float(en(mesh, start)), rel=1e-12)
    with pytest.raises(MeshError, match=r"'conformal' with a free boundary shrinks the map "
                                        r"towards a point.*jp\.least_squares_map"):
        jp.minimize(mesh, "conformal", free_boundary=True)


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
    # (max_iters 40 as in test_solvers_decrease_energy_without_flips: optimistix compiles its
    # loop for each max_steps, about 2.5 s, and the named energy's run shares that one)
    mine = jp.energy(lambda s1, s2: s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2)
    for solver in ["newton", "lbfgs"]:
        a = jp.minimize(mesh, mine, init=start, solver=solver, max_iters=40, verbose=False)
        b = jp.minimize(mesh, "symmetric_dirichlet", init=start, solver=solver, max_iters=40, verbose=False)
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


@pytest.mark.slow
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


def test_a_fixed_boundary_map_does_not_depend_on_the_units(mesh, tmp_path):
    # the default start's circle is scaled to the surface's area, so the same mesh in units
    # 1e-3 and 1e3 of its own gives the same map up to that scale and the same energy (with
    # the unit circle fixed, camelhead's largest aspect went 5.87 / 8.95 / 671 in units
    # 1e-4 / 1 / 1e3); in the library and in the CLI
    from jaxparam.cli import main
    import json
    V, F = np.asarray(mesh.vertices), mesh.faces
    res = {s: jp.minimize(jp.TriMesh(V * s, F), "symmetric_dirichlet", verbose=False)
           for s in (1e-3, 1e3)}
    assert res[1e-3].energy == pytest.approx(res[1e3].energy, rel=1e-8)
    np.testing.assert_allclose(res[1e-3].uv * 1e6, res[1e3].uv, rtol=0,
                               atol=1e-7 * float(np.abs(res[1e3].uv).max()))
    a3 = float(jnp.sum(jp.geometry.face_areas(V * 1e3, F)))
    assert float(jnp.sum(jp.geometry.signed_areas(res[1e3].uv, F))) == pytest.approx(a3, rel=1e-9)
    energies = []
    for s in (1e-3, 1e3):
        p = tmp_path / f"m{s:g}.obj"
        jp.save(p, jp.TriMesh(V * s, F))
        rep = tmp_path / f"r{s:g}.json"
        assert main(["flatten", str(p), "-o", str(tmp_path / f"o{s:g}.obj"), "--energy",
                     "symmetric-dirichlet", "--report", str(rep), "-q"]) == 0
        r = json.loads(rep.read_text())
        assert r["start"] == "convex-map"
        energies.append(r["energy"])
    assert energies[0] == pytest.approx(energies[1], rel=1e-6)


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
    from jaxparam.optimize.newton import projected_sv_hessian, psd_project
    en = jp.energies.ENERGIES[name]
    rng = np.random.default_rng(3)
    # (each side jitted, compiled once for the 5 Jacobians: eagerly 4-8 s for the first energy)
    hessian = jax.jit(jax.hessian(lambda v: en.of_J(v.reshape(2, 2))))
    project, closed_form = jax.jit(psd_project), jax.jit(lambda J: projected_sv_hessian(J, en.of_sv))
    for _ in range(5):
        J = rng.standard_normal((2, 2))
        if np.linalg.det(J) < 0:
            J[0] *= -1
        H = hessian(jnp.asarray(J.reshape(-1)))
        ref = np.asarray(project(H[None]))[0]
        got = np.asarray(closed_form(jnp.asarray(J)))
        np.testing.assert_allclose(got, ref, atol=1e-10 * np.abs(ref).max())


def test_face_hessian_pull_back_matches_the_dense_product():
    # newton._pull_back writes D^T H_J D out from D's block structure (issue 17): it must equal
    # the dense product for real Jacobian maps (random triangles) and random symmetric H_J.
    from jaxparam.optimize.newton import _pull_back
    from jaxparam.optimize.problem import jacobian_maps
    rng = np.random.default_rng(5)
    V = rng.standard_normal((30, 3))
    F = np.stack([np.arange(10), np.arange(10, 20), np.arange(20, 30)], axis=1)
    D = jacobian_maps(jp.geometry.local_frames(jnp.asarray(V), F))
    A = rng.standard_normal((10, 4, 4))
    HJ = jnp.asarray(A + A.transpose(0, 2, 1))
    ref = np.einsum("mai,mab,mbj->mij", np.asarray(D), np.asarray(HJ), np.asarray(D))
    got = np.asarray(_pull_back(HJ, D))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    assert np.array_equal(got, got.transpose(0, 2, 1))


def test_solver_registry_names_classes_and_instances(mesh, start):
    from jaxparam import optimize as O
    assert O.SOLVERS == {"newton": O.Newton, "lbfgs": O.LBFGS, "bfgs": O.BFGS,
                         "jaxopt_lbfgs": O.JaxoptLBFGS}
    for name, cls in O.SOLVERS.items():
        assert cls.name == name and isinstance(O.solver_from(name), cls)
        assert O.solver_from(name.replace("_", "-")) == cls()
    mine = O.Newton(regularization=1e-9)
    assert O.solver_from(mine) is mine and O.solver_from(O.LBFGS) == O.LBFGS()
    a = jp.minimize(mesh, "mips", init=start, solver="newton", max_iters=5, verbose=False)
    b = jp.minimize(mesh, "mips", init=start, solver=O.Newton(), max_iters=5, verbose=False)
    np.testing.assert_array_equal(a.uv, b.uv)
    c = jp.minimize(mesh, "mips", init=start, solver=mine, max_iters=5, verbose=False)
    assert c.solver == "newton" and c.flips == 0 and c.energy <= c.history[0]
    d = jp.minimize(mesh, "mips", init=start, solver=O.LBFGS(history_length=3, patience=1),
                    max_iters=5, verbose=False)
    assert d.solver == "lbfgs" and d.iterations <= 5 and d.energy < d.history[0]


def test_unknown_solver_lists_the_registry(mesh):
    with pytest.raises(jp.MeshError, match=r"unknown solver 'adam'; use one of \['bfgs', "
                       r"'jaxopt_lbfgs', 'lbfgs', 'newton'\] or pass a solver instance"):
        jp.minimize(mesh, "mips", solver="adam")
    with pytest.raises(jp.MeshError, match="unknown solver 3"):
        jp.minimize(mesh, "mips", solver=3)


def test_optimistix_records_each_accepted_step_and_stops_by_the_rules(mesh, start):
    r = jp.minimize(mesh, "symmetric_dirichlet", init=start, solver="lbfgs", max_iters=4,
                    verbose=False)
    assert (r.iterations, r.reason, r.converged) == (4, "max_iters", False)
    assert len(r.history) == len(r.times) == 5 and np.all(np.diff(r.times) >= 0)
    z = jp.minimize(mesh, "symmetric_dirichlet", init=start, solver="bfgs", max_iters=0,
                    verbose=False)
    assert z.iterations == 0 and len(z.history) == 1
    np.testing.assert_array_equal(z.uv, start)
    t = jp.minimize(mesh, "symmetric_dirichlet", init=start, solver="lbfgs", max_seconds=0.0,
                    max_iters=300, verbose=False)     # 300: test_newton_and_lbfgs_reach_the_same_minimum's loop
    assert (t.iterations, t.reason) == (1, "time limit")


def count_compiles(fn):
    """How many XLA compilations ``fn()`` triggers."""
    events = []
    listen = lambda event, duration, **kw: events.append(event)
    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        fn()
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    return events.count("/jax/core/compile/backend_compile_duration")


# (L-BFGS's case, 14 s, with the slow tests since session 27; Newton's stays always on)
@pytest.mark.parametrize("solver", ["newton", pytest.param("lbfgs", marks=pytest.mark.slow)])
def test_equal_energies_share_compiled_code(mesh, start, solver):
    from jaxparam.optimize import problem

    def f(s1, s2):
        return s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2

    def g(s1, s2):
        return s1 ** 2 + s2 ** 2 + s1 ** -2 + s2 ** -2

    run = lambda e: jp.minimize(mesh, e, init=start, solver=solver, max_iters=2, verbose=False)
    assert count_compiles(lambda: run(jp.energy(f))) > 0
    n = problem.energy_value_and_grad._cache_size()
    assert count_compiles(lambda: run(jp.energy(f))) == 0      # a fresh, equal energy
    assert problem.energy_value_and_grad._cache_size() == n
    assert count_compiles(lambda: run(jp.energy(g))) > 0       # another function: no collision
    assert problem.energy_value_and_grad._cache_size() == n + 1


@pytest.mark.parametrize("free_boundary", [True, False])
def test_the_hessian_pattern_is_the_dof_pairs_of_the_faces(free_boundary):
    # Reference: every (row dof, col dof) pair of every face, sorted and deduplicated (the
    # construction the block-wise one replaced, issue 17).
    from jaxparam.optimize import problem as pb

    mesh = jp.shapes.disk(5, seed=3, height=0.2)
    free = np.asarray(pb.free_vertices(mesh.topology, free_boundary), np.int64)
    hp = pb.hessian_pattern(mesh.topology, free.tobytes())
    assert pb.hessian_pattern(mesh.topology, free.tobytes()) is hp        # cached
    slot = np.full(mesh.n_vertices, -1)
    slot[free] = np.arange(free.size)
    s = slot[mesh.faces]
    dof = np.where(s[:, :, None] >= 0, 2 * s[:, :, None] + np.arange(2), -1).reshape(-1, 6)
    r, c = np.repeat(dof, 6, axis=1).ravel(), np.tile(dof, (1, 6)).ravel()
    ok = (r >= 0) & (c >= 0)
    N = 2 * free.size
    uniq, inv = np.unique(r[ok] * N + c[ok], return_inverse=True)
    assert np.array_equal(hp.pattern.indices, uniq % N)
    assert np.array_equal(hp.pattern.indptr, np.concatenate([[0], np.cumsum(np.bincount(uniq // N, minlength=N))]))
    assert np.array_equal(hp.pos[ok], inv) and np.all(hp.pos[~ok] == -1)
    assert np.array_equal(hp.diag, np.searchsorted(uniq, np.arange(N) * (N + 1)))


def test_the_host_normalization_equals_the_jax_one():
    from jaxparam.optimize import problem as pb

    mesh = jp.shapes.disk(5, seed=4, height=0.3)
    uv = np.asarray(jp.convex_map(mesh))
    P = pb.Problem(mesh, jp.energies.get("symmetric_dirichlet"), True, uv)
    x = np.asarray(P.x0) * 1.7 + 0.3 * np.sin(np.arange(P.x0.size))
    ref = np.asarray(pb.normalized(x, P.base, P.free, P.F))
    assert np.max(np.abs(P.normalize(x) - ref)) < 1e-13 * np.max(np.abs(ref))


# --- shape buckets (issue 17, item 2) -----------------------------------------------------

def test_buckets_cover_every_size_in_small_steps():
    from jaxparam.optimize.padding import BUCKET_STEPS, MIN_BUCKET, bucket
    sizes = np.arange(0, 200_000, 37)
    b = np.array([bucket(int(s)) for s in sizes])
    assert np.all(b >= sizes) and np.all(np.diff(b) >= 0) and b[0] == MIN_BUCKET
    big = sizes > MIN_BUCKET
    assert np.all(b[big] <= np.ceil(sizes[big] * 2 ** (1 / BUCKET_STEPS)) + 1)
    assert np.unique(b).size < 0.01 * sizes.size            # few distinct shapes


@pytest.mark.parametrize("free", [False, True])
@pytest.mark.parametrize("energy", ["symmetric_dirichlet", "arap", "angle"])
def test_padded_kernels_equal_unpadded(mesh, start, free, energy):
    """The ghost faces and sink vertex contribute nothing: energy, gradient, flip count,
    max step and Hessian equal the unpadded kernels to rounding."""
    from jaxparam.optimize import newton as nt, problem as pb
    en = jp.energies.get(energy)
    prob = pb.Problem(mesh, en, free, start)
    assert prob.padded.F.shape[0] > mesh.n_faces and prob.padded.K >= prob.free.size
    rng = np.random.default_rng(0)
    x = np.asarray(prob.x0) + 1e-3 * rng.standard_normal(prob.x0.shape)
    d = rng.standard_normal(x.shape)
    f0, g0 = pb.energy_value_and_grad(jnp.asarray(x), *prob.arrays, en=prob.en)
    f, g = prob.value_and_grad(x)
    assert f == pytest.approx(float(f0), rel=1e-13) and prob.value(x) == pytest.approx(f, rel=1e-13)
    np.testing.assert_allclose(g, np.asarray(g0), rtol=0, atol=1e-13 * np.abs(g0).max())
    assert prob.flipped(x) == int(pb.count_flipped(jnp.asarray(x), prob.base, prob.free, prob.F))
    t0 = float(pb.max_step_along(jnp.asarray(x), jnp.asarray(d), prob.base, prob.free, prob.F))
    assert prob.max_step(x, d) == pytest.approx(t0, rel=1e-13)
    hp = prob.hessian_pattern
    H0 = nt.face_hessians(jnp.asarray(x), *prob.arrays, prob.jacobian_maps, en=prob.en, project=True)
    want = np.asarray(nt._assemble(H0, hp.pos, nnz=hp.pattern.nnz))
    np.testing.assert_allclose(nt.sparse_hessian(prob, x), want, rtol=0,
                               atol=1e-13 * np.abs(want).max())


@pytest.mark.parametrize("free", [False, True])
def test_host_assembly_equals_the_device_scatter(mesh, start, free, monkeypatch):
    """On the CPU the face Hessians are summed by :attr:`Problem.assembly` (a SciPy CSR
    product); elsewhere by the device scatter.  Both give the same values, and every face
    entry lands in at most one slot."""
    from jaxparam.optimize import newton as nt, problem as pb
    prob = pb.Problem(mesh, jp.energies.get("symmetric_dirichlet"), free, start)
    A = prob.assembly
    assert A.shape == (prob.hessian_pattern.pattern.nnz, prob.padded.F.shape[0] * 36)
    assert np.all(np.diff(A.tocsc().indptr) <= 1) and np.all(A.data == 1.0)
    x = np.asarray(prob.x0) * 1.01
    host = nt.sparse_hessian(prob, x)
    monkeypatch.setattr(nt.jax, "default_backend", lambda: "gpu")
    device = nt.sparse_hessian(prob, x)
    np.testing.assert_allclose(host, device, rtol=0, atol=1e-14 * np.abs(device).max())
    assert host.flags.writeable


@pytest.mark.parametrize("free", [False, True])
def test_similar_meshes_share_compiled_kernels(free):
    """Two meshes of different sizes in the same buckets minimize with the kernels the
    first one compiled: no new entry in any jit cache."""
    from jaxparam.optimize import newton as nt, problem as pb
    a = jp.shapes.plane_grid(15, 15, jitter=0.2)
    b = jp.shapes.plane_grid(15, 16, jitter=0.2)
    assert (a.n_vertices, a.n_faces) != (b.n_vertices, b.n_faces)
    kernels = [pb.energy_value, pb.energy_value_and_grad, pb.count_flipped, pb.max_step_along,
               nt.face_hessians, nt._assemble]
    ra = jp.minimize(a, "symmetric_dirichlet", free_boundary=free, max_iters=3, verbose=False)
    sizes = [k._cache_size() for k in kernels]
    rb = jp.minimize(b, "symmetric_dirichlet", free_boundary=free, max_iters=3, verbose=False)
    assert ra.iterations >= 1 and rb.iterations >= 1 and rb.flips == 0
    assert [k._cache_size() for k in kernels] == sizes


def test_buckets_off_is_the_unpadded_computation(mesh, start):
    """``jp.config.buckets = False``: no padding, and the energy, gradient and Hessian are
    bitwise those of the unpadded kernels."""
    from jaxparam.optimize import newton as nt, problem as pb
    jp.config.buckets = False
    try:
        prob = pb.Problem(mesh, jp.energies.get("symmetric_dirichlet"), True, start)
        assert prob.padded.F.shape[0] == mesh.n_faces and prob.padded.K == prob.free.size
        x = np.asarray(prob.x0) * 1.01
        f0, g0 = pb.energy_value_and_grad(jnp.asarray(x), *prob.arrays, en=prob.en)
        f, g = prob.value_and_grad(x)
        assert f == float(f0)
        np.testing.assert_array_equal(g, np.asarray(g0))
        hp = prob.hessian_pattern
        H0 = nt.face_hessians(jnp.asarray(x), *prob.arrays, prob.jacobian_maps, en=prob.en,
                              project=True)
        np.testing.assert_array_equal(nt.sparse_hessian(prob, x),
                                      np.asarray(nt._assemble(H0, hp.pos, nnz=hp.pattern.nnz)))
    finally:
        jp.config.buckets = None
    assert jp.config.buckets


@pytest.mark.parametrize("energy, what", [("dirichlet", "shrinks the map"),
                                          ("stretch", "grows the map")])
def test_a_free_boundary_is_refused_for_energies_with_no_free_minimum(energy, what):
    # Found in QA (jaxparam flatten snail*1e4 --energy dirichlet / stretch --free-boundary):
    # "converged", exit 0, with the map 1e-4 across (dirichlet) or 2e7 across (stretch).
    mesh = jp.shapes.graph_surface(6)
    with pytest.raises(jp.MeshError, match=f"'{energy}' with a free boundary {what}.*free_boundary=False"):
        jp.minimize(mesh, energy, free_boundary=True)
    res = jp.minimize(mesh, energy, max_iters=5, verbose=False)      # a fixed boundary is fine
    assert np.all(np.isfinite(np.asarray(res.uv)))


@pytest.fixture(scope="module")
def two_charts():
    """Two disconnected disks as one chart mesh (the atlas's layout): a coarse and a fine
    graph surface, the second one's start warped radially (``r -> r^0.3``, one-to-one) so
    that its first Newton step is cut short by a flip."""
    from jaxparam.atlas import flatten as fl
    a, b = jp.shapes.graph_surface(6), jp.shapes.graph_surface(9)
    V = np.vstack([np.asarray(a.vertices), np.asarray(b.vertices) + [3.0, 0.0, 0.0]])
    F = np.vstack([a.faces, b.faces + a.n_vertices])
    chart = np.r_[np.zeros(a.n_faces, int), np.ones(b.n_faces, int)]
    cm = fl.chart_mesh(V, F, chart)
    uv0 = fl.convex_start(cm)
    on = cm.uv_chart == 1
    c = uv0[on].mean(0)
    r = np.linalg.norm(uv0[on] - c, axis=1, keepdims=True)
    uv0[on] = c + (uv0[on] - c) * (r / r.max()) ** -0.7
    return cm, uv0


def test_blockwise_search_steps_each_piece_on_its_own(two_charts):
    """One piece's flip-free bound no longer caps the other piece's step; every piece's
    energy decreases (Armijo) and nothing flips."""
    from jaxparam.optimize import newton as nt, problem as pb, search
    cm, uv0 = two_charts
    en = jp.energies.get("symmetric_dirichlet")
    plain = pb.Problem(cm.mesh, en, True, uv0)
    blocked = pb.Problem(cm.mesh, en, True, uv0, face_blocks=cm.chart)
    x = np.asarray(plain.x0)
    f, g = plain.value_and_grad(x)
    vals = nt.sparse_hessian(plain, x)
    vals[plain.hessian_pattern.diag] += 1e-8 * vals[plain.hessian_pattern.diag].mean()
    d = -jp.sparse.factorize(plain.hessian_pattern.pattern, vals, symmetric=True).solve(g)
    steps = plain.face_energies_and_steps(x, d)[1][:cm.mesh.n_faces]
    bound = [steps[cm.chart == k].min() for k in (0, 1)]
    assert bound[1] < 1.0 < bound[0]               # the warped chart flips first
    x1, f1, t1 = search.flip_free_armijo(plain, x, f, g, d)
    x2, f2, t2 = search.flip_free_armijo(blocked, x, f, g, d)
    assert t1 <= bound[1] and t2 == 1.0
    dof_chart = np.repeat(cm.uv_chart[plain.free], 2)
    np.testing.assert_array_equal(x2[dof_chart == 0], x[dof_chart == 0] + d[dof_chart == 0])
    step1 = (x2 - x)[dof_chart == 1] / d[dof_chart == 1]
    assert 0 < np.nanmax(step1) <= bound[1] * (1 + 1e-12)
    assert blocked.flipped(x2) == 0 and f2 < f1 < f
    e0, _ = blocked.face_energies(x)
    e2, _ = blocked.face_energies(x2)
    for k in (0, 1):
        on = blocked.blocks.face == k
        assert e2[on].sum() < e0[on].sum()
    assert f2 == pytest.approx(e2.sum(), rel=1e-12) and f2 == pytest.approx(blocked.value(x2), rel=1e-12)


def test_blockwise_newton_reaches_each_charts_own_minimum(two_charts):
    """Minimizing the chart mesh with a step per chart gives each chart the minimum it has
    when minimized alone, in no more iterations than one shared step."""
    from jaxparam.atlas import flatten as fl
    cm, uv0 = two_charts
    en = jp.energies.get("symmetric_dirichlet")
    uv, res = fl.minimize_charts(cm, en, uv0)
    prob = jp.optimize.Problem(cm.mesh, en, True, uv0)
    shared = jp.optimize.solver_from("newton").run(prob, jp.optimize.StopRules(), verbose=False)
    assert res.converged and res.iterations <= shared.iterations
    for k in (0, 1):
        sub, ids = fl.sub_mesh(cm, k)
        alone = jp.minimize(sub, "symmetric_dirichlet", init=uv0[ids], free_boundary=True,
                            energy_rtol=1e-14, verbose=False)
        assert float(en(sub, uv[ids])) == pytest.approx(alone.energy, rel=1e-7)
        assert jp.distortion(sub, uv[ids]).flips == 0


def test_face_energies_sum_to_the_energy(two_charts):
    """The per-face terms of the blockwise search, on all faces or on a subset (bucketed
    gather), agree with each other and sum to the energy."""
    cm, uv0 = two_charts
    prob = jp.optimize.Problem(cm.mesh, jp.energies.get("symmetric_dirichlet"), True, uv0,
                               face_blocks=cm.chart)
    x = np.asarray(prob.x0)
    e, area = prob.face_energies(x)
    assert e.sum() == pytest.approx(prob.value(x), rel=1e-13)
    assert np.all(area[:cm.mesh.n_faces] > 0)
    sub = prob.blocks.faces_of(np.array([1]))
    assert sorted(sub.tolist()) == np.flatnonzero(cm.chart == 1).tolist()
    e1, a1 = prob.face_energies_of(x, sub)
    np.testing.assert_allclose(e1, e[sub], rtol=1e-14, atol=0)
    np.testing.assert_array_equal(a1, area[sub])
    e2, steps = prob.face_energies_and_steps(x, np.ones_like(x))
    np.testing.assert_allclose(e2, e, rtol=1e-14, atol=0)


def test_free_boundary_default_start_is_the_conformal_map():
    """With a free boundary and a scale-dependent energy, ``minimize`` starts from the
    least-squares conformal map: on a developable patch (a 3/4 turn of a cylinder) that is
    an isometry already, so Newton is done in a step or two at the isometry's energy (4),
    where the convex map's circle needs many."""
    from jaxparam.optimize import driver
    m = jp.shapes.cylinder_patch(16, 8)
    start = driver.conformal_start(m)
    assert start is not None
    a3 = float(np.sum(jp.host.face_areas(np.asarray(m.vertices), m.faces)))
    auv = float(np.sum(jp.host.signed_areas(start, m.faces)))
    scaled = start * np.sqrt(a3 / auv)        # minimize's rescaling to the 3D area
    assert float(jp.energies.get("symmetric_dirichlet")(m, scaled)) == pytest.approx(4.0, abs=1e-9)
    res = jp.minimize(m, "symmetric_dirichlet", free_boundary=True, verbose=False)
    convex = jp.minimize(m, "symmetric_dirichlet", free_boundary=True, verbose=False,
                         init=jp.convex_map(m))
    assert res.iterations <= 2 < convex.iterations
    assert res.energy == pytest.approx(4.0, abs=1e-9) and res.flips == 0
    assert res.energy <= convex.energy + 1e-12


def test_free_boundary_start_falls_back_to_the_convex_map(monkeypatch):
    """Where the conformal map folds a triangle (or crosses its own boundary), the start is
    the convex map; a clockwise conformal map is mirrored, not refused; a fixed boundary and
    a scale-invariant energy keep the convex map."""
    from jaxparam.optimize import driver
    m = jp.shapes.plane_grid(8, 8, jitter=0.2)
    good = driver.conformal_map(m.vertices, m.topology, np.zeros(m.n_vertices, np.int64), 1)
    folded = good.copy()
    folded[m.topology.interior[0]] = good[m.topology.boundary[0]] * 3.0
    monkeypatch.setattr(driver, "conformal_map", lambda *a: folded.copy())
    assert driver.conformal_start(m) is None
    np.testing.assert_array_equal(driver.default_start(m, True, False), np.asarray(jp.convex_map(m)))
    monkeypatch.setattr(driver, "conformal_map", lambda *a: good * np.array([1.0, -1.0]))
    mirrored = driver.conformal_start(m)
    assert mirrored is not None and np.all(jp.host.signed_areas(mirrored, m.faces) > 0)
    monkeypatch.setattr(driver, "conformal_map", lambda *a: pytest.fail("not asked for"))
    np.testing.assert_array_equal(driver.default_start(m, False, False), np.asarray(jp.convex_map(m)))
    np.testing.assert_array_equal(driver.default_start(m, True, True), np.asarray(jp.convex_map(m)))


def _vase(around=40, along=2):
    """A tube of revolution closed at one end by a fan: a disk whose free-boundary ARAP
    optimum crushes triangles (session 20's held-out vase, small)."""
    tube = jp.shapes.revolution(around, along)
    V, F = np.asarray(tube.vertices), np.asarray(tube.faces)
    i, c = np.arange(around), V.shape[0]
    cap = np.stack([(i + 1) % around, i, np.full(around, c)], 1)
    return jp.TriMesh(np.vstack([V, [0.0, 0.0, 0.0]]), np.vstack([F, cap]))


def test_collapsed_triangles_are_counted_and_warned():
    from jaxparam.optimize import CollapsedMapWarning
    vase = _vase()
    with pytest.warns(CollapsedMapWarning, match=r"triangles collapsed in the UVs.*'arap'"):
        res = jp.minimize(vase, "arap", free_boundary=True, verbose=False)
    assert res.flips == 0 and res.collapsed >= 1
    rep = jp.distortion(vase, res.uv)
    assert rep.collapsed == res.collapsed and rep.max_aspect > jp.tol.COLLAPSED_ASPECT
    # the count is the faces' aspect, checked here from the Jacobians' singular values
    fd = jp.metrics.face_distortion(vase, res.uv)
    aspect = np.asarray(fd["s1"]) ** 2 / (np.asarray(fd["area_uv"]) / np.asarray(fd["area3d"]))
    assert int(np.sum(aspect > jp.tol.COLLAPSED_ASPECT)) == res.collapsed
    # a barrier energy on the same disk: none, and no warning
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", CollapsedMapWarning)
        res = jp.minimize(vase, "symmetric_dirichlet", free_boundary=True, verbose=False)
    assert res.collapsed == 0 and jp.distortion(vase, res.uv).collapsed == 0


def _ramp(nr: int = 4, nt: int = 80, turns: float = 1.3, c: float = 0.05) -> jp.TriMesh:
    """A strip winding ``turns`` times round the z axis and slowly rising (a spiral ramp):
    its nearly isometric flattening winds more than once, so it overlaps itself."""
    r, t = np.linspace(1.0, 1.6, nr), np.linspace(0, 2 * np.pi * turns, nt)
    R, T = np.meshgrid(r, t, indexing="ij")
    V = np.c_[(R * np.cos(T)).ravel(), (R * np.sin(T)).ravel(), (c * T).ravel()]
    i = np.arange(nr * nt).reshape(nr, nt)
    a, b, cc, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    return jp.TriMesh(V, np.r_[np.c_[a, b, cc], np.c_[a, cc, d]])


# Found in QA (session 21): a free boundary that swung round onto itself was returned with
# "0 flipped" and no word (the report's boundary_overlaps only).
def test_a_free_boundary_that_crosses_itself_is_warned():
    import warnings

    from jaxparam.optimize import BoundaryOverlapWarning
    ramp = _ramp()
    with pytest.warns(BoundaryOverlapWarning, match=r"the free boundary crosses itself \(\d+ pairs "
                      r"of boundary edges; first: \(\d+, \d+\) and \(\d+, \d+\)\).*jp\.atlas"):
        res = jp.minimize(ramp, "symmetric_dirichlet", free_boundary=True, verbose=False)
    assert res.flips == 0 and res.boundary_overlaps == jp.metrics.boundary_overlaps(ramp, res.uv) > 0
    with warnings.catch_warnings():           # the fixed circle cannot cross itself: no warning
        warnings.simplefilter("error", BoundaryOverlapWarning)
        res = jp.minimize(ramp, "symmetric_dirichlet", verbose=False, max_iters=5)
    assert res.boundary_overlaps == 0


def test_collapsed_count_under_jit_equals_the_host_one():
    vase = _vase(40, 4)         # its fixed-boundary ARAP optimum collapses a ring
    F = vase.faces
    count = jax.jit(lambda V: jp.minimize(jp.TriMesh(V, F), "arap", verbose=False).collapsed)(
        jnp.asarray(vase.vertices))
    with pytest.warns(jp.optimize.CollapsedMapWarning):
        host = jp.minimize(vase, "arap", verbose=False).collapsed
    assert int(count) == host > 0


def test_jacobi_eigh_matches_lapack_eigh():
    from jaxparam.optimize.newton import jacobi_eigh, psd_project
    rng = np.random.default_rng(20)
    for k in (4, 6):
        A = rng.standard_normal((200, k, k))
        A = A + A.transpose(0, 2, 1)
        A[0] = np.diag(np.arange(k, dtype=float))          # already diagonal
        A[1] = 2.0 * np.eye(k)                             # one repeated eigenvalue
        A[2] = 0.0                                         # nothing to rotate
        A[3] = np.outer(np.ones(k), np.ones(k))            # rank one: k - 1 zero eigenvalues
        A = jnp.asarray(A)
        lam, U = jacobi_eigh(A)
        np.testing.assert_allclose(np.sort(np.asarray(lam), -1), np.asarray(jnp.linalg.eigh(A)[0]),
                                   rtol=0, atol=1e-12 * float(jnp.abs(A).max()))
        np.testing.assert_allclose(np.asarray(jnp.einsum("...ji,...jk->...ik", U, U)),
                                   np.broadcast_to(np.eye(k), A.shape), atol=1e-13)
        np.testing.assert_allclose(np.asarray(psd_project(A, lapack=False)),
                                   np.asarray(psd_project(A)), rtol=0,
                                   atol=1e-12 * float(jnp.abs(A).max()))


def test_newton_in_a_host_callback_calls_no_lapack(monkeypatch):
    # jax.jit of an ARAP minimize hung in 3 of 4 runs on the 2-core box: the solver runs in a
    # pure_callback on one of XLA's two pool threads, and LAPACK's batched eigh waited on the
    # other for parts of its batch that nobody could run (optimize.in_callback).
    import jaxparam.optimize.newton as nt
    vase = _vase(12, 2)
    prob = jp.optimize.Problem(vase, jp.ENERGIES["arap"], False, np.asarray(jp.convex_map(vase)))
    args = (jnp.asarray(prob.padded.x(np.asarray(prob.x0))), *prob.padded_arrays, prob.padded.D)
    hlo = {lap: nt.face_hessians.lower(*args, en=prob.en, project=True, lapack=lap).as_text()
           for lap in (True, False)}
    assert "lapack" in hlo[True] and "lapack" not in hlo[False]
    seen = []
    real = nt.face_hessians
    monkeypatch.setattr(nt, "face_hessians", lambda *a, **k: seen.append(k["lapack"]) or real(*a, **k))
    uv = jax.jit(lambda V: jp.minimize(jp.TriMesh(V, vase.faces), "arap", verbose=False).uv)(
        jnp.asarray(vase.vertices))
    assert np.all(np.isfinite(np.asarray(uv))) and seen and not any(seen)
    jp.minimize(vase, "arap", verbose=False)                # outside a callback: LAPACK again
    assert seen[-1] is True
