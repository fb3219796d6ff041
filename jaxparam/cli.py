"""The ``jaxparam`` command.

Exit codes: 0 done, 2 usage, 3 bad input (the message names the problem and
where), 4 a solver failed (the message names the stage).  Names take hyphens
on the command line (``shape-preserving``) and underscores in Python.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

EXIT_OK, EXIT_USAGE, EXIT_INPUT, EXIT_SOLVER = 0, 2, 3, 4

WEIGHTS = ["uniform", "inverse-distance", "shape-preserving", "mean-value", "harmonic"]
BOUNDARIES = ["circle", "square", "plane"]
SPACINGS = ["uniform", "chord"]


def _py(name: str) -> str:
    return name.replace("-", "_")


def _enable_compile_cache() -> None:
    """Persistent JAX compilation cache, so a second run skips most compilation."""
    import jax

    cache = os.environ.get("JAXPARAM_CACHE", str(Path.home() / ".cache" / "jaxparam" / "jax"))
    try:
        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
    except Exception:  # an old JAX without the option: run uncached
        pass


def _clean(obj):
    """JSON-safe: non-finite floats become null, numpy scalars plain numbers."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if hasattr(obj, "item") and not isinstance(obj, (str, bytes)):
        try:
            obj = obj.item()
        except (ValueError, AttributeError):
            pass
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path, data) -> None:
    from .mesh import atomic_write

    atomic_write(path, lambda f: json.dump(_clean(data), f, indent=2))


def report_dict(mesh, uv, *, weights=None, seconds=None, extra=None) -> dict:
    """The report's metrics as a plain dict (keys as in DESIGN.md)."""
    from .metrics import distortion

    rep = distortion(mesh, uv, weights=weights).to_dict()
    out = {k: rep[k] for k in ("vertices", "faces", "flips", "boundary_overlaps", "sym_dirichlet",
                               "mips", "max_aspect", "angle_distortion", "area_distortion",
                               "unreferenced_vertices")}
    out["theorem1"] = rep["theorem1"]
    if seconds is not None:
        out["seconds"] = seconds
    if extra:
        out.update(extra)
    return out


class _Seconds(dict):
    """Wall-clock seconds per stage: ``clock("name")`` closes the stage that ran since the
    previous call (or since the clock was made)."""

    def __init__(self):
        super().__init__()
        self._t = time.perf_counter()

    def __call__(self, name: str) -> None:
        now = time.perf_counter()
        self[name] = now - self._t
        self._t = now


def _report_and_plot(args, rep: dict, plot) -> None:
    """Write ``--report`` and draw ``--plot`` when asked; ``plot(path)`` draws the picture."""
    if args.report:
        write_json(args.report, rep)
    if getattr(args, "plot", None):
        plot(args.plot)


# -- subcommands -----------------------------------------------------------------------------

def cmd_info(args) -> int:
    from .mesh import load

    t0 = time.perf_counter()
    mesh = load(args.mesh)
    info = mesh.topology.summary()
    info["file"] = str(args.mesh)
    info["is_disk"] = bool(mesh.topology.is_disk)
    info["seconds"] = time.perf_counter() - t0
    if args.json:
        print(json.dumps(_clean(info), indent=2))
    else:
        for k, v in info.items():
            print(f"{k:24s} {v}")
    return EXIT_OK


