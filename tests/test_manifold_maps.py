"""The MAPS route of jaxparam.manifold (the default): it never gets blocked, keeps the genus,
and its map is a bijection onto the base domain whose inverse the remesh runs exactly."""
import numpy as np
import pytest

import jaxparam as jp
from conftest import data_path
from jaxparam.errors import MeshError, TopologyError
from jaxparam.manifold import REFERENCE, manifold_map
from jaxparam.manifold.parameterization import fewest_faces
from jaxparam.manifold.report import fidelity


def plate(holes: int, n: int = 6, h: float = 0.15) -> jp.TriMesh:
    """A closed surface of genus ``holes``: a grid plate with ``holes`` square holes, its top
    (z = +h inside) and bottom (z = -h) sheets joined along every boundary loop."""
    nx, ny = holes * (n + 2) + 2 + 1, n + 4 + 1             # grid vertices
    cells = np.ones((nx - 1, ny - 1), bool)
    for k in range(holes):
        x0 = 2 + k * (n + 2)
        cells[x0:x0 + n, 2:2 + n] = False
    i, j = np.nonzero(cells)
    a, b, c, d = i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    on_rim = np.zeros(nx * ny, bool)
    for loop in jp.topology.boundary_loops(F, nx * ny):
        on_rim[loop] = True
    # The other diagonal where one would make a triangle of rim vertices only (the two
    # sheets would share it).
    flip = (on_rim[a] & on_rim[b] & on_rim[c]) | (on_rim[a] & on_rim[c] & on_rim[d])
    F = np.concatenate([np.stack([a, b, np.where(flip, d, c)], 1), np.stack([np.where(flip, b, a), c, d], 1)])
    used = np.unique(F)
    new = np.full(nx * ny, -1)
    new[used] = np.arange(used.size)
    F = new[F]
    X, Y = np.meshgrid(np.arange(nx) / (nx - 1) * holes, np.arange(ny) / (ny - 1), indexing="ij")
    P = np.stack([X.ravel(), Y.ravel()], 1)[used]
    top = jp.TriMesh(np.column_stack([P, np.zeros(len(P))]), F)
    rim = np.zeros(len(P), bool)
    for loop in top.topology.boundary_loops:
        rim[loop] = True
    inner = np.flatnonzero(~rim)
    # Bottom sheet: inner vertices duplicated, rim vertices shared.
    bot_id = np.arange(len(P))
    bot_id[inner] = len(P) + np.arange(inner.size)
    V = np.concatenate([np.column_stack([P, np.where(rim, 0.0, h)]), np.column_stack([P[inner], np.full(inner.size, -h)])])
    F2 = np.concatenate([F, bot_id[F][:, ::-1]])
    return jp.TriMesh(V, F2, name=f"plate{holes}")


def capsule(length: float = 8.0, radius: float = 0.5, k: int = 16, rings: int = 40) -> jp.TriMesh:
    """A long capsule (a thin shape): a cylinder of ``length`` with half-sphere caps."""
    cap = k // 4
    lat = np.concatenate([np.linspace(-np.pi / 2, 0, cap + 1)[1:], np.zeros(rings - 1),
                          np.linspace(0, np.pi / 2, cap + 1)[:-1]])
    z0 = np.concatenate([np.full(cap, -length / 2), np.linspace(-length / 2, length / 2, rings + 1)[1:-1],
                         np.full(cap, length / 2)])
    t = 2 * np.pi * np.arange(k) / k
    R = radius * np.cos(lat)[:, None]
    Z = (z0 + radius * np.sin(lat))[:, None]
    V = np.column_stack([(R * np.cos(t)).ravel(), (R * np.sin(t)).ravel(), np.broadcast_to(Z, (lat.size, k)).ravel()])
    nr = lat.size
    V = np.concatenate([V, [[0, 0, -length / 2 - radius], [0, 0, length / 2 + radius]]])
    s, e = nr * k, nr * k + 1
    r, c = np.meshgrid(np.arange(nr - 1), np.arange(k), indexing="ij")
    a, b = r * k + c, r * k + (c + 1) % k
    F = [np.stack([a, b, b + k], -1).reshape(-1, 3), np.stack([a, b + k, a + k], -1).reshape(-1, 3)]
    cc = np.arange(k)
    F.append(np.stack([np.full(k, s), (cc + 1) % k, cc], 1))
    F.append(np.stack([np.full(k, e), (nr - 1) * k + cc, (nr - 1) * k + (cc + 1) % k], 1))
    return jp.TriMesh(V, np.concatenate(F), name="capsule")


def _check(mesh, nb, levels=2, lift_tol=1e-9, mapped=None):
    base, param = mapped or manifold_map(mesh, nb)
    t = mesh.topology
    assert base.n_faces == nb and base.topology.genus == t.genus and base.topology.is_closed
    # Every input vertex lies in its base triangle; base vertices are themselves.
    assert np.all(param.vertex_bary >= 0) and np.allclose(param.vertex_bary.sum(1), 1)
    X = np.asarray(param.lift(param.vertex_face, param.vertex_bary @ REFERENCE))
    np.testing.assert_allclose(X, np.asarray(mesh.vertices), atol=lift_tol * np.ptp(np.asarray(mesh.vertices)))
    semi = param.remesh(levels)
    st = semi.mesh.topology
    assert semi.mesh.n_faces == nb * 4 ** levels and st.is_closed and st.genus == t.genus
    assert st.n_components == 1
    return base, param, semi


