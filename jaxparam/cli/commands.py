"""The handlers of the ``jaxparam`` subcommands: ``cmd_<name>(args) -> exit code``.

Each loads its input (:func:`begin`), runs the library, and hands the result to
:func:`finish`, which writes ``-o``, ``--report`` and ``--plot`` all or nothing and prints
the summary line.  Named options arrive hyphenated (:mod:`.arguments`) and are passed to
the library as :func:`~jaxparam.options.canonical` names.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Callable

import numpy as np

from .. import tol
from ..clock import StageClock
from ..errors import MeshError, MeshFileError, PointCloudError
from ..io import load, load_points, read_arrays, save
from ..mesh import TriMesh
from ..options import canonical, default_of
from .arguments import flatten_options
from .pipeline import (EXIT_INPUT, EXIT_OK, clean, enable_compile_cache, flatten_mesh, flip_warning,
                       report_dict, write_json)

__all__ = ["begin", "finish", "drawing", "warn_unconverged", "cmd_info", "cmd_flatten", "cmd_meshless", "cmd_fit",
           "cmd_remesh", "cmd_compress", "cmd_manifold"]


def begin(path, *, reader: Callable = load, compile_cache: bool = True):
    """``(data, clock)``: the input read by ``reader`` (a mesh by default) and a
    :class:`~jaxparam.clock.StageClock` holding its ``"load"`` seconds.  Turns on the
    persistent compilation cache first for commands that compile (``compile_cache``)."""
    if compile_cache:
        enable_compile_cache()
    clock = StageClock()
    data = reader(path)
    clock("load")
    return data, clock


def drawing(name: str, *data) -> Callable[[str], None]:
    """``plot(path)`` that draws ``jaxparam.plot.<name>(*data, path)`` and closes the figure;
    matplotlib is imported only when a picture is asked for."""
    def draw(path) -> None:
        import matplotlib.pyplot as plt

        from .. import plot

        plt.close(getattr(plot, name)(*data, path))

    return draw


def warn_unconverged(command: str, rep: dict, name: str = "") -> bool:
    """Print a warning on stderr when the report ``rep`` says a minimization stopped
    unconverged (``rep["converged"]`` is False); returns whether it did."""
    if rep.get("converged", True):
        return False
    where = f" on {name}" if name else ""
    print(f"jaxparam {command}: warning: the minimization{where} stopped after "
          f"{rep.get('iterations')} iterations without converging (energy "
          f"{rep.get('energy', float('nan')):.6g}); the result is usable but not optimal: raise "
          "--max-iters or try another --solver", file=sys.stderr)
    return True


def warn_flips(command: str, rep: dict) -> bool:
    """Print a warning on stderr when the report ``rep`` counts flipped or degenerate UV
    triangles (``rep["flips"] > 0``), with the cause and remedy of
    :func:`~jaxparam.cli.pipeline.flip_warning`; returns whether it did."""
    text = flip_warning(rep)
    if text is None:
        return False
    print(f"jaxparam {command}: warning: {text}", file=sys.stderr)
    return True


def finish(args, mesh, uv, line: str, *, report: dict | None = None,
           plot: Callable | None = None, save_stage: str | None = None, texture=None) -> int:
    """Write the command's outputs, all or nothing, then print ``line``; returns ``EXIT_OK``.

    **Arguments:** ``args`` the parsed command line (``output``, and ``report``/``plot``
    when the command has them); ``mesh`` and ``uv: (n, 2)`` (or None: ``mesh.uv``) saved
    to ``args.output``; ``report`` written to ``--report``; ``plot(path)`` draws
    ``--plot``; ``save_stage`` the key under which the save's seconds go into
    ``report["seconds"]`` (before the report is written); ``texture`` an image embedded in a
    ``.glb``/``.gltf`` output (:func:`jaxparam.io.save`'s ``texture=``).

    A failure while writing (or Ctrl-C) removes what this run already wrote, then
    re-raises.
    """
    written = []
    try:
        clock = StageClock()
        if texture is None:
            save(args.output, mesh, uv)
        else:
            save(args.output, mesh, uv, texture=texture)
        written.append(args.output)
        if save_stage and report is not None:
            report["seconds"][save_stage] = clock(save_stage)
        if report is not None and getattr(args, "report", None):
            write_json(args.report, report)
            written.append(args.report)
        if plot is not None and getattr(args, "plot", None):
            plot(args.plot)
    except BaseException:
        for path in written:
            Path(path).unlink(missing_ok=True)
        raise
    print(line)
    return EXIT_OK


def cmd_info(args) -> int:
    """``jaxparam info MESH [--json]``: the topology facts of a mesh.  A mesh that fails the
    checks (a bowtie vertex, inconsistent winding, a zero-area face, ...) still gets the facts
    that need no valid topology, and the defect, with exit code 3."""
    try:
        mesh, clock = begin(args.mesh, compile_cache=False)
        info = mesh.topology.summary()          # the checks run here, or when the mesh is made
    except MeshFileError:
        raise
    except MeshError as exc:
        return _info_of_invalid(args, exc)
    info["file"] = str(args.mesh)
    info["is_disk"] = bool(mesh.topology.is_disk)
    clock("summary")
    info["seconds"] = clock.total
    _print_info(args, info)
    return EXIT_OK


def _print_info(args, info: dict) -> None:
    if args.json:
        print(json.dumps(clean(info), indent=2))
    else:
        for k, v in info.items():
            print(f"{k:24s} {v}")


def _info_of_invalid(args, exc) -> int:
    """``jaxparam info`` of a mesh the checks refuse: counts, bounding box, degenerate faces
    and unused vertices (no topology), then the defect; exit code 3."""
    from ..mesh import zero_area_faces

    V, F = read_arrays(args.mesh)
    used = np.zeros(V.shape[0], bool)
    used[F.ravel()] = True                    # (the readers refuse indices out of range)
    # the TriMesh check's own test (relative to the mesh's size), so the count and the defect
    # agree (an exact-zero test counted 0 where the defect named a face; session 27)
    zero = zero_area_faces(V, F) if F.size else np.zeros(0, np.int64)
    info = {"vertices": int(V.shape[0]), "faces": int(F.shape[0]),
            "bounding_box": (V.max(0) - V.min(0)).tolist() if V.size else None,
            "zero_area_faces": int(zero.size), "unused_vertices": int(np.sum(~used)),
            "file": str(args.mesh), "valid": False, "defect": str(exc)}
    _print_info(args, info)
    return EXIT_INPUT


def cmd_flatten(args) -> int:
    """``jaxparam flatten MESH -o OUT.obj``: :func:`~.pipeline.flatten_mesh` on one file.
    The sparse solver's runtime starts in the background while the mesh loads."""
    from ..sparse import warm_up

    warming = warm_up()
    try:
        mesh, clock = begin(args.mesh)
    finally:
        # Also when the input is refused: the interpreter must not exit while the thread is
        # still inside MKL's start-up (a segmentation fault, exit code 139, instead of 3).
        warming.join()
    uv, rep = flatten_mesh(mesh, **flatten_options(args), say=lambda m: print(m, file=sys.stderr))
    rep["seconds"]["load"] = clock["load"]
    warn_unconverged("flatten", rep)
    warn_flips("flatten", rep)
    texture = None
    if getattr(args, "checker_texture", False):
        if Path(args.output).suffix.lower() not in (".glb", ".gltf"):
            print("jaxparam flatten: note: --checker-texture applies to .glb/.gltf outputs only; "
                  f"{args.output} is written without a texture", file=sys.stderr)
        else:
            from ..io import checker_texture

            texture = checker_texture()
    return finish(args, mesh, uv, report=rep, plot=drawing("plot_uv", mesh, uv),
                  save_stage="save", texture=texture,
                  line=f"{args.output}: {rep['vertices']} vertices, {rep['faces']} faces, "
                       f"{rep['flips']} flipped, "
                       + (f"{rep['collapsed']} collapsed, " if rep.get("collapsed") else "")
                       + f"max aspect {rep['max_aspect']:.3g}")


def cmd_meshless(args) -> int:
    """``jaxparam meshless POINTS -o OUT.obj``: parameterize and triangulate a point set."""
    from ..points import reconstruct_surface

    P, clock = begin(args.points, reader=load_points)
    try:
        rec = reconstruct_surface(P, k=args.k, weights=canonical(args.weights),
                                  boundary=canonical(args.boundary),
                                  merge_duplicates=args.merge_duplicates, holes=args.holes)
    except PointCloudError as exc:
        if "boundary=indices" in str(exc):
            # options of the Python API that the command line has not
            raise PointCloudError(
                str(exc).rstrip(".") + ": on the command line, cut the surface open (keep a "
                "disk-like part of the points); boundary indices and the gap are options of "
                "jp.reconstruct_surface(points, boundary_indices=..., gap=...) in Python.") from None
        if "merge_duplicates=True" not in str(exc):
            raise
        raise PointCloudError(str(exc).replace("pass merge_duplicates=True",
                                               "pass --merge-duplicates")) from None
    clock("meshless_map_and_reconstruction")
    if rec.outliers.size:
        print(f"jaxparam meshless: warning: {rec.outliers.size} outliers left out of the mesh "
              f"(points {', '.join(map(str, rec.outliers[:5].tolist()))}"
              f"{', ...' if rec.outliers.size > 5 else ''})", file=sys.stderr)
    mesh, uv, used = rec.mesh, np.nan_to_num(np.asarray(rec.uv)), int(rec.points_used.size)
    rep = report_dict(mesh, rec.uv, seconds=clock, extra={
        "points": int(P.shape[0]), "points_used": used,
        "boundary_points": int(rec.boundary.size), "outliers": int(rec.outliers.size),
        "squeezed": rec.squeezed, "holes": rec.holes, "k": args.k, "weights": args.weights})
    if rep["collapsed"]:
        # uniform weights on a small, dense neighbour graph: two points with the same
        # neighbours (up to each other) get one UV (session 20: 24 of 176 small random sets)
        default_k = default_of(reconstruct_surface, "k")
        other = ("use --weights shape-preserving (the default) or mean-value, or another --k"
                 if canonical(args.weights) not in ("shape_preserving", "mean_value")
                 else "try another --k")
        print(f"jaxparam meshless: warning: {rep['collapsed']} triangles collapsed in the UVs "
              f"(aspect s1/s2 above {tol.COLLAPSED_ASPECT:.0e}: points mapped onto one place or "
              f"one line); {other} (this run: {args.k}; the default: {default_k})",
              file=sys.stderr)
    return finish(args, mesh, uv, report=rep, plot=drawing("plot_uv", mesh, uv),
                  line=f"{args.output}: {P.shape[0]} points, {used} used, {mesh.n_faces} faces, "
                       f"{rec.holes} hole{'s' if rec.holes != 1 else ''}, {rep['flips']} flipped")


def cmd_fit(args) -> int:
    """``jaxparam fit MESH -o OUT.obj``: a smooth surface over a mesh's UVs, sampled on a grid."""
    from ..fitting import fit_surface

    mesh, clock = begin(args.mesh, compile_cache=False)
    if mesh.uv is None and mesh.texcoords is not None:
        raise MeshFileError(f"{args.mesh}: the mesh's texture coordinates have seams (several "
                            "UVs at one vertex, as an atlas writes); a surface is fitted over one "
                            "UV per vertex, a disk map: jaxparam flatten MESH -o MESH_WITH_UV.obj")
    if mesh.uv is not None and mesh.topology.n_components > 1:
        # an atlas saved as .glb/.ply: its vertices are split at the seams, so each chart is
        # a component of its own and the UVs look like one map (session 21)
        raise MeshFileError(f"{args.mesh}: the mesh has {mesh.topology.n_components} connected "
                            "components (an atlas's charts, split at their seams, look like this); "
                            "a surface is fitted over one disk map: flatten a single disk mesh "
                            "(jaxparam flatten MESH -o MESH_WITH_UV.obj) and fit that")
    if mesh.uv is None:
        raise MeshFileError(f"{args.mesh}: the mesh has no per-vertex texture coordinates (vt); "
                            "flatten it first: jaxparam flatten MESH -o MESH_WITH_UV.obj")
    surf = fit_surface(mesh, mesh.uv, kind=canonical(args.surface))
    out = surf.sample(args.resolution)
    clock("fit")
    V = np.asarray(mesh.vertices)[mesh.topology.referenced]
    rel = float(surf.residual_rms) / max(float(np.linalg.norm(np.ptp(V, axis=0))), 1e-300)
    if rel > FIT_RESIDUAL_WARN:
        print(f"jaxparam fit: warning: the spline misses the mesh's vertices by {100 * rel:.2g} % of "
              "the bounding-box diagonal (RMS): its UVs squeeze parts of the mesh into places the "
              "knots cannot resolve. Use --surface clough-tocher (it interpolates), or flatten "
              "with a map that spreads the samples (e.g. jaxparam flatten --energy "
              "symmetric-dirichlet --free-boundary)", file=sys.stderr)
    return finish(args, out, out.uv, plot=drawing("plot_isocurves", surf),
                  line=f"{args.output}: {args.surface} surface sampled on a {args.resolution}^2 "
                       f"grid, {out.n_faces} faces, residual RMS {100 * rel:.2g} % of the "
                       f"diagonal ({clock.total:.2f} s)")


#: ``jaxparam fit`` warns when the spline's residual RMS exceeds this share of the bounding-box
#: diagonal (session 20, the default spline): camelhead's circle map 2.8 % (spikes where it
#: squeezes the head), halftunnel's 4.5 %; camelhead's free-boundary symmetric Dirichlet map
#: 0.27 %, lilium, snail and bump-domain's circle maps 0.02-0.08 %.
FIT_RESIDUAL_WARN = 0.02


def cmd_remesh(args) -> int:
    """``jaxparam remesh MESH -o OUT.obj``: subdivision connectivity over a base domain."""
    from ..remesh import area_aware_map, check_remesh_input, measure_errors, remesh

    mesh, clock = begin(args.mesh)
    check_remesh_input(mesh, args.levels, base_faces=args.base_faces)   # before the map's work
    # the area-aware map (L2 stretch minimized inside the circle or the square); the square
    # took the plain convex map, 21 % of the diagonal off at level 4 where the circle's area-aware
    # map was at 0.6 % (a held-out sphere with one face removed, session 22)
    # levels: reweighted where this remesh is far from the input, as jp.remesh does (without
    # them the CLI's camelhead level-6 remesh was 0.66 % of the diagonal off, jp.remesh's 0.12 %)
    uv = area_aware_map(mesh, weights=canonical(args.weights), boundary=canonical(args.boundary),
                        levels=args.levels, corners=args.base_faces)
    clock("parameterize")
    semi = remesh(mesh, uv, levels=args.levels, base_faces=args.base_faces)
    clock("remesh")
    extra = {"levels": args.levels, "base_faces": int(semi.base_faces.shape[0]),
             "input_vertices": mesh.n_vertices, "input_faces": mesh.n_faces}
    if getattr(args, "report", None):
        extra["errors"] = measure_errors(mesh, semi).as_dict()
        clock("errors")
    rep = report_dict(semi.mesh, semi.uv, seconds=clock, extra=extra)
    return finish(args, semi.mesh, semi.uv, report=rep, plot=drawing("plot_remesh", semi),
                  line=f"{args.output}: {semi.mesh.n_vertices} vertices, "
                       f"{semi.mesh.n_faces} faces, "
                       f"subdivision connectivity of order {args.levels} over "
                       f"{semi.base_faces.shape[0]} base faces")


def cmd_compress(args) -> int:
    """``jaxparam compress MESH -o OUT.obj --keep F``: wavelet compression of a remeshed mesh;
    errors are relative to the bounding-box diagonal."""
    from ..wavelets import compress

    mesh, clock = begin(args.mesh, compile_cache=False)
    if mesh.topology.n_components > 1:
        # jaxparam manifold's output for several components: their remeshes one after the
        # other, each with its own subdivision numbering; each is compressed on its own,
        # keeping the same share of its coefficients
        from ..manifold import split_components

        parts = split_components(mesh)
        X = np.empty((mesh.n_vertices, 3))
        kept = base = 0
        levels = []
        for verts, _, sub in parts:
            one = compress(sub, args.keep, wavelet=canonical(args.wavelet))
            X[verts] = np.asarray(one.mesh.vertices)
            kept += one.kept
            base += one.hierarchy.counts[0]
            levels.append(one.hierarchy.levels)
        small_mesh = TriMesh(X, mesh.faces, uv=mesh.uv, name=mesh.name)
        stored = (base + kept) / mesh.n_vertices
        extra = {"components": len(parts), "levels": levels}
    else:
        small = compress(mesh, args.keep, wavelet=canonical(args.wavelet))
        small_mesh, kept, stored = small.mesh, small.kept, small.stored_fraction
        X = np.asarray(small_mesh.vertices)
        extra = {"levels": small.hierarchy.levels}
    clock("compress")
    V = np.asarray(mesh.vertices)
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    err = np.linalg.norm(X - V, axis=1)
    rep = {"vertices": small_mesh.n_vertices, "faces": small_mesh.n_faces, **extra,
           "coefficients_kept": kept, "stored_fraction": stored,
           "max_error": float(err.max() / diag), "rms_error": float(np.sqrt(np.mean(err ** 2)) / diag),
           "wavelet": args.wavelet, "seconds": {"compress": clock.total}}
    return finish(args, small_mesh, mesh.uv, report=rep,
                  line=f"{args.output}: kept {kept} coefficients, "
                       f"{100 * stored:.2f} % of the vertices' data; error max "
                       f"{100 * rep['max_error']:.3f} %, RMS {100 * rep['rms_error']:.3f} % "
                       "of the bounding-box diagonal")


def cmd_manifold(args) -> int:
    """``jaxparam manifold MESH -o OUT.obj``: a closed mesh of any genus over a base domain,
    remeshed with subdivision connectivity."""
    from ..manifold import manifold_map
    from ..manifold.report import fidelity

    mesh, clock = begin(args.mesh, compile_cache=False)
    if mesh.topology.n_components > 1:
        return _manifold_components(args, mesh, clock)
    base, param = manifold_map(mesh, args.base_faces, method=canonical(args.method))
    clock("parameterize")
    semi = param.remesh(args.levels)
    clock("remesh")
    out = semi.mesh
    t = out.topology
    rep = {"vertices": out.n_vertices, "faces": out.n_faces, "genus": int(t.genus),
           "base_vertices": base.n_vertices, "base_faces": base.n_faces, "levels": args.levels,
           "input_vertices": mesh.n_vertices, "input_faces": mesh.n_faces,
           "work_vertices": param.mesh.n_vertices, "seconds": clock,
           "folded": _folded(semi, mesh)}
    if getattr(args, "fidelity", False):
        rep["fidelity"] = fidelity(param, semi, mesh).as_dict()
        clock("fidelity")
    _warn_folded(rep["folded"], out.n_faces)
    return finish(args, out, None, report=rep, plot=drawing("plot_remesh", semi),
                  line=f"{args.output}: {out.n_vertices} vertices, {out.n_faces} faces, genus "
                       f"{t.genus}, subdivision connectivity of order {args.levels} over "
                       f"{base.n_faces} base faces{_folded_note(rep['folded'])}")


def _folded(semi, mesh) -> int:
    """Remesh faces facing against the input faces their corners lie on
    (:func:`jaxparam.manifold.report.folded_faces`): a fold the distances do not show."""
    from ..manifold.report import folded_faces

    return folded_faces(np.asarray(semi.mesh.vertices, np.float64), np.asarray(semi.mesh.faces),
                        np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces))


