"""trimesh interop (to_trimesh, from_trimesh) and as_mesh: every mesh-taking function takes a
TriMesh, a trimesh.Trimesh or a (V, F) pair, and names the type of anything else."""
import numpy as np
import pytest

import jaxparam as jp
from jaxparam import io

trimesh = pytest.importorskip("trimesh")


@pytest.fixture(scope="module")
def small():
    return jp.shapes.disk(3, seed=4, height=0.3)


def test_to_and_from_trimesh_keep_order_and_uvs(small):
    uv = np.random.default_rng(1).random((small.n_vertices, 2))
    t = io.to_trimesh(small, uv)
    assert isinstance(t, trimesh.Trimesh)
    np.testing.assert_array_equal(t.vertices, np.asarray(small.vertices))
    np.testing.assert_array_equal(t.faces, small.faces)
    np.testing.assert_array_equal(t.visual.uv, uv)
    back = io.from_trimesh(t)
    np.testing.assert_array_equal(back.vertices, np.asarray(small.vertices))
    np.testing.assert_array_equal(back.faces, small.faces)
    np.testing.assert_array_equal(back.uv, uv)
    assert io.from_trimesh(io.to_trimesh(small)).uv is None
    assert io.to_trimesh(small.with_uv(uv)).visual.uv.shape == uv.shape


def test_nothing_is_merged():
    """Two triangles whose shared edge has two copies of each end (a cut): trimesh with
    process=True would weld them into 4 vertices."""
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    F = np.array([[0, 1, 2], [3, 5, 4]])
    assert len(trimesh.Trimesh(V, F).vertices) == 4          # what merging would do
    m = io.from_trimesh(trimesh.Trimesh(V, F, process=False))
    assert m.n_vertices == 6 and m.topology.n_components == 2
    assert len(io.to_trimesh(m).vertices) == 6


def test_as_mesh_accepts_three_kinds_and_names_anything_else(small):
    V, F = np.asarray(small.vertices), small.faces
    assert io.as_mesh(small) is small
    for obj in [(V, F), [V, F], trimesh.Trimesh(V, F, process=False)]:
        m = io.as_mesh(obj)
        np.testing.assert_array_equal(m.vertices, V)
        np.testing.assert_array_equal(m.faces, F)
    with pytest.raises(TypeError, match=r"convex_map: expected a jaxparam TriMesh, a trimesh.Trimesh "
                                        r"or a \(vertices, faces\) pair, got dict"):
        io.as_mesh({"v": V}, "convex_map")
    with pytest.raises(TypeError, match=r"got tuple of length 3"):
        io.as_mesh((V, F, None))
    with pytest.raises(TypeError, match=r"got numpy.ndarray"):
        io.as_mesh(V)
    with pytest.raises(TypeError, match=r"from_trimesh: expected a trimesh.Trimesh.*Scene.*to_geometry"):
        io.from_trimesh(trimesh.Scene())


def test_every_mesh_function_takes_trimesh_and_pairs(small):
    V, F = np.asarray(small.vertices), small.faces
    kinds = [(V, F), trimesh.Trimesh(V, F, process=False)]
    uv = np.asarray(jp.convex_map(small))
    for obj in kinds:
        np.testing.assert_array_equal(np.asarray(jp.convex_map(obj)), uv)
        np.testing.assert_array_equal(np.asarray(jp.least_squares_map(obj)),
                                      np.asarray(jp.least_squares_map(small)))
        assert jp.distortion(obj, uv).flips == jp.distortion(small, uv).flips == 0
    a = jp.minimize(small, max_iters=3, verbose=False)
    b = jp.minimize((V, F), max_iters=3, verbose=False)
    np.testing.assert_allclose(np.asarray(a.uv), np.asarray(b.uv), atol=1e-12)
    s1 = jp.fit_surface(small, uv, kind="clough_tocher")
    s2 = jp.fit_surface(kinds[1], uv, kind="clough_tocher")
    np.testing.assert_array_equal(np.asarray(s1.sample(5).vertices), np.asarray(s2.sample(5).vertices))
    r1 = jp.remesh(small, uv, levels=1, errors=False)
    r2 = jp.remesh((V, F), uv, levels=1, errors=False)
    np.testing.assert_array_equal(np.asarray(r1.mesh.vertices), np.asarray(r2.mesh.vertices))


@pytest.mark.parametrize("name", ["convex_map", "least_squares_map", "distortion", "minimize",
                                  "fit_surface", "remesh", "manifold_map", "save"])
def test_every_mesh_function_names_a_wrong_type(tmp_path, name):
    f = getattr(jp, name)
    args = {"distortion": ("x", None), "fit_surface": ("x", None), "remesh": ("x", None),
            "save": (tmp_path / "o.obj", "x")}.get(name, ("x",))
    with pytest.raises(TypeError, match=rf"{name}: expected a jaxparam TriMesh.*got str"):
        f(*args)


# ------------------------------------------------------------------------------------------
# Boundary UVs per vertex, in any loop order (libigl's included)
# ------------------------------------------------------------------------------------------

def circle_uv(k, phase=0.3):
    t = phase + 2 * np.pi * np.arange(k) / k
    return np.stack([np.cos(t), np.sin(t)], 1)


