""":func:`minimize` and :class:`MinimizeResult`: argument checks, the start, and the hand-off
to a solver (or to :func:`~jaxparam.optimize.implicit.minimize_traced` when an input is traced:
``jax.grad``, ``jax.vmap``, ``jax.jit``)."""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from .. import energies as en_mod
from .. import geometry as geo
from .. import metrics
from .. import tol
from ..host import (face_areas as host_face_areas, face_quantities, map_aspects,
                    signed_areas as host_signed_areas)
from ..errors import MeshError, SolverError
from ..io import as_mesh
from ..mesh import TriMesh
from ..options import is_flag
from .base import BoundaryOverlapWarning, CollapsedMapWarning, Solver, StopRules
from .conformal import conformal_map, orient_disks
from .implicit import is_traced, minimize_traced
from .problem import Problem
from .solvers import solver_from

__all__ = ["MinimizeResult", "minimize", "check_start", "conformal_start", "free_start",
           "default_start"]


@dataclass(frozen=True)
class MinimizeResult:
    """What :func:`minimize` returns.

    **Fields:** ``uv (n, 2)`` (a JAX array, differentiable, when an input was traced);
    ``energy`` (final, area-weighted mean density);
    ``iterations`` (accepted steps); ``converged`` (a stop because the energy stopped
    falling counts only near a stationary point: :data:`~jaxparam.optimize.base.STALL_RTOL`;
    ``reason`` then says so); ``history`` (energy after each
    iteration, the start first); ``seconds`` (wall time, compilation included);
    ``reason`` (why it stopped); ``flips`` (always 0 from an injective start);
    ``boundary_overlaps`` (free boundary: crossings of the boundary with itself;
    :func:`minimize` warns :class:`BoundaryOverlapWarning` then);
    ``collapsed`` (faces not flipped but of aspect ``s1 / s2`` above
    :data:`jaxparam.tol.COLLAPSED_ASPECT`: segments in all but name, which an energy without
    a barrier can end with; :func:`minimize` warns :class:`CollapsedMapWarning` then);
    ``solver`` (the solver's registry name); ``times`` (seconds since the start at each
    entry of ``history``).  Under ``jax.jit`` and ``jax.vmap`` the scalars are JAX
    arrays and the lists empty (:func:`minimize` says which).
    """

    uv: object
    energy: float
    iterations: int
    converged: bool
    history: list = field(repr=False)
    seconds: float
    reason: str
    flips: int
    boundary_overlaps: int
    collapsed: int
    solver: str = "newton"
    times: list = field(default_factory=list, repr=False)


def check_start(mesh, uv0, where: str = "minimize") -> None:
    """Raise :class:`SolverError` (stage ``"init"``) unless every face of ``uv0 (n, 2)`` has
    a positive signed area."""
    A = host_signed_areas(np.nan_to_num(np.asarray(uv0, np.float64)), mesh.faces)
    bad = np.flatnonzero(A <= 0)
    if bad.size:
        raise SolverError(
            f"{where}: the start is not injective: {bad.size} of {A.size} triangles are flipped or "
            f"degenerate (first: face {int(bad[0])}); start from a one-to-one map such as "
            "jp.convex_map(mesh) (positive weights, convex boundary).", stage="init")


def warn_collapsed(mesh, uv: np.ndarray, energy: str, where: str = "minimize",
                   stacklevel: int = 3) -> int:
    """The number of collapsed faces of ``uv (n, 2)`` (:func:`jaxparam.host.map_aspects` above
    :data:`jaxparam.tol.COLLAPSED_ASPECT`), warning :class:`CollapsedMapWarning` when there
    are any."""
    F = np.asarray(mesh.faces)
    aspect = map_aspects(face_quantities(np.asarray(mesh.vertices, np.float64), F,
                                         np.asarray(uv, np.float64)))
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(aspect > tol.COLLAPSED_ASPECT)
    if bad.size:
        worst = float(np.max(aspect[bad]))
        warnings.warn(
            f"{where}: {bad.size} of {F.shape[0]} triangles collapsed in the UVs (not flipped, "
            f"but of aspect s1/s2 above {tol.COLLAPSED_ASPECT:.0e}, up to {worst:.2g}; first: "
            f"face {int(bad[0])}), so they get no texels across: the energy {energy!r} has no "
            "barrier against a triangle shrinking to a segment. Minimize one that has: "
            "'symmetric_dirichlet' or 'mips'.", CollapsedMapWarning, stacklevel=stacklevel)
    return int(bad.size)


