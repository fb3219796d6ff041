"""The ``jaxparam`` command.

Exit codes: 0 done, 2 usage, 3 bad input (the message names the problem and
where), 4 a solver failed (the message names the stage), 130 interrupted
(``batch`` adds 1: an unexpected error in some file).  Named options take
either spelling on the command line (``shape-preserving`` or
``shape_preserving``); defaults are those of the library functions the
options mirror.

Every subcommand takes ``--quiet`` (no progress bars: ``jp.config.progress = False``;
``JAXPARAM_PROGRESS=0`` and ``TQDM_DISABLE=1`` do the same); ``-o`` is checked
(:func:`jaxparam.io.check_output_format`) before any work.  ``jaxparam --version`` prints
the version.

Modules: :mod:`.pipeline` (the flatten pipeline, reports, exit codes: library
code), :mod:`.arguments` (named options and API defaults), :mod:`.commands`
(the subcommand handlers), :mod:`.batch` (``jaxparam batch``).
"""
from __future__ import annotations

import argparse
import sys
import warnings

from ..errors import JaxparamError
from ..io import check_output_format
from ..linear import convex_map
from ..options import default_of
from ..settings import config
from ..weights import KINDS as WEIGHT_KINDS
from . import batch, commands
from .arguments import (HelpFormatter, add_flatten_options, add_mirrored, add_named,
                        flatten_option_conflict, subparser, version)
from .pipeline import EXIT_INTERRUPTED, EXIT_USAGE, failure, flatten_mesh, report_dict, write_json

__all__ = ["main", "build_parser", "flatten_mesh", "report_dict", "write_json"]

def _command(sub, name: str, help: str, func, input_name: str = "mesh", *, report: bool = True,
             plot: bool = True) -> argparse.ArgumentParser:
    """Add subcommand ``name`` run by ``func(args)``, with its input, ``-o/--output`` and, when
    asked, ``--report`` and ``--plot``; returns its parser for the further options."""
    p = subparser(sub, name, help)
    p.add_argument(input_name, help=f"the input {'point set (.xyz, .txt, .ply, .npy)' if input_name == 'points' else 'mesh (.obj, .off, .ply, .stl, .glb, ...)'}")
    p.add_argument("-o", "--output", required=True,
                   help="the output mesh: .obj, .ply, .glb, .gltf or .off (UVs dropped)")
    if report:
        p.add_argument("--report", help="write the report (JSON) here")
    if plot:
        p.add_argument("--plot", help="draw a picture (PNG) here")
    p.set_defaults(func=func)
    return p


#: The subcommands, in help order.
COMMANDS = ("info", "flatten", "meshless", "fit", "remesh", "compress", "manifold", "atlas",
            "batch")


def _add_commands(sub, only: str | None = None) -> None:
    """Every subcommand but ``batch``, or only the one named ``only``.  The modules that a
    subcommand's options mirror (the points, fitting, remesh, wavelet, manifold and atlas
    stacks) are imported only when its parser is built, so ``jaxparam flatten`` loads none."""
    adders = {"info": _add_info, "flatten": _add_flatten, "meshless": _add_meshless,
              "fit": _add_fit, "remesh": _add_remesh, "compress": _add_compress,
              "manifold": _add_manifold, "atlas": _add_atlas}
    for name, add in adders.items():
        if only is None or only == name:
            add(sub)


def _add_atlas(sub) -> None:
    from .atlas import add_atlas_parser

    add_atlas_parser(sub, _command)


def _add_info(sub) -> None:
    p = subparser(sub, "info", "topology facts of a mesh")
    p.add_argument("mesh", help="the input mesh")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=commands.cmd_info)


def _add_flatten(sub) -> None:
    p = _command(sub, "flatten", "parameterize a disk mesh", commands.cmd_flatten)
    add_flatten_options(p)
    p.add_argument("--checker-texture", action="store_true",
                   help="embed a checkerboard texture in a .glb/.gltf output, so any glTF "
                        "viewer shows the map")


def _add_meshless(sub) -> None:
    from ..points import WEIGHTS as POINT_WEIGHTS
    from ..points import reconstruct_surface

    p = _command(sub, "meshless", "parameterize and triangulate unorganized points",
                 commands.cmd_meshless, "points")
    add_mirrored(p, "--k", reconstruct_surface, "k", "neighbours per point")
    add_named(p, "--weights", POINT_WEIGHTS, default_of(reconstruct_surface, "weights"))
    add_named(p, "--boundary", ["circle", "square"], default_of(reconstruct_surface, "boundary"))
    p.add_argument("--merge-duplicates", action="store_true",
                   default=default_of(reconstruct_surface, "merge_duplicates"),
                   help="keep one of each set of equal points (scans often repeat points); the "
                        "copies get their first's UV and stay out of the faces")
    p.add_argument("--no-holes", dest="holes", action="store_false",
                   default=default_of(reconstruct_surface, "holes"),
                   help="bridge the holes of the scan with long triangles (a disk) instead of "
                        "leaving them open")