def holed():
    """A 5x5 grid with the faces around its centre vertex removed: two boundary loops."""
    g = jp.shapes.plane_grid(5, 5, jitter=0.2, seed=1)
    keep = ~np.any(g.faces == 12, axis=1)
    V = np.asarray(g.vertices)
    V = V + np.stack([0 * V[:, 0], 0 * V[:, 0], 0.2 * V[:, 0] ** 2], 1)
    return jp.TriMesh(V, g.faces[keep])


@pytest.mark.parametrize("make", [lambda: jp.shapes.disk(3, seed=4, height=0.3), holed])
def test_boundary_uvs_in_any_order_give_the_same_map(make):
    mesh = make()
    loop = jp.boundary.boundary_loop(mesh)
    assert loop.size == mesh.topology.boundary_loops[0].size
    uv_b = circle_uv(loop.size)
    ref = np.asarray(jp.convex_map(mesh, boundary=uv_b))
    np.testing.assert_array_equal(ref[loop], uv_b)          # the loop convex_map uses is ours
    perm = np.random.default_rng(0).permutation(loop.size)
    shuffled = np.asarray(jp.convex_map(mesh, boundary=uv_b[perm], boundary_indices=loop[perm]))
    as_dict = np.asarray(jp.convex_map(mesh, boundary={int(loop[i]): uv_b[i] for i in perm}))
    np.testing.assert_array_equal(shuffled, ref)
    np.testing.assert_array_equal(as_dict, ref)
    lsq = np.asarray(jp.least_squares_map(mesh, boundary=uv_b[perm], boundary_indices=loop[perm]))
    np.testing.assert_array_equal(lsq, np.asarray(jp.least_squares_map(mesh, boundary=uv_b)))


def test_libigl_loop_order_gives_our_map():
    igl = pytest.importorskip("igl")
    mesh = jp.shapes.disk(3, seed=4, height=0.3)
    igl_loop = np.asarray(igl.boundary_loop(mesh.faces), np.int64)
    ours = jp.boundary.boundary_loop(mesh)
    assert set(igl_loop.tolist()) == set(ours.tolist())
    uv_igl = circle_uv(igl_loop.size)                        # UVs listed in libigl's order
    got = np.asarray(jp.convex_map(mesh, boundary=uv_igl, boundary_indices=igl_loop))
    np.testing.assert_array_equal(got[igl_loop], uv_igl)
    row = {int(v): i for i, v in enumerate(igl_loop)}
    ref = np.asarray(jp.convex_map(mesh, boundary=uv_igl[[row[int(v)] for v in ours]]))
    np.testing.assert_array_equal(got, ref)
    # libigl's harmonic map with the same boundary agrees (harmonic weights, both sides).
    H = igl.harmonic(np.asarray(mesh.vertices), mesh.faces, igl_loop, uv_igl, 1)
    ours_h = np.asarray(jp.convex_map(mesh, weights="harmonic", boundary=uv_igl,
                                      boundary_indices=igl_loop))
    np.testing.assert_allclose(ours_h, H, atol=1e-9)


def test_boundary_uv_errors_name_the_vertices():
    mesh = jp.shapes.disk(3, seed=4, height=0.3)
    loop = jp.boundary.boundary_loop(mesh)
    interior = int(np.flatnonzero(~mesh.topology.is_boundary)[0])
    uv_b = circle_uv(loop.size)
    bad = {int(v): uv_b[i] for i, v in enumerate(loop[1:])}
    bad[interior] = (0.0, 0.0)
    with pytest.raises(jp.MeshError, match=rf"exactly the {loop.size} vertices of the longest boundary "
                                            rf"loop .*missing vertices {loop[0]} \(1 in all\); "
                                            rf"vertices {interior} \(1 in all\) are not on it"):
        jp.convex_map(mesh, boundary=bad)
    with pytest.raises(jp.MeshError, match=r"vertices .* given more than once"):
        jp.convex_map(mesh, boundary=uv_b, boundary_indices=np.r_[loop[:-1], loop[0]])
    with pytest.raises(jp.MeshError, match=rf"{loop.size} boundary vertices need \({loop.size}, 2\) UVs"):
        jp.convex_map(mesh, boundary=uv_b[:3], boundary_indices=loop)
    with pytest.raises(jp.MeshError, match=r"boundary_indices: given only with a \(k, 2\) array"):
        jp.convex_map(mesh, boundary="square", boundary_indices=loop)
    with pytest.raises(jp.MeshError, match=r"closed"):
        jp.boundary.boundary_loop(jp.shapes.sphere(1))


@pytest.mark.slow
def test_gradients_flow_to_shuffled_boundary_uvs():
    import jax
    import jax.numpy as jnp

    mesh = jp.shapes.disk(2, seed=4, height=0.3)
    loop = jp.boundary.boundary_loop(mesh)
    perm = np.random.default_rng(2).permutation(loop.size)
    uv_b = jnp.asarray(circle_uv(loop.size)[perm])
    w = np.random.default_rng(3).random((mesh.n_vertices, 2))

    def loss(b):
        return jnp.sum(jp.convex_map(mesh, boundary=b, boundary_indices=loop[perm]) * w)

    g = np.asarray(jax.grad(loss)(uv_b))
    e = np.zeros_like(np.asarray(uv_b))
    e[1, 0] = 1e-6
    fd = (loss(uv_b + e) - loss(uv_b - e)) / 2e-6
    np.testing.assert_allclose(g[1, 0], fd, rtol=1e-6)