def warn_overlaps(mesh, uv: np.ndarray, where: str = "minimize", stacklevel: int = 3) -> int:
    """The number of pairs of boundary edges of ``uv (n, 2)`` that cross
    (:func:`jaxparam.metrics.boundary_crossings`), warning :class:`BoundaryOverlapWarning`
    when there are any."""
    S, pairs = metrics.boundary_crossings(mesh, uv)
    if pairs.size:
        a, b = S[pairs[0, 0]], S[pairs[0, 1]]
        warnings.warn(
            f"{where}: the free boundary crosses itself ({pairs.shape[0]} pair"
            f"{'s' if pairs.shape[0] != 1 else ''} of boundary edges; first: ({int(a[0])}, "
            f"{int(a[1])}) and ({int(b[0])}, {int(b[1])})): no triangle is flipped, but the map "
            "folds over itself as a whole, so two parts of the surface share texels. Fix the "
            "boundary (free_boundary=False; jaxparam flatten without --free-boundary), start "
            "from another map (init=), or cut the mesh into charts (jp.atlas, which splits a "
            "chart whose boundary crosses).", BoundaryOverlapWarning, stacklevel=stacklevel)
    return int(pairs.shape[0])


def _collapsed_traced(mesh, uv):
    """:func:`warn_collapsed`'s count in JAX (under ``jax.jit`` or ``jax.vmap``), no warning."""
    V = jnp.asarray(mesh.vertices, jnp.float64)
    J = geo.jacobians(V, mesh.faces, uv)
    s1, _ = geo.singular_values(J)
    det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    return jnp.sum((det > 0) & (s1 * s1 > tol.COLLAPSED_ASPECT * det))


def _concrete(a):
    """``a`` as a host array when its value is known now (a constant, or a tracer of
    ``jax.grad`` whose primal is concrete), else ``None`` (under ``jax.jit`` or
    ``jax.vmap``)."""
    try:
        return np.asarray(jax.lax.stop_gradient(a), np.float64)
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return None


def conformal_start(mesh) -> np.ndarray | None:
    """The default start of a free-boundary :func:`minimize`: the mesh's least-squares
    conformal map (:func:`jaxparam.optimize.conformal.conformal_map`, two boundary vertices pinned, one
    sparse solve on the minimization's own Hessian pattern), mirrored when it came out
    clockwise.  **Returns:** ``uv (n, 2)`` (NaN rows for vertices in no face), or ``None``
    where the map inverts or flattens a triangle, is not finite or crosses its own boundary
    (a convex-combination map is one-to-one; this one need not be)."""
    t = mesh.topology
    label = np.zeros(t.n_vertices, np.int64)
    uv = conformal_map(mesh.vertices, t, label, 1)
    if orient_disks(uv, mesh.faces, np.zeros(mesh.n_faces, np.int64), label, 1)[0] or (
            metrics.boundary_overlaps(mesh, uv) > 0):
        return None
    uv[~t.referenced] = np.nan
    return uv


def free_start(mesh, free_boundary: bool, scale_invariant: bool) -> np.ndarray | None:
    """The start :func:`minimize` takes instead of the convex map, or ``None``: with a free
    boundary and an energy that is not scale-invariant, the :func:`conformal_start` where it
    is one-to-one.  (A scale-invariant energy's optimum takes its scale and centroid from the
    start, so its start stays the convex map, differentiable in the vertices.)"""
    return conformal_start(mesh) if free_boundary and not scale_invariant else None


