"""Speed as users feel it (issue 17): whole processes, first calls, and compile counts.

Three columns for each job, each the median of paired runs (jaxparam and its peer one after the
other, ``--repeat`` times):

- **cold**: a fresh process with an empty compilation cache (``JAXPARAM_CACHE`` a new folder);
- **warm cache**: a fresh process whose cache the previous run filled;
- **in process**: the first and the second call inside one process, for the default JAX path
  and for ``host=True`` (NumPy weights and assembly, no tracing; what ``jaxparam flatten`` uses).

Jobs: ``jaxparam flatten MESH -o x.obj`` against a libigl script that loads the mesh, maps the
boundary to a circle, solves the harmonic map and writes an OBJ with UVs; and ``import
jaxparam`` against ``import jax``.  Then the number of XLA compilations that ``convex_map``
needs over the disk meshes of ``../shared/data`` in one process (shape bucketing shares them).

Usage::

    python benchmarks/startup.py                      # camelhead, 5 paired runs
    python benchmarks/startup.py --mesh M.off --repeat 3
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
MESHES = HERE.parent.parent / "shared" / "data" / "meshes"
PY = sys.executable
JAXPARAM = str(Path(PY).with_name("jaxparam"))

IGL_SCRIPT = r'''
import sys, igl, numpy as np
V, F = igl.read_triangle_mesh(sys.argv[1])
b = igl.boundary_loop(F)
uv = igl.harmonic(V, F, b, igl.map_vertices_to_circle(V, b), 1)
with open(sys.argv[2], "w") as f:
    np.savetxt(f, V, fmt="v %.17g %.17g %.17g")
    np.savetxt(f, uv, fmt="vt %.17g %.17g")
    np.savetxt(f, np.repeat(F + 1, 2, axis=1), fmt="f %d/%d %d/%d %d/%d")
'''

IN_PROCESS = r'''
import sys, time, jaxparam as jp
host = sys.argv[2] == "host"
mesh = jp.load(sys.argv[1])
t = time.perf_counter(); jp.convex_map(mesh, host=host); first = time.perf_counter() - t
mesh = jp.load(sys.argv[1])
t = time.perf_counter(); jp.convex_map(mesh, host=host); print(first, time.perf_counter() - t)
'''

COMPILES = r'''
import sys, jax, jaxparam as jp
count = [0]
jax.monitoring.register_event_duration_secs_listener(
    lambda name, secs, **kw: count.__setitem__(0, count[0] + (name == "/jax/core/compile/backend_compile_duration")))
for path in sys.argv[1:]:
    mesh = jp.load(path)
    before = count[0]
    jp.convex_map(mesh, host=True)
    host = count[0] - before
    before = count[0]
    jp.convex_map(mesh)
    print(f"{path.rsplit(chr(47), 1)[-1]:<18} {mesh.faces.shape[0]:>8} {count[0] - before:>9} {host:>9}")
'''


def timed(cmd, env=None) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env={**os.environ, **(env or {})})
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default=str(MESHES / "camelhead.off"))
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    out = tempfile.mkdtemp()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}; python {platform.python_version()}")
    rows = {"jaxparam flatten": {"cold": [], "warm": []}, "libigl script": {"cold": [], "warm": []},
            "import jaxparam": {"cold": [], "warm": []}, "import jax": {"cold": [], "warm": []}}
    for r in range(args.repeat):
        cache = tempfile.mkdtemp()
        env = {"JAXPARAM_CACHE": cache, "JAXPARAM_PROGRESS": "0"}
        for col in ("cold", "warm"):
            rows["jaxparam flatten"][col].append(
                timed([JAXPARAM, "flatten", args.mesh, "-o", f"{out}/jp.obj"], env))
            rows["libigl script"][col].append(
                timed([PY, "-c", IGL_SCRIPT, args.mesh, f"{out}/igl.obj"]))
            rows["import jaxparam"][col].append(timed([PY, "-c", "import jaxparam"], env))
            rows["import jax"][col].append(timed([PY, "-c", "import jax"]))
    inproc = {path: subprocess.run([PY, "-c", IN_PROCESS, args.mesh, path], check=True,
                                   capture_output=True, text=True,
                                   env={**os.environ, "JAXPARAM_PROGRESS": "0"}).stdout.split()
              for path in ("jax", "host")}
    med = {k: {c: statistics.median(v) for c, v in cols.items()} for k, cols in rows.items()}
    print(f"\nwhole process on {Path(args.mesh).name}, median of {args.repeat} paired runs (s)")
    print(f"{'job':<18} {'cold':>7} {'warm cache':>11}")
    for k, cols in med.items():
        print(f"{k:<18} {cols['cold']:>7.2f} {cols['warm']:>11.2f}")
    ratio = med["jaxparam flatten"]["warm"] / med["libigl script"]["warm"]
    print(f"flatten / libigl script, warm cache: {ratio:.2f} (goal <= 1.5)")
    for path, (first, again) in inproc.items():
        print(f"convex_map in process, {path + ' path:':<10} first call {float(first):.3f} s, "
              f"second {float(again):.3f} s")
    disks = [str(MESHES / n) for n in ("camelhead.off", "camel_b.obj", "lilium.obj", "snail.obj",
                                        "bump-domain.obj", "grid.off", "planexy.off", "halftunnel.off")
             if (MESHES / n).exists()]
    print("\nXLA compilations of convex_map, one process, meshes in this order "
          "(host: host=True, the CLI's path, run first on each mesh)")
    print(f"{'mesh':<18} {'faces':>8} {'jax path':>9} {'host':>9}")
    print(subprocess.run([PY, "-c", COMPILES, *disks], capture_output=True, text=True,
                         env={**os.environ, "JAXPARAM_CACHE": "off", "JAXPARAM_PROGRESS": "0"}
                         ).stdout.rstrip())


if __name__ == "__main__":
    main()
