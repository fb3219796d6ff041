"""What the closed-mesh report says about the map itself (issue 13: no base-domain triangle
flips, every input vertex in its base triangle), and the straight drawing ``param.face_uv``."""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from jaxparam.manifold.overlay import _drawn_in, base_charts, unfolding
from jaxparam.manifold.report import fidelity, map_pieces_turned_over, misplaced_vertices
from jaxparam.triangles import doubled_areas


@pytest.fixture(scope="module")
def torus(torus_map):
    return torus_map[0], torus_map[2]          # conftest's torus(32, 16) at 40 base faces


@pytest.fixture(scope="module")
def genus_two(plate_map):
    """A genus-2 plate at 38 base faces: its straight drawing turns faces over from the first
    corner's chart (45 of 432 faces, measured) and fewer from the chart chosen (29).
    conftest's map, shared with test_manifold_maps."""
    return plate_map[0], plate_map[2]


def test_no_piece_of_the_map_turns_over_and_every_vertex_is_in_place(torus):
    mesh, param = torus
    rep = fidelity(param, param.remesh(2), mesh, samples=2000)
    assert rep.flipped == 0 and rep.misplaced == 0, rep
    assert {"flipped", "drawn_flipped", "misplaced"} <= set(rep.as_dict())
    # The drawing is counted apart from the map: the two numbers are not the same quantity.
    drawn = np.asarray(param.face_uv)
    assert rep.drawn_flipped == int(np.sum(~(doubled_areas(drawn) > 0)))


def test_a_turned_over_piece_of_the_map_is_counted(torus):
    _, param = torus
    levels = list(param.structure.history.levels)
    f, which, survive, before, after = levels[3]
    before = before.copy()
    before[5] = before[5][[0, 2, 1]]                 # one old flat triangle turned over
    after = after.copy()
    k = int(np.flatnonzero(survive)[0])
    after[k] = after[k][[1, 0, 2]]                   # one new flat triangle turned over
    levels[3] = (f, which, survive, before, after)
    assert map_pieces_turned_over(SimpleNamespace(levels=levels)) == 2


def test_a_vertex_off_its_place_is_counted(torus):
    _, param = torus
    b = np.array(param.vertex_bary)
    moved = replace(param, vertex_bary=np.roll(b, 1, axis=0))   # every vertex given another's place
    assert misplaced_vertices(moved) > 0.9 * b.shape[0]
    b[7] = [1.2, -0.1, -0.1]
    assert misplaced_vertices(replace(param, vertex_bary=b)) >= 1


def test_each_face_is_drawn_in_a_chart_that_does_not_turn_it_over_where_one_exists(genus_two):
    mesh, param = genus_two
    F = np.asarray(mesh.faces)
    vf, vb = np.asarray(param.vertex_face), np.asarray(param.vertex_bary)
    U = unfolding(param.base_faces, param.base_vertices.size,
                  base_charts(np.asarray(mesh.vertices)[param.base_vertices], param.base_faces))
    drawn = [_drawn_in(F, F[:, c], vf, vb, U) for c in range(3)]
    bad = np.stack([~(doubled_areas(uv) > 0) for _, uv in drawn])
    chosen_bad = ~(doubled_areas(np.asarray(param.face_uv)) > 0)
    assert bad[0].sum() > chosen_bad.sum() > 0      # the case this checks occurs here
    np.testing.assert_array_equal(chosen_bad, bad.all(0))
    # Each face is drawn in its region's chart: the region is one of its corners' triangles.
    ok = ~chosen_bad
    assert np.all((param.region[:, None] == vf[F]).any(1))
    for c in range(3):
        here = ok & (param.region == vf[F[:, c]]) & ~bad[c]
        np.testing.assert_allclose(np.asarray(param.face_uv)[here], drawn[c][1][here], atol=1e-14)
