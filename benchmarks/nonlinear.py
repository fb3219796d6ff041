"""Symmetric Dirichlet with a free boundary: jaxparam's solvers against libigl's SLIM.

From the same Tutte start (uniform weights on a circle, rescaled to the 3D
area), runs SLIM (``igl.slim_precompute``/``igl.slim_solve``, 100 iterations)
and jaxparam's ``newton`` and ``lbfgs``; reports energy against wall-clock,
the time to come within 1% of SLIM's 100-iteration energy, flips and
boundary overlaps.  MIPS and the angle energy are run against SLIM's
CONFORMAL (= MIPS).  Every energy is evaluated by jaxparam's own formula
(area-weighted mean density, isometry = 4 for symmetric Dirichlet).
JIT compilation is timed apart: each jaxparam run is done twice and the
second is reported.

Usage::

    python benchmarks/nonlinear.py                  # camelhead
    python benchmarks/nonlinear.py --refine 0 1 2   # and refined (363k faces at 2)
    python benchmarks/nonlinear.py --compiles       # XLA compiles of minimize, shared meshes

``--compiles`` counts XLA backend compilations (JAX's monitoring events) of a 2-iteration
free-boundary ``newton`` run on every open mesh of ``../shared/data/meshes`` in one process
(the persistent cache is turned off, so cache hits do not hide compiles; ``JAXPARAM_BUCKETS=0``
shows the figures without shape buckets).
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

import jaxparam as jp

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes" / "camelhead.off"


def slim_run(mesh, uv0, energy_type, iters):
    import igl

    V = np.asfortranarray(np.asarray(mesh.vertices))
    F = np.asfortranarray(mesh.faces.astype(np.int32))
    t0 = time.perf_counter()
    data = igl.slim_precompute(V, F, np.asfortranarray(uv0), energy_type,
                               np.zeros(0, np.int32), np.zeros((0, 2), order="F"), 0.0)
    times, uvs = [time.perf_counter() - t0], [uv0]
    for _ in range(iters):
        uv = np.asarray(igl.slim_solve(data, 1))
        times.append(time.perf_counter() - t0)
        uvs.append(uv[:, :2].copy())
    return times, uvs


def ours(mesh, uv0, energy, solver, iters, secs, energy_rtol=1e-12):
    kw = dict(init=uv0, free_boundary=True, solver=solver, max_iters=iters, verbose=False,
              max_seconds=secs, energy_rtol=energy_rtol)
    t = time.perf_counter()
    jp.minimize(mesh, energy, **{**kw, "max_iters": 2})
    first = time.perf_counter() - t
    # The timed run builds its Hessian pattern (and PARDISO's analysis) again, as SLIM's time
    # includes its precomputation: only compiled kernels are reused.
    jp.optimize.problem.hessian_pattern.cache_clear()
    t = time.perf_counter()
    res = jp.minimize(mesh, energy, **kw)
    total = time.perf_counter() - t
    return res, total, first


def perturbed(mesh):
    """``mesh`` sheared (x += 0.4 y) with seeded Gaussian noise of 0.1 % of its bounding-box
    diagonal per axis on every vertex (a held-out mesh no one has tuned to)."""
    V = np.array(mesh.vertices, np.float64)
    V[:, 0] += 0.4 * V[:, 1]
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    V += np.random.default_rng(0).normal(scale=1e-3 * diag, size=V.shape)
    return jp.TriMesh(V, mesh.faces)


def first_time_within(times, values, target, rel=0.01):
    for t, v in zip(times, values):
        if v <= target * (1 + rel):
            return t
    return float("nan")


def compile_counts() -> int:
    """The ``--compiles`` table: compiles and compile seconds of each mesh's minimize."""
    import jax
    import jax.monitoring

    ev = {"n": 0, "s": 0.0}

    def listen(name, secs, **_):
        if name == "/jax/core/compile/backend_compile_duration":
            ev["n"] += 1
            ev["s"] += secs

    jax.monitoring.register_event_duration_secs_listener(listen)
    print(f"buckets {jp.config.buckets}, load {os.getloadavg()[0]:.1f}")
    print(f"{'mesh':14s} {'faces':>7s} {'compiles':>8s} {'compile s':>9s} {'wall s':>7s}")
    total = [0, 0.0]
    for path in sorted(DATA.parent.iterdir()):
        try:
            mesh = jp.load(path)
            uv0 = np.asarray(jp.convex_map(mesh))
        except jp.errors.JaxparamError:      # closed or non-manifold: not a disk
            continue
        n0, s0, t0 = ev["n"], ev["s"], time.perf_counter()
        jp.minimize(mesh, "symmetric_dirichlet", init=uv0, free_boundary=True, max_iters=2,
                    verbose=False)
        n, s = ev["n"] - n0, ev["s"] - s0
        total[0] += n
        total[1] += s
        print(f"{path.stem:14s} {mesh.n_faces:7d} {n:8d} {s:9.2f} {time.perf_counter() - t0:7.2f}",
              flush=True)
    print(f"{'total':14s} {'':7s} {total[0]:8d} {total[1]:9.2f}  (load {os.getloadavg()[0]:.1f})")
    return 0