def test_generated_shapes_of_genus_1_and_2_at_their_fewest_base_faces_never_fail(plate_map):
    # Genus 0 at its fewest (4): the scaled sphere below; the rest of the generated shapes,
    # sphere(2) at 4 with them since session 29: the slow test below.  The plate's map is
    # conftest's, shared with test_manifold_report.
    assert plate(2).topology.genus == 2 and plate(3).topology.is_closed
    _check(jp.shapes.torus(24, 12), 24)
    _check(plate_map[0], 38, mapped=plate_map[1:])


def _scaled(mesh, axis: int, factor: float):
    V = np.asarray(mesh.vertices).copy()
    V[:, axis] *= factor
    return jp.TriMesh(V, mesh.faces)


# Found in QA (session 21): scaled along one axis, a mesh's rings are needles whose wedges
# flatten wider than 0.9 pi at every vertex, and the decimation stopped early (this sphere at
# 520 faces, bunny with z x 20 at 3040 of 100); such rings now go last, flattened with
# blended angles.
def test_a_mesh_scaled_along_one_axis_decimates_to_the_fewest_faces():
    # the map runs back through the needle rings to the input vertices within 1e-7 of the
    # extent (1.7e-8 measured; 1e-12 on well-shaped rings)
    _check(_scaled(jp.shapes.sphere(3), 2, 20.0), 4, lift_tol=1e-7)


@pytest.mark.slow
@pytest.mark.data
@pytest.mark.parametrize("name, axis, factor, nb", [
    ("bunny.off", 2, 20.0, 100), ("bunny.off", 2, 1.0, 4), ("3holes.off", 2, 0.05, 52),
    ("rocker-arm.obj", 2, 0.05, 24)])
def test_shared_meshes_scaled_along_one_axis_never_fail(name, axis, factor, nb):
    # bunny with z x 20: rings of needle triangles, through which the map runs back to the
    # input vertices within 6e-4 of the extent (session 21; exact to 1e-12 on the others)
    tol = 1e-3 if factor == 20.0 else 1e-9
    _check(_scaled(jp.load(data_path("meshes", name)), axis, factor), nb, levels=1, lift_tol=tol)


@pytest.mark.slow
def test_generated_shapes_of_genus_0_to_3_and_a_capsule_never_fail():
    _check(jp.shapes.sphere(2), 4)
    _check(jp.shapes.sphere(2), 40)
    torus = jp.shapes.torus(24, 12)
    for nb in (60, 200):
        _check(torus, nb)
    _check(plate(3), 52)
    _check(capsule(), 40)


def test_the_fewest_faces_each_genus_allows():
    assert [fewest_faces(g) for g in range(4)] == [4, 24, 38, 52]
    with pytest.raises(MeshError, match=r"even integer in \[24, 576\).*genus-1.*got 22"):
        manifold_map(jp.shapes.torus(24, 12), 22)


def test_the_map_is_a_bijection_onto_the_base_domain(torus_map):
    mesh, base, param = torus_map                       # torus(32, 16), 40 base faces
    H = param.structure.history
    # Points on a base edge pulled back from both of its base triangles meet on the surface
    # (the pieces glue with no gap or overlap), and base corners come back to base vertices.
    F0 = param.base_faces
    t0 = base.topology
    ef = t0.edge_faces
    s = np.linspace(0.05, 0.95, 7)
    pts = []
    for side in (0, 1):
        f = ef[:, side]
        a, b = t0.edges[:, 0], t0.edges[:, 1]
        ca = np.argmax(F0[f] == a[:, None], axis=1)
        cb = np.argmax(F0[f] == b[:, None], axis=1)
        bary = np.zeros((f.size, s.size, 3))
        bary[np.arange(f.size)[:, None], :, ca[:, None]] = 1 - s
        bary[np.arange(f.size)[:, None], :, cb[:, None]] = s
        face, bb = H.pull_back(np.repeat(f, s.size), bary.reshape(-1, 3))
        V = np.asarray(mesh.vertices)
        pts.append(np.einsum("kc,kcd->kd", bb, V[mesh.faces[face]]))
    np.testing.assert_allclose(pts[0], pts[1], atol=1e-9)
    # Distinct base points pull back to distinct surface points (one-to-one).
    rng = np.random.default_rng(0)
    r = rng.integers(0, 40, 4000)
    q = rng.dirichlet([1, 1, 1], 4000)
    face, bb = H.pull_back(r, q)
    X = np.einsum("kc,kcd->kd", bb, np.asarray(mesh.vertices)[mesh.faces[face]])
    from scipy.spatial import cKDTree
    pairs = cKDTree(X).query_pairs(1e-9)
    assert not pairs
    # The pieces' areas add up to the surface's.
    semi = param.remesh(4)
    A = lambda V, F: 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    assert abs(A(np.asarray(semi.mesh.vertices), semi.mesh.faces) / A(np.asarray(mesh.vertices), mesh.faces) - 1) < 0.01


