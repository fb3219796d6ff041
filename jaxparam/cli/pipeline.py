"""The flatten pipeline and the reports of the ``jaxparam`` command, as library code.

``jaxparam flatten``, ``jaxparam batch`` and ``make demo`` all import from here, so the
commands cannot drift apart: :func:`flatten_mesh` (convex map, optional minimization,
report), :func:`report_dict` (the report's metrics), :func:`write_json` and :func:`clean`
(JSON-safe, all-or-nothing reports), :func:`failure` with the exit-code table, and
:func:`enable_compile_cache`.

Names in reports are spelled as on the command line (``shape-preserving``); the library
is called with the canonical names (``shape_preserving``).
"""
from __future__ import annotations

import json
import math
from typing import Callable

import numpy as np

from ..clock import StageClock
from ..errors import JaxparamError, SolverError
from ..disk import disk_check
from ..io import atomic_write
from ..linear import convex_map
from ..metrics import distortion
from ..options import canonical, default_of, hyphenated

__all__ = ["EXIT_OK", "EXIT_INTERNAL", "EXIT_USAGE", "EXIT_INPUT", "EXIT_SOLVER",
           "EXIT_INTERRUPTED", "failure", "enable_compile_cache", "clean", "write_json",
           "REPORT_KEYS", "report_dict", "flip_warning", "FLATTEN_OPTIONS", "flatten_mesh"]

#: Exit codes of ``jaxparam`` and ``jaxparam batch``: done; an unexpected error (a bug;
#: batch only, the command itself lets it propagate); usage (argparse's); bad input (the
#: message names the problem and where); a solver failed (the message names the stage);
#: interrupted by Ctrl-C.
EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_INPUT, EXIT_SOLVER, EXIT_INTERRUPTED = 0, 1, 2, 3, 4, 130


def failure(exc: BaseException) -> tuple[int, str]:
    """``(exit code, message)`` for an exception that stopped a command or a batch file.

    A :class:`SolverError` gives ``EXIT_SOLVER`` and ``"solver failed at stage '<stage>':
    <message>"``; any other :class:`JaxparamError` ``EXIT_INPUT`` and its message; anything
    else (a bug) ``EXIT_INTERNAL`` and ``"internal error: <type>: <message>"``.
    """
    if isinstance(exc, SolverError):
        return EXIT_SOLVER, f"solver failed at stage '{exc.stage}': {exc}"
    if isinstance(exc, JaxparamError):
        return EXIT_INPUT, str(exc)
    return EXIT_INTERNAL, f"internal error: {type(exc).__name__}: {exc}"


def enable_compile_cache() -> None:
    """Turn on JAX's persistent compilation cache, so a second run skips most compilation:
    :attr:`jp.config.compile_cache <jaxparam.settings.Settings.compile_cache>` (the folder
    ``$JAXPARAM_CACHE``, else ``~/.cache/jaxparam/jax``; ``JAXPARAM_CACHE=off`` turns it off).

    ``import jaxparam`` already does this; the commands and the batch workers' initializer
    call it to say so.  It imports no JAX: the setting is applied when JAX loads (at once if
    it is loaded), so a command that never needs JAX (a linear ``flatten``) never loads it.
    """
    from ..lazy_jax import when_jax_loads
    from ..settings import configure_jax

    when_jax_loads(configure_jax)


def clean(obj):
    """``obj`` made JSON-safe, recursively through dicts, lists and tuples: non-finite floats
    become None (``null``), numpy scalars and 0-d arrays plain Python numbers."""
    if isinstance(obj, dict):
        return {k: clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean(v) for v in obj]
    if hasattr(obj, "item") and not isinstance(obj, (str, bytes)):
        try:
            obj = obj.item()
        except (ValueError, AttributeError):
            pass
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path, data) -> None:
    """Write ``clean(data)`` as indented JSON to ``path``, all or nothing
    (:func:`jaxparam.io.atomic_write`)."""
    atomic_write(path, lambda f: json.dump(clean(data), f, indent=2))


#: The metrics a report takes from :func:`jaxparam.distortion`, in order.
REPORT_KEYS = ("vertices", "faces", "flips", "collapsed", "boundary_overlaps", "sym_dirichlet",
               "sym_dirichlet_scaled", "mips", "max_aspect", "angle_distortion", "area_distortion",
               "unreferenced_vertices", "theorem1")


def report_dict(mesh, uv, *, weights=None, seconds=None, extra=None) -> dict:
    """The report of a parameterization as a plain dict (keys as in DESIGN.md).

    **Arguments:** ``mesh`` and ``uv: (n, 2)`` as for :func:`jaxparam.distortion`;
    ``weights`` the convex-combination weights used (a name, for the Theorem 1 check) or
    None; ``seconds`` wall-clock seconds per stage (a dict, e.g. a
    :class:`~jaxparam.clock.StageClock`), stored under ``"seconds"``; ``extra`` further
    keys, added last.

    **Returns:** ``{key: value for key in REPORT_KEYS}``, then ``seconds`` and ``extra``.
    """
    rep = distortion(mesh, uv, weights=weights).to_dict()
    out = {k: rep[k] for k in REPORT_KEYS}
    if seconds is not None:
        out["seconds"] = seconds
    if extra:
        out.update(extra)
    return out


