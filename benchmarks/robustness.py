"""A 2M-face mesh end to end: no NaN, no flip, and the peak memory.

A 1000 x 1000 grid over the unit square lifted by a smooth height field
(1,996,002 faces), flattened with each positive weight kind in its own
process; peak memory is that process's ru_maxrss.

Usage::

    python benchmarks/robustness.py [--n 1000] [--weights shape_preserving mean_value]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np


def run(n: int, weights: str) -> dict:
    import jaxparam as jp

    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    V = np.column_stack([u.ravel(), v.ravel(), 0.2 * np.sin(4 * u.ravel()) * np.cos(3 * v.ravel())])
    F = jp.shapes.grid_faces(n, n)
    t = time.perf_counter()
    mesh = jp.TriMesh(V, F)
    uv = np.asarray(jp.convex_map(mesh, weights=weights))
    secs = time.perf_counter() - t
    return {"faces": int(F.shape[0]), "weights": weights, "seconds": secs,
            "nan": int(np.isnan(uv).sum()), "flips": jp.metrics.flips(mesh, uv),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--weights", nargs="*", default=["uniform", "inverse_distance", "shape_preserving",
                                                    "mean_value", "harmonic"])
    ap.add_argument("--one", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(run(int(args.one[0]), args.one[1])))
        return 0
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    print(f"{'faces':>9s} {'weights':18s} {'seconds':>8s} {'nan':>5s} {'flips':>5s} {'peak MB':>8s}")
    for w in args.weights:
        p = subprocess.run([sys.executable, __file__, "--one", str(args.n), w], capture_output=True, text=True)
        if p.returncode:
            print(f"{'':9s} {w:18s} failed: {p.stderr.strip().splitlines()[-1:]}")
            continue
        r = json.loads(p.stdout.strip().splitlines()[-1])
        print(f"{r['faces']:9d} {w:18s} {r['seconds']:8.2f} {r['nan']:5d} {r['flips']:5d} {r['peak_rss_mb']:8.0f}",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