def test_the_error_falls_as_the_level_rises_and_is_reported(torus_map):
    # (torus(32, 16) since session 29, the map shared: Hausdorff 0.045, 0.016, 0.0066 at
    # levels 1-3, area distortion 3.0; torus(48, 24) had its own map, 6-9 s)
    mesh, base, param = torus_map
    reps = [fidelity(param, param.remesh(j), mesh, samples=3000) for j in (1, 2, 3)]
    h = [r.hausdorff for r in reps]
    assert h[0] > h[1] > h[2] and h[2] < 0.01
    assert all(r.rms_in <= r.hausdorff_in and r.rms_out <= r.hausdorff_out for r in reps)
    assert 1.0 <= reps[2].area_distortion < 10.0
    assert set(reps[2].as_dict()) >= {"hausdorff", "rms_in", "rms_out", "area_distortion"}


def test_bad_input_is_refused_before_any_work_with_the_place_named():
    with pytest.raises(TopologyError, match=r"1 boundary loop.*through vertices"):
        manifold_map(jp.shapes.graph_surface(6), 10)
    s = jp.shapes.sphere(1)
    V = np.concatenate([np.asarray(s.vertices), np.asarray(s.vertices) + 3])
    two = jp.TriMesh(V, np.concatenate([s.faces, s.faces + s.n_vertices]))
    with pytest.raises(TopologyError, match=r"2 connected components.*manifold_map_each"):
        manifold_map(two, 20)
    with pytest.raises(MeshError, match="unknown method"):
        manifold_map(s, 20, method="lscm")


# Found in QA (session 21): a component's failure told the user to "ask for more than 8
# base faces" when the 12 they gave were a total shared by two components.
def test_a_components_failure_names_it_and_the_shares(monkeypatch):
    import jaxparam.manifold.components as C
    from jaxparam.errors import SolverError

    s = jp.shapes.sphere(1)
    V = np.concatenate([np.asarray(s.vertices), np.asarray(s.vertices) + 3])
    two = jp.TriMesh(V, np.concatenate([s.faces, s.faces + s.n_vertices]))

    def fail(sub, nb, **kw):
        raise SolverError("manifold_map: decimation stopped at 8 faces: ...; ask for more than "
                          "8 base faces.", stage="decimate")
    monkeypatch.setattr(C, "manifold_map", fail)
    with pytest.raises(SolverError, match=r"component 0 \(vertices from 0, genus 0, 80 faces\), "
                       r"given 6 of the base faces \[6, 6\].*ask for more than 8 base faces\. "
                       r"Pass one count per component") as e:
        C.manifold_map_each(two, 12)
    assert e.value.stage == "decimate"


@pytest.mark.slow          # 11 s; the suite's non-slow run reached 627 s on a clean clone
def test_several_components_are_parameterized_one_at_a_time():
    from jaxparam.manifold import manifold_map_each

    a, b = jp.shapes.torus(16, 8), jp.shapes.sphere(1)           # 256 and 80 faces
    V = np.concatenate([np.asarray(b.vertices) + 5.0, np.asarray(a.vertices)])
    F = np.concatenate([b.faces, a.faces + b.n_vertices])
    mesh = jp.TriMesh(V, F)
    parts = manifold_map_each(mesh, 80)
    # Largest first; the total shared by faces (80 * 256 / 336 -> 60, 80 * 80 / 336 -> 20).
    assert [p.base.n_faces for p in parts] == [60, 20]
    assert [p.param.mesh.topology.genus for p in parts] == [1, 0]
    for p in parts:
        np.testing.assert_array_equal(np.asarray(p.param.mesh.vertices), V[p.vertices])
        np.testing.assert_array_equal(p.vertices[p.param.mesh.faces], F[p.faces])
        t = p.param.remesh(2).mesh.topology
        assert t.is_closed and t.n_components == 1 and t.genus == p.param.mesh.topology.genus
    assert sorted(np.concatenate([p.faces for p in parts]).tolist()) == list(range(F.shape[0]))
    # One count per component; a count a component cannot take is named before any work.
    assert [p.base.n_faces for p in manifold_map_each(mesh, [40, 20])] == [40, 20]
    with pytest.raises(MeshError, match=r"component 1 .*genus 0, 80 faces.*got 3"):
        manifold_map_each(mesh, [40, 3])
    with pytest.raises(MeshError, match=r"2 counts for a mesh of 3 components"):
        manifold_map_each(jp.TriMesh(np.concatenate([V, V[:b.n_vertices] + 9]),
                                     np.concatenate([F, b.faces + V.shape[0]])), [40, 20])
    # A component with a hole is refused, with the component named.
    g = jp.shapes.graph_surface(6)
    holed = jp.TriMesh(np.concatenate([V, np.asarray(g.vertices) + 20]), np.concatenate([F, g.faces + V.shape[0]]))
    with pytest.raises(TopologyError, match=r"component 2 .*boundary loop"):
        manifold_map_each(holed, 80)


def test_with_vertices_moves_the_remesh_with_the_positions(torus_map):
    import jax
    import jax.numpy as jnp
    mesh, base, param = torus_map           # conftest's (sphere(2) at 20 before session 29)
    V0 = jnp.asarray(mesh.vertices)
    np.testing.assert_array_equal(np.asarray(param.with_vertices(V0).remesh(2).mesh.vertices),
                                  np.asarray(param.remesh(2).mesh.vertices))
    D = jnp.asarray(np.random.default_rng(1).standard_normal(V0.shape))
    loss = lambda V: jnp.sum(param.with_vertices(V).remesh(2).mesh.vertices ** 2)
    g = jax.grad(loss)(V0)
    eps = 1e-6
    fd = (loss(V0 + eps * D) - loss(V0 - eps * D)) / (2 * eps)
    assert abs(float(fd - jnp.sum(g * D))) <= 1e-6 * abs(float(fd))


