"""Results pickle (multiprocessing, joblib, caches): the surfaces, the atlases and the
energies they hold, which are built from lambdas and closures that pickle cannot store."""
import pickle

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxparam as jp


def user_density(s1, s2):
    return s1 ** 2 + s2 ** -2


@pytest.fixture(scope="module")
def mesh():
    return jp.shapes.graph_surface(8, jitter=0.1)


@pytest.mark.parametrize("kind", ["spline", "clough_tocher"])
def test_a_fitted_surface_pickles_and_evaluates_the_same(mesh, kind):
    surf = jp.fit_surface(mesh, jp.convex_map(mesh), kind=kind)
    back = pickle.loads(pickle.dumps(surf))
    q = np.random.default_rng(0).uniform(-0.6, 0.6, (50, 2))
    np.testing.assert_array_equal(back.evaluate(q), surf.evaluate(q))
    assert back.kind == kind and back.bbox == surf.bbox and back.residual_rms == surf.residual_rms


@pytest.mark.slow
def test_a_surface_fitted_to_traced_points_refuses_to_pickle(mesh):
    uv = np.asarray(jp.convex_map(mesh))
    seen = []

    def loss(X):
        surf = jp.fit_surface(X, uv)
        with pytest.raises(jp.MeshError, match="traced.*cannot be pickled"):
            pickle.dumps(surf)
        seen.append(True)
        return jnp.sum(surf.evaluate(uv[:3]))

    jax.grad(loss)(jnp.asarray(mesh.vertices))
    assert seen


def test_energies_pickle_by_name_or_by_value():
    for name, en in jp.ENERGIES.items():
        assert pickle.loads(pickle.dumps(en)) is en, name
    user = jp.energy(user_density)
    back = pickle.loads(pickle.dumps(user))
    assert back == user
    with pytest.raises((pickle.PicklingError, AttributeError)):
        pickle.dumps(jp.energy(lambda s1, s2: s1 / s2))       # a lambda: as with any pickle


def test_an_atlas_pickles(mesh):
    atlas = jp.atlas(mesh, texture_size=128)
    back = pickle.loads(pickle.dumps(atlas))
    np.testing.assert_array_equal(back.uv, atlas.uv)
    np.testing.assert_array_equal(back.uv_faces, atlas.uv_faces)
    assert back.energy == atlas.energy and back.stats == atlas.stats