def _add_fit(sub) -> None:
    from ..fitting import KINDS as FIT_KINDS
    from ..fitting import Surface, fit_surface

    p = _command(sub, "fit", "a smooth surface over a mesh's UVs", commands.cmd_fit, report=False)
    add_named(p, "--surface", FIT_KINDS, default_of(fit_surface, "kind"), what="surface kind")
    add_mirrored(p, "--resolution", Surface.sample, "resolution",
                 "samples along each side of the grid")


def _add_remesh(sub) -> None:
    from ..remesh import remesh

    p = _command(sub, "remesh", "remesh a disk mesh with subdivision connectivity",
                 commands.cmd_remesh)
    add_mirrored(p, "--levels", remesh, "levels", "subdivision levels")
    add_mirrored(p, "--base-faces", remesh, "base_faces", "triangles of the base domain, a fan")
    add_named(p, "--weights", WEIGHT_KINDS, default_of(convex_map, "weights"))
    add_named(p, "--boundary", ["circle", "square"], default_of(convex_map, "boundary"))


def _add_compress(sub) -> None:
    from ..wavelets import WAVELETS, compress

    p = _command(sub, "compress", "wavelet compression of a mesh made by jaxparam remesh",
                 commands.cmd_compress, plot=False)
    add_mirrored(p, "--keep", compress, "keep", "fraction of wavelet coefficients kept",
                 type=float)
    add_named(p, "--wavelet", WAVELETS, default_of(compress, "wavelet"))


def _add_manifold(sub) -> None:
    from ..manifold import ManifoldParameterization, manifold_map

    p = _command(sub, "manifold", "parameterize a closed mesh of any genus over a base domain "
                 "and remesh it with subdivision connectivity", commands.cmd_manifold)
    add_mirrored(p, "--base-faces", manifold_map, "base_faces", "triangles of the base domain")
    add_mirrored(p, "--method", manifold_map, "method",
                 "maps (the map built during decimation, never blocked) or paths (surface edges "
                 "traced along mesh edges)", type=str)
    p.add_argument("--fidelity", action="store_true",
                   help="add the remesh's Hausdorff and RMS distances to the input (both ways, "
                        "relative to the diagonal), its worst area distortion, folded remesh "
                        "faces, the map's turned-over pieces (flipped), faces turned over in "
                        "the straight drawing face_uv (drawn_flipped) and input vertices off "
                        "their base triangle (misplaced) to --report")
    add_mirrored(p, "--levels", ManifoldParameterization.remesh, "levels", "subdivision levels")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The ``jaxparam`` argument parser: one subparser per command, ``func`` its handler
    (``only``: just that subcommand's, which :func:`main` builds when the command line
    names one, so a command imports only the stacks it uses)."""
    ap = argparse.ArgumentParser(prog="jaxparam", description="Differentiable parameterization "
                                 "of triangle meshes and point sets (Floater & Hormann).",
                                 epilog="'jaxparam COMMAND --help' shows each command's options, "
                                        "defaults and an example.",
                                 formatter_class=HelpFormatter)
    ap.add_argument("--version", action="version", version=f"jaxparam {version()}")
    ap.add_argument("-q", "--quiet", action="store_true",
                    help="no progress bars (also JAXPARAM_PROGRESS=0 or TQDM_DISABLE=1)")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_commands(sub, only)
    if only is None or only == "batch":
        batch.add_parser(sub)
    return ap


def main(argv=None) -> int:
    """Run ``jaxparam`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code.

    Usage errors exit through argparse (``SystemExit(2)``); library errors are printed as
    ``jaxparam <command>: <message>`` and give 3 or 4 (:func:`~.pipeline.failure`).
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    named = next((a for a in argv if not a.startswith("-")), None)
    args = build_parser(named if named in COMMANDS else None).parse_args(argv)
    conflict = flatten_option_conflict(args)
    if conflict:
        print(f"jaxparam {args.command}: error: {conflict}", file=sys.stderr)
        return EXIT_USAGE
    if args.quiet:
        config.progress = False
    try:
        with warnings.catch_warnings():
            # The library's warnings as the command's own lines, not Python's
            # "file.py:103: UserWarning: ... <source line>".
            warnings.showwarning = (lambda message, *_a, **_k: print(
                f"jaxparam {args.command}: warning: {message}", file=sys.stderr))
            if getattr(args, "output", None) and args.command != "batch":
                check_output_format(args.output)        # an unknown extension fails before work
            return args.func(args)
    except JaxparamError as exc:
        code, message = failure(exc)
        print(f"jaxparam {args.command}: {message}", file=sys.stderr)
        return code
    except KeyboardInterrupt:
        print(f"jaxparam {args.command}: interrupted; no partial output was written",
              file=sys.stderr)
        return EXIT_INTERRUPTED