# every closed mesh of ../shared/data (bumpy since session 33: it is closed too)
CLOSED = ["bunny.off", "cow.off", "3holes.off", "decimated-knight.off", "rocker-arm.obj", "bumpy.off"]


@pytest.mark.slow
@pytest.mark.data
@pytest.mark.parametrize("name", CLOSED)
@pytest.mark.parametrize("nb", [50, 100, 200, 400])
def test_every_closed_mesh_of_shared_data_at_every_base_count(name, nb):
    mesh = jp.load(data_path("meshes", name))
    nb = max(nb, fewest_faces(mesh.topology.genus))     # 3holes (genus 3) allows 52 and up
    base, param, semi = _check(mesh, nb, levels=3)
    rep = fidelity(param, semi, mesh, samples=5000)
    # A regression guard, not the 0.5 % goal, which the unsmoothed MAPS map does not
    # reach on every mesh yet (before the rules were relaxed step by step, the worst at level
    # 3 was decimated-knight at 50 base faces: 13 % Hausdorff, 2.4 % RMS).
    assert rep.hausdorff < 0.2 and rep.rms < 0.04, rep
    # The map has no turned-over piece and every input vertex is in its base triangle.
    assert rep.flipped == 0 and rep.misplaced == 0, rep


@pytest.mark.slow
@pytest.mark.data
@pytest.mark.parametrize("name, bound", [("bunny.off", 0.0045), ("3holes.off", 0.004), ("rocker-arm.obj", 0.0065),
                                         ("cow.off", 0.0068), ("decimated-knight.off", 0.0085),
                                         ("bumpy.off", 0.003)])
def test_level_4_lies_within_one_or_two_percent_of_the_diagonal_at_100_base_faces(name, bound):
    """Measured 0.72 %, 0.27 %, 0.63 %, 0.85 %, 0.94 % (Hausdorff both ways, bounding-box
    diagonal) with the samples relaxed across base edges, and at the finest level too where
    that is estimated closer (cow, decimated-knight; 1.00 and 1.09 % with the level-3
    relaxation only; 0.83, 0.34, 0.70, 1.30, 1.19 % without any; cow and decimated-knight were 4.6 % and 10.2 % before the decimation's rules
    were relaxed step by step, which keeps the tips of thin parts in the base domain).  The
    issue's goal is 0.5 % on every mesh; this is a regression guard.  With the base domain
    chosen among three area caps (session 10; 50,000 samples): 0.48 %, 0.26 %, 0.48 %, 0.69 %,
    0.71 %; with the tips snapped (manifold/snap.py, session 16): 0.34 %, 0.26 %, 0.48 %,
    0.57 %, 0.71 %.  Session 17 (a grid of step 1/8 on every face finds the farthest points
    the samples miss): 0.38 %, 0.29 %, 0.55 %, 0.61 %, 0.70 %.  Session 25 (a fourth area
    cap; grid 1/8): 0.37 %, 0.29 %, 0.33 %, 0.50 %, 0.46 %.  Session 33 (50,000 samples /
    grid 1/8): 0.33 / 0.37, 0.26 / 0.29, 0.30 / 0.33, 0.49 / 0.50, 0.40 / 0.46 %, and bumpy
    0.20 / 0.20 %."""
    mesh = jp.load(data_path("meshes", name))
    base, param = manifold_map(mesh, 100)
    rep = param.report(4, samples=20_000)
    assert rep.hausdorff < bound and rep.rms < bound / 10, rep


@pytest.mark.slow          # 14 s; the suite's non-slow run reached 627 s on a clean clone
@pytest.mark.data
def test_relaxing_the_samples_across_base_edges_brings_the_remesh_closer():
    """The default remesh relaxes the samples in the base domain (error-driven, across base
    edges): same connectivity, the base vertices stay, the surface is followed more closely
    (level 3 at 100 base faces, Hausdorff both ways: measured 1.98 -> 1.78 % of the diagonal,
    RMS 0.247 -> 0.220 %
    on decimated-knight), and ``with_vertices(V0)`` gives the same remesh."""
    mesh = jp.load(data_path("meshes", "decimated-knight.off"))
    base, param = manifold_map(mesh, 100)
    plain, semi = param.remesh(3, relax=False), param.remesh(3)
    np.testing.assert_array_equal(plain.mesh.faces, semi.mesh.faces)
    n0 = param.base_vertices.size
    np.testing.assert_array_equal(np.asarray(semi.mesh.vertices)[:n0], np.asarray(plain.mesh.vertices)[:n0])
    moved = np.linalg.norm(np.asarray(semi.mesh.vertices) - np.asarray(plain.mesh.vertices), axis=1)
    assert np.mean(moved > 1e-9) > 0.5                      # most samples moved
    a, b = fidelity(param, plain, mesh, samples=5000), fidelity(param, semi, mesh, samples=5000)
    assert b.hausdorff < a.hausdorff and b.rms < a.rms, (a, b)
    np.testing.assert_array_equal(np.asarray(param.with_vertices(np.asarray(mesh.vertices)).remesh(3).mesh.vertices),
                                  np.asarray(semi.mesh.vertices))


