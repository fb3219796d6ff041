"""What ``import jaxparam`` costs and sets up: lazy submodules, the persistent compilation cache."""
import json
import os
import subprocess
import sys

import pytest

import jaxparam as jp

HEAVY = ("scipy.sparse", "scipy.spatial", "matplotlib", "trimesh", "equinox", "optimistix",
         "jaxparam.linear", "jaxparam.points", "jaxparam.manifold", "jaxparam.optimize")


def _python(code: str, **env) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "JAX_PLATFORMS": "cpu", **env})
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1]


def test_import_loads_no_heavy_module():
    loaded = json.loads(_python(
        "import sys, json, jaxparam; print(json.dumps(sorted(m for m in %r if m in sys.modules)))"
        % (HEAVY,)))
    assert loaded == []


def test_first_use_loads_what_it_needs_and_names_stay_public():
    names = json.loads(_python(
        "import json, jaxparam as jp; import jaxparam.manifold;"
        "print(json.dumps([callable(jp.remesh), type(jp.remesh).__name__, jp.TriMesh.__name__,"
        " sorted(set(jp.__all__) - set(dir(jp)))]))"))
    # jp.remesh stays the function even after a module imported the submodule jaxparam.remesh
    assert names == [True, "function", "TriMesh", []]


def test_unknown_attribute_and_unknown_setting_are_refused():
    with pytest.raises(AttributeError, match="no attribute 'convex_mapp'"):
        jp.convex_mapp  # noqa: B018
    with pytest.raises(AttributeError, match="no setting 'progres'"):
        jp.config.progres = False


def test_a_second_process_reuses_the_compilation_cache(tmp_path):
    code = ("import jaxparam as jp; m = jp.shapes.disk(4, seed=2, height=0.3);"
            "print(jp.convex_map(m, weights='mean_value').shape)")
    cache = tmp_path / "cache"
    env = {"JAXPARAM_CACHE": str(cache), "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0"}
    _python(code, **env)
    stored = sorted(p.name for p in cache.iterdir())
    assert stored, "the first process stored no compiled kernel"
    _python(code, **env)
    assert sorted(p.name for p in cache.iterdir()) == stored   # nothing new: all reused


def test_the_cache_can_be_turned_off(tmp_path):
    off = json.loads(_python("import json, jaxparam as jp, jax;"
                             "print(json.dumps([jp.config.compile_cache,"
                             " jax.config.jax_enable_compilation_cache]))",
                             JAXPARAM_CACHE="off"))
    assert off == [None, False]