def flip_warning(rep: dict) -> str | None:
    """What to tell the user about the flipped or degenerate UV triangles a report ``rep``
    counts (``rep["flips"]``), with the cause its Theorem 1 check names and the remedy; None
    when there are none.  The causes, in order: dividing edges on a straight side of the
    boundary polygon; a boundary polygon that is not convex (``--boundary plane``); negative
    weights (``harmonic``); else, where Theorem 1 holds, faces shrunk below floating-point
    resolution, which a convex map does to a part far from the boundary (an open tube 250
    radii long, its second loop filled: 95 of 6,368 faces, session 27)."""
    flips = rep.get("flips") or 0
    if flips <= 0:
        return None
    t1 = rep.get("theorem1") or {}
    edges = t1.get("dividing_edges_on_boundary") or []
    if edges:
        named = ", ".join(f"({int(a)}, {int(b)})" for a, b in edges[:5])
        why = (f": the dividing edges {named} (interior edges with both ends on the boundary) "
               "lie on one straight side of the boundary polygon, so their faces are flat; use "
               "--boundary circle, or split those edges")
    elif t1 and t1.get("convex_boundary") is False:
        why = (": the boundary polygon is not convex (a projection onto a plane is not), so "
               "Theorem 1 does not hold; use --boundary circle or square")
    elif t1 and t1.get("positive_weights") is False:
        why = (f": {t1.get('negative_weights', 'some')} weights are negative (a harmonic weight "
               "is negative where the two angles opposite its edge sum to more than 180 degrees), so "
               "Theorem 1 does not hold; use --weights shape-preserving (the default) or "
               "mean-value, which never fold")
    elif t1.get("holds"):
        why = (": Theorem 1 holds, so these are faces the map shrank below floating-point "
               "resolution, as a convex map does to a long or thin part far from the boundary "
               "(a tube mapped through one end); cut the mesh open along that part, so that "
               "the boundary runs beside it")
    else:
        why = ""
    return f"{flips} faces of the map are flipped or degenerate (zero area) in the UVs{why}"


#: The keyword options of :func:`flatten_mesh`, as ``jaxparam flatten`` parses them.
FLATTEN_OPTIONS = ("weights", "boundary", "spacing", "energy", "free_boundary", "solver",
                   "max_iters")


def flatten_mesh(mesh, *, weights: str = default_of(convex_map, "weights"),
                 boundary: str = default_of(convex_map, "boundary"),
                 spacing: str = default_of(convex_map, "spacing"), energy: str | None = None,
                 free_boundary: bool = False, solver: str = "newton", max_iters: int = 200,
                 say: Callable[[str], object] = print, verbose: bool | None = None):
    """The flatten pipeline on a loaded disk mesh: a convex map, then, when ``energy`` is
    given, :func:`jaxparam.minimize` from it (with ``free_boundary``, from the least-squares
    conformal map where :func:`jaxparam.minimize`'s own default would take it: the report's
    ``start`` says which); then the report.

    **Arguments:** ``mesh`` a disk-topology :class:`~jaxparam.TriMesh` (extra boundary loops
    are filled virtually; ``say`` gets a note); ``weights``, ``boundary``, ``spacing`` as
    for :func:`jaxparam.convex_map`; ``energy``, ``free_boundary``, ``solver``,
    ``max_iters`` as for :func:`jaxparam.minimize`; the defaults are those functions'.
    Names may be spelled with hyphens or underscores.  ``verbose`` the minimization's
    progress bar (None: ``jp.config.progress``).

    **Returns:** ``(uv, report)``: ``uv (n, 2) float64`` numpy, and :func:`report_dict`'s
    dict with ``seconds`` (``convex_map``, ``minimize`` when run, ``report``) and the
    options, names spelled with hyphens.

    **Raises:** :class:`~jaxparam.TopologyError` for a mesh that is not a disk, and what
    :func:`jaxparam.convex_map` and :func:`jaxparam.minimize` raise.
    """
    seconds = StageClock()
    disk_check(mesh, "convex_map")      # before the holes note: no note for a mesh refused anyway
    holes = max(0, len(mesh.topology.boundary_loops) - 1)
    extra = {"weights": hyphenated(weights), "boundary": hyphenated(boundary),
             "spacing": hyphenated(spacing), "holes_filled": holes}
    if holes:
        say(f"note: {holes} extra boundary loop(s) (holes) filled virtually; the longest loop "
            "is mapped to the boundary")
    seconds.restart()
    # host=True: the one-off call takes the NumPy path (no tracing, no compilation; equal to
    # the JAX path to rounding), the largest part of a short command's time (issue 17).
    uv = np.asarray(convex_map(mesh, weights=canonical(weights), boundary=canonical(boundary),
                               spacing=canonical(spacing), host=True))
    seconds("convex_map")
    weights_used = canonical(weights)
    if energy:
        from ..energies import get as get_energy
        from ..optimize import minimize     # lazily: the optimize stack costs 0.2 s to import
        from ..optimize.driver import free_start, to_surface_area

        # jp.minimize's own start where it does not take the convex map (computed above)
        invariant = get_energy(canonical(energy)).scale_invariant
        start = free_start(mesh, free_boundary, invariant)
        kind = "convex-map" if start is None else "conformal-map"
        if start is None and not invariant:
            # as jp.minimize's default start: the convex map at the surface's area, so that
            # a scale-dependent energy's map does not depend on the mesh's units
            start = to_surface_area(mesh, uv)
        res = minimize(mesh, canonical(energy), init=uv if start is None else start,
                       free_boundary=free_boundary, solver=canonical(solver),
                       max_iters=max_iters, verbose=verbose)
        seconds("minimize")
        uv = np.asarray(res.uv)
        extra["start"] = kind
        extra.update({"energy": float(res.energy), "iterations": int(res.iterations),
                      "converged": bool(res.converged), "energy_name": hyphenated(energy),
                      "solver": hyphenated(solver), "free_boundary": bool(free_boundary)})
        weights_used = None
    with seconds.stage("report"):
        rep = report_dict(mesh, uv, weights=weights_used, seconds=seconds, extra=extra)
    return uv, rep
