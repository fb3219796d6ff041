"""Bars on the long stages: reconstruct_surface's stages and remesh's error measurement show
through jaxparam.progress, and the library switch silences them."""
import io

import numpy as np
import pytest

import jaxparam as jp
from jaxparam import progress as prog


@pytest.fixture
def captured(monkeypatch):
    """Every bar made through jaxparam.progress, with its description and whether it shows."""
    made = []
    real = prog.progress

    def spy(iterable=None, **kw):
        bar = real(iterable, **{**kw, "delay": 0.0})
        made.append((kw["desc"], not bar.disable, bar))
        return bar

    monkeypatch.setattr(prog, "progress", spy)
    import sys

    import jaxparam.remesh  # noqa: F401  (jp.remesh is the function; the module is in sys.modules)
    monkeypatch.setattr(sys.modules["jaxparam.remesh"], "progress", spy)
    return made


def _points(n=600, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    return np.column_stack([xy, 0.1 * np.sin(3 * xy[:, 0])])


def test_reconstruction_shows_its_stages_and_the_switch_silences_them(captured):
    rec = jp.reconstruct_surface(_points(), verbose=True)
    desc, shown, bar = captured[-1]
    assert desc == "reconstruct_surface" and shown
    assert bar.n >= 4 and set(rec.seconds) >= {"neighbours", "delaunay", "peel_and_topology"}
    jp.config.progress = False
    try:
        jp.reconstruct_surface(_points(), verbose=None)
        assert captured[-1][0] == "reconstruct_surface" and not captured[-1][1]
    finally:
        jp.config.progress = None


def test_remesh_errors_advance_a_bar_per_level(captured):
    mesh = jp.shapes.disk(4, seed=1, height=0.2)
    semi = jp.remesh(mesh, jp.convex_map(mesh), levels=2)
    import sys

    sys.modules["jaxparam.remesh"].measure_errors(mesh, semi, samples=500)
    desc, shown, bar = [c for c in captured if c[0] == "remesh errors"][-1]
    assert bar.n == 3
