"""Convex-combination maps against libigl, stage by stage.

Every weight kind of jaxparam against ``igl.harmonic`` (cotangent, k=1, and
uniform Laplacian) and ``igl.lscm`` on camelhead and on camelhead refined by
1-to-4 splits.  Each (mesh, method) runs in its own subprocess so its peak
memory (ru_maxrss) is its own; jaxparam runs twice in that process, the first
run compiling, the second timed with a fresh TriMesh (so no cached topology or
factorization is reused) — compile seconds are reported apart.

Usage::

    python benchmarks/linear.py                 # camelhead x1, x4, x16, x64 (1.45M faces)
    python benchmarks/linear.py --refine 0 1    # only the small ones
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
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATA = HERE.parent.parent / "shared" / "data" / "meshes" / "camelhead.off"
METHODS = ["uniform", "inverse_distance", "shape_preserving", "mean_value", "harmonic",
           "shape_preserving+host", "harmonic+host", "igl_harmonic", "igl_uniform", "igl_lscm"]


def _mesh_arrays(refine: int):
    import numpy as np

    import jaxparam as jp

    mesh = jp.shapes.refine(jp.load(os.environ.get("JAXPARAM_BENCH_MESH", DATA)), refine)
    return np.asarray(mesh.vertices), mesh.faces


def run_one(method: str, refine: int) -> dict:
    """Runs in a subprocess; returns the stage timings."""
    import numpy as np

    V, F = _mesh_arrays(refine)
    out = {"method": method, "faces": int(F.shape[0]), "vertices": int(V.shape[0])}
    if method.startswith("igl_"):
        import igl

        import jaxparam as jp

        loop = jp.topology.boundary_loops(F)[0]
        t = time.perf_counter()
        bnd = igl.boundary_loop(F)
        bc = igl.map_vertices_to_circle(V, bnd)
        if method == "igl_lscm":
            b = np.array([bnd[0], bnd[len(bnd) // 2]])
            res = igl.lscm(V, F, b, bc[[0, len(bnd) // 2]])
            uv = res[0] if isinstance(res, tuple) else res
        elif method == "igl_uniform":
            import scipy.sparse as sp
            Adj = igl.adjacency_matrix(F).astype(float)
            L = (sp.diags(np.asarray(Adj.sum(1)).ravel()) - Adj).tocsc()
            uv = igl.min_quad_with_fixed(L, np.zeros((V.shape[0], 2)), bnd, bc, pd=True)
        else:
            uv = igl.harmonic(V, F, bnd, bc, 1)
        out["total"] = time.perf_counter() - t
        uv = np.asarray(uv)
        A = jp.geometry.signed_areas(uv, F)
        area_sign = np.sign(np.sum(np.asarray(A)))
        out["flips"] = int(np.sum(np.asarray(A) * area_sign <= 0))
        del loop
    elif method.endswith("+host"):
        import jaxparam as jp

        # convex_map(host=True): NumPy weights, assembly and scatter, nothing compiled (the
        # CLI's path).  Run 1 warms the solver library; run 2, on a fresh mesh, is timed.
        kind = method[: -len("+host")]
        jp.convex_map(jp.TriMesh(V, F, validate=False), weights=kind, host=True)
        t0 = time.perf_counter()
        mesh = jp.TriMesh(V, F, validate=False)
        uv = jp.convex_map(mesh, weights=kind, host=True)
        out["total"] = time.perf_counter() - t0
        out["flips"] = jp.metrics.flips(mesh, uv)
    else:
        import jax

        import jaxparam as jp
        from jaxparam import sparse

        # Run 1 compiles.
        t = time.perf_counter()
        uv = jp.convex_map(jp.TriMesh(V, F, validate=False), weights=method)
        uv.block_until_ready()
        first = time.perf_counter() - t
        # Run 2: a fresh mesh and topology, compiled code reused, timed end to end.
        t0 = time.perf_counter()
        mesh = jp.TriMesh(V, F, validate=False)
        uv = jp.convex_map(mesh, weights=method)
        uv.block_until_ready()
        out["total"] = time.perf_counter() - t0
        # Run 3, stage by stage on another fresh mesh (nothing cached from run 2).
        stages = {}
        t = time.perf_counter()
        mesh = jp.TriMesh(V, F, validate=False)
        mesh.topology
        stages["topology"] = time.perf_counter() - t
        t = time.perf_counter()
        w, sym = jp.weights.entry_weights(mesh.vertices, mesh.topology, method)
        w.block_until_ready()
        stages["weights"] = time.perf_counter() - t
        t = time.perf_counter()
        S = jp.linear.interior_system(mesh.topology)
        stages["pattern"] = time.perf_counter() - t
        # Factorization and solve apart, on the assembled system.
        vals, rhs = jp.combination.assemble(S, w, jax.numpy.zeros((mesh.topology.boundary.size, 2)),
                                            normalize=False)
        vals = np.asarray(vals)
        t = time.perf_counter()
        fac = sparse.factorize(S.pattern, vals, symmetric=sym)
        stages["factorize"] = time.perf_counter() - t
        t = time.perf_counter()
        fac.solve(np.asarray(rhs) + 1.0)
        stages["solve"] = time.perf_counter() - t
        stages["backend"] = fac.backend
        out.update(stages)
        out["compile_overhead"] = max(0.0, first - out["total"])
        out["flips"] = jp.metrics.flips(mesh, uv)
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--refine", type=int, nargs="*", default=[0, 1, 2, 3])
    ap.add_argument("--methods", nargs="*", default=METHODS)
    ap.add_argument("--one", nargs=2, help=argparse.SUPPRESS)
    ap.add_argument("--json", help="also write the rows to this JSON file")
    ap.add_argument("--data", type=Path, default=DATA,
                    help="the base mesh to refine (default camelhead; e.g. camel_b.obj --refine 4 "
                         "for a 915k-face mesh not in ../shared)")
    args = ap.parse_args()
    os.environ["JAXPARAM_BENCH_MESH"] = str(args.data)
    if args.one:
        print(json.dumps(run_one(args.one[0], int(args.one[1]))))
        return 0
    if not args.data.exists():
        print(f"{args.data} not found: the benchmark needs ../shared/data")
        return 1
    rows = []
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}")
    hdr = (f"{'faces':>8s} {'method':18s} {'total s':>8s} {'topo':>6s} {'weights':>7s} {'factor':>7s} "
           f"{'pattern':>7s} {'solve':>6s} {'compile':>7s} {'peak MB':>8s} {'flips':>5s} {'backend':>8s}")
    print(hdr)
    for r in args.refine:
        for m in args.methods:
            proc = subprocess.run([sys.executable, __file__, "--one", m, str(r), "--data", str(args.data)],
                                  capture_output=True,
                                  text=True, timeout=1800)
            if proc.returncode != 0:
                print(f"{'?':>8s} {m:18s} failed: {proc.stderr.strip().splitlines()[-1:]}")
                continue
            row = json.loads(proc.stdout.strip().splitlines()[-1])
            rows.append(row)
            f = lambda k: f"{row[k]:.3f}" if isinstance(row.get(k), float) else "-"
            print(f"{row['faces']:8d} {m:18s} {row['total']:8.3f} {f('topology'):>6s} {f('weights'):>7s} "
                  f"{f('factorize'):>7s} {f('pattern'):>7s} {f('solve'):>6s} {f('compile_overhead'):>7s} "
                  f"{row['peak_rss_mb']:8.0f} {row['flips']:5d} {row.get('backend', '-'):>8s}", flush=True)
        # Ratios against igl.harmonic on this size.
        base = [x for x in rows if x["method"] == "igl_harmonic" and x["faces"] == rows[-1]["faces"]]
        for name in ("shape_preserving", "shape_preserving+host", "harmonic", "harmonic+host"):
            sp = [x for x in rows if x["method"] == name and x["faces"] == rows[-1]["faces"]]
            if base and sp:
                print(f"{'':8s} {name} / igl.harmonic = {sp[0]['total'] / base[0]['total']:.3f}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
