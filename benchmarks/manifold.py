"""Closed meshes of any genus (survey §9): success, seconds per stage, fidelity, Fig. 26.

Tables printed:

1. **Success over base-face counts**: every closed mesh of ``../shared/data/meshes`` at
   ``base_faces`` 50, 100, 200, 400 with defaults (``method="maps"``): whether
   ``jp.manifold_map`` succeeds, its seconds, the level-4 remesh's seconds, Hausdorff and
   RMS both ways (``jp.distance.surface_distance``, % of the bounding-box diagonal), the
   worst area distortion, the turned-over pieces of the map (``flipped``), the faces whose
   straight drawing ``face_uv`` is turned over (``drawn``) and the input vertices off their
   place in the base domain (``misplaced``).  ``--paths`` adds the old path-tracing route beside it.
2. **Scaling**: bunny refined (midpoint 1-to-4 splits) to about 10k, 30k, 100k (and 400k
   with ``--big``) faces, to 100 base faces at level 4: seconds per stage.
3. **Fig. 26**: about 100 base faces, level 3, lifted wavelets keeping 2 % of the input's
   vertex data (``3 n`` numbers): the error of the compressed remesh.
4. **MeshLab's isoparametrization** (``pymeshlab``, a benchmark peer only) on the same
   meshes where it installs, paired with ours: seconds, success, faces, error, load.

Usage::

    python benchmarks/manifold.py [--paths] [--big] [--quick] [--meshlab] [--scaling]
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "meshes"
CLOSED = ["bunny.off", "cow.off", "3holes.off", "decimated-knight.off", "rocker-arm.obj", "bumpy.off"]


def _dist(jp, A, B, samples=20_000):
    d = jp.distance.surface_distance(np.asarray(A.vertices), A.faces, np.asarray(B.vertices), B.faces,
                                     samples=samples)
    return d


def success_table(jp, method: str, counts=(50, 100, 200, 400), face_grid: int = 0) -> None:
    """``face_grid``: also a barycentric grid of step ``1/face_grid`` on every face of both
    meshes in the distances (``surface_distance``'s), which finds a large face's farthest
    point where the 20,000 random samples miss it."""
    from jaxparam.manifold import fewest_faces, fidelity
    print(f"\n## success over base-face counts (method={method!r}, level 4, face grid {face_grid})")
    print(f"{'mesh':>20s} {'genus':>5s} {'faces':>6s} {'base':>5s} {'result':>8s} {'map s':>6s} "
          f"{'remesh s':>8s} {'H %':>7s} {'H in %':>7s} {'H out %':>7s} {'RMS in %':>8s} {'RMS out %':>9s} "
          f"{'area':>6s} {'flipped':>7s} {'drawn':>5s} {'misplaced':>9s}")
    ok = total = 0
    for name in CLOSED:
        mesh = jp.load(DATA / name)
        least = fewest_faces(mesh.topology.genus)
        for nb in counts:
            nb = max(nb, least)                   # genus 3 allows 52 base faces and up
            if nb >= mesh.n_faces:
                continue
            total += 1
            t = time.perf_counter()
            try:
                base, param = jp.manifold_map(mesh, nb, method=method, verbose=False)
            except jp.SolverError as exc:
                print(f"{name:>20s} {mesh.topology.genus:5d} {mesh.n_faces:6d} {nb:5d} {'failed':>8s} "
                      f"{time.perf_counter() - t:6.1f}  ({exc.stage})", flush=True)
                continue
            t_map = time.perf_counter() - t
            t = time.perf_counter()
            semi = param.remesh(4)
            t_rem = time.perf_counter() - t
            r = fidelity(param, semi, mesh, samples=20_000, face_grid=face_grid)
            ok += 1
            print(f"{name:>20s} {mesh.topology.genus:5d} {mesh.n_faces:6d} {nb:5d} {'ok':>8s} {t_map:6.1f} "
                  f"{t_rem:8.1f} {100 * r.hausdorff:7.3f} {100 * r.hausdorff_in:7.3f} {100 * r.hausdorff_out:7.3f} "
                  f"{100 * r.rms_in:8.4f} {100 * r.rms_out:9.4f} {r.area_distortion:6.1f} "
                  f"{r.flipped:7d} {r.drawn_flipped:5d} {r.misplaced:9d}", flush=True)
    print(f"success: {ok}/{total}")


def scaling_table(jp, big: bool) -> None:
    from jaxparam.subdivision import midpoint_refine
    print("\n## scaling: bunny refined, 100 base faces, level 4 (wall seconds; CPU seconds of "
          "this process beside them, which a loaded machine does not inflate)")
    print(f"{'faces':>8s} {'map s':>7s} {'map cpu':>7s} {'remesh s':>8s} {'rem cpu':>7s} {'total s':>8s} {'total cpu':>9s} "
          f"{'load':>5s}")
    mesh = jp.load(DATA / "bunny.off")
    V, F = np.asarray(mesh.vertices), mesh.faces
    sizes = [10_000, 30_000, 100_000] + ([400_000] if big else [])
    for target in sizes:
        W, G = V, F
        while G.shape[0] * 4 <= target * 1.3:
            W, G = midpoint_refine(W, G)
        if G.shape[0] < 0.6 * target:          # bunny is 7k: 1 split -> 28k, 2 -> 111k
            W, G = midpoint_refine(W, G)
        m = jp.TriMesh(W, G)
        load = _load()
        t, c = time.perf_counter(), time.process_time()
        base, param = jp.manifold_map(m, 100, verbose=False)
        t_map, c_map = time.perf_counter() - t, time.process_time() - c
        t, c = time.perf_counter(), time.process_time()
        param.remesh(4)
        t_rem, c_rem = time.perf_counter() - t, time.process_time() - c
        print(f"{m.n_faces:8d} {t_map:7.1f} {c_map:7.1f} {t_rem:8.1f} {c_rem:7.1f} {t_map + t_rem:8.1f} "
              f"{c_map + c_rem:9.1f} {load:>5s}", flush=True)


def relax_table(jp, extra=()) -> None:
    """Paired, same process: level 4 at 100 base faces without and with the relaxation of the
    samples across base edges (``remesh(4, relax=False)`` / the default)."""
    from jaxparam.manifold import fidelity
    print("\n## relaxing the samples across base edges: level 4, 100 base faces, Hausdorff / RMS "
          "both ways, % of the diagonal (remesh CPU seconds)")
    print(f"{'mesh':>26s} {'faces':>6s} {'H plain':>8s} {'H relaxed':>9s} {'RMS plain':>9s} "
          f"{'RMS relaxed':>11s} {'cpu plain':>9s} {'cpu relaxed':>11s} {'load':>5s}")
    for path in [DATA / n for n in CLOSED] + [Path(e) for e in extra]:
        mesh = jp.load(path)
        base, param = jp.manifold_map(mesh, 100, verbose=False)
        row = []
        for relax in (False, None):                 # None: the default (guarded, closest kept)
            c = time.process_time()
            semi = param.remesh(4, relax=relax)
            row.append((fidelity(param, semi, mesh, samples=20_000), time.process_time() - c))
        (a, ca), (b, cb) = row
        print(f"{path.name:>26s} {mesh.n_faces:6d} {100 * a.hausdorff:8.3f} {100 * b.hausdorff:9.3f} "
              f"{100 * a.rms:9.4f} {100 * b.rms:11.4f} {ca:9.1f} {cb:11.1f} {_load():>5s}", flush=True)


def fig26(jp) -> None:
    print("\n## Fig. 26: ~100 base faces, level 3, wavelets keeping 2 % of the input's vertex data")
    print(f"{'mesh':>20s} {'kept coeffs':>11s} {'of input %':>10s} {'H %':>7s} {'RMS %':>7s} {'H remesh %':>10s}")
    for name in CLOSED:
        mesh = jp.load(DATA / name)
        nb = 100 if mesh.n_faces > 400 else 40
        base, param = jp.manifold_map(mesh, nb, verbose=False)
        semi = param.remesh(3)
        budget = 0.02 * mesh.n_vertices                      # coefficient vectors (3 numbers each)
        n_coeffs = semi.mesh.n_vertices - base.n_vertices
        keep = max(budget - base.n_vertices, 0) / max(n_coeffs, 1)
        small = jp.wavelets.compress(semi, keep)
        d = _dist(jp, mesh, small.mesh)
        d0 = _dist(jp, mesh, semi.mesh)
        kept = int(round(keep * n_coeffs)) + base.n_vertices
        print(f"{name:>20s} {kept:11d} {100 * kept / mesh.n_vertices:10.2f} {100 * d.hausdorff:7.3f} "
              f"{100 * d.rms:7.4f} {100 * d0.hausdorff:10.3f}", flush=True)


def _load() -> str:
    """The 1-minute load average (the box is shared: seconds inflate with it)."""
    return f"{os.getloadavg()[0]:.1f}" if hasattr(os, "getloadavg") else "-"


def meshlab(jp, names=CLOSED, base=100, levels=4, samplingrate=10, timeout=600) -> None:
    """MeshLab's isoparametrization (Pietroni et al.; ``pymeshlab``, a peer here only) beside
    ``jp.manifold_map`` on the same meshes, paired (ours, then MeshLab, back to back):
    abstract domain of ``base`` +- 10 % faces (``targetabstractmin/maxfacenum``), remeshed
    with ``samplingrate`` (MeshLab's default 10; 16 gave 72.9k faces on bunny, 3x our
    level 4's 25.6k, and the faces grow as its square, so 10 should give about 28k).
    MeshLab runs in a child process (it can take minutes, or crash), stopped after
    ``timeout`` seconds."""
    print(f"\n## MeshLab isoparametrization (pymeshlab, peer) vs jaxparam, ~{base} base faces, "
          f"level {levels} / samplingrate {samplingrate}")
    try:
        import pymeshlab  # noqa: F401
    except ImportError:
        print("pymeshlab is not installed (pip install pymeshlab): skipped")
        return
    import subprocess
    import sys
    import tempfile
    print(f"{'mesh':>20s} {'who':>9s} {'result':>8s} {'seconds':>8s} {'faces':>7s} {'H %':>7s} {'RMS %':>7s} "
          f"{'load':>5s}")
    for name in names:
        mesh = jp.load(DATA / name)
        load = _load()
        t = time.perf_counter()
        base_mesh, param = jp.manifold_map(mesh, max(base, 52), verbose=False)
        semi = param.remesh(levels)
        sec = time.perf_counter() - t
        d = _dist(jp, mesh, semi.mesh)
        print(f"{name:>20s} {'jaxparam':>9s} {'ok':>8s} {sec:8.1f} {semi.mesh.n_faces:7d} {100 * d.hausdorff:7.3f} "
              f"{100 * d.rms:7.4f} {load:>5s}", flush=True)
        load = _load()
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "iso.npz"
            code = (
                "import sys, time, numpy as np, pymeshlab\n"
                "ms = pymeshlab.MeshSet(); ms.load_new_mesh(sys.argv[1]); t = time.perf_counter()\n"
                f"ms.compute_iso_parametrization(targetabstractminfacenum={int(0.9 * base)}, "
                f"targetabstractmaxfacenum={int(1.1 * base)})\n"
                f"ms.generate_iso_parametrization_remeshing(samplingrate={samplingrate})\n"
                "m = ms.current_mesh()\n"
                "np.savez(sys.argv[2], V=m.vertex_matrix(), F=m.face_matrix(), t=time.perf_counter() - t)\n")
            t = time.perf_counter()
            try:
                run = subprocess.run([sys.executable, "-c", code, str(DATA / name), str(out)],
                                     capture_output=True, text=True, timeout=timeout)
                res = "ok" if run.returncode == 0 and out.exists() else "failed"
                why = (run.stderr.strip().splitlines() or [""])[-1][:60] if res != "ok" else ""
            except subprocess.TimeoutExpired:
                res, why = "timeout", f"> {timeout} s"
            sec = time.perf_counter() - t
            if res == "ok":
                z = np.load(out)
                d = jp.distance.surface_distance(np.asarray(mesh.vertices), mesh.faces, z["V"], z["F"],
                                                 samples=20_000)
                print(f"{name:>20s} {'MeshLab':>9s} {res:>8s} {float(z['t']):8.1f} {z['F'].shape[0]:7d} "
                      f"{100 * d.hausdorff:7.3f} {100 * d.rms:7.4f} {load:>5s}", flush=True)
            else:
                print(f"{name:>20s} {'MeshLab':>9s} {res:>8s} {sec:8.1f} {'-':>7s} {'-':>7s} {'-':>7s} {load:>5s}  "
                      f"{why}", flush=True)


def main() -> int:
    import jaxparam as jp

    ap = argparse.ArgumentParser()
    ap.add_argument("--paths", action="store_true", help="also the path-tracing route")
    ap.add_argument("--big", action="store_true", help="add 400k faces to the scaling table")
    ap.add_argument("--quick", action="store_true", help="only the success table at 100 base faces")
    ap.add_argument("--meshlab", action="store_true", help="only the MeshLab isoparametrization comparison")
    ap.add_argument("--scaling", action="store_true", help="only the scaling table")
    ap.add_argument("--face-grid", type=int, default=0, metavar="G",
                    help="success table: add a grid of step 1/G on every face to the distances")
    ap.add_argument("--relax", nargs="*", metavar="MESH", default=None,
                    help="only the relaxation before/after table (extra meshes may follow)")
    a = ap.parse_args()
    jp.config.progress = False                    # tables only (the remesh's pull-back has a bar)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"load {_load()}")
    if a.meshlab:
        meshlab(jp)
        return 0
    if a.scaling:
        scaling_table(jp, a.big)
        return 0
    if a.relax is not None:
        relax_table(jp, a.relax)
        return 0
    success_table(jp, "maps", (100,) if a.quick else (50, 100, 200, 400), a.face_grid)
    if a.quick:
        return 0
    if a.paths:
        success_table(jp, "paths", face_grid=a.face_grid)
    scaling_table(jp, a.big)
    fig26(jp)
    meshlab(jp)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