def flatten_mesh(mesh, args, *, say=print):
    """Run the flatten pipeline on a loaded mesh; returns ``(uv, report)``."""
    import numpy as np

    from .linear import convex_map, disk_check

    seconds = {}
    disk_check(mesh, "convex_map")      # before the holes note: no note for a mesh refused anyway
    holes = max(0, len(mesh.topology.boundary_loops) - 1)
    extra = {"weights": args.weights, "boundary": args.boundary, "spacing": args.spacing,
             "holes_filled": holes}
    if holes:
        say(f"note: {holes} extra boundary loop(s) (holes) filled virtually; the longest loop "
            "is mapped to the boundary")
    t = time.perf_counter()
    uv = convex_map(mesh, weights=_py(args.weights), boundary=args.boundary, spacing=args.spacing)
    uv = np.asarray(uv)
    seconds["convex_map"] = time.perf_counter() - t
    weights_used = _py(args.weights)
    if args.energy:
        from .optimize import minimize

        t = time.perf_counter()
        res = minimize(mesh, _py(args.energy), init=uv, free_boundary=args.free_boundary,
                       solver=args.solver, max_iters=args.max_iters, verbose=False)
        seconds["minimize"] = time.perf_counter() - t
        uv = np.asarray(res.uv)
        extra.update({"energy": float(res.energy), "iterations": int(res.iterations),
                      "converged": bool(res.converged), "energy_name": args.energy,
                      "solver": args.solver, "free_boundary": bool(args.free_boundary)})
        weights_used = None
    t = time.perf_counter()
    rep = report_dict(mesh, uv, weights=weights_used, seconds=seconds, extra=extra)
    seconds["report"] = time.perf_counter() - t
    return uv, rep


def cmd_flatten(args) -> int:
    from .mesh import load, save

    _enable_compile_cache()
    t = time.perf_counter()
    mesh = load(args.mesh)
    load_s = time.perf_counter() - t
    uv, rep = flatten_mesh(mesh, args, say=lambda m: print(m, file=sys.stderr))
    rep["seconds"]["load"] = load_s
    t = time.perf_counter()
    written = []
    try:  # a failure while writing (or Ctrl-C) removes what this run already wrote
        save(args.output, mesh, uv)
        written.append(args.output)
        rep["seconds"]["save"] = time.perf_counter() - t
        if args.report:
            write_json(args.report, rep)
            written.append(args.report)
        if args.plot:
            from .plot import plot_uv

            plot_uv(mesh, uv, args.plot)
    except BaseException:
        for path in written:
            Path(path).unlink(missing_ok=True)
        raise
    print(f"{args.output}: {rep['vertices']} vertices, {rep['faces']} faces, {rep['flips']} flipped, "
          f"max aspect {rep['max_aspect']:.3g}")
    return EXIT_OK


def cmd_meshless(args) -> int:
    import numpy as np

    from .mesh import save
    from .points import load_points, reconstruct_surface

    _enable_compile_cache()
    seconds = _Seconds()
    P = load_points(args.points)
    seconds("load")
    rec = reconstruct_surface(P, k=args.k, weights=_py(args.weights), boundary=args.boundary)
    seconds("meshless_map_and_reconstruction")
    save(args.output, rec, np.nan_to_num(np.asarray(rec.uv)))
    used = int(rec.topology.referenced.sum())
    rep = report_dict(rec, rec.uv, seconds=seconds, extra={
        "points": int(P.shape[0]), "points_used": used, "boundary_points": int(rec.boundary_points.size),
        "k": args.k, "weights": args.weights})
    from .plot import plot_uv

    _report_and_plot(args, rep, lambda path: plot_uv(rec, np.nan_to_num(np.asarray(rec.uv)), path))
    print(f"{args.output}: {P.shape[0]} points, {used} used, {rec.n_faces} faces, {rep['flips']} flipped")
    return EXIT_OK


def cmd_fit(args) -> int:
    from .errors import MeshFileError
    from .fitting import fit_surface
    from .mesh import load, save

    t = time.perf_counter()
    mesh = load(args.mesh)
    if mesh.uv is None:
        raise MeshFileError(f"{args.mesh}: the mesh has no per-vertex texture coordinates (vt); "
                            "flatten it first: jaxparam flatten MESH -o MESH_WITH_UV.obj")
    surf = fit_surface(mesh, mesh.uv, kind=_py(args.surface))
    out = surf.sample(args.resolution)
    save(args.output, out, out.uv)
    if args.plot:
        from .plot import plot_isocurves

        plot_isocurves(surf, args.plot)
    print(f"{args.output}: {args.surface} surface sampled on a {args.resolution}^2 grid, "
          f"{out.n_faces} faces ({time.perf_counter() - t:.2f} s)")
    return EXIT_OK


