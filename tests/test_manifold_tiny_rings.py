"""MAPS decimation of dense inputs made of flat pieces (issue 13): clusters of tiny faces at
creases and tips, where no collapse passes the shape rules, go before the rules are relaxed
for every ring (:data:`jaxparam.manifold.maps.TINY_RING`), so they do not fill the base
domain with faces that hold almost nothing."""
import numpy as np
import pytest

import jaxparam as jp
from conftest import data_path
from jaxparam.manifold import fidelity
from jaxparam.manifold import maps
from jaxparam.manifold.parameterization import LARGE_MESH_CAP
from jaxparam.subdivision import midpoint_refine


def _refined_cow(times: int):
    mesh = jp.load(data_path("meshes", "cow.off"))
    V, F = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces)
    for _ in range(times):
        V, F = midpoint_refine(V, F)
    return V, F


def _tiny_base_faces(V, F, base_faces: int) -> int:
    """How many base faces of the capped MAPS decimation have under 1 % of the mean base
    face's area."""
    kept, B, _, _, _ = maps.maps_decimate(V, F, base_faces, area_cap=LARGE_MESH_CAP, verbose=False)
    P = V[kept][B]
    area = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    return int(np.sum(area < 1e-2 * area.mean()))


def test_tiny_rings_go_before_the_rules_are_relaxed(monkeypatch):
    V, F = _refined_cow(1)                        # 22k faces, flat in each of cow's faces
    with_tiny = _tiny_base_faces(V, F, 100)
    monkeypatch.setattr(maps, "TINY_RING", 0.0)   # no ring is tiny: the rules alone
    without = _tiny_base_faces(V, F, 100)
    assert with_tiny < without, (with_tiny, without)
    assert with_tiny <= 1


@pytest.mark.slow
def test_a_cow_refined_twice_is_remeshed_faithfully():
    V, F = _refined_cow(2)                        # 88k faces: 2.6 % of the diagonal before
    mesh = jp.TriMesh(V, F)
    _, param = jp.manifold_map(mesh, 100, verbose=False)
    report = fidelity(param, param.remesh(4), mesh, samples=20_000)
    assert report.hausdorff < 0.01, report.hausdorff
