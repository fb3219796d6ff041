"""Speed as users feel it (issue 17): whole processes, first calls, and compile counts.

Three columns for each job, each the median of paired runs (jaxparam and its peer one after the
other, ``--repeat`` times):

- **cold**: a fresh process with an empty compilation cache (``JAXPARAM_CACHE`` a new folder);
- **warm cache**: a fresh process whose cache the previous run filled;
- **in process**: the first and the second call inside one process, for the default JAX path
  and for ``host=True`` (NumPy weights and assembly, no tracing; what ``jaxparam flatten`` uses).

Jobs: ``jaxparam flatten MESH -o x.obj`` (shape-preserving weights, the default), with
``--weights harmonic`` (the libigl script's weights) and with ``--energy symmetric-dirichlet
--free-boundary`` (Newton: the JAX path, where the compilation cache matters) against a libigl
script that loads the mesh, maps the
boundary to a circle, solves the harmonic map and writes an OBJ with UVs; and ``import
jaxparam`` against ``import jax``.  Then the number of XLA compilations that ``convex_map``
needs over the disk meshes of ``../shared/data`` in one process (shape bucketing shares them).

Usage::

    python benchmarks/startup.py                      # camelhead, 5 paired runs
    python benchmarks/startup.py --mesh M.off --repeat 3
    python benchmarks/startup.py --heldout --skip-in-process   # + lilium refined (26k faces)
    python benchmarks/startup.py --methods --repeat 3          # every method, three columns

``--methods`` times one call of each public method at a small size in fresh processes: its
first call with an empty cache (**cold**), its first call in a second process that reuses the
cache the first one filled (**warm cache**; cold and warm run back to back, a pair a round) and
its second call in the same process (**in process**, compiled), with the whole process's wall
time and the first call's CPU seconds (all threads) beside them.
"""
from __future__ import annotations

import argparse
import os
import platform
import resource
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

IN_PROCESS_MIN = r'''
import sys, time, jaxparam as jp
mesh = jp.load(sys.argv[1])
uv = jp.convex_map(mesh, host=True)
kw = dict(init=uv, free_boundary=True, verbose=False)
t = time.perf_counter(); r = jp.minimize(mesh, "symmetric_dirichlet", **kw); first = time.perf_counter() - t
t = time.perf_counter(); jp.minimize(mesh, "symmetric_dirichlet", **kw)
print(first, time.perf_counter() - t, r.iterations)
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


#: ``--methods``: name -> (setup, call), Python run after ``import jaxparam as jp, numpy as np``
#: with ``M`` the shared meshes folder and ``P`` the points folder.
METHODS = {
    "convex_map (shape-preserving)": ("mesh = jp.load(M + '/camelhead.off')", "jp.convex_map(mesh)"),
    "convex_map host=True": ("mesh = jp.load(M + '/camelhead.off')", "jp.convex_map(mesh, host=True)"),
    "convex_map harmonic": ("mesh = jp.load(M + '/camelhead.off')",
                            "jp.convex_map(mesh, weights='harmonic')"),
    "least_squares_map": ("mesh = jp.load(M + '/camelhead.off')", "jp.least_squares_map(mesh)"),
    "minimize sd, fixed boundary": ("mesh = jp.load(M + '/camelhead.off')",
                                    "jp.minimize(mesh, 'symmetric_dirichlet', verbose=False)"),
    "minimize sd, free boundary": ("mesh = jp.load(M + '/camelhead.off')",
                                   "jp.minimize(mesh, 'symmetric_dirichlet', free_boundary=True, "
                                   "verbose=False)"),
    "meshless_map": ("pts = jp.load_points(P + '/camelhead.xyz')", "jp.meshless_map(pts)"),
    "remesh, 3 levels": ("mesh = jp.load(M + '/camelhead.off'); uv = jp.convex_map(mesh, host=True)",
                         "jp.remesh(mesh, uv, levels=3)"),
    "manifold_map": ("mesh = jp.load(M + '/decimated-knight.off')", "jp.manifold_map(mesh, 100)"),
    "atlas": ("mesh = jp.load(M + '/decimated-knight.off')", "jp.atlas(mesh)"),
}

METHOD_RUN = r'''
import json, sys, time
t0 = time.perf_counter()
import jaxparam as jp, numpy as np
M, P = sys.argv[1], sys.argv[2]
exec(sys.argv[3])
call = compile(sys.argv[4], "call", "eval")
t, c = time.perf_counter(), time.process_time()
eval(call)
first, first_cpu = time.perf_counter() - t, time.process_time() - c
exec(sys.argv[3])                      # a fresh input object (no per-object cache)
t, c = time.perf_counter(), time.process_time()
eval(call)
again, again_cpu = time.perf_counter() - t, time.process_time() - c
print(json.dumps(dict(first=first, first_cpu=first_cpu, again=again, again_cpu=again_cpu,
                      process=time.perf_counter() - t0)))