def test_cli_manifold_method_and_fidelity(tmp_path):
    """``jaxparam manifold --method --fidelity``: the report carries the distances."""
    import json

    import jaxparam as jp
    from jaxparam.cli import main

    src = tmp_path / "ico.off"
    jp.save(src, jp.TriMesh(*_icosphere_arrays()))
    out, rep = tmp_path / "o.obj", tmp_path / "r.json"
    assert main(["manifold", str(src), "-o", str(out), "--levels", "1", "--base-faces", "20",
                 "--method", "maps", "--fidelity", "--report", str(rep), "--quiet"]) == 0
    fid = json.loads(rep.read_text())["fidelity"]
    assert 0 <= fid["hausdorff"] < 0.2 and fid["rms_in"] <= fid["hausdorff"]


def _icosphere_arrays():
    import trimesh

    m = trimesh.creation.icosphere(2)
    return np.asarray(m.vertices), np.asarray(m.faces)


def test_relaxed_samples_are_dropped_when_they_stretch_the_remesh():
    # _stretches (the remesh's guard) drops the relaxed samples when the longest remesh edge
    # grows past RELAX_MAX_EDGE_GROWTH; a fake lift (the samples' region index as a position)
    # shows both.
    from jaxparam.manifold.finish import RELAX_MAX_EDGE_GROWTH, stretches as _stretches

    faces = np.array([[0, 1, 2]])
    lift = lambda r, b: np.c_[r, np.zeros((r.size, 2))].astype(float)  # noqa: E731
    r0, b0 = np.array([0, 1, 2]), np.zeros((3, 3))
    grown = np.array([0, 1, 2 * RELAX_MAX_EDGE_GROWTH + 0.1])
    kept = np.array([0, 1, 2 * RELAX_MAX_EDGE_GROWTH - 0.1])
    assert _stretches(lift(grown, b0 + 1), lift(r0, b0), faces)
    assert not _stretches(lift(kept, b0 + 1), lift(r0, b0), faces)


@pytest.mark.slow
def test_default_remesh_of_a_sheared_noisy_cow_is_not_worse_than_unrelaxed():
    # Held-out input (not in ../shared): cow sheared (x += 0.4 y, z *= 1.7) with Gaussian noise
    # of 0.2 % of the extent. Relaxed without the guard, its remesh had faces cutting across
    # the surface (remesh -> input 1.16 -> 4.07 % of the diagonal); the default must not be
    # worse than the unrelaxed remesh.
    m = jp.load(data_path("meshes", "cow.off"))
    V = np.asarray(m.vertices).copy()
    V[:, 0] += 0.4 * V[:, 1]
    V[:, 2] *= 1.7
    V += np.random.default_rng(3).normal(scale=0.002 * np.ptp(V, 0).max(), size=V.shape)
    mesh = jp.TriMesh(V, np.asarray(m.faces))
    _, param = manifold_map(mesh, verbose=False)
    plain = fidelity(param, param.remesh(4, relax=False), param.mesh)
    default = fidelity(param, param.remesh(4), param.mesh)
    assert default.hausdorff <= 1.05 * plain.hausdorff, (default, plain)


