"""Numerical robustness: tiny angles, extreme scales, interrupted writes."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import DegenerateFaceError, MeshFileError


def sliver_mesh(eps: float) -> jp.TriMesh:
    """A disk whose centre vertex sits eps (relative) away from an edge: angles near eps."""
    mesh = jp.shapes.disk(4, seed=0)
    V = np.asarray(mesh.vertices).copy()
    F = mesh.faces
    # Move vertex 0 (the centre) almost onto the segment of two of its neighbours.
    ring = mesh.topology.ring_idx[mesh.topology.ring_ptr[0]:mesh.topology.ring_ptr[1]]
    a, b = V[ring[0]], V[ring[1]]
    n = np.cross(b - a, [0, 0, 1.0])
    V[0] = 0.5 * (a + b) + eps * n / np.linalg.norm(n) * np.linalg.norm(b - a)
    return jp.TriMesh(V, F)


@pytest.mark.parametrize("eps", [1e-4, 1e-8])
def test_nearly_degenerate_triangles_give_finite_maps_and_gradients(eps):
    mesh = sliver_mesh(eps)
    for kind in ["mean_value", "shape_preserving", "uniform", "inverse_distance"]:
        uv = np.asarray(jp.convex_map(mesh, weights=kind))
        assert np.all(np.isfinite(uv)), kind
    g = jax.grad(lambda V: jnp.sum(jp.convex_map(jp.TriMesh(V, mesh.faces, validate=False),
                                                 weights="mean_value") ** 2))(jnp.asarray(mesh.vertices))
    assert not np.any(np.isnan(np.asarray(g)))


def test_exactly_degenerate_is_refused():
    with pytest.raises(DegenerateFaceError, match="zero area"):
        sliver_mesh(0.0)


@pytest.mark.parametrize("scale", [1e-6, 1e6])
def test_scale_invariance_of_the_maps(scale, grid_mesh):
    V = np.asarray(grid_mesh.vertices)
    for kind in jp.weights.KINDS:
        a = np.asarray(jp.convex_map(grid_mesh, weights=kind))
        b = np.asarray(jp.convex_map(jp.TriMesh(V * scale, grid_mesh.faces), weights=kind))
        np.testing.assert_allclose(a, b, atol=1e-9, err_msg=kind)


@pytest.mark.parametrize("scale", [1e-6, 1e6])
def test_scale_invariant_energy_minimizes_at_any_scale(scale):
    mesh = jp.shapes.graph_surface(6)
    m2 = jp.TriMesh(np.asarray(mesh.vertices) * scale, mesh.faces)
    a = jp.minimize(mesh, "mips", free_boundary=True, max_iters=10, verbose=False)
    b = jp.minimize(m2, "mips", free_boundary=True, max_iters=10, verbose=False)
    assert b.flips == 0 and np.isfinite(b.energy)
    assert b.energy == pytest.approx(a.energy, rel=1e-6)


def test_minimizer_time_and_iteration_limits():
    mesh = jp.shapes.graph_surface(10)
    r = jp.minimize(mesh, "symmetric_dirichlet", max_iters=3, verbose=False)
    assert r.iterations <= 3 and r.reason in ("max_iters",) or r.converged
    r = jp.minimize(mesh, "symmetric_dirichlet", max_seconds=0.0, verbose=False)
    assert r.iterations == 1 and r.reason == "time limit"


def test_interrupted_write_leaves_no_file(tmp_path, grid_mesh, monkeypatch):
    target = tmp_path / "out.obj"

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savetxt", boom)
    with pytest.raises(KeyboardInterrupt):
        jp.save(target, grid_mesh, np.zeros((grid_mesh.n_vertices, 2)))
    assert list(tmp_path.iterdir()) == []


def test_failure_midway_keeps_the_old_file_and_leaves_no_temporary(tmp_path, grid_mesh, monkeypatch):
    target = tmp_path / "out.obj"
    target.write_text("old content")
    real, calls = np.savetxt, []

    def disk_full_on_second_block(f, *a, **k):      # the vertices are written, then the disk fills
        calls.append(1)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real(f, *a, **k)

    monkeypatch.setattr(np, "savetxt", disk_full_on_second_block)
    with pytest.raises(MeshFileError, match=r"out.obj: writing the file failed \(No space left"):
        jp.save(target, grid_mesh, np.zeros((grid_mesh.n_vertices, 2)))
    assert len(calls) == 2
    assert target.read_text() == "old content" and list(tmp_path.iterdir()) == [target]


def test_json_report_is_all_or_nothing(tmp_path):
    from jaxparam.cli import write_json

    with pytest.raises(TypeError):
        write_json(tmp_path / "r.json", {"a": 1.0, "b": object()})     # fails mid-dump
    assert list(tmp_path.iterdir()) == []
    write_json(tmp_path / "r.json", {"a": float("nan"), "b": np.float64(2)})
    assert (tmp_path / "r.json").read_text().replace(" ", "").replace("\n", "") == '{"a":null,"b":2.0}'
    assert oct((tmp_path / "r.json").stat().st_mode & 0o777) != oct(0o600)   # usual permissions


@pytest.mark.parametrize("exc, code", [(KeyboardInterrupt, 130), (MeshFileError("r.json: boom"), 3)])
def test_cli_flatten_writes_nothing_when_a_late_stage_fails(tmp_path, monkeypatch, exc, code):
    import jaxparam.cli as cli

    src = tmp_path / "in.obj"
    jp.save(src, jp.shapes.graph_surface(5))

    def fail(*a, **k):
        raise exc

    monkeypatch.setattr(cli, "write_json", fail)        # the mesh is saved, then the report fails
    out, rep = tmp_path / "out.obj", tmp_path / "r.json"
    assert cli.main(["flatten", str(src), "-o", str(out), "--report", str(rep)]) == code
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.obj"]