def _add_points_commands(sub) -> None:
    p = sub.add_parser("meshless", help="parameterize and triangulate unorganized points")
    p.add_argument("points")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--k", type=int, default=10)
    p.add_argument("--weights", choices=["uniform", "inverse-distance", "shape-preserving", "mean-value"],
                   default="shape-preserving")
    p.add_argument("--boundary", choices=["circle", "square"], default="circle")
    p.add_argument("--report")
    p.add_argument("--plot")
    p.set_defaults(func=cmd_meshless)
    p = sub.add_parser("fit", help="a smooth surface over a mesh's UVs")
    p.add_argument("mesh")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--surface", choices=["spline", "clough-tocher"], default="spline")
    p.add_argument("--resolution", type=int, default=64)
    p.add_argument("--plot")
    p.set_defaults(func=cmd_fit)


def cmd_remesh(args) -> int:
    from .linear import convex_map
    from .mesh import load, save
    from .remesh import remesh

    _enable_compile_cache()
    seconds = _Seconds()
    mesh = load(args.mesh)
    seconds("load")
    uv = convex_map(mesh, weights=_py(args.weights), boundary=args.boundary)
    seconds("parameterize")
    semi = remesh(mesh, uv, levels=args.levels, corners=args.base_faces)
    seconds("remesh")
    save(args.output, semi, semi.uv)
    rep = report_dict(semi, semi.uv, seconds=seconds, extra={
        "levels": args.levels, "base_faces": int(semi.base_faces.shape[0]),
        "input_vertices": mesh.n_vertices, "input_faces": mesh.n_faces})
    from .plot import plot_remesh

    _report_and_plot(args, rep, lambda path: plot_remesh(semi, path))
    print(f"{args.output}: {semi.n_vertices} vertices, {semi.n_faces} faces, subdivision connectivity "
          f"of order {args.levels} over {semi.base_faces.shape[0]} base faces")
    return EXIT_OK


def cmd_compress(args) -> int:
    import numpy as np

    from .mesh import load, save
    from .wavelets import compress

    t = time.perf_counter()
    mesh = load(args.mesh)
    small = compress(mesh, args.keep, wavelet=args.wavelet)
    seconds = {"compress": time.perf_counter() - t}
    save(args.output, small, mesh.uv)
    V, X = np.asarray(mesh.vertices), np.asarray(small.vertices)
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    err = np.linalg.norm(X - V, axis=1)
    rep = {"vertices": small.n_vertices, "faces": small.n_faces, "levels": small.hierarchy.levels,
           "coefficients_kept": small.kept, "stored_fraction": small.stored_fraction,
           "max_error": float(err.max() / diag), "rms_error": float(np.sqrt(np.mean(err ** 2)) / diag),
           "wavelet": args.wavelet, "seconds": seconds}
    _report_and_plot(args, rep, None)
    print(f"{args.output}: kept {small.kept} coefficients, {100 * small.stored_fraction:.2f} % of the "
          f"vertices' data; error max {100 * rep['max_error']:.3f} %, RMS {100 * rep['rms_error']:.3f} % "
          "of the bounding-box diagonal")
    return EXIT_OK


def cmd_manifold(args) -> int:
    from .manifold import manifold_map
    from .mesh import load, save

    seconds = _Seconds()
    mesh = load(args.mesh)
    seconds("load")
    base, param = manifold_map(mesh, args.base_faces)
    seconds("parameterize")
    semi = param.remesh(args.levels)
    seconds("remesh")
    save(args.output, semi)
    t = semi.topology
    rep = {"vertices": semi.n_vertices, "faces": semi.n_faces, "genus": int(t.genus),
           "base_vertices": base.n_vertices, "base_faces": base.n_faces, "levels": args.levels,
           "input_vertices": mesh.n_vertices, "input_faces": mesh.n_faces,
           "work_vertices": param.mesh.n_vertices, "seconds": seconds}
    from .plot import plot_remesh

    _report_and_plot(args, rep, lambda path: plot_remesh(semi, path))
    print(f"{args.output}: {semi.n_vertices} vertices, {semi.n_faces} faces, genus {t.genus}, "
          f"subdivision connectivity of order {args.levels} over {base.n_faces} base faces")
    return EXIT_OK