def test_grid_lift_is_exact_at_grid_points_and_for_an_affine_lift():
    # The finest sweeps lift through a grid (one exact pull-back, then linear interpolation);
    # the dyadic samples of the grid's level are grid points, lifted exactly.
    from jaxparam.manifold.relax import GridLift

    rng = np.random.default_rng(0)
    A, c = rng.standard_normal((4, 3, 3)), rng.standard_normal((4, 3))
    calls = []

    def affine(r, b):                                  # an affine map per base face
        calls.append(r.size)
        return np.einsum("kc,kcd->kd", b, A[r]) + c[r]

    g = GridLift(affine, 4, 3)
    assert calls == [GridLift.points(4, 3)] == [4 * 9 * 10 // 2]
    r = rng.integers(0, 4, 500)
    b = rng.dirichlet(np.ones(3), 500)
    b[:3] = np.eye(3)                                  # corners and edges too
    b[3] = [0.5, 0.5, 0.0]
    np.testing.assert_allclose(g(r, b), affine(r, b), atol=1e-12)
    bent = GridLift(lambda r, b: np.c_[b[:, :2], (b[:, 0] * b[:, 1])[:, None]], 1, 2)
    grid_pt = np.array([[0.25, 0.5, 0.25]])
    np.testing.assert_array_equal(bent(np.zeros(1, int), grid_pt), [[0.25, 0.5, 0.125]])
    mid = np.array([[0.375, 0.375, 0.25]])             # between grid points: interpolated
    np.testing.assert_allclose(bent(np.zeros(1, int), mid), [[0.375, 0.375, 0.125]], atol=1e-15)


def test_estimated_distance_sees_a_cut_tip_and_is_zero_on_the_input():
    # The remesh keeps the candidate closest to the input by this estimate; it must be 0 for
    # the input itself and see a tip that a coarser surface cuts off.
    from jaxparam.manifold.relax import estimated_distance, sharpest_vertices

    mesh = jp.shapes.sphere(2)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    tip = V.copy()
    tip[0] *= 1.5                                       # one vertex pulled out: a tip
    sharp = sharpest_vertices(tip, F, 10)
    assert 0 in sharp
    assert estimated_distance(tip, F, sharp, tip, F) < 1e-12
    d = estimated_distance(tip, F, sharp, V, F)         # the tip cut off
    assert d > 0.3 * np.linalg.norm(V[0])


def _largest_share(V, F, vertex_face, base_faces):
    A = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    va = np.bincount(F.ravel(), np.repeat(A / 3, 3), minlength=V.shape[0])
    return np.bincount(vertex_face, va, minlength=base_faces).max() / va.sum()


@pytest.mark.data
def test_the_area_cap_keeps_base_faces_from_holding_a_large_share_of_the_surface():
    # Quadric collapses let cow's flat flanks grow without bound: one base face of 100 held
    # 13.4 % of the input's area (1 % is the mean). A hard cap of 1.5x the mean share (the
    # held area spread over the flattened ring) measured 2.0 %.
    from jaxparam.manifold.maps import maps_decimate
    mesh = jp.load(data_path("meshes", "cow.off"))
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    free = maps_decimate(V, F, 100, verbose=False)
    capped = maps_decimate(V, F, 100, area_cap=(1.5, 0, 0), verbose=False)
    assert capped[1].shape == (100, 3)
    assert _largest_share(V, F, free[2], 100) > 0.08
    assert _largest_share(V, F, capped[2], 100) < 0.03


def test_manifold_map_keeps_the_base_domain_estimated_closest(monkeypatch):
    # With several area caps, the base domain kept is the one whose default remesh the
    # estimate finds closest to the input (before its tips are snapped and its fans
    # contracted, which is done to the one kept); above SELECT_MAX_FACES, LARGE_MESH_CAP's.
    from jaxparam.manifold import parameterization as P
    from jaxparam.manifold.relax import estimated_distance, sharpest_vertices
    mesh = plate(2, n=4)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces, np.int64)
    caps = (None, (1.0, 0, 0))
    sharp = sharpest_vertices(V, F)
    params, errs = [], []
    for c in caps:
        monkeypatch.setattr(P, "AREA_CAPS", (c,))
        params.append(manifold_map(mesh, 40, verbose=False)[1])
        semi = params[-1]._remesh_from(*params[-1]._samples(P.SELECT_LEVEL, None, snap=False))
        errs.append(estimated_distance(V, F, sharp, np.asarray(semi.mesh.vertices), semi.mesh.faces))
    assert not np.array_equal(params[0].base_vertices, params[1].base_vertices)
    monkeypatch.setattr(P, "AREA_CAPS", caps)
    _, param = manifold_map(mesh, 40, verbose=False)
    want = params[int(np.argmin(errs))]
    assert np.array_equal(param.base_vertices, want.base_vertices)
    assert np.array_equal(param.base_faces, want.base_faces)
    monkeypatch.setattr(P, "SELECT_MAX_FACES", 0)
    monkeypatch.setattr(P, "LARGE_MESH_CAP", caps[1])
    _, param = manifold_map(mesh, 40, verbose=False)
    assert np.array_equal(param.base_vertices, params[1].base_vertices)
    # Nor for base domains whose level-SELECT_LEVEL remesh is too large to compare (session
    # 21: cow at 5,518 base faces took 255 s choosing, for a level-2 remesh).
    monkeypatch.setattr(P, "SELECT_MAX_FACES", 10 ** 9)
    monkeypatch.setattr(P, "SELECT_MAX_REMESH_FACES", 40 * 4 ** P.SELECT_LEVEL - 1)
    _, param = manifold_map(mesh, 40, verbose=False)
    assert np.array_equal(param.base_vertices, params[0].base_vertices)


def test_manifold_map_keeps_the_chosen_remesh_samples(monkeypatch, plate_map):
    # Issue 13: the level-SELECT_LEVEL samples the base domain was chosen by are kept, so
    # param.remesh(SELECT_LEVEL) does not relax them again, and gives what recomputing gives
    # (also for moved positions: the samples are held fixed like the point location).
    from dataclasses import replace
    from jaxparam.manifold import parameterization as P
    mesh, _, param = plate_map          # conftest's plate(2) at 38 (plate(2, n=4) at 40 before session 29)
    assert [s[0] for s in param.structure.samples] == [P.SELECT_LEVEL]
    fresh = replace(param, structure=replace(param.structure, samples=()))
    want = fresh.remesh(P.SELECT_LEVEL)
    V1 = np.asarray(mesh.vertices) * np.array([1.0, 1.2, 0.9])
    moved = np.asarray(fresh.with_vertices(V1).remesh(P.SELECT_LEVEL).mesh.vertices)

    def fail(*args, **kwargs):
        raise AssertionError("the kept samples were relaxed again")

    monkeypatch.setattr(P, "_relaxed_samples", fail)
    for _ in range(2):
        got = param.remesh(P.SELECT_LEVEL)
        np.testing.assert_array_equal(np.asarray(got.mesh.vertices), np.asarray(want.mesh.vertices))
        np.testing.assert_array_equal(np.asarray(got.mesh.faces), np.asarray(want.mesh.faces))
    np.testing.assert_array_equal(np.asarray(param.with_vertices(V1).remesh(P.SELECT_LEVEL).mesh.vertices), moved)
    with pytest.raises(AssertionError, match="relaxed again"):     # other levels: computed
        param.remesh(P.SELECT_LEVEL - 1)


