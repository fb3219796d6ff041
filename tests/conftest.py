"""Shared fixtures: x64 and rank-promotion errors, tiny generated meshes, the shared data folder."""
import os
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxparam as jp  # noqa: E402

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
if "JAXPARAM_DATA" in os.environ:
    DATA = Path(os.environ["JAXPARAM_DATA"])


def data_path(*parts) -> Path:
    """Path into ../shared/data; skips the test with a reason when the folder is absent."""
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"test data not found at {p} (../shared/data is absent)")
    return p


@pytest.fixture(scope="session")
def grid_mesh():
    return jp.shapes.graph_surface(12)


@pytest.fixture(scope="session")
def disk_mesh():
    return jp.shapes.disk(5, seed=1, height=0.3)


@pytest.fixture(scope="session")
def planar_mesh():
    return jp.shapes.plane_grid(9, 9, jitter=0.3, seed=3, tilt=True)


@pytest.fixture(scope="session")
def single_triangle():
    return jp.TriMesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))


# Closed meshes' maps, each made once for the tests that only read them (a manifold_map takes
# 3-8 s on the 2-core box; session 29).
@pytest.fixture(scope="session")
def torus_map():
    """``(mesh, base, param)``: torus(32, 16) over 40 base faces by the default route (MAPS)."""
    mesh = jp.shapes.torus(32, 16)
    return (mesh, *jp.manifold_map(mesh, 40, verbose=False))


@pytest.fixture(scope="session")
def plate_map():
    """``(mesh, base, param)``: test_manifold_maps.plate(2), genus 2, at its fewest 38 base faces."""
    from test_manifold_maps import plate
    mesh = plate(2)
    return (mesh, *jp.manifold_map(mesh, 38, verbose=False))


@pytest.fixture(scope="session")
def torus_paths_map():
    """``(mesh, base, param)``: torus(40, 20) over 40 base faces by ``method="paths"``, the
    route whose charts tile the base triangles and are re-solved by ``with_vertices``."""
    mesh = jp.shapes.torus(40, 20)
    return (mesh, *jp.manifold_map(mesh, 40, method="paths"))


def pytest_collection_modifyitems(config, items):
    """The notebooks first (`make test`: about 3 of the suite's minutes, in one file): under
    pytest-xdist's hand-out by file one process starts them while the other takes the rest,
    instead of one process running them alone at the end."""
    items.sort(key=lambda item: item.get_closest_marker("notebook") is None)   # a stable sort
