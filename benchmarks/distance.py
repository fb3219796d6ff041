"""Exact point-to-mesh distances: jaxparam.distance against libigl's AABB tree, paired.

Every report's "how far" (remesh errors, manifold fidelity, the scans' tests) is
``jaxparam.distance.point_triangle_distance``.  For each mesh: ``--samples`` area-weighted
points on a copy of it moved by 0.1 % of its diagonal along the vertex normals (the query
a surface distance makes), then jaxparam's numpy search (``compiled=False``), jaxparam's
default (the nearest faces from ``point-cloud-utils`` when the ``fast`` extra is installed)
and ``igl.point_mesh_squared_distance`` on the same points, in turn, ``--repeats`` rounds;
the medians, the ratios to libigl and the largest difference of the distances from
libigl's (relative to the diagonal).  Meshes: camelhead and cow from
``../shared/data``; generated slivers (a surface of revolution of 2000 x 5 and 5000 x 2
quads: aspect 640 and 4000) and camelhead scaled 1000 : 1 : 0.01.

Usage::

    python benchmarks/distance.py [--samples 50000] [--repeats 3]
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

DATA = Path(os.environ.get("JAXPARAM_DATA", Path(__file__).resolve().parent.parent.parent / "shared" / "data"))


def meshes():
    import jaxparam as jp

    out = {}
    for name in ("camelhead.off", "cow.off"):
        path = DATA / "meshes" / name
        if path.exists():
            m = jp.load(path)
            out[name.split(".")[0]] = (np.asarray(m.vertices), np.asarray(m.faces))
    for around, along in ((2000, 5), (5000, 2)):
        m = jp.shapes.revolution(around, along)
        out[f"lathe {around}x{along}"] = (np.asarray(m.vertices), np.asarray(m.faces))
    if "camelhead" in out:
        V, F = out["camelhead"]
        out["camelhead 1000:1:0.01"] = (V * [1e3, 1, 1e-2], F)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=50_000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    import igl

    from jaxparam.distance import bounding_diagonal, point_triangle_distance, sample_surface
    from jaxparam.host import vertex_normals

    from jaxparam.distance import compiled_nearest_faces

    fast = compiled_nearest_faces(np.zeros((1, 3)), np.eye(3), np.array([[0, 1, 2]])) is not None
    print(f"default search: {'point-cloud-utils (fast extra)' if fast else 'numpy (no fast extra)'}")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"{args.samples} samples + the vertices of a copy moved 0.1 % of the diagonal; "
          f"medians of {args.repeats} pairs")
    print(f"{'mesh':>24s} {'faces':>8s} {'numpy s':>8s} {'default s':>9s} {'igl s':>8s} "
          f"{'numpy/igl':>9s} {'default/igl':>11s} {'max |diff|':>11s}")
    for name, (V, F) in meshes().items():
        diag = bounding_diagonal(V)
        W = V + 1e-3 * diag * vertex_normals(V, F)
        P = np.concatenate([sample_surface(W, F, args.samples, seed=0)[0], W])
        tn, tj, ti = [], [], []
        for _ in range(args.repeats):
            t = time.perf_counter()
            dn, _, _ = point_triangle_distance(P, V, F, compiled=False)
            tn.append(time.perf_counter() - t)
            t = time.perf_counter()
            d, _, _ = point_triangle_distance(P, V, F)
            tj.append(time.perf_counter() - t)
            t = time.perf_counter()
            d2 = igl.point_mesh_squared_distance(P, V, F.astype(np.int64))[0]
            ti.append(time.perf_counter() - t)
        n, a, b = statistics.median(tn), statistics.median(tj), statistics.median(ti)
        diff = float(max(np.abs(d - np.sqrt(d2)).max(), np.abs(dn - np.sqrt(d2)).max())) / diag
        print(f"{name:>24s} {len(F):8d} {n:8.3f} {a:9.3f} {b:8.3f} {n / b:9.2f} {a / b:11.2f} "
              f"{diff:11.2e}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