def test_decimations_run_together_give_each_cap_alone():
    # Issue 13: decimate_caps shares the collapses the caps agree on, and each result is
    # bitwise the one maps_decimate gives with that cap alone (and the same error).
    from jaxparam.manifold.maps import AREA_CAPS, decimate_caps, maps_decimate
    mesh = jp.load(data_path("meshes", "decimated-knight.off"))
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    caps = (*AREA_CAPS, (1.0, 0, 0))
    together = decimate_caps(V, F, 60, caps, verbose=False)
    assert len({r[1].tobytes() for r in together}) > 1                # they do branch
    for cap, got in zip(caps, together):
        want = maps_decimate(V, F, 60, area_cap=cap, verbose=False)
        for a, b in zip(want[:4], got[:4]):
            assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
        assert len(want[4].levels) == len(got[4].levels)
        for la, lb in zip(want[4].levels, got[4].levels):
            assert all(p.tobytes() == q.tobytes() for p, q in zip(la, lb))
    T = jp.shapes.torus(24, 12)
    errs = decimate_caps(np.asarray(T.vertices), np.asarray(T.faces), 14, AREA_CAPS, verbose=False)
    assert all(isinstance(e, jp.SolverError) and "stopped at 18 faces" in str(e) for e in errs)


def test_decimations_do_not_depend_on_where_the_mesh_is():
    """Found in QA: the same mesh moved by 1e6 got another base domain (quadric costs x^T Q x
    carry the planes' offsets, which cancel far from the origin).  Both decimations centre the
    mesh first."""
    from jaxparam.manifold.decimate import decimate
    from jaxparam.manifold.maps import AREA_CAPS, decimate_caps

    mesh = jp.shapes.torus(24, 12)
    V = np.asarray(mesh.vertices) + 0.01 * np.random.default_rng(1).standard_normal((mesh.n_vertices, 3))
    F = np.asarray(mesh.faces)
    here = decimate_caps(V, F, 40, AREA_CAPS)
    far = decimate_caps(V + 1e6, F, 40, AREA_CAPS)
    for a, b in zip(here, far):
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    kept, F0 = decimate(jp.TriMesh(V, F), 40)
    kept_far, F0_far = decimate(jp.TriMesh(V + 1e6, F), 40)
    assert np.array_equal(kept, kept_far) and np.array_equal(F0, F0_far)


def _bumpy_sphere(seed: int = 0):
    """A sphere (1,280 faces) with 30 vertices pushed out by 12 %: tips narrower than a
    level-3 remesh over 20 base faces, which its dyadic samples miss."""
    m = jp.shapes.sphere(3)
    V = np.asarray(m.vertices).copy()
    tips = np.random.default_rng(seed).choice(V.shape[0], 30, replace=False)
    V[tips] *= 1.12
    return jp.TriMesh(V, np.asarray(m.faces)), tips


def test_tips_cut_off_by_the_remesh_get_a_sample_and_nothing_turns_over(monkeypatch):
    # manifold/snap.py: the samples nearest to the tips that the remesh cuts off move onto
    # them, exactly; the connectivity and the base vertices stay, no remesh face turns over
    # in its chart, and the tips come closer (the same parameterization, snapping off/on).
    import jaxparam.manifold.parameterization as pz
    from jaxparam.manifold.relax import BaseDomain, signed_chart_areas
    from jaxparam.subdivision import dyadic_hierarchy

    mesh, tips = _bumpy_sphere()
    V = np.asarray(mesh.vertices)
    _, param = manifold_map(mesh, 20, verbose=False)
    on = param.remesh(3)
    monkeypatch.setattr(pz, "SNAP_ROUNDS", 0)
    off = param.remesh(3)
    np.testing.assert_array_equal(on.mesh.faces, off.mesh.faces)
    n0 = param.base_vertices.size
    Xon, Xoff = np.asarray(on.mesh.vertices), np.asarray(off.mesh.vertices)
    np.testing.assert_array_equal(Xon[:n0], Xoff[:n0])

    def hits(X):
        return sum(bool(np.min(np.linalg.norm(X - V[t], axis=1)) == 0.0) for t in tips)

    assert hits(Xon) >= hits(Xoff) + 5, (hits(Xon), hits(Xoff))
    a, b = fidelity(param, off, mesh, samples=5000), fidelity(param, on, mesh, samples=5000)
    assert b.hausdorff_in < a.hausdorff_in, (a, b)
    # Every remesh face keeps its orientation in the base domain.
    monkeypatch.undo()
    F0 = np.asarray(param.base_faces)
    H = dyadic_hierarchy(F0, int(F0.max()) + 1, 3)
    _, r, b, _ = param._samples(3, None)
    D = BaseDomain(V[param.base_vertices], F0)
    assert np.all(signed_chart_areas(D, H.faces[-1], r, b) > 0)


