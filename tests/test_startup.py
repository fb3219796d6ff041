"""What ``import jaxparam`` costs and sets up: no JAX until something needs it (then float64
and the persistent compilation cache, whoever imports JAX), lazy submodules, and a linear
``jaxparam flatten`` that never loads JAX (issue 17)."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import jaxparam as jp

HEAVY = ("jax", "jaxlib", "scipy.sparse", "scipy.spatial", "matplotlib", "trimesh", "equinox", "optimistix",
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


def test_importing_jaxparam_turns_on_float64_and_the_cache_for_jax_imported_after_or_before(tmp_path):
    code = ("import json, sys{first}; import jaxparam as jp; loaded = 'jax' in sys.modules;"
            "import jax, jax.numpy as jnp;"
            "print(json.dumps([loaded, str(jnp.ones(2).dtype), jax.config.jax_enable_x64,"
            " jax.config.jax_compilation_cache_dir]))")
    cache = str(tmp_path / "c")
    assert json.loads(_python(code.format(first=""), JAXPARAM_CACHE=cache)) == [
        False, "float64", True, cache]
    assert json.loads(_python(code.format(first="; import jax"), JAXPARAM_CACHE=cache)) == [
        True, "float64", True, cache]


def test_kernels_defined_before_jax_loads_work_after(tmp_path):
    # TriMesh (a pytree registered when JAX loads) and a jitted library kernel, both touched
    # before any JAX import: under jax.jit and with .lower like any jitted function.
    out = json.loads(_python(
        "import json, sys, numpy as np, jaxparam as jp;"
        "from jaxparam import combination as comb;"
        "m = jp.TriMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]]), [[0, 1, 2]]);"
        "before = 'jax' in sys.modules;"
        "import jax;"
        "s = jax.jit(lambda mm: mm.vertices.sum())(m);"
        "x = comb.scatter(np.ones((1, 2)), np.zeros((2, 2)), np.array([0]), np.array([1, 2]), n=3);"
        "low = comb.scatter.lower(np.ones((1, 2)), np.zeros((2, 2)), np.array([0]),"
        " np.array([1, 2]), n=3) is not None;"
        "print(json.dumps([before, float(s), str(x.dtype), np.asarray(x).tolist(), low,"
        " comb.scatter.__name__]))"))
    assert out == [False, 2.0, "float64", [[1, 1], [0, 0], [0, 0]], True, "scatter"]


def test_a_linear_flatten_loads_no_jax(tmp_path):
    mesh = jp.shapes.disk(6, seed=1, height=0.2)
    src = tmp_path / "d.off"
    jp.save(src, mesh)
    run = ("import json, sys; from jaxparam.cli import main;"
           "rc = main(['flatten', {src!r}, '-o', {out!r}, '-q'{more}]);"
           "print(json.dumps([rc] + [m in sys.modules for m in ('jax', 'equinox', 'optimistix')]))")
    out = tmp_path / "d.obj"
    assert json.loads(_python(run.format(src=str(src), out=str(out), more=""))) == [
        0, False, False, False]
    uv = jp.load(out).uv
    ref = jp.convex_map(mesh)                       # the JAX path, in this process
    assert np.max(np.abs(uv - np.asarray(ref))) < 1e-12
    # (tests/test_cli.py runs flatten with --energy, which loads JAX.)