def default_start(mesh, free_boundary: bool, scale_invariant: bool):
    """:func:`minimize`'s start when ``init`` is None: :func:`free_start` where there is
    one, else ``convex_map(mesh)``."""
    from ..linear import convex_map

    uv = free_start(mesh, free_boundary, scale_invariant)
    return convex_map(mesh) if uv is None else uv


def to_surface_area(mesh, uv: np.ndarray) -> np.ndarray:
    """``uv (n, 2)`` about its centroid, scaled so that the parameter domain's area is the
    surface's (host).  A scale-dependent energy (symmetric Dirichlet, ARAP, ...) is then
    minimized at the mesh's own scale, whatever its units: with the unit circle fixed,
    camelhead in units 1e-4 / 1 / 1e3 of its own gave symmetric Dirichlet maps of largest
    aspect 5.87 / 8.95 / 671 (session 18)."""
    a3 = float(np.sum(host_face_areas(np.asarray(mesh.vertices, np.float64), mesh.faces)))
    auv = float(np.sum(host_signed_areas(np.nan_to_num(uv), mesh.faces)))
    return (uv - boundary_centroid(mesh, uv)) * np.sqrt(a3 / auv)


def boundary_centroid(mesh, uv):
    """The mean ``(1, 2)`` of ``uv``'s boundary rows (NumPy or JAX): the centre a start is
    scaled about.  Not the mean of every row: a fixed boundary's result would then move with
    the interior of the start, whose shape-preserving weights kink on regular grids (a
    gradient 1.7 % off on planexy.off, session 22); the UV area ``auv`` depends on the boundary
    alone too (the signed areas of a one-to-one map sum to the boundary polygon's)."""
    b = np.flatnonzero(mesh.topology.is_boundary & mesh.topology.referenced)
    return uv[b].mean(axis=0, keepdims=True)