def _warn_folded(folded, faces: int) -> None:
    """A warning on stderr, with the remedy, when the remesh has folded faces (the success
    line's count alone went unnoticed: cow's level-3 remesh folds 311 of 6,400; session 27)."""
    n = int(np.sum(folded))
    if n:
        print(f"jaxparam manifold: warning: {n} of the remesh's {faces} faces "
              f"({100 * n / max(faces, 1):.1f} %) are folded: they face against the input surface "
              "where their corners lie, where the map stretches a thin or sharp part; more base "
              "faces fold fewer (cow at 25,600 faces: 100 base faces at level 4 fold 800, 400 at "
              "level 3 fold 160)", file=sys.stderr)


def _folded_note(folded) -> str:
    """The success line's word on folded remesh faces (nothing when there are none)."""
    n = int(np.sum(folded))
    return (f"; {n} folded faces (facing against the input faces their corners lie on; "
            "--fidelity gives the distances too)") if n else ""


def _manifold_components(args, mesh, clock) -> int:
    """``jaxparam manifold`` on a mesh of several closed components: each over a base domain
    of its own (``--base-faces`` is the total, shared by the components' faces;
    :func:`jaxparam.manifold.manifold_map_each`), remeshed at ``--levels``, and written as
    one mesh, the components' remeshes one after the other, largest first."""
    from ..manifold import manifold_map_each
    from ..manifold.report import fidelity

    parts = manifold_map_each(mesh, args.base_faces, method=canonical(args.method))
    clock("parameterize")
    semis = [part.param.remesh(args.levels) for part in parts]
    clock("remesh")
    starts = np.cumsum([0] + [s.mesh.n_vertices for s in semis])
    out = TriMesh(np.concatenate([np.asarray(s.mesh.vertices, np.float64) for s in semis]),
                  np.concatenate([np.asarray(s.mesh.faces) + k for s, k in zip(semis, starts)]),
                  name=f"{mesh.name or 'mesh'} remeshed")
    rows = []
    for part, semi in zip(parts, semis):
        row = {"input_vertices": int(part.vertices.size), "input_faces": int(part.faces.size),
               "first_input_vertex": int(part.vertices[0]), "vertices": semi.mesh.n_vertices,
               "faces": semi.mesh.n_faces, "genus": int(semi.mesh.topology.genus),
               "base_vertices": part.base.n_vertices, "base_faces": part.base.n_faces,
               "work_vertices": part.param.mesh.n_vertices}
        sub = TriMesh(np.asarray(mesh.vertices)[part.vertices],
                      np.searchsorted(part.vertices, np.asarray(mesh.faces)[part.faces]))
        if getattr(args, "fidelity", False):
            row["fidelity"] = fidelity(part.param, semi, sub).as_dict()
        row["folded"] = _folded(semi, sub)
        rows.append(row)
    if getattr(args, "fidelity", False):
        clock("fidelity")
    rep = {"vertices": out.n_vertices, "faces": out.n_faces, "components": rows,
           "genus": [r["genus"] for r in rows], "base_faces": sum(r["base_faces"] for r in rows),
           "levels": args.levels, "input_vertices": mesh.n_vertices, "input_faces": mesh.n_faces,
           "seconds": clock}
    _warn_folded([r["folded"] for r in rows], out.n_faces)
    return finish(args, out, None, report=rep, plot=drawing("plot_remesh", semis),
                  line=f"{args.output}: {out.n_vertices} vertices, {out.n_faces} faces, "
                       f"{len(parts)} components of genus {', '.join(str(r['genus']) for r in rows)}, "
                       f"subdivision connectivity of order {args.levels} over "
                       f"{', '.join(str(r['base_faces']) for r in rows)} base faces"
                       f"{_folded_note([r['folded'] for r in rows])}")
