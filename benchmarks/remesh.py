"""Remeshing with subdivision connectivity and wavelet compression (survey §7), timed.

Part 1: camelhead refined 0, 1 and 2 times by 1-to-4 splits, its shape-preserving circle map,
and ``jp.remesh`` at several levels: seconds of the base domain and refinement, of the point
location in the map, and of the whole call (second call; the first one compiles), peak memory.
Part 2: ``jp.wavelets.compress`` of camelhead's level-6 remesh (default, area-aware map),
lazy, lifted and butterfly wavelets: share of the data stored and the error against the
uncompressed remesh (% of the bounding-box diagonal), two ways: the RMS of the vertex moves
(``RMS err``, what the wavelet goal has been measured by) and the RMS surface distance
(``surf RMS``: :func:`jaxparam.distance.surface_distance` both ways, the larger, as
``Remesh.errors`` measures a remesh; a vertex moved along the surface does not count); the
rate-distortion picture (vertex RMS error against the fraction of coefficients kept, one curve
per wavelet) goes to ``--plot``.  With ``--compress-all`` the same at 5 % kept for every disk
mesh in ``../shared/data/meshes``, each wavelet's two errors over the lazy wavelet's.
Part 3 (``--faithful``): the default remesh (area-aware map) of every disk mesh in
``../shared/data/meshes``: seconds, and per level the Hausdorff (larger way) and RMS
distance from the input, % of the diagonal (``Remesh.errors``).  Part 4 (``--default-map``):
``jp.remesh(mesh, levels=6)`` at each ``--refine``, paired in one process: its default map
(``area_aware_map``: Newton and error-driven rounds up to 40k faces, reweighted convex maps
above), the shape-preserving convex map and (above 40k) the Newton map the default was before
session 9: seconds of the map and of the remesh, CPU seconds, level-6 Hausdorff and the load.
Part 5 (``--large``): inputs above 40k faces (shared meshes refined, one perturbed, a generated
relief), the reweighted map with and without its error-driven rounds, paired; only this part.

Usage::

    python benchmarks/remesh.py [--refine 0 1 2] [--levels 5 6 7] [--plot rd.png]
                                [--faithful] [--default-map] [--compress-all] [--large]
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


def disk_meshes(folder: Path):
    """``(path, mesh)`` for every mesh file in ``folder`` (sorted) that loads and is a disk."""
    import jaxparam as jp

    for path in sorted(folder.iterdir()):
        try:
            mesh = jp.load(path)
        except jp.MeshError:
            continue
        if mesh.topology.is_disk:
            yield path, mesh


def relief(n: int = 161, seed: int = 5):
    """A held-out disk of ``2 (n - 1)^2`` faces: a square grid lifted onto 40 narrow Gaussian
    bumps (widths 1-5 % of the side) and a fine ripple, as a scanned relief."""
    import jaxparam as jp
    g = jp.shapes.plane_grid(n, n)
    V = np.asarray(g.vertices, np.float64).copy()
    rng = np.random.default_rng(seed)
    cx, cy, w = rng.uniform(0, 1, 40), rng.uniform(0, 1, 40), rng.uniform(0.01, 0.05, 40)
    r2 = (V[:, 0, None] - cx) ** 2 + (V[:, 1, None] - cy) ** 2
    V[:, 2] = (0.08 * np.exp(-r2 / (2 * w ** 2))).sum(1) + 0.002 * np.sin(60 * V[:, 0]) * np.cos(50 * V[:, 1])
    return jp.TriMesh(V, g.faces)


def perturbed(mesh, scale: float = 0.15, seed: int = 7):
    """``mesh`` with each vertex moved along its normal by ``scale`` x the mean edge x N(0, 1)."""
    import jaxparam as jp
    V, F = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces)
    n = jp.host.vertex_normals(V, F, np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    edge = np.mean(np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1))
    return jp.TriMesh(V + scale * edge * np.random.default_rng(seed).normal(size=(len(V), 1)) * n, F)


def large_table(jp, samples: int) -> None:
    """Above 40k faces, paired in one process: ``area_aware_map(mesh)`` (the reweighted map,
    the default before session 33) against ``area_aware_map(mesh, levels=6)`` (what
    ``jp.remesh(mesh, levels=6)`` takes now: its error-driven rounds up to 200k faces), and
    the convex map: seconds of the map, the level-6 remesh's Hausdorff (% of the diagonal)."""
    from jaxparam.distance import surface_distance
    from jaxparam.remesh import area_aware_map
    folder = DATA.parent
    cases = [("camelhead x4", lambda: jp.shapes.refine(jp.load(DATA), 1)),
             ("camelhead x4 perturbed", lambda: perturbed(jp.shapes.refine(jp.load(DATA), 1))),
             ("camel_b x16", lambda: jp.shapes.refine(jp.load(folder / "camel_b.obj"), 2)),
             ("lilium x16", lambda: jp.shapes.refine(jp.load(folder / "lilium.obj"), 2)),
             ("snail x64", lambda: jp.shapes.refine(jp.load(folder / "snail.obj"), 3)),
             ("bump-domain x16", lambda: jp.shapes.refine(jp.load(folder / "bump-domain.obj"), 2)),
             ("relief (generated)", relief),
             ("camelhead x16", lambda: jp.shapes.refine(jp.load(DATA), 2))]
    print(f"\nabove 40k faces, level 6: the reweighted map alone / with its error-driven rounds / the "
          f"convex map ({samples} samples per surface): map s, L6 Hausdorff %")
    print(f"{'mesh':>24s} {'faces':>7s} {'reweighted s':>12s} {'H %':>6s} {'rounds s':>9s} {'H %':>6s} "
          f"{'convex s':>9s} {'H %':>6s} {'load':>5s}")
    for name, make in cases:
        mesh = make()
        V = np.asarray(mesh.vertices)
        row = []
        for f in (lambda: area_aware_map(mesh), lambda: area_aware_map(mesh, levels=6),
                  lambda: jp.convex_map(mesh, boundary="circle")):
            t = time.perf_counter()
            uv = np.asarray(f())
            sec = time.perf_counter() - t
            semi = jp.remesh(mesh, uv, levels=6)
            d = surface_distance(V, mesh.faces, np.asarray(semi.mesh.vertices), semi.mesh.faces,
                                 samples=samples, seed=0)
            row += [sec, 100 * d.hausdorff]
        print(f"{name:>24s} {mesh.n_faces:7d} {row[0]:12.2f} {row[1]:6.3f} {row[2]:9.2f} {row[3]:6.3f} "
              f"{row[4]:9.2f} {row[5]:6.3f} {os.getloadavg()[0]:5.1f}", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--refine", type=int, nargs="*", default=[0, 1, 2])
    ap.add_argument("--levels", type=int, nargs="*", default=[5, 6, 7])
    ap.add_argument("--plot", default=None, help="rate-distortion picture (PNG)")
    ap.add_argument("--faithful", action="store_true", help="errors of every disk mesh")
    ap.add_argument("--default-map", action="store_true", help="time the default map too")
    ap.add_argument("--samples", type=int, default=20_000, help="points per surface (errors)")
    ap.add_argument("--large", action="store_true",
                    help="above 40k faces: the reweighted map with and without its error-driven rounds")
    ap.add_argument("--compress-all", action="store_true",
                    help="5 %% compression errors over lazy's, every disk mesh")
    args = ap.parse_args()
    import jaxparam as jp
    if args.large:                                  # part 5 alone
        large_table(jp, args.samples)
        return 0
    from jaxparam.remesh import (AREA_MAP_FULL_FACES, area_aware_map, area_map_iters, base_domain,
                                 measure_errors, refine_domain)
    from jaxparam.distance import surface_distance
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

    if args.default_map:
        print(f"\njp.remesh(mesh, levels=6), paired: the default map (area-aware: Newton and error-driven "
              f"rounds up to {AREA_MAP_FULL_FACES} faces, reweighted convex maps above) against the "
              f"convex map and against Newton ({args.samples} samples per surface; load = 1-min average)")
        print(f"{'input faces':>12s} {'map':>9s} {'map s':>8s} {'remesh s':>9s} {'CPU s':>7s} "
              f"{'L6 H %':>8s} {'load':>5s}")
        for r in args.refine:
            mesh = jp.shapes.refine(base, r) if r else base
            big = mesh.n_faces > AREA_MAP_FULL_FACES          # as jp.remesh's default
            maps = {"convex": lambda m: jp.convex_map(m, boundary="circle"),
                    "default": lambda m: area_aware_map(m, levels=6)}
            if big:                                           # the session-8 default there
                maps["newton"] = lambda m: area_aware_map(m, max_iters=area_map_iters(m.n_faces))
            for name, make in maps.items():
                load, t, c = os.getloadavg()[0], time.perf_counter(), time.process_time()
                uv = np.asarray(make(mesh))
                t_map = time.perf_counter() - t
                t = time.perf_counter()
                semi = jp.remesh(mesh, uv, levels=6)
                t_re, cpu = time.perf_counter() - t, time.process_time() - c
                d = surface_distance(np.asarray(mesh.vertices), mesh.faces, np.asarray(semi.mesh.vertices),
                                     semi.mesh.faces, samples=args.samples, seed=0)
                h = 100 * max(float(d.hausdorff_ab), float(d.hausdorff_ba))
                print(f"{mesh.n_faces:12d} {name:>9s} {t_map:8.2f} {t_re:9.2f} {cpu:7.1f} {h:8.3f} "
                      f"{load:5.1f}", flush=True)

    if args.faithful:
        folder = DATA.parent
        print(f"\ndefault remesh (area-aware map), level by level: Hausdorff / RMS, % of the diagonal "
              f"({args.samples} samples per surface)")
        for path, mesh in disk_meshes(folder):
            t = time.perf_counter()
            semi = jp.remesh(mesh, levels=6, errors=False)
            sec = time.perf_counter() - t
            e = measure_errors(mesh, semi, samples=args.samples)
            cells = " ".join(f"{100 * h:.3f}/{100 * r:.4f}" for h, r in zip(e.hausdorff, e.rms))
            print(f"{path.name:>16s} {mesh.n_faces:7d} faces {sec:7.1f} s  {cells}", flush=True)

    def errors(semi, small):
        """(vertex RMS, vertex max, surface RMS) of ``small`` against ``semi``, % of the diagonal."""
        V, X = np.asarray(semi.mesh.vertices), np.asarray(small.mesh.vertices)
        e = np.linalg.norm(X - V, axis=1) / np.linalg.norm(np.ptp(V, axis=0))
        F = semi.mesh.faces
        surf = surface_distance(V, F, X, F, samples=args.samples).rms
        return 100 * np.sqrt(np.mean(e ** 2)), 100 * e.max(), 100 * surf

    if args.compress_all:
        print(f"\n5 % of the coefficients kept, level-6 default remesh: vertex RMS / surface RMS "
              f"over the lazy wavelet's ({args.samples} samples per surface)")
        for path, mesh in disk_meshes(DATA.parent):
            semi = jp.remesh(mesh, levels=6)
            errs = {w: errors(semi, jp.wavelets.compress(semi, 0.05, wavelet=w)) for w in jp.wavelets.WAVELETS}
            lazy = errs["lazy"]
            cells = " ".join(f"{w} {e[0] / lazy[0]:.3f} / " + (f"{e[2] / lazy[2]:.3f}" if lazy[2] > 1e-12 else
                                                            f"lazy 0, {w} {e[2]:.2g} %")
                             for w, e in errs.items() if w != "lazy")
            print(f"{path.name:>16s} lazy {lazy[0]:.4f} % / {lazy[2]:.4f} %  {cells}", flush=True)

    mesh = base
    semi = jp.remesh(mesh, levels=6)
    print(f"\ncompression of camelhead's level-6 remesh ({semi.mesh.n_vertices} vertices)")
    print(f"{'wavelet':>9s} {'keep':>6s} {'stored %':>9s} {'RMS err %':>10s} {'max err %':>10s} "
          f"{'/ lazy':>7s} {'surf RMS %':>11s} {'/ lazy':>7s} {'seconds':>8s}")
    keeps = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2)
    curves, surfs = {}, {}
    for wavelet in jp.wavelets.WAVELETS:
        jp.wavelets.compress(semi, 0.01, wavelet=wavelet)       # compiles
        curves[wavelet], surfs[wavelet] = [], []
        for keep in keeps:
            t = time.perf_counter()
            small = jp.wavelets.compress(semi, keep, wavelet=wavelet)
            np.asarray(small.mesh.vertices)
            sec = time.perf_counter() - t
            rms, worst, surf = errors(semi, small)
            curves[wavelet].append(rms)
            surfs[wavelet].append(surf)
            i = len(curves[wavelet]) - 1
            ratio = rms / curves["lazy"][i] if "lazy" in curves else 1.0
            sratio = surf / surfs["lazy"][i] if "lazy" in surfs and surfs["lazy"][i] > 0 else 1.0
            print(f"{wavelet:>9s} {keep:6.3f} {100 * small.stored_fraction:9.2f} "
                  f"{rms:10.4f} {worst:10.3f} {ratio:7.2f} {surf:11.4f} {sratio:7.2f} {sec:8.3f}")
    if args.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5, 3.6))
        for wavelet, rms in curves.items():
            ax.loglog([100 * k for k in keeps], rms, "o-", label=wavelet)
        ax.set_xlabel("coefficients kept (%)")
        ax.set_ylabel("RMS error (% of diagonal)")
        ax.set_title("camelhead, level-6 remesh: rate-distortion")
        ax.legend()
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        plt.close(fig)
        print(f"rate-distortion picture: {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
