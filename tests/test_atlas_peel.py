"""A chart whose map crosses its own boundary gives up the faces at the crossing, not half of
itself (`jaxparam.atlas.build._peeled_or_halved`, issue 18, session 32)."""
from pathlib import Path

import numpy as np
import pytest

import jaxparam as jp
from jaxparam.atlas import build
from jaxparam.atlas.charts import face_csr, split_chart

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes"


def _wound_strip(turn):
    """A 24 x 3 strip of quads (144 triangles) and its corner UVs wound on an annulus through ``turn`` radians:
    past a full turn the map's boundary crosses itself where the strip's end comes round."""
    g = jp.shapes.plane_grid(25, 4)
    V = np.asarray(g.vertices, float)
    u = (V[:, 0] - V[:, 0].min()) / np.ptp(V[:, 0])
    v = (V[:, 1] - V[:, 1].min()) / np.ptp(V[:, 1])
    r = 1.0 + 0.3 * v
    uv = np.stack([r * np.cos(turn * u), r * np.sin(turn * u)], 1)
    return g, V, uv[g.faces]


def test_a_chart_crossing_itself_gives_up_the_faces_at_the_crossing():
    g, V, corner_uv = _wound_strip(2.1 * np.pi)
    faces = np.arange(g.n_faces)
    pieces = build._peeled_or_halved(V, g.faces, faces, corner_uv, face_csr(g.topology))
    assert len(pieces) == 2
    rest, peel = pieces
    assert np.array_equal(np.sort(np.r_[rest, peel]), faces)
    assert 0 < peel.size <= build.PEEL_SHARE * g.n_faces                 # measured 36 of 144
    # the peeled faces are those at both ends of the strip, where the wound outline overlaps
    x = V[g.faces[peel]].mean(1)[:, 0]
    lo, hi = V[:, 0].min(), V[:, 0].max()
    assert np.all((x < lo + 0.3 * (hi - lo)) | (x > hi - 0.3 * (hi - lo)))
    # without a crossing the chart is halved, as before
    g, V, corner_uv = _wound_strip(1.5 * np.pi)
    halves = build._peeled_or_halved(V, g.faces, faces, corner_uv, face_csr(g.topology))
    expected = split_chart(faces, face_csr(g.topology), merge_small=True)
    assert len(halves) == len(expected)
    assert all(np.array_equal(a, b) for a, b in zip(halves, expected))


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "camelhead.off").exists(), reason="../shared/data is not beside the repository")
def test_camelhead_atlas_covers_three_quarters():
    """Halved, camelhead's crossing charts gave 76 charts covering 73.1 %; peeled, 132 covering
    77.6 % (xatlas: 305 charts, 57.3 %)."""
    from test_atlas import check_atlas

    mesh = jp.load(DATA / "camelhead.off")
    a = jp.atlas(mesh, verbose=False)
    check_atlas(mesh, a, min_coverage=0.75)
    assert a.n_charts < 305


def test_charts_that_still_fold_after_max_splits_are_halved_not_refused(monkeypatch):
    """Past ``max_splits`` rounds the charts that still fold or cross themselves are halved
    (no peeling) until they do not: cow x256 (1.41M faces) was refused after 375 s with 2
    charts folded after 16 rounds.  Here with no split rounds at all: a 2-turn helical tube
    (1,584 faces) was refused ("1 charts still fold over"); now 27 charts (measured), none
    folded, none overlapping."""
    from test_atlas import check_atlas

    mesh = jp.shapes.helical_tube(2.0, 100, 8)
    monkeypatch.setattr(build, "FINAL_HALVINGS", 0)
    with pytest.raises(jp.SolverError, match="still fold over"):
        jp.atlas(mesh, max_splits=0, verbose=False)
    monkeypatch.undo()
    a = jp.atlas(mesh, max_splits=0, verbose=False)
    check_atlas(mesh, a, min_coverage=0.4)
