"""Remeshing with subdivision connectivity and wavelet compression (survey §7), timed.

Part 1: camelhead refined 0, 1 and 2 times by 1-to-4 splits, its shape-preserving circle map,
and ``jp.remesh`` at several levels: seconds of the base domain and refinement, of the point
location in the map, and of the whole call (second call; the first one compiles), peak memory.
Part 2: ``jp.wavelets.compress`` of camelhead's level-6 remesh, lazy and lifted wavelets:
share of the data stored and the error against the uncompressed remesh (% of the
bounding-box diagonal).

Usage::

    python benchmarks/remesh.py [--refine 0 1 2] [--levels 5 6 7]
"""
from __future__ import annotations

import argparse
import os
import platform
import resource
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "meshes" / "camelhead.off"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--refine", type=int, nargs="*", default=[0, 1, 2])
    ap.add_argument("--levels", type=int, nargs="*", default=[5, 6, 7])
    args = ap.parse_args()
    import jaxparam as jp
    from jaxparam.remesh import base_domain, refine_domain
    from jaxparam.triangles import locate

    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    print(f"{'input faces':>12s} {'levels':>6s} {'remesh faces':>12s} {'refine s':>9s} {'locate s':>9s} "
          f"{'remesh s':>9s} {'max |x - surface|':>18s} {'peak MB':>8s}")
    base = jp.load(DATA)
    for r in args.refine:
        mesh = jp.shapes.refine(base, r) if r else base
        uv = np.asarray(jp.convex_map(mesh))
        loop = mesh.topology.boundary_loops[0]
        for levels in args.levels:
            jp.remesh(mesh, uv, levels=levels)                    # compiles
            t = time.perf_counter()
            uv0, F0, s0, curve = base_domain(uv, loop, 6)
            uvj, H = refine_domain(uv0, F0, s0, curve, levels)
            t_refine = time.perf_counter() - t
            t = time.perf_counter()
            face, bary = locate(uv, mesh.faces, uvj)
            t_locate = time.perf_counter() - t
            t = time.perf_counter()
            semi = jp.remesh(mesh, uv, levels=levels)
            np.asarray(semi.mesh.vertices)
            t_all = time.perf_counter() - t
            # Each vertex against the face it was lifted from: distance to that face's plane.
            V = np.asarray(mesh.vertices)
            X = np.asarray(semi.mesh.vertices)
            P = V[mesh.faces[face]]
            n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            off = np.abs(np.sum((X - P[:, 0]) * n, 1)).max()
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            print(f"{mesh.n_faces:12d} {levels:6d} {semi.mesh.n_faces:12d} {t_refine:9.3f} {t_locate:9.3f} "
                  f"{t_all:9.3f} {off:18.1e} {peak:8.0f}", flush=True)

    mesh = base
    semi = jp.remesh(mesh, jp.convex_map(mesh), levels=6)
    V = np.asarray(semi.mesh.vertices)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    print(f"\ncompression of camelhead's level-6 remesh ({semi.mesh.n_vertices} vertices)")
    print(f"{'wavelet':>8s} {'keep':>6s} {'stored %':>9s} {'RMS err %':>10s} {'max err %':>10s} {'seconds':>8s}")
    for wavelet in ("lazy", "lifted"):
        jp.wavelets.compress(semi, 0.01, wavelet=wavelet)       # compiles
        for keep in (0.01, 0.02, 0.05, 0.1, 0.2):
            t = time.perf_counter()
            small = jp.wavelets.compress(semi, keep, wavelet=wavelet)
            X = np.asarray(small.mesh.vertices)
            sec = time.perf_counter() - t
            e = np.linalg.norm(X - V, axis=1) / diag
            print(f"{wavelet:>8s} {keep:6.2f} {100 * small.stored_fraction:9.2f} "
                  f"{100 * np.sqrt(np.mean(e ** 2)):10.3f} {100 * e.max():10.3f} {sec:8.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
