"""Numerical robustness: tiny angles, extreme scales, interrupted writes."""
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import DegenerateFaceError, MeshFileError
from jaxparam.io import obj as obj_io


def sliver_mesh(eps: float, *, validate: bool = True) -> jp.TriMesh:
    """A planar disk whose centre vertex sits ``eps |b - a|`` inside the segment of two of its
    neighbours a, b: the triangle (0, a, b) has two angles near 2 eps and one near pi."""
    mesh = jp.shapes.disk(4, seed=0)
    V = np.asarray(mesh.vertices).copy()
    ring = mesh.topology.ring_idx[mesh.topology.ring_ptr[0]:mesh.topology.ring_ptr[1]]
    a, b = V[ring[0]], V[ring[1]]
    n = np.cross([0, 0, 1.0], b - a)          # the ring runs anticlockwise: its inside is on the left
    V[0] = 0.5 * (a + b) + eps * n / np.linalg.norm(n) * np.linalg.norm(b - a)
    return jp.TriMesh(V, mesh.faces, mesh.topology, validate=validate)


POSITIVE = ["uniform", "inverse_distance", "shape_preserving", "mean_value"]


@pytest.mark.parametrize("eps", [1e-4, 1e-8, 1e-12])
def test_nearly_degenerate_triangles_give_finite_maps_and_gradients(eps):
    """Angles near 2 eps (and one near pi): every positive weight kind gives a one-to-one map
    and finite gradients (unit row sums keep the system well scaled when a mean-value weight
    grows like 1/angle).  Harmonic weights (negative here) either work or say the system is too
    badly conditioned, as a SolverError."""
    mesh = sliver_mesh(eps)
    V0 = jnp.asarray(mesh.vertices)
    for kind in POSITIVE:
        uv = np.asarray(jp.convex_map(mesh, weights=kind))
        assert np.all(np.isfinite(uv)) and jp.metrics.flips(mesh, uv) == 0, kind
    for kind in ["shape_preserving", "mean_value"]:     # the kinds built from angles (tan, polar map)
        g = jax.grad(lambda V: jnp.sum(jp.convex_map(mesh.with_vertices(V), weights=kind) ** 2))(V0)
        assert np.all(np.isfinite(np.asarray(g))), kind
    try:
        uv = np.asarray(jp.convex_map(mesh, weights="harmonic"))
        assert np.all(np.isfinite(uv))
    except jp.SolverError as exc:
        assert eps < 1e-10 and exc.stage == "solve"
        assert re.search(r"37 x 37 system left a relative residual of .* badly conditioned", str(exc))


@pytest.mark.parametrize("eps", [0.0, 1e-15])
def test_triangles_below_the_degenerate_tolerance_are_refused(eps):
    with pytest.raises(DegenerateFaceError, match=r"faces \d+ \(1 in all\) have zero area \(face \d+ = \(\d+, \d+, 0\)\).*validate=False"):
        sliver_mesh(eps)
    assert sliver_mesh(eps, validate=False).n_faces > 0          # the documented way around


@pytest.mark.parametrize("scale", [1e-6, 1e6])
def test_scale_invariance_of_the_maps(scale, grid_mesh):
    V = np.asarray(grid_mesh.vertices)
    for kind in jp.weights.KINDS:
        a = np.asarray(jp.convex_map(grid_mesh, weights=kind))
        b = np.asarray(jp.convex_map(jp.TriMesh(V * scale, grid_mesh.faces), weights=kind))
        np.testing.assert_allclose(a, b, atol=1e-9, err_msg=kind)


def test_minimizer_at_extreme_scales_and_its_limits():
    """A scale-invariant energy reaches the same value on the mesh scaled by 1e-6 and 1e6 (no
    under/overflow in areas or Jacobians); max_iters and max_seconds stop it (nothing hangs).
    One mesh and one energy throughout, so the compiled code is shared."""
    mesh = jp.shapes.graph_surface(6)
    a = jp.minimize(mesh, "mips", free_boundary=True, max_iters=10, verbose=False)
    for scale in [1e-6, 1e6]:
        b = jp.minimize(jp.TriMesh(np.asarray(mesh.vertices) * scale, mesh.faces), "mips",
                        free_boundary=True, max_iters=10, verbose=False)
        assert b.flips == 0 and np.isfinite(b.energy)
        assert b.energy == pytest.approx(a.energy, rel=1e-6), scale
    assert a.converged and a.iterations < 10          # the reference run stops on its own ...
    r = jp.minimize(mesh, "mips", free_boundary=True, max_iters=3, verbose=False)
    # ... after more than 3 iterations, so max_iters=3 is what stops this one, short of the optimum.
    assert r.iterations == 3 and r.reason == "max_iters" and not r.converged
    assert r.energy > a.energy * (1 + 1e-6)
    r = jp.minimize(mesh, "mips", free_boundary=True, max_seconds=0.0, verbose=False)
    assert r.iterations == 1 and r.reason == "time limit" and not r.converged


def test_interrupted_write_leaves_no_file(tmp_path, grid_mesh, monkeypatch):
    target = tmp_path / "out.obj"

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(obj_io, "write_rows", boom)     # the OBJ writer's row writer
    with pytest.raises(KeyboardInterrupt):
        jp.save(target, grid_mesh, np.zeros((grid_mesh.n_vertices, 2)))
    assert list(tmp_path.iterdir()) == []


def test_failure_midway_keeps_the_old_file_and_leaves_no_temporary(tmp_path, grid_mesh, monkeypatch):
    target = tmp_path / "out.obj"
    target.write_text("old content")
    real, calls = obj_io.write_rows, []

    def disk_full_on_second_block(f, *a, **k):      # the vertices are written, then the disk fills
        calls.append(1)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real(f, *a, **k)

    monkeypatch.setattr(obj_io, "write_rows", disk_full_on_second_block)
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
    from jaxparam.cli import commands

    src = tmp_path / "in.obj"
    jp.save(src, jp.shapes.graph_surface(5))

    def fail(*a, **k):
        raise exc

    monkeypatch.setattr(commands, "write_json", fail)   # the mesh is saved, then the report fails
    out, rep = tmp_path / "out.obj", tmp_path / "r.json"
    assert cli.main(["flatten", str(src), "-o", str(out), "--report", str(rep)]) == code
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.obj"]
