"""``jaxparam atlas MESH -o OUT.obj``: a UV atlas of any manifold mesh (issue 18).

The output keeps the input's vertices in their order; the atlas's UVs are per corner
(OBJ ``f v/vt``, PLY face ``texcoord``; glTF, which has one UV per vertex, splits vertices
at the seams).
"""
from __future__ import annotations

import sys
from pathlib import Path

from ..atlas import atlas
from ..clock import StageClock
from ..errors import MeshError, SolverError
from ..io import save
from ..options import default_of
from ..energies import ENERGIES
from ..options import canonical
from .arguments import add_mirrored, add_named
from .pipeline import EXIT_OK, enable_compile_cache, write_json

__all__ = ["cmd_atlas", "add_atlas_parser"]




def add_atlas_parser(sub, command) -> None:
    """Add the ``atlas`` subcommand with ``command(sub, name, help, func)`` (the CLI's
    helper that adds the input, ``-o``, ``--report`` and ``--plot``)."""
    p = command(sub, "atlas", "a UV atlas (charts, flip-free maps, packing) of any mesh: "
                "closed or open, any genus, several components", cmd_atlas)
    add_mirrored(p, "--texture-size", atlas, "texture_size", "texels a side of the texture")
    add_mirrored(p, "--margin-texels", atlas, "margin_texels", "least gap between charts, and "
                 "between a chart and the texture's border, in texels")
    add_mirrored(p, "--cone", atlas, "cone", "largest angle (degrees) between a face normal and "
                 "its chart's mean normal", type=float)
    add_mirrored(p, "--compact", atlas, "compact", "most new charts, as a share of the charts, "
                 "from cutting concave charts so they pack tighter (0: none)", type=float)
    add_named(p, "--energy", sorted(ENERGIES), default_of(atlas, "energy"),
              "distortion energy each chart's map minimizes")
    add_named(p, "--normals", ("auto", "raw", "smoothed"), default_of(atlas, "normals"),
              "face normals the cones test: auto (smoothed where the mesh is found noisy), raw "
              "(each face's own) or smoothed (for a noisy mesh, a scan)")
    add_named(p, "--start", ("conformal", "convex"), default_of(atlas, "start"),
              "each chart's start: its least-squares conformal map (the convex one where that "
              "folds) or its convex-combination map")


def report_of(mesh, a, seconds: dict) -> dict:
    """The ``--report`` JSON of an atlas."""
    s = a.stats
    rep = {"vertices": int(mesh.n_vertices), "faces": int(mesh.n_faces)}
    rep.update({k: (float(v) if isinstance(v, float) else v) for k, v in s.to_dict().items()
                if k != "seconds"})
    rep["sym_dirichlet"] = float(s.sym_dirichlet)
    rep["boundary_overlaps"] = int(s.overlaps)
    rep["texture_size"] = int(a.packing.texture_size)
    rep["margin_texels"] = int(a.packing.margin_texels)
    rep["seconds"] = {**{k: float(v) for k, v in s.seconds.items()}, **seconds}
    return rep


def plot_atlas(a, path) -> None:
    """Draw the packed charts (one colour per chart) to ``path`` (PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    fig, ax = plt.subplots(figsize=(6, 6), dpi=150)
    cols = plt.get_cmap("tab20")(a.chart % 20)
    ax.add_collection(PolyCollection(a.uv[a.uv_faces], facecolors=cols, edgecolors="none"))
    ax.plot([0, 1, 1, 0, 0], [0, 0, 1, 1, 0], "k-", lw=0.5)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_aspect("equal")
    ax.set_title(f"{a.stats.charts} charts, {100 * a.stats.coverage:.1f} % covered")
    fig.savefig(path)
    plt.close(fig)


def cmd_atlas(args) -> int:
    """Run ``jaxparam atlas``: load, build the atlas, write the mesh (and report, plot)."""
    from ..io import load

    enable_compile_cache()
    clock = StageClock()
    mesh = load(args.mesh)
    clock("load")
    try:
        a = atlas(mesh, energy=canonical(args.energy), texture_size=args.texture_size,
                  margin_texels=args.margin_texels, cone=args.cone, compact=args.compact,
                  start=canonical(args.start), normals=canonical(args.normals))
    except (MeshError, SolverError) as exc:     # the messages name the Python options
        text = str(exc).replace("margin_texels", "--margin-texels").replace(
            "texture_size", "--texture-size")
        if text == str(exc):
            raise
        if isinstance(exc, SolverError):
            raise SolverError(text, stage=exc.stage) from None
        raise type(exc)(text) from None
    clock("atlas")
    written = []
    try:
        save(args.output, mesh, a.uv, uv_faces=a.uv_faces)
        written.append(args.output)
        rep = report_of(mesh, a, {"load": clock["load"], "save": clock("save")})
        if getattr(args, "report", None):
            write_json(args.report, rep)
            written.append(args.report)
        if getattr(args, "plot", None):
            plot_atlas(a, args.plot)
    except BaseException:
        for p in written:
            Path(p).unlink(missing_ok=True)
        raise
    s = a.stats
    print(f"{args.output}: {mesh.n_faces} faces, {s.charts} charts, {s.flips} flipped, "
          f"{100 * s.coverage:.1f} % of the square covered, max aspect {s.max_aspect:.3g}",
          file=sys.stdout)
    return EXIT_OK