def minimize(mesh, energy="symmetric_dirichlet", *, init=None, free_boundary: bool = False,
             solver: str | Solver = "newton", max_iters: int = 200,
             energy_rtol: float = tol.ENERGY_RTOL, grad_rtol: float = tol.GRAD_RTOL,
             max_seconds: float | None = None, verbose: bool | None = None,
             strict: bool = False) -> MinimizeResult:
    """Minimize a distortion energy over the UVs without ever inverting a triangle.

    **Arguments:**

    - ``mesh``: a disk :class:`~jaxparam.TriMesh` (its vertices may be JAX tracers: see
      *Transformations*).
    - ``energy``: a name (``"symmetric_dirichlet"``, ``"mips"``, ``"angle"``, ...) or
      ``jp.energy(f)`` (``jp.energy(f, params)`` for one with parameters).
    - ``init``: ``(n, 2)`` one-to-one start; default ``convex_map(mesh)``
      (shape-preserving weights, circle), and with ``free_boundary`` and an energy that is
      not scale-invariant (``symmetric_dirichlet``, ``arap``, ...) the least-squares
      conformal map where that is one-to-one (:func:`conformal_start`: no folded triangle,
      no boundary self-crossing), which lets the boundary start near where it ends (Newton,
      symmetric Dirichlet, against the convex map: camelhead 25 -> 19 steps, snail x16 12 -> 5;
      under ``jax.jit`` and ``jax.vmap``, where the vertices have no value yet, the convex
      map).  With a scale-dependent energy the start is rescaled to the 3D area
      (:func:`to_surface_area`) where it is free to be: with ``free_boundary``, and for the
      default start with the boundary fixed (its circle then has the radius
      ``sqrt(area / pi)``, not 1), so that the result does not depend on the mesh's units.
      An explicit ``init`` with the boundary fixed is taken as it is.
    - ``free_boundary``: let the boundary move (False: the start's boundary stays).
    - ``solver``: a name of :data:`jaxparam.optimize.SOLVERS` (``"newton"``, ``"lbfgs"``,
      ``"bfgs"``, ``"jaxopt_lbfgs"``; hyphens allowed), or a solver instance with its own
      settings, e.g. ``jp.optimize.Newton(regularization=1e-9)``.
    - ``max_iters``, ``energy_rtol``, ``grad_rtol``, ``max_seconds``: stopping rules
      (:class:`jaxparam.optimize.StopRules`).
    - ``verbose``: a progress bar for runs longer than a second (None: as
      ``jp.config.progress`` says, on unless ``JAXPARAM_PROGRESS=0`` or ``TQDM_DISABLE=1``).
    - ``strict``: refuse to differentiate a run that did not converge (a
      :class:`SolverError`, stage ``"gradient"``, when the gradient is taken) instead of
      warning :class:`~jaxparam.optimize.UnconvergedGradientWarning`.

    **Returns:** a :class:`MinimizeResult`.

    **Transformations.**  ``jax.grad`` (and ``jax.vjp``, ``jax.jacrev``) of a function of
    ``res.uv`` with respect to the vertex positions, to ``init`` or to the energy's
    parameters is the implicit gradient of the optimum (:mod:`jaxparam.optimize.implicit`):
    one solve with the true Hessian, through the energy's dependence on the inputs and
    through the fixed boundary's (the default start ``convex_map(mesh)`` moves with the
    vertices; an explicit ``init``'s boundary rows are the fixed UVs).  The free rows of
    ``init`` do not move a converged optimum: their gradient is 0.  With a free boundary
    the optimum is unique only up to a rigid motion (and a scale, fixed by the
    normalization, for a scale-invariant energy): the gradient is exact for losses
    invariant under rigid motions of the UVs.  Differentiating a run that did not converge
    warns (the gradient is that of the stopping point) or, with ``strict``, raises.
    ``jax.vmap`` (e.g. over vertex positions with the same faces) runs one minimization
    per batch element; under ``jax.jit`` and ``jax.vmap`` ``energy``, ``iterations``,
    ``converged`` and ``flips`` of the result are JAX arrays, ``history`` and ``times``
    are empty, ``reason`` is ``""`` and ``seconds`` is NaN.

    Raises :class:`SolverError` (stage ``"init"``) when the start has a flipped triangle
    (under ``jax.jit`` or ``jax.vmap`` the start is checked in the forward callback, and the
    error reaches the caller wrapped in a ``jax.errors.JaxRuntimeError``),
    :class:`MeshError` for an unknown solver, a bad argument or an energy that closes over
    a JAX tracer (pass such values as ``jp.energy(f, params)``).

    Example::

        res = jp.minimize(mesh, "symmetric_dirichlet", free_boundary=True)
        res.uv, res.energy, res.iterations
    """
    mesh = as_mesh(mesh, "minimize")
    from ..linear import disk_check

    en = en_mod.get(energy)
    if en_mod.captures_tracer(en):
        raise MeshError(
            f"minimize: the energy {en.name!r} closes over a traced value (a JAX tracer, e.g. a "
            "parameter under jax.grad captured by a lambda), which its compiled kernels cannot "
            "take; pass it as a parameter instead: jp.energy(lambda s1, s2, p: ..., params=p), "
            "and jax.grad reaches it through the implicit gradient.")
    if not is_flag(free_boundary):
        raise MeshError(f"minimize: free_boundary must be True or False, got {free_boundary!r}.")
    if free_boundary and en_mod.ENERGIES.get(en.name) is en and en.name in en_mod.NO_FREE_MINIMUM:
        raise MeshError(
            f"minimize: {en.name!r} with a free boundary {en_mod.NO_FREE_MINIMUM[en.name]}; keep "
            "the boundary fixed (free_boundary=False), or minimize an energy with a free "
            "minimum: 'symmetric_dirichlet', 'arap' or 'mips'.")
    solver = solver_from(solver)
    stop = StopRules(max_iters=max_iters, energy_rtol=energy_rtol, grad_rtol=grad_rtol,
                     max_seconds=max_seconds)      # checks them, before any work
    disk_check(mesh, "minimize")
    if is_traced((mesh.vertices, init, en.params)):
        return _minimize_traced(mesh, en, init, free_boundary, solver, stop, verbose, strict)
    default = init is None
    if default:
        init = default_start(mesh, free_boundary, en.scale_invariant)
    uv0 = np.asarray(init, np.float64)
    if uv0.shape != (mesh.n_vertices, 2):
        raise MeshError(f"minimize: init must have shape ({mesh.n_vertices}, 2), got {uv0.shape}.")
    check_start(mesh, uv0)
    if (free_boundary or default) and not en.scale_invariant:
        uv0 = to_surface_area(mesh, uv0)
    prob = Problem(mesh, en, free_boundary, uv0)
    res = solver.run(prob, stop, verbose=verbose)
    uv = np.array(prob.uv(res.x))
    uv[~mesh.topology.referenced] = np.nan
    return MinimizeResult(uv=uv, energy=res.energy, iterations=res.iterations,
                          converged=res.converged, history=res.history, seconds=res.seconds,
                          reason=res.reason, flips=prob.flipped(res.x),
                          boundary_overlaps=warn_overlaps(mesh, uv) if free_boundary else 0,
                          collapsed=warn_collapsed(mesh, uv, en.name), solver=solver.name,
                          times=res.times)