def main() -> int:
    import sys

    if "--compiles" in sys.argv:
        jp.config.compile_cache = None
        return compile_counts()
    import igl

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--refine", type=int, nargs="*", default=[0])
    ap.add_argument("--slim-iters", type=int, default=100)
    ap.add_argument("--energies", nargs="*", default=["symmetric_dirichlet", "mips", "angle"])
    ap.add_argument("--solvers", nargs="*", default=["newton", "lbfgs"])
    ap.add_argument("--slim-cache", type=Path, default=None,
                    help="folder keeping SLIM's per-iteration times and energies (one .npz per "
                         "mesh and energy): reused when present, written when not, so a long "
                         "SLIM run is done once")
    ap.add_argument("--data", type=Path, nargs="*", default=[DATA],
                    help="base meshes (default camelhead); e.g. lilium.obj --refine 1 for a "
                         "26k-face mesh not in ../shared")
    ap.add_argument("--energy-rtol", type=float, default=1e-12,
                    help="minimize's energy_rtol (1e-12: full convergence; the library's default "
                         "is jaxparam.tol.ENERGY_RTOL)")
    ap.add_argument("--perturb", action="store_true",
                    help="a harder held-out mesh: after refining, shear (x += 0.4 y) and move "
                         "each vertex by Gaussian noise of 0.1 %% of the bounding-box diagonal "
                         "per axis (seed 0)")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    for data, r in [(d, r) for d in args.data for r in args.refine]:
        base = jp.load(data)
        mesh = jp.shapes.refine(base, r) if r else base
        if args.perturb:
            mesh = perturbed(mesh)
        uv0 = np.asarray(jp.convex_map(mesh, weights="uniform"))
        a3 = float(np.sum(np.asarray(jp.geometry.face_areas(np.asarray(mesh.vertices), mesh.faces))))
        auv = float(np.sum(np.asarray(jp.geometry.signed_areas(uv0, mesh.faces))))
        uv0 = (uv0 - uv0.mean(0)) * np.sqrt(a3 / auv)
        print(f"\n{Path(data).stem} x{4 ** r}{' sheared + noise' if args.perturb else ''}: {mesh.n_faces} faces, load {os.getloadavg()[0]:.1f}")
        print(f"{'energy':20s} {'method':8s} {'iters':>5s} {'seconds':>8s} {'to SLIM-1%':>10s} "
              f"{'final E':>10s} {'flips':>5s} {'overlaps':>8s} {'compile':>7s} {'/ SLIM':>6s}")
        for name in args.energies:
            slim_type = (igl.MappingEnergyType.SYMMETRIC_DIRICHLET if name == "symmetric_dirichlet"
                         else igl.MappingEnergyType.CONFORMAL)
            cache = (args.slim_cache / f"slim_{mesh.n_faces}_{name}_{args.slim_iters}.npz"
                     if args.slim_cache else None)
            if cache is not None and cache.exists():
                z = np.load(cache)
                st, svals, fl, ov = list(z["times"]), list(z["energies"]), int(z["flips"]), int(z["overlaps"])
            else:
                st, suvs = slim_run(mesh, uv0, slim_type, args.slim_iters)
                en = jp.energies.get(name)
                svals = [float(en(mesh, u)) for u in suvs]
                fl = jp.metrics.flips(mesh, suvs[-1])
                ov = jp.metrics.boundary_overlaps(mesh, suvs[-1])
                if cache is not None:
                    cache.parent.mkdir(parents=True, exist_ok=True)
                    np.savez(cache, times=st, energies=svals, flips=fl, overlaps=ov)
            target = svals[-1]
            print(f"{name:20s} {'SLIM':8s} {args.slim_iters:5d} {st[-1]:8.2f} {st[-1]:10.2f} "
                  f"{target:10.5f} {fl:5d} {ov:8d} {'-':>7s}", flush=True)
            for solver in args.solvers:
                iters = 200 if solver == "newton" else 3000
                res, total, first = ours(mesh, uv0, name, solver, iters, secs=max(3 * st[-1], 30),
                                         energy_rtol=args.energy_rtol)
                tw = first_time_within(res.times, res.history, target)
                print(f"{'':20s} {solver:8s} {res.iterations:5d} {total:8.2f} {tw:10.2f} "
                      f"{res.energy:10.5f} {res.flips:5d} {res.boundary_overlaps:8d} "
                      f"{max(0.0, first - total * 2 / max(res.iterations, 1)):7.2f} "
                      f"{total / st[-1]:6.3f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