def test_a_snap_pushes_no_other_tip_off_and_no_face_off_the_input():
    # One round of snap_tips on a sphere's level-3 samples, with tips in pairs of neighbours
    # (without the guard, one tip of seed 0 is pushed off): no tip ends farther from
    # the remesh than it was, unless it is nearer than the tip its nearest moved sample
    # took (cow: a horn's sample taken by its neighbour cut the horn 0.45 -> 0.57 %); and no
    # face around a moved sample stands off the input (on a 1/6 grid) farther than that
    # sample's tip was from the remesh.
    import jaxparam.manifold.parameterization as pz
    from jaxparam.distance import point_triangle_distance
    from jaxparam.manifold.relax import BaseDomain, sharpest_vertices
    from jaxparam.manifold.finish import lift_with
    from jaxparam.manifold.snap import bend, snap_tips

    m = jp.shapes.sphere(3)
    V, F = np.asarray(m.vertices).copy(), np.asarray(m.faces)
    tips = np.random.default_rng(0).choice(V.shape[0], 15, replace=False)
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    heads, first = np.unique(E[:, 0], return_index=True)
    V[tips] *= 1.12                                 # 15 tips, each with a neighbour tip
    V[E[first[np.searchsorted(heads, tips)], 1]] *= 1.10
    _, param = manifold_map(jp.TriMesh(V, F), 20, verbose=False)
    H, r, b, pull = param._samples(3, None, snap=False)
    S, G = param.structure, H.faces[-1]
    P, Fm = pz._centred(S.positions), np.asarray(param.mesh.faces, np.int64)
    X = lift_with(S.history, P, Fm)(r, b) if pull is None else np.einsum("kc,kcd->kd", pull[1], P[Fm[pull[0]]])
    tips = sharpest_vertices(P, Fm)
    D = BaseDomain(P[param.base_vertices], np.asarray(param.base_faces, np.int64))
    _, _, Xs, source = snap_tips(D, G, r, b, X, P, Fm, tips, param.vertex_face, S.vertex_bary, rounds=1)
    moved = np.flatnonzero(source >= 0)
    assert moved.size >= 5
    np.testing.assert_allclose(Xs[moved], P[source[moved]], atol=1e-12)
    before = point_triangle_distance(P[tips], X, G)[0]
    after = point_triangle_distance(P[tips], Xs, G)[0]
    took = np.zeros(P.shape[0])
    took[tips] = before
    nearest = moved[np.argmin(np.linalg.norm(Xs[moved][None] - P[tips][:, None], axis=2), axis=1)]
    pushed = (after > before * (1 + 1e-6)) & (after > took[source[nearest]])
    assert not pushed.any(), np.flatnonzero(pushed)
    assert after.max() < before.max()
    around = np.flatnonzero(np.isin(G, moved).any(1))
    limit = np.where(source[G[around]] >= 0, took[np.maximum(source[G[around]], 0)], np.inf).min(1)
    assert np.all(bend(Xs[G[around]], P, Fm) <= limit * (1 + 1e-9))


def test_snapping_moves_nothing_when_no_tip_is_off_the_remesh():
    # A remesh that is the input itself has no tip off it: snap_tips moves no sample.
    from jaxparam.manifold.relax import BaseDomain
    from jaxparam.manifold.snap import snap_tips

    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2]])
    D = BaseDomain(V, F)
    r = np.zeros(3, np.int64)
    b = np.eye(3)
    out = snap_tips(D, F, r, b, V, V, F, np.arange(3), r, b)
    assert np.all(out[3] == -1)
    np.testing.assert_array_equal(out[2], V)


def _noisy_sphere(V, F):
    """The sphere's vertices with Gaussian noise of 0.3 of its mean edge (seed 0)."""
    edge = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    return V + np.random.default_rng(0).normal(0, 0.3 * edge, V.shape)


def test_noise_at_the_edge_scale_is_told_from_bending():
    # maps.noise_dominates: neighbours' umbrella offsets along the normal are anti-correlated
    # under white noise and correlated on a bending surface, however coarse (a 20-face
    # icosahedron, a torus), and only there are the positions given back as they are.
    from jaxparam.manifold.maps import decision_positions, noise_dominates

    fine, coarse, torus = jp.shapes.sphere(3), jp.shapes.sphere(0), jp.shapes.torus()
    for m in (fine, coarse, torus):
        W, G = np.asarray(m.vertices), np.asarray(m.faces)
        assert not noise_dominates(W, G)
        np.testing.assert_array_equal(decision_positions(W, G), W)
    V, F = np.asarray(fine.vertices), np.asarray(fine.faces)
    assert noise_dominates(_noisy_sphere(V, F), F)


@pytest.mark.slow          # 8 s
def test_a_noisy_sphere_is_decimated_on_smoothed_positions_and_mapped_on_its_own(monkeypatch):
    # The decimation takes the smoothed positions; the map is still a bijection onto the base
    # domain, built on the input's own positions (_check lifts every vertex back).
    import jaxparam.manifold.parameterization as pz

    fine = jp.shapes.sphere(3)
    V, F = np.asarray(fine.vertices), np.asarray(fine.faces)
    noisy = _noisy_sphere(V, F)
    seen = []
    real = pz.decimate_caps
    monkeypatch.setattr(pz, "decimate_caps", lambda W, *a, **k: seen.append(W) or real(W, *a, **k))
    _check(jp.TriMesh(noisy, F), 20, levels=2)
    assert len(seen) == 1 and not np.allclose(seen[0], noisy)
    # The smoothed positions are closer to the sphere than the noisy ones.
    assert np.std(np.linalg.norm(seen[0], axis=1)) < 0.5 * np.std(np.linalg.norm(noisy, axis=1))