def _add_remesh_commands(sub) -> None:
    p = sub.add_parser("remesh", help="remesh a disk mesh with subdivision connectivity")
    p.add_argument("mesh")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--levels", type=int, default=4)
    p.add_argument("--base-faces", type=int, default=6, help="triangles of the base domain (a fan)")
    p.add_argument("--weights", choices=WEIGHTS, default="shape-preserving")
    p.add_argument("--boundary", choices=["circle", "square"], default="circle")
    p.add_argument("--report")
    p.add_argument("--plot")
    p.set_defaults(func=cmd_remesh)
    p = sub.add_parser("compress", help="wavelet compression of a mesh made by jaxparam remesh")
    p.add_argument("mesh")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--keep", type=float, required=True, help="fraction of wavelet coefficients kept")
    p.add_argument("--wavelet", choices=["lazy", "lifted"], default="lifted")
    p.add_argument("--report")
    p.set_defaults(func=cmd_compress)
    p = sub.add_parser("manifold", help="parameterize a closed mesh of any genus over a base domain "
                                        "and remesh it with subdivision connectivity")
    p.add_argument("mesh")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--base-faces", type=int, default=100)
    p.add_argument("--levels", type=int, default=3)
    p.add_argument("--report")
    p.add_argument("--plot")
    p.set_defaults(func=cmd_manifold)


def _add_flatten_options(p) -> None:
    p.add_argument("--weights", choices=WEIGHTS, default="shape-preserving")
    p.add_argument("--boundary", choices=BOUNDARIES, default="circle")
    p.add_argument("--spacing", choices=SPACINGS, default="chord")
    p.add_argument("--energy", default=None,
                   help="minimize this energy after the convex map (e.g. symmetric-dirichlet, mips)")
    p.add_argument("--free-boundary", action="store_true")
    p.add_argument("--solver", default="newton", choices=["newton", "lbfgs", "jaxopt-lbfgs", "bfgs"])
    p.add_argument("--max-iters", type=int, default=100)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="jaxparam", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("info", help="topology facts of a mesh")
    p.add_argument("mesh")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("flatten", help="parameterize a disk mesh")
    p.add_argument("mesh")
    p.add_argument("-o", "--output", required=True)
    _add_flatten_options(p)
    p.add_argument("--report")
    p.add_argument("--plot")
    p.set_defaults(func=cmd_flatten)
    for extend in _EXTENSIONS:
        extend(sub)
    return ap


#: Functions ``f(subparsers)`` that add further subcommands (points, remeshing, ...).
_EXTENSIONS: list = [_add_points_commands, _add_remesh_commands]


def _add_batch_command(sub) -> None:
    """``jaxparam batch`` (jaxparam/batch.py), handed this module's flatten pipeline."""
    from .batch import add_parser

    add_parser(sub, add_flatten_options=_add_flatten_options, flatten=flatten_mesh, clean=_clean,
               prepare=_enable_compile_cache)


_EXTENSIONS.append(_add_batch_command)


def main(argv=None) -> int:
    from .errors import JaxparamError, SolverError

    ap = build_parser()
    args = ap.parse_args(argv)
    if getattr(args, "solver", None):
        args.solver = _py(args.solver)
    try:
        return args.func(args)
    except SolverError as exc:
        print(f"jaxparam {args.command}: solver failed at stage '{exc.stage}': {exc}", file=sys.stderr)
        return EXIT_SOLVER
    except JaxparamError as exc:
        print(f"jaxparam {args.command}: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print(f"jaxparam {args.command}: interrupted; no partial output was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