'''


def method_columns(repeat: int) -> None:
    """The ``--methods`` table: medians over ``repeat`` rounds of a cold and a warm-cache
    process of each method, back to back."""
    import json

    points = str(MESHES.parent / "points")
    print(f"\nevery method, fresh processes, median of {repeat} rounds (s); load "
          f"{os.getloadavg()[0]:.1f}")
    print(f"{'method':<32} {'cold':>7} {'warm cache':>10} {'in process':>10} {'cold CPU':>8} "
          f"{'warm CPU':>8} {'in proc. CPU':>12} {'process cold':>12} {'warm':>6}")
    for name, (setup, call) in METHODS.items():
        got = {"cold": [], "warm": []}
        for _ in range(repeat):
            cache = tempfile.mkdtemp()
            for col in ("cold", "warm"):
                out = subprocess.run([PY, "-c", METHOD_RUN, str(MESHES), points, setup, call],
                                     check=True, capture_output=True, text=True,
                                     env={**os.environ, "JAXPARAM_CACHE": cache,
                                          "JAXPARAM_PROGRESS": "0"}).stdout
                got[col].append(json.loads(out.strip().splitlines()[-1]))
        med = {col: {k: statistics.median(r[k] for r in rows) for k in rows[0]}
               for col, rows in got.items()}
        again = statistics.median([r["again"] for rows in got.values() for r in rows])
        again_cpu = statistics.median([r["again_cpu"] for rows in got.values() for r in rows])
        print(f"{name:<32} {med['cold']['first']:>7.2f} {med['warm']['first']:>10.2f} "
              f"{again:>10.3f} {med['cold']['first_cpu']:>8.2f} {med['warm']['first_cpu']:>8.2f} "
              f"{again_cpu:>12.3f} "
              f"{med['cold']['process']:>12.2f} {med['warm']['process']:>6.2f}  "
              f"(load {os.getloadavg()[0]:.1f})", flush=True)


def timed(cmd, env=None) -> tuple[float, float]:
    """``(wall seconds, CPU seconds)`` of one run of ``cmd``: the CPU time (user + system, all
    threads) is what a loaded machine inflates least."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env={**os.environ, **(env or {})})
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def heldout_mesh(folder: str) -> str:
    """lilium refined once (26,360 faces): a mesh not in ``../shared/data``, written as OFF."""
    path = f"{folder}/lilium_r1.off"
    subprocess.run([PY, "-c", "import sys, jaxparam as jp; jp.save(sys.argv[2], jp.shapes.refine("
                    "jp.load(sys.argv[1]), 1))", str(MESHES / "lilium.obj"), path], check=True)
    return path


def whole_process(mesh: str, repeat: int, out: str) -> dict:
    """Median seconds of each job, cold and warm cache, over ``repeat`` paired rounds."""
    jobs = {
        "jaxparam flatten": lambda: [JAXPARAM, "flatten", mesh, "-o", f"{out}/jp.obj"],
        "jaxparam flatten --weights harmonic": lambda: [JAXPARAM, "flatten", mesh, "-o",
                                                       f"{out}/jph.obj", "--weights", "harmonic"],
        "jaxparam flatten --energy sd --free": lambda: [
            JAXPARAM, "flatten", mesh, "-o", f"{out}/jpe.obj", "--energy", "symmetric-dirichlet",
            "--free-boundary"],
        "libigl script": lambda: [PY, "-c", IGL_SCRIPT, mesh, f"{out}/igl.obj"],
        "import jaxparam": lambda: [PY, "-c", "import jaxparam"],
        "import jax": lambda: [PY, "-c", "import jax"],
    }
    rows = {k: {"cold": [], "warm": [], "warm cpu": []} for k in jobs}
    for r in range(repeat):
        cache = tempfile.mkdtemp()
        env = {"JAXPARAM_CACHE": cache, "JAXPARAM_PROGRESS": "0"}
        for col in ("cold", "warm"):
            for k, cmd in jobs.items():
                wall, cpu = timed(cmd(), env)
                rows[k][col].append(wall)
                if col == "warm":
                    rows[k]["warm cpu"].append(cpu)
    return {k: {c: statistics.median(v) for c, v in cols.items()} for k, cols in rows.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", nargs="*", default=[str(MESHES / "camelhead.off")])
    ap.add_argument("--heldout", action="store_true",
                    help="also lilium refined once (26k faces, not in ../shared/data)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--skip-in-process", action="store_true",
                    help="only the whole-process table")
    ap.add_argument("--methods", action="store_true",
                    help="only the table of every method's cold / warm-cache / in-process call")
    ap.add_argument("--only", nargs="*", default=None,
                    help="with --methods: the methods whose name starts with one of these")
    args = ap.parse_args()
    if args.methods:
        print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
              f"python {platform.python_version()}")
        if args.only:
            for k in [k for k in METHODS if not any(k.startswith(o) for o in args.only)]:
                del METHODS[k]
        method_columns(args.repeat)
        return
    out = tempfile.mkdtemp()
    meshes = list(args.mesh) + ([heldout_mesh(out)] if args.heldout else [])
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}; python {platform.python_version()}")
    for mesh in meshes:
        med = whole_process(mesh, args.repeat, out)
        print(f"\nwhole process on {Path(mesh).name}, median of {args.repeat} paired runs (s), "
              f"load {os.getloadavg()[0]:.1f}")
        print(f"{'job':<36} {'cold':>7} {'warm cache':>11} {'warm, CPU s':>12}")
        for k, cols in med.items():
            print(f"{k:<36} {cols['cold']:>7.2f} {cols['warm']:>11.2f} {cols['warm cpu']:>12.2f}")
        for k in ("jaxparam flatten", "jaxparam flatten --weights harmonic"):
            ratio = med[k]["warm"] / med["libigl script"]["warm"]
            cpu = med[k]["warm cpu"] / med["libigl script"]["warm cpu"]
            print(f"{k} / libigl script, warm cache: {ratio:.2f} wall, {cpu:.2f} CPU "
                  "(goal <= 1.5)")
    if args.skip_in_process:
        return
    mesh = meshes[0]
    inproc = {path: subprocess.run([PY, "-c", IN_PROCESS, mesh, path], check=True,
                                   capture_output=True, text=True,
                                   env={**os.environ, "JAXPARAM_PROGRESS": "0"}).stdout.split()
              for path in ("jax", "host")}
    for path, (first, again) in inproc.items():
        print(f"convex_map in process, {path + ' path:':<10} first call {float(first):.3f} s, "
              f"second {float(again):.3f} s")
    for col in ("cold", "warm"):
        cache = tempfile.mkdtemp() if col == "cold" else cache
        first, again, its = subprocess.run(
            [PY, "-c", IN_PROCESS_MIN, mesh], check=True, capture_output=True, text=True,
            env={**os.environ, "JAXPARAM_PROGRESS": "0", "JAXPARAM_CACHE": cache}).stdout.split()
        print(f"minimize(symmetric_dirichlet, free_boundary) in process, {col} cache: first call "
              f"{float(first):.2f} s, second {float(again):.2f} s ({its} newton iterations)")
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
