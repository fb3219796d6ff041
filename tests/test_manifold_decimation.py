"""The MAPS decimation on a mesh where every vertex is next to a high-valence pole (issue 13:
a capsule of sliver quads collapsed 2 vertices a level for thousands of levels)."""
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.manifold import maps as M
from jaxparam.manifold.report import map_pieces_turned_over
from test_manifold_maps import capsule as capsule_of_revolution


def sliver_capsule(k: int, rings: int = 3) -> jp.TriMesh:
    """A closed capsule of revolution: ``rings`` rings of ``k`` vertices (radius 0.5, 1 apart)
    joined by sliver quads, and two poles of valence ``k``."""
    zs = np.arange(rings) - (rings - 1) / 2
    t = 2 * np.pi * np.arange(k) / k
    ring = np.column_stack([0.5 * np.cos(t), 0.5 * np.sin(t)])
    V = np.concatenate([np.column_stack([ring, np.full(k, z)]) for z in zs]
                       + [[[0, 0, zs[0] - 0.3], [0, 0, zs[-1] + 0.3]]])
    s, e = rings * k, rings * k + 1
    r, c = np.meshgrid(np.arange(rings - 1), np.arange(k), indexing="ij")
    a, b = r * k + c, r * k + (c + 1) % k
    cc = np.arange(k)
    F = np.concatenate([np.stack([a, b, b + k], -1).reshape(-1, 3), np.stack([a, b + k, a + k], -1).reshape(-1, 3),
                        np.stack([np.full(k, s), (cc + 1) % k, cc], 1),
                        np.stack([np.full(k, e), (rings - 1) * k + cc, (rings - 1) * k + (cc + 1) % k], 1)])
    return jp.TriMesh(V, F, name="sliver_capsule")


@pytest.fixture(scope="module")
def capsule():
    return sliver_capsule(600)


def test_a_stalled_decimation_lets_collapses_share_a_pole(capsule, monkeypatch):
    V, F = np.asarray(capsule.vertices), np.asarray(capsule.faces)
    kept, F0, vface, vbary, history = M.maps_decimate(V, F, 40, verbose=False)
    monkeypatch.setattr(M, "STALL_LEVELS", 10 ** 9)         # never share a ring vertex
    old = M.maps_decimate(V, F, 40, verbose=False)[4]
    assert len(history.levels) < 0.2 * len(old.levels), (len(history.levels), len(old.levels))
    # Still a bijection onto a closed genus-0 base domain of 40 faces, every vertex in place.
    assert F0.shape == (40, 3) and jp.topology.build(F0, kept.size).genus == 0
    assert map_pieces_turned_over(history) == 0
    face, b = history.pull_back(vface, vbary, verbose=False)
    X = np.einsum("kc,kcd->kd", b, V[F[face]])
    np.testing.assert_allclose(X, V, atol=1e-9)


def test_decimations_that_never_stall_are_unchanged(monkeypatch):
    # A capsule with poles of valence 32 (hubs) that decimates at a normal pace: the same
    # collapses as with the stall rule off; sharing its poles from the start would differ.
    mesh = capsule_of_revolution(k=32, rings=20)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    same = lambda a, b: all(np.array_equal(x, y) for p, q in zip(a, b) for x, y in zip(p[:4], q[:4]))
    now = M.decimate_caps(V, F, 60, M.AREA_CAPS, verbose=False)
    monkeypatch.setattr(M, "STALL_LEVELS", 10 ** 9)
    assert same(now, M.decimate_caps(V, F, 60, M.AREA_CAPS, verbose=False))
    monkeypatch.setattr(M, "STALL_LEVELS", 1)
    monkeypatch.setattr(M, "STALL_SHARE", 1.0)                # every level a stall: hubs shared
    assert not same(now, M.decimate_caps(V, F, 60, M.AREA_CAPS, verbose=False))


def test_a_mesh_above_the_choice_size_is_decimated_with_the_large_mesh_cap(monkeypatch):
    # Above SELECT_MAX_FACES one base domain is made, with LARGE_MESH_CAP (uncapped, a dense
    # bunny's level-4 remesh lay 0.662 % of the diagonal off, capped 0.325 %); a large
    # base-face count on a small mesh keeps the first cap.  The size rule is lowered here so
    # that a small torus stands for a large mesh.
    import importlib
    P = importlib.import_module("jaxparam.manifold.parameterization")
    seen = []
    real = P.decimate_caps

    def spy(V, F, base_faces, caps, **kw):
        seen.append(tuple(caps))
        return real(V, F, base_faces, caps, **kw)

    monkeypatch.setattr(P, "decimate_caps", spy)
    torus = jp.shapes.torus(16, 10)
    monkeypatch.setattr(P, "SELECT_MAX_FACES", torus.n_faces - 1)
    jp.manifold_map(torus, 40, verbose=False)
    monkeypatch.setattr(P, "SELECT_MAX_FACES", torus.n_faces)
    monkeypatch.setattr(P, "SELECT_MAX_REMESH_FACES", 0)
    jp.manifold_map(torus, 40, verbose=False)
    assert seen == [(P.LARGE_MESH_CAP,), (M.AREA_CAPS[0],)]
    assert P.LARGE_MESH_CAP in M.AREA_CAPS and P.LARGE_MESH_CAP is not None
