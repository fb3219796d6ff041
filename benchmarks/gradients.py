"""Gradient time over forward time of each public differentiable function, on camelhead.

For every function ``f(V)`` of the vertex positions (issue 12, item 7): the forward time
(``jax.jit(f)``, compiled) and the gradient time (``jax.jit(jax.grad(lambda V: sum(f(V)**2)))``,
compiled), timed in pairs (a forward call, then a gradient call on the same positions), and
the median over ``--repeats`` pairs of each time and of the pair's ratio (the goal is <= 2;
pairing keeps a loaded machine's drift out of the ratio).  Two settings:

- ``same V``: every call on the same positions, so the sparse solve's factorization cache
  (keyed on the matrix values) hits and the forward pass is assembly + one solve;
- ``new V``: every call on new positions (``V + 1e-9 j N(0, 1)``, ``j`` counting the calls),
  as in an optimization loop: each call factorizes once, and the gradient's adjoint solve
  reuses its own forward pass's factor.

A function that cannot be put under ``jax.jit`` is timed eagerly (marked ``eager``); one
whose gradient fails is reported as ``failed: <reason>``.

``--clock cpu`` times the process's CPU time (all threads) instead of the wall clock: on a
machine shared with other jobs a call of a few milliseconds is preempted more often the longer
it runs, which inflates wall-clock ratios; CPU time counts only the work.  Run it pinned to
one core (``taskset -c 1``) so that idle worker threads spinning on a second core are not
counted; pinned, the rows with a sparse factorization (the maps, ``minimize``) are very slow,
so use ``--clock cpu`` for the energies (``--only energy``).

Usage::

    python benchmarks/gradients.py [--mesh camelhead.off] [--repeats 5] [--only NAME ...]
                                   [--clock wall|cpu]
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
import traceback
from pathlib import Path

import numpy as np

DATA = Path(os.environ.get("JAXPARAM_DATA", "/work/shared/data/meshes"))


def cases(mesh, want=lambda name: True):
    """``name -> f(V)`` for every differentiable public function on ``mesh`` whose name
    ``want`` accepts (the meshless maps' neighbour graph is built only when one is wanted)."""
    import jax.numpy as jnp
    import jaxparam as jp

    out = {}
    for w in jp.weights.KINDS:
        out[f"convex_map {w}"] = (lambda w: lambda V: jp.convex_map(
            mesh.with_vertices(V), weights=w, boundary="circle"))(w)
    out["least_squares_map"] = lambda V: jp.least_squares_map(mesh.with_vertices(V))
    out["minimize symmetric_dirichlet (newton, fixed bnd)"] = lambda V: jp.minimize(
        mesh.with_vertices(V), "symmetric_dirichlet", verbose=False).uv

    # Meshless map on the mesh's vertices: the neighbour graph and the boundary are topology,
    # computed once from the concrete points and passed in (needed under jax.grad).
    meshless = [w for w in ("inverse_distance", "mean_value", "shape_preserving")
                if want(f"meshless_map {w}")]
    P0 = np.asarray(mesh.vertices)
    graph = jp.points.point_graph(P0) if meshless else None
    bnd = np.asarray(jp.meshless_map(P0, graph=graph)[1]) if meshless else None
    for w in meshless:
        out[f"meshless_map {w}"] = (lambda w: lambda V: jp.meshless_map(
            V, graph=graph, boundary_indices=bnd, weights=w)[0])(w)

    # Energies of a fixed UV as functions of the 3D positions (the total E of eq. (10)).
    uv0 = jnp.asarray(jp.convex_map(mesh, weights="mean_value"))
    geo, F = jp.geometry, mesh.faces
    for e in ("symmetric_dirichlet", "mips", "arap", "conformal"):
        out[f"energy {e} (fixed uv)"] = (lambda e: lambda V: jp.ENERGIES[e](
            mesh.with_vertices(V), uv0))(e)
        # The same values through the minimizer's kernel (energies.total), which JAX
        # differentiates itself: the hand-written derivative's baseline (issue 12).
        out[f"energy {e} (fixed uv, JAX's derivative)"] = (lambda e: lambda V: jp.energies.total(
            jp.ENERGIES[e], geo.local_frames(V, F), geo.face_areas(V, F), uv0[F]))(e)
    return {k: f for k, f in out.items() if want(k)}


CLOCK = {"wall": time.perf_counter, "cpu": time.process_time}


def paired(fwd, grad, V, repeats, fresh, clock=time.perf_counter):
    """Medians ``(forward_s, gradient_s, ratio)`` over ``repeats`` pairs of calls."""
    import jax

    def once(fn, X):
        t = clock()
        jax.block_until_ready(fn(X))
        return clock() - t

    once(fwd, V), once(grad, V)                         # compile (or first eager run)
    rng = np.random.default_rng(0)
    tf, tg = [], []
    for i in range(repeats):
        if fresh:
            tf.append(once(fwd, V + 1e-9 * (2 * i + 1) * rng.standard_normal(V.shape)))
            tg.append(once(grad, V + 1e-9 * (2 * i + 2) * rng.standard_normal(V.shape)))
        else:
            tf.append(once(fwd, V))
            tg.append(once(grad, V))
    return (statistics.median(tf), statistics.median(tg),
            statistics.median(b / a for a, b in zip(tf, tg)))


def measure(f, V, repeats, clock=time.perf_counter):
    """``({"same": (fwd, grad, ratio), "new": (...)}, mode)``; raises on failure of either."""
    import jax
    import jax.numpy as jnp

    def loss(V):
        y = f(V)
        return jnp.nansum(jnp.square(y))

    mode = "jit"
    fwd, grad = jax.jit(f), jax.jit(jax.grad(loss))
    try:
        jax.block_until_ready(grad(V))
    except Exception as exc:                            # noqa: BLE001 - fall back to eager
        if "Tracer" not in type(exc).__name__ and "Concretization" not in str(exc) \
                and "TracerArrayConversion" not in str(exc):
            raise
        mode = "eager"
        fwd, grad = f, jax.grad(loss)
    g = np.asarray(grad(V))
    if not np.all(np.isfinite(g)):
        raise FloatingPointError(f"non-finite gradient ({np.sum(~np.isfinite(g))} entries)")
    return {"same": paired(fwd, grad, V, repeats, False, clock),
            "new": paired(fwd, grad, V, repeats, True, clock)}, mode


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mesh", default=str(DATA / "camelhead.off"))
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--only", nargs="*", help="substrings of the case names to run")
    ap.add_argument("--clock", choices=sorted(CLOCK), default="wall",
                    help="wall clock (default) or the process's CPU time")
    args = ap.parse_args()

    import jax
    import jax.numpy as jnp
    import jaxparam as jp

    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    print(f"machine: {platform.machine()} {platform.processor() or ''}, {os.cpu_count()} cores, "
          f"JAX {jax.__version__} on {jax.default_backend()}, Python {platform.python_version()}, "
          f"load average at start {load:.1f}")
    mesh = jp.load(args.mesh)
    print(f"mesh: {Path(args.mesh).name}, {mesh.n_vertices} vertices, {mesh.n_faces} faces; "
          f"medians of {args.repeats} pairs of compiled calls (forward, then gradient), "
          f"{args.clock} clock")
    V = jnp.asarray(mesh.vertices, dtype=jnp.float64)
    print("| function | same V: forward s | gradient s | ratio | new V: forward s | gradient s | ratio |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    def want(name):
        return not args.only or any(s in name for s in args.only)

    for name, f in cases(mesh, want).items():
        try:
            times, mode = measure(f, V, args.repeats, CLOCK[args.clock])
        except Exception as exc:                        # noqa: BLE001 - report and move on
            msg = str(exc).strip().splitlines()
            reason = f"{type(exc).__name__}: {msg[0][:120] if msg else ''}"
            print(f"| {name} | failed: {reason} | | | | | |", flush=True)
            if os.environ.get("GRADIENTS_TRACEBACK"):
                traceback.print_exc()
            continue
        tag = "" if mode == "jit" else " (eager)"
        cells = " | ".join(f"{a:.4f} | {b:.4f} | {r:.2f}" for a, b, r in (times["same"], times["new"]))
        print(f"| {name}{tag} | {cells} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