def _minimize_traced(mesh, en, init, free_boundary, solver, stop, verbose, strict):
    """:func:`minimize` when the vertices, ``init`` or the energy's parameters are JAX
    tracers: the start as a JAX array (the default one differentiable in the vertices),
    then :func:`~jaxparam.optimize.implicit.minimize_traced`."""
    from ..linear import convex_map

    default = init is None
    if default:
        # A free boundary's optimum does not depend on the start (its rows' gradient is 0;
        # for an energy that is not scale-invariant, not even through its scale), so the
        # conformal start may be a constant; under jax.jit the vertices have no value.
        V = _concrete(mesh.vertices)
        uv = None if V is None else free_start(TriMesh(V, mesh.faces, mesh.topology,
                                                       validate=False),
                                               free_boundary, en.scale_invariant)
        init = convex_map(mesh) if uv is None else uv
    init = jnp.asarray(init, jnp.float64)
    if init.shape != (mesh.n_vertices, 2):
        raise MeshError(f"minimize: init must have shape ({mesh.n_vertices}, 2), got {init.shape}.")
    known = _concrete(init)
    if known is not None:
        check_start(mesh, known)
    if (free_boundary or default) and not en.scale_invariant:
        # the fixed circle too (the default start): a scale-dependent energy's optimum must
        # not depend on the mesh's units; differentiable in the vertices through the areas
        V = jnp.asarray(mesh.vertices, jnp.float64)
        a3 = jnp.sum(geo.face_areas(V, mesh.faces))
        auv = jnp.sum(geo.signed_areas(jnp.nan_to_num(init), mesh.faces))
        init = (init - boundary_centroid(mesh, init)) * jnp.sqrt(a3 / auv)
    base = jnp.where(jnp.isnan(init), 0.0, init)
    uv, info, runs = minimize_traced(mesh, en, base, free_boundary, solver, stop, verbose,
                                     strict=strict, checked=known is not None)
    run = runs.close()
    if run is not None:       # the forward callback ran once, now (an eager jax.grad)
        res = run.result
        uvh = np.array(run.problem.uv(res.x))
        uvh[~mesh.topology.referenced] = np.nan
        overlaps = warn_overlaps(mesh, uvh, stacklevel=4) if free_boundary else 0
        return MinimizeResult(uv=uv, energy=res.energy, iterations=res.iterations,
                              converged=res.converged, history=res.history, seconds=res.seconds,
                              reason=res.reason, flips=run.flips, boundary_overlaps=overlaps,
                              collapsed=warn_collapsed(run.problem.mesh, uvh, en.name, stacklevel=4),
                              solver=solver.name, times=res.times)
    # under jax.jit (the callback has not run yet) or jax.vmap (it ran once per element)
    return MinimizeResult(uv=uv, energy=info.energy, iterations=info.iterations,
                          converged=info.converged, history=[], seconds=float("nan"), reason="",
                          flips=info.flips, boundary_overlaps=0,
                          collapsed=_collapsed_traced(mesh, uv), solver=solver.name, times=[])
