"""Triangle soups (unwelded faces, as STL exporters write) get the coincident-vertex diagnosis
from every command that needs stitched faces, before any work (held-out sweep, session 26:
`jaxparam atlas` made one chart per triangle and packed 1,653 of them for 177 s; `jaxparam
manifold` said "close the holes")."""
import numpy as np
import pytest

import jaxparam as jp


def _soup(mesh):
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    return jp.TriMesh(V[F].reshape(-1, 3), np.arange(3 * F.shape[0]).reshape(-1, 3))


def test_atlas_and_manifold_refuse_a_soup_naming_the_coincident_vertices():
    soup = _soup(jp.shapes.sphere(1))
    with pytest.raises(jp.errors.TopologyError, match=r"atlas: vertices \d+ and \d+ coincide.*not stitched"):
        jp.atlas(soup)
    with pytest.raises(jp.errors.TopologyError, match=r"manifold_map: vertices \d+ and \d+ coincide"):
        jp.manifold_map(soup, 20)
    with pytest.raises(jp.errors.TopologyError, match=r"manifold_map_each: vertices \d+ and \d+ coincide"):
        jp.manifold.manifold_map_each(soup, 20)


def test_a_mesh_cut_along_one_seam_is_still_an_atlas():
    # the upper and lower halves of a sphere, their equator vertices duplicated: two pieces
    # that meet but are not stitched (an export split along a UV seam) are not a soup
    m = jp.shapes.sphere(1)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    upper = V[F].mean(1)[:, 2] > 0
    G = F.copy()
    lower_verts = np.unique(F[~upper])
    new = np.full(V.shape[0], -1)
    new[lower_verts] = V.shape[0] + np.arange(lower_verts.size)
    G[~upper] = new[F[~upper]]
    W = np.concatenate([V, V[lower_verts]])
    used = np.unique(G)
    remap = np.full(W.shape[0], -1)
    remap[used] = np.arange(used.size)
    cut = jp.TriMesh(W[used], remap[G])
    assert cut.topology.n_components == 2
    a = jp.atlas(cut, verbose=False)
    assert a.stats.flips == 0 and a.n_charts >= 2
