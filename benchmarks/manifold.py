"""Closed meshes of any genus (survey §9): base domain, parameterization, remesh, compression.

For each closed mesh of ``../shared/data/meshes`` and base-face count: whether
``jp.manifold_map`` succeeds, its seconds, the size of the mesh it parameterized (the input
refined so the surface edges have room), the level-3 remesh's seconds and its largest
distance to the input surface (libigl, % of the bounding-box diagonal), and the lifted
wavelet compression to 5 % of the coefficients (RMS error against the remesh, %).

Usage::

    python benchmarks/manifold.py
"""
from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "meshes"
CASES = [("decimated-knight.off", 100), ("bumpy.off", 100), ("cow.off", 100), ("bunny.off", 60),
         ("bunny.off", 100), ("bunny.off", 150), ("rocker-arm.obj", 150), ("rocker-arm.obj", 300),
         ("3holes.off", 200)]


def main() -> int:
    import jaxparam as jp

    try:
        import igl
    except ImportError:
        igl = None
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    print(f"{'mesh':>20s} {'genus':>5s} {'faces':>6s} {'base':>5s} {'result':>7s} {'map s':>7s} "
          f"{'work verts':>10s} {'remesh s':>8s} {'max dist %':>10s} {'5% RMS %':>9s}")
    for name, nb in CASES:
        mesh = jp.load(DATA / name)
        t = time.perf_counter()
        try:
            base, param = jp.manifold_map(mesh, nb)
        except jp.SolverError as exc:
            print(f"{name:>20s} {mesh.topology.genus:5d} {mesh.n_faces:6d} {nb:5d} {'failed':>7s} "
                  f"{time.perf_counter() - t:7.1f}  ({exc.stage})", flush=True)
            continue
        t_map = time.perf_counter() - t
        t = time.perf_counter()
        semi = param.remesh(3)
        X = np.asarray(semi.mesh.vertices)
        t_remesh = time.perf_counter() - t
        V = np.asarray(mesh.vertices)
        diag = np.linalg.norm(np.ptp(V, axis=0))
        dist = "-"
        if igl is not None:
            d2 = igl.point_mesh_squared_distance(X, V, mesh.faces)[0]
            dist = f"{100 * np.sqrt(d2.max()) / diag:.1e}"
        small = np.asarray(jp.wavelets.compress(semi, 0.05).mesh.vertices)
        rms = 100 * np.sqrt(np.mean(np.sum((small - X) ** 2, 1))) / diag
        print(f"{name:>20s} {mesh.topology.genus:5d} {mesh.n_faces:6d} {nb:5d} {'ok':>7s} {t_map:7.1f} "
              f"{param.mesh.n_vertices:10d} {t_remesh:8.2f} {dist:>10s} {rms:9.3f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
