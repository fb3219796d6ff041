"""Step 4 of :mod:`jaxparam.manifold`: the parameterization object, its remesh, and :func:`manifold_map`."""
from __future__ import annotations

from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp
import numpy as np

from .. import topology as topo
from .. import weights as wts
from ..options import choose
from ..errors import MeshError, SolverError
from ..mesh import TriMesh, refuse_zero_area
from ..io import as_mesh
from ..remesh import Remesh
from ..subdivision import dyadic_hierarchy, dyadic_refine, split_corner_values
from ..triangles import barycentric, locate
from .charts import REFERENCE, ChartSystem, chart_values, charts, surface_triangles
from .decimate import decimate
from .finish import finished, lift_with, stretches
from .maps import AREA_CAPS, decimate_caps
from .noise import decision_positions
from .overlay import base_charts, draw_faces, unfolding
from .relax import (FINEST_ITERATIONS, GRID_MAX_POINTS, BaseDomain, GridLift, estimated_distance,
                    relax_samples, sharpest_vertices)
from .paths import apply_steps, refine_all, room_for_paths, trace_paths
from .report import check_closed_manifold, fidelity
from .snap import SNAP_ROUNDS

__all__ = ["ManifoldParameterization", "ManifoldStructure", "manifold_map"]


class _Static(tuple):
    """Arrays as pytree static data: equal when they are the same array objects, so jit's
    cache recognizes a parameterization without comparing (or hashing) array contents."""

    def __hash__(self):
        return hash(tuple(map(id, self)))

    def __eq__(self, other):
        return (isinstance(other, _Static) and len(self) == len(other)
                and all(a is b for a, b in zip(self, other)))


_CHART_FIELDS = ("base_vertices", "base_faces", "region", "face_uv", "vertex_face", "vertex_bary")
_STATIC_FIELDS = ("base_vertices", "base_faces", "region", "vertex_face", "structure")


@dataclass(frozen=True, eq=False)
class ManifoldStructure:
    """The discrete choices of a :func:`manifold_map` (numpy), held fixed by
    :meth:`ManifoldParameterization.with_vertices`.

    **Fields:** ``n_input`` the input mesh's vertex count; ``steps`` the refinements from the
    input to the parameterized mesh (each new vertex the mean of its parents, see
    :func:`~jaxparam.manifold.paths.apply_steps`); ``topology`` the parameterized mesh's;
    ``charts`` the :class:`~jaxparam.manifold.charts.ChartSystem` (paths, fixed vertices,
    the solve's pattern; ``None`` on the ``"maps"`` route, whose charts are the decimation's
    barycentric coordinates); ``located_uv (m, 3, 2)`` the chart coordinates :meth:`lift`
    locates points in (those of the parameterization :func:`manifold_map` returned);
    ``method`` the route; on the ``"maps"`` route ``vertex_bary (n, 3)`` the vertices'
    barycentric coordinates from the decimation and ``history`` there the
    :class:`~jaxparam.manifold.maps.MapsHistory` that :meth:`lift` pulls points back through
    (the exact inverse of the decimation's map), ``positions (n, 3)`` there the input
    positions :meth:`ManifoldParameterization.remesh` relaxes its samples with (held fixed);
    ``samples`` remesh samples already computed, ``((levels, r, b, pulled), ...)`` (base faces
    ``(k,)``, barycentric coordinates ``(k, 3)``, their pull-back ``(face, bary)`` onto the
    input or ``None``) for ``remesh(levels)`` with the default ``relax=None``: on the ``"maps"``
    route :func:`manifold_map` keeps those of the level :data:`SELECT_LEVEL` remesh it chose
    the base domain by, so ``param.remesh(SELECT_LEVEL)`` only lifts them (issue 13).  They
    depend on the fields above only (the positions held fixed), not on the vertices
    :meth:`ManifoldParameterization.with_vertices` is given, so they stay valid there."""

    n_input: int
    steps: tuple
    topology: topo.Topology
    charts: ChartSystem | None
    located_uv: np.ndarray | None = None
    method: str = "paths"
    vertex_bary: np.ndarray | None = None
    history: object = None
    positions: np.ndarray | None = None
    samples: tuple = ()


def _barycentric(T, p):
    """Barycentric coordinates ``(k, 3)`` of ``p (k, 2)`` in triangles ``T (k, 3, 2)`` (JAX)."""
    a, b, c = T[:, 0], T[:, 1], T[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    l1 = ((b[:, 0] - p[:, 0]) * (c[:, 1] - p[:, 1]) - (b[:, 1] - p[:, 1]) * (c[:, 0] - p[:, 0])) / det
    l2 = ((c[:, 0] - p[:, 0]) * (a[:, 1] - p[:, 1]) - (c[:, 1] - p[:, 1]) * (a[:, 0] - p[:, 0])) / det
    return jnp.stack([l1, l2, 1.0 - l1 - l2], axis=1)


def _dyadic_samples(F0: np.ndarray, H, level: int):
    """The base face ``(n,)`` and barycentric coordinates ``(n, 3)`` of every vertex of level
    ``level`` of the dyadic hierarchy ``H`` of base faces ``F0``."""
    bary = np.broadcast_to(np.eye(3), (F0.shape[0], 3, 3)).copy()   # corner -> bary in base face
    for _ in range(level):
        bary = split_corner_values(bary)
    F = H.faces[level]
    base_of_face = np.arange(F.shape[0]) // (4 ** level)
    # One corner per vertex gives its base face and barycentric coordinates.
    corner = np.full(H.counts[level], -1, np.int64)
    corner[F.ravel()[::-1]] = np.arange(F.size)[::-1]
    return base_of_face[corner // 3], bary.reshape(-1, 3)[corner]


def _traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _solve(S: ManifoldStructure, vertices, name):
    """The parameterized mesh and its charts at input positions ``vertices`` (JAX, traced or
    not; numpy out when concrete)."""
    V = jnp.asarray(vertices, jnp.float64)
    Vw = apply_steps(V, S.steps)
    concrete = not _traced(Vw)
    W = TriMesh(np.asarray(Vw) if concrete else Vw, S.topology.faces, S.topology,
                validate=False, name=name)
    if S.charts is None:                               # maps: the charts do not move with V
        return W, S.located_uv, S.vertex_bary
    face_uv, vbary = chart_values(S.charts, W)
    if concrete:
        face_uv, vbary = np.asarray(face_uv), np.asarray(vbary)
    return W, face_uv, vbary


def _relaxed_samples(S: ManifoldStructure, base_vertices, vertex_face, Fm, F0, H, levels: int,
                     guarded: bool, snap: bool = True):
    """The remesh's samples ``(r (n,), b (n, 3), pulled)`` (base face, barycentric
    coordinates, and their pull-back ``(face, bary)`` onto the input or ``None``) with the
    relaxation (see :meth:`ManifoldParameterization.remesh`).

    Candidates: the plain dyadic samples; the level ``levels - 1`` samples relaxed, with
    their edges' midpoints; those relaxed further at the finest level
    (:data:`~jaxparam.manifold.relax.FINEST_ITERATIONS` sweeps).  The sweeps lift through a
    :class:`~jaxparam.manifold.relax.GridLift` of level ``levels + 1`` (one exact pull-back;
    the level ``levels - 1`` sweeps lift exactly: through the grid they were as often worse as
    better, e.g. decimated-knight sheared 1.26 -> 1.45 % after the choice).
    ``guarded``: drop a relaxed candidate that stretches the remesh (:func:`~jaxparam.manifold.finish.stretches`;
    the plain samples when both are dropped), then keep the one closest to the input by :func:`~jaxparam.manifold.relax.estimated_distance`
    (relaxing further is not closer everywhere: at level 4 over 100 base faces the finest
    sweeps took cow 0.99 -> 0.85 % and decimated-knight 1.09 -> 0.94 % of the diagonal, but
    bunny 0.72 -> 0.77 % and rocker-arm 0.63 -> 0.73 %); otherwise the most relaxed one.
    Then the input's tips that the kept samples cut off are snapped to
    (:func:`~jaxparam.manifold.snap.snap_tips`; ``vertex_face (N,)`` and ``S.vertex_bary``
    place them in the base domain), when the estimate finds the snapped remesh closer
    (``snap``; :func:`_maps_route` chooses its base domain unsnapped and snaps the chosen one's
    samples only, :func:`_finish_chosen`).

    Everything here runs on the positions centred on their bounding box: the choices compare
    lengths and distances, and on coordinates far from the origin their rounding decided some
    of them (a jittered bumpy sphere moved by 1e3 got another remesh, 1.3 % of its diagonal
    apart).  Only the samples' base faces and coordinates, and their pull-back, come out."""
    P = _centred(S.positions)
    lift = lift_with(S.history, P, Fm)
    D = BaseDomain(P[base_vertices], F0)
    m0, n = F0.shape[0], H.counts[-1]
    use_grid = GridLift.points(m0, levels + 1) <= GRID_MAX_POINTS
    sweep_lift = GridLift(lift, m0, levels + 1) if use_grid else lift
    r, b = _dyadic_samples(F0, H, levels - 1)
    cands = [relax_samples(D, lift, H.faces[-2], H.parents[-1], r, b)]
    if FINEST_ITERATIONS and use_grid:
        edges = dyadic_refine(H.faces[-1], n)[1]
        r2, b2 = relax_samples(D, sweep_lift, H.faces[-1], edges, *cands[0], iterations=FINEST_ITERATIONS)
        cands.append((r2[:n], b2[:n]))
    if not guarded:
        return (*cands[-1], None)
    plain = _dyadic_samples(F0, H, levels)
    pulled = [S.history.pull_back(*c, verbose=False) for c in cands]
    Xs = [sweep_lift(*plain)] + [np.einsum("kc,kcd->kd", bb, P[Fm[f]]) for f, bb in pulled]
    # Xs[0]: the plain samples, grid points, which the grid lifts exactly.
    kept = [i for i in range(1, len(Xs)) if not stretches(Xs[i], Xs[0], H.faces[-1])]
    snap, sharp, error = bool(snap and SNAP_ROUNDS), None, None
    if not kept:
        best, (r, b), pull = 0, plain, None
    elif len(kept) == 1 and not snap:
        best = kept[0]
        (r, b), pull = cands[best - 1], pulled[best - 1]
    else:
        sharp = sharpest_vertices(P, Fm)
        errors = [estimated_distance(P, Fm, sharp, Xs[i], H.faces[-1]) for i in kept]
        best = kept[int(np.argmin(errors))]
        (r, b), pull, error = cands[best - 1], pulled[best - 1], min(errors)
    if not snap:
        return r, b, pull
    if sharp is None:
        sharp = sharpest_vertices(P, Fm)
        error = estimated_distance(P, Fm, sharp, Xs[best], H.faces[-1])
    return finished(S.history, S.vertex_bary, D, P, Fm, H.faces[-1], vertex_face, sharp, r, b, pull,
                    Xs[best], Xs[0], error, both_orders=Fm.shape[0] <= SELECT_MAX_FACES)


def _finish_chosen(param, levels: int, H, r, b, pull):
    """:func:`~jaxparam.manifold.finish.finished` for samples that :func:`_relaxed_samples`
    chose unfinished (the base domain :func:`_maps_route` keeps): what it needs is made again
    here."""
    S = param.structure
    P = _centred(S.positions)
    Fm = np.asarray(param.mesh.faces, np.int64)
    F0 = np.asarray(param.base_faces, np.int64)
    lift = lift_with(S.history, P, Fm)
    X = lift(r, b) if pull is None else np.einsum("kc,kcd->kd", pull[1], P[Fm[pull[0]]])
    X0 = lift(*_dyadic_samples(F0, H, levels))
    sharp = sharpest_vertices(P, Fm)
    error = estimated_distance(P, Fm, sharp, X, H.faces[-1])
    D = BaseDomain(P[param.base_vertices], F0)
    return finished(S.history, S.vertex_bary, D, P, Fm, H.faces[-1], param.vertex_face, sharp, r, b,
                    pull, X, X0, error, both_orders=Fm.shape[0] <= SELECT_MAX_FACES)


def _centred(P: np.ndarray) -> np.ndarray:
    """Positions ``P (n, 3)`` less the centre of their bounding box."""
    return P - 0.5 * (P.min(0) + P.max(0))


@jax.tree_util.register_pytree_node_class
@dataclass(frozen=True, eq=False)
class ManifoldParameterization:
    """A parameterization of a closed mesh over its base domain ``T^0`` (survey §9).

    - ``mesh``: the mesh parameterized (the input, or the input refined without moving its
      surface, whose first vertices are the input's);
    - ``base_vertices (n0,)``: the mesh vertices that are ``T^0``'s vertices;
    - ``base_faces (m0, 3)``: ``T^0``'s faces over ``base_vertices``;
    - ``region (m,)``: the base face of each mesh face (its surface triangle);
    - ``face_uv (m, 3, 2)``: each mesh face's corners in its base face's chart (the
      reference triangle :data:`~jaxparam.manifold.REFERENCE`; on the ``"maps"`` route the
      base triangle's own shape, the face drawn straight between its corners' images,
      which :meth:`lift` does not use);
    - ``vertex_face (n,)``, ``vertex_bary (n, 3)``: a base face of each vertex and its
      barycentric coordinates there (``phi^{-1}`` of the vertex);
    - ``structure``: the :class:`ManifoldStructure` (the discrete choices) that
      :meth:`with_vertices` re-solves the charts with; ``None`` for one built by hand.

    A JAX pytree whose leaves are ``mesh`` (its vertex positions), ``face_uv`` and
    ``vertex_bary``; the combinatorial data are concrete numpy, static data.  :meth:`lift`
    and :meth:`remesh` are differentiable in the leaves, and :meth:`with_vertices` in the
    input mesh's positions (the route for ``jax.grad``: see there).
    """

    mesh: TriMesh
    base_vertices: np.ndarray
    base_faces: np.ndarray
    region: np.ndarray
    face_uv: np.ndarray
    vertex_face: np.ndarray
    vertex_bary: np.ndarray
    structure: ManifoldStructure | None = None

    def __repr__(self) -> str:
        # one line, as TriMesh's: the arrays' values flooded a notebook cell (86 kB for a
        # 320-face sphere, session 21)
        method = getattr(self.structure, "method", None)
        return (f"ManifoldParameterization(mesh={self.mesh!r}, {self.base_faces.shape[0]} base "
                f"faces over {len(self.base_vertices)} base vertices"
                + (f", method={method!r}" if method else "") + ")")

    def tree_flatten(self):
        return (self.mesh, self.face_uv, self.vertex_bary), _Static(getattr(self, f) for f in _STATIC_FIELDS)

    @classmethod
    def tree_unflatten(cls, static, children):
        mesh, face_uv, vertex_bary = children
        base_vertices, base_faces, region, vertex_face, structure = static
        return cls(mesh, base_vertices, base_faces, region, face_uv, vertex_face, vertex_bary, structure)

    def with_vertices(self, vertices) -> "ManifoldParameterization":
        """The same parameterization, discrete choices held fixed, for new positions of the
        input mesh's vertices: differentiable in ``vertices``.

        **Arguments:** ``vertices (n, 3)``: positions of the vertices of the mesh given to
        :func:`manifold_map` (not of the refined ``self.mesh``); numpy, JAX arrays or tracers.

        **Held fixed** (computed once, by :func:`manifold_map`, from concrete positions): the
        base domain (which vertices are base vertices, the base faces), the refinement of the
        mesh that made room for the paths (its new vertices stay the midpoints and centroids
        of the same input vertices: a fixed linear map of ``vertices``), the traced surface
        edges (paths) and surface triangles (``region``), the charts' connectivity (which
        vertices are fixed on which side of the reference triangle, the pattern of the solve)
        and, in :meth:`lift` and :meth:`remesh`, the mesh face each chart point is located in.
        **Recomputed** (JAX): the refined positions, the chord-length parameters of the path
        vertices, the convex-combination weights and the solve for the free vertices
        (:mod:`jaxparam.combination`, the differentiable sparse route under tracing), hence
        ``face_uv``, ``vertex_bary`` and the lifted/remeshed positions.  For positions far
        from those the structure was computed at (faces flipping in their charts), compute a
        new :func:`manifold_map` instead; nothing here checks.

        ``param.with_vertices(V0)``, ``V0`` the positions :func:`manifold_map` saw, gives
        ``param`` again exactly.  Example::

            base, param = jp.manifold_map(mesh, base_faces=40)      # eager: the combinatorics
            V0 = jnp.asarray(mesh.vertices)
            g = jax.grad(lambda V: loss(param.with_vertices(V).remesh(levels=2).mesh.vertices))(V0)
        """
        S = self.structure
        if S is None:
            raise MeshError("ManifoldParameterization.with_vertices: this parameterization has no "
                            "structure (it was not made by jp.manifold_map); make it with "
                            "jp.manifold_map(mesh) first.")
        shape = tuple(getattr(vertices, "shape", np.shape(vertices)))
        if shape != (S.n_input, 3):
            raise MeshError(f"ManifoldParameterization.with_vertices: vertices must have shape "
                            f"({S.n_input}, 3), the mesh given to manifold_map, got {shape}.")
        W, face_uv, vbary = _solve(S, vertices, self.mesh.name)
        return ManifoldParameterization(W, self.base_vertices, self.base_faces, self.region, face_uv,
                                        self.vertex_face, vbary, S)

    def remesh(self, levels: int = 3, *, relax: bool | None = None) -> Remesh:
        """The ``levels``-fold dyadic refinement of ``T^0`` mapped onto the surface (§9,
        Fig. 26 (c)), each vertex through its base triangle's chart (eq. (11)).

        ``relax`` (default: on for the ``"maps"`` route): before the finest level is made,
        relax the level ``levels - 1`` samples across base edges, error-driven
        (:func:`~jaxparam.manifold.relax.relax_samples`), so the samples gather where the
        surface needs them; the finest samples are then the relaxed edges' midpoints.  The
        relaxation is computed once from the positions :func:`manifold_map` saw (held fixed,
        like the point location), so ``param.with_vertices(V0).remesh(j)`` is
        ``param.remesh(j)`` and the remesh stays differentiable in the positions.  By default
        (``relax=None``) the relaxed samples are kept only if the remesh's longest edge grows
        by at most :data:`~jaxparam.manifold.finish.RELAX_MAX_EDGE_GROWTH` over the
        unrelaxed one's (else the unrelaxed samples are used); ``relax=True`` keeps them
        regardless.  With
        :data:`~jaxparam.manifold.relax.FINEST_ITERATIONS` the finest samples are then relaxed
        too, and by default, of the relaxed candidates that pass the guard (relaxed at level
        ``levels - 1``; relaxed at the finest level too), the one closest to the input by
        :func:`~jaxparam.manifold.relax.estimated_distance` is kept (:func:`_relaxed_samples`).

        Differentiable in the parameterization's leaves (its mesh's positions and charts),
        so ``param.with_vertices(V).remesh(levels)`` is differentiable in ``V``.

        **Returns:** a :class:`~jaxparam.remesh.Remesh`: ``.mesh`` a closed :class:`TriMesh`
        with subdivision connectivity whose vertices lie on the surface (no UVs: a closed
        remesh has no plane domain), ``.hierarchy`` for :mod:`jaxparam.wavelets`."""
        if not (isinstance(levels, (int, np.integer)) and 0 <= levels <= 8):
            raise MeshError(f"manifold remesh: levels must be an integer in [0, 8], got {levels!r}.")
        return self._remesh_from(*self._samples(int(levels), relax))

    def _samples(self, levels: int, relax, snap: bool = True):
        """``(H, r, b, pulled)``: the dyadic hierarchy of the base domain and the samples of
        :meth:`remesh` (see :func:`_relaxed_samples`); those of ``structure.samples`` when
        it holds them (``relax=None``)."""
        F0 = np.asarray(self.base_faces, np.int64)
        H = dyadic_hierarchy(F0, int(F0.max()) + 1, levels)
        S = self.structure
        guarded = relax is None
        if guarded and S is not None:
            for lv, r, b, pulled in S.samples:
                if lv == levels:
                    return H, r, b, pulled
        if relax is None:
            relax = S is not None and S.history is not None and S.positions is not None
        if relax and levels >= 2:
            if S is None or S.history is None or S.positions is None:
                raise MeshError("manifold remesh: relax=True needs a parameterization made by "
                                "jp.manifold_map(mesh, method='maps'); pass relax=False.")
            r, b, pulled = _relaxed_samples(S, self.base_vertices, self.vertex_face,
                                            np.asarray(self.mesh.faces), F0,
                                            H, levels, guarded, snap)
        else:
            (r, b), pulled = _dyadic_samples(F0, H, levels), None
        return H, r, b, pulled

    def _remesh_from(self, H, r, b, pulled) -> Remesh:
        """The :class:`~jaxparam.remesh.Remesh` of samples from :meth:`_samples`."""
        if pulled is None:
            X = self.lift(r, b @ REFERENCE)
        else:                                   # the pull-back the choice made, not redone
            idx = jnp.asarray(self.mesh.faces[pulled[0]])
            X = jnp.einsum("kc,kcd->kd", jnp.asarray(pulled[1]), jnp.asarray(self.mesh.vertices)[idx])
        return Remesh(TriMesh(X, H.faces[-1], validate=False, name="manifold_remesh"), H)

    def report(self, levels: int = 4, *, samples: int = 20_000, seed: int = 0):
        """How faithful the level-``levels`` remesh is: a
        :class:`~jaxparam.manifold.report.ManifoldReport` (Hausdorff and RMS distances both
        ways relative to the bounding-box diagonal, the worst area distortion, faces turned
        over in their charts).  Example: ``param.report(4).hausdorff``."""
        return fidelity(self, self.remesh(levels), self.mesh, samples=samples, seed=seed)

    def lift(self, region: np.ndarray, uv: np.ndarray):
        """Surface points ``(k, 3)`` of chart points ``uv (k, 2)`` (concrete) in base faces
        ``region (k,)``.

        Every chart is the reference triangle; the charts are laid out side by side in one
        plane so a single point location serves all of them.  The location (which mesh face
        holds each point) uses ``structure.located_uv``, the charts :func:`manifold_map`
        computed (a discrete choice, held fixed); the barycentric coordinates there come from
        ``face_uv`` and the points from ``mesh.vertices``, both differentiable."""
        S = self.structure
        m0 = self.base_faces.shape[0]
        if S is not None and S.history is not None:
            face, b = S.history.pull_back(np.asarray(region), barycentric(REFERENCE[None], np.asarray(uv, np.float64)))
            idx = jnp.asarray(self.mesh.faces[face])
            return jnp.einsum("kc,kcd->kd", jnp.asarray(b), jnp.asarray(self.mesh.vertices)[idx])
        ref = S.located_uv if S is not None and S.located_uv is not None else np.asarray(self.face_uv)
        cols = int(np.ceil(np.sqrt(m0)))
        offset = 2.0 * np.stack([np.arange(m0) % cols, np.arange(m0) // cols], 1)
        corners = (ref + offset[self.region][:, None, :]).reshape(-1, 2)
        tri = np.arange(corners.shape[0]).reshape(-1, 3)
        uv = np.asarray(uv, np.float64)
        face, _ = locate(corners, tri, uv + offset[np.asarray(region)])
        b = _barycentric(jnp.asarray(self.face_uv)[face], jnp.asarray(uv))
        idx = jnp.asarray(self.mesh.faces[face])
        return jnp.einsum("kc,kcd->kd", b, jnp.asarray(self.mesh.vertices)[idx])


METHODS = ("maps", "paths")

#: Inputs of at most this many faces get one base domain per cap of
#: :data:`~jaxparam.manifold.maps.AREA_CAPS` and keep the one whose default level
#: :data:`SELECT_LEVEL` remesh (relaxed, as ``param.remesh`` makes it)
#: :func:`~jaxparam.manifold.relax.estimated_distance` finds closest to the input; larger
#: ones get the first cap only (each extra domain costs a decimation and a remesh: this keeps
#: a 100k-face mesh within its time budget).  Why a choice and not one rule: the Hausdorff
#: distance turns on whether a crease or tip keeps a base vertex, and no cap wins everywhere
#: (level 4, 100 base faces, % of the diagonal, no cap / (1.5, 3, 1) / (1.5, 2, 0): bunny
#: 0.78 / 0.56 / 0.48, cow 0.85 / 0.69 / 0.83, decimated-knight 0.94 / 1.24 / 0.71, bunny
#: decimated 0.36 / 0.37 / 0.63; benchmarks/README.md).  The estimate of the *plain* remesh
#: chose worse than this one: the relaxation reorders the candidates.
SELECT_MAX_FACES = 30_000
SELECT_LEVEL = 4

#: The one area cap (of :data:`~jaxparam.manifold.maps.AREA_CAPS`) an input of more than
#: :data:`SELECT_MAX_FACES` faces is decimated with.  Uncapped, the flat parts of a dense
#: input grow into base faces that hold many times the mean area, and the level-4 samples
#: crowd elsewhere (session 28, level 4 at 100 base faces, % of the diagonal, no cap -> this
#: cap, same seconds: bunny refined twice, 111k faces, 0.662 -> 0.325; bunny Loop-subdivided
#: twice 0.796 -> 0.444; cow refined twice 5.53 -> 2.61; 3holes refined twice 0.243 -> 0.245;
#: rocker-arm refined with noise 0.456 -> 0.476).
LARGE_MESH_CAP = (1.5, 3, 1)

#: The choice among base domains runs only while the level :data:`SELECT_LEVEL` remesh it
#: compares has at most this many faces (``base_faces * 4 ** SELECT_LEVEL``: up to 468 base
#: faces); with more base faces the first cap's domain is kept, as above
#: :data:`SELECT_MAX_FACES`.  Each candidate's relaxed level-4 remesh took most of the time:
#: cow at 2,000 base faces 88 s (64 s of it relaxing three 512k-face remeshes), at 5,518 of
#: its 5,520 faces 255 s, even for a level-2 remesh (session-21 option sweep).
SELECT_MAX_REMESH_FACES = 120_000




def fewest_faces(genus: int) -> int:
    """The fewest base faces :func:`manifold_map` accepts for a closed surface of ``genus``:
    4 for the sphere (a tetrahedron), ``14 g + 10`` for genus ``g >= 1``.

    Triangulations with fewer faces exist (Ringel and Jungerman: 14 for the torus, 24 for
    genus 2, 28 for genus 3), but a decimation rarely finds them: measured, half-edge
    collapses get stuck at 16-18 faces on tori, 28 on a genus-2 and 42 on a genus-3 plate,
    so the bound keeps a margin and every count from it up succeeds."""
    return 4 if genus == 0 else 14 * int(genus) + 10


def manifold_map(mesh: TriMesh, base_faces: int = 100, *, weights: str = "mean_value",
                 method: str = "maps", verbose: bool | None = None):
    """Parameterize a closed mesh of any genus over a decimated base domain (survey §9).

    **Arguments:** ``mesh`` closed, one component, orientable; ``base_faces`` the size of the
    base domain ``T^0`` (even; at least :func:`fewest_faces`: ``4`` for genus 0 and
    ``14 g + 10`` for genus ``g >= 1``; fewer than the mesh's faces); ``method`` the
    route: ``"maps"`` (default: the map is built during the decimation, MAPS, Lee et al.
    1998, so it never gets blocked; on inputs of at most :data:`SELECT_MAX_FACES` faces, and
    for at most :data:`SELECT_MAX_REMESH_FACES` ``/ 256`` base faces, it decimates once per
    area cap of :data:`~jaxparam.manifold.maps.AREA_CAPS` and keeps the
    base domain whose remesh is estimated closest to the input) or ``"paths"`` (surface
    edges traced along the mesh's
    edges, Floater, Hormann and Reimers, with refinement when blocked; can fail with a
    :class:`SolverError`); ``weights`` the convex-combination weights inside the surface
    triangles (``"paths"`` only); ``verbose`` the progress bars (default: the library's
    switch, ``jp.config.progress``).

    **Returns:** ``(base, param)``: ``base`` a :class:`TriMesh` ``T^0`` whose vertices are
    mesh vertices (``param.base_vertices``), and a :class:`ManifoldParameterization`
    (``param.remesh(levels)`` remeshes with subdivision connectivity).

    **Differentiation.**  The discrete stages (decimation, refinement, path tracing, surface
    triangles, the charts' connectivity) need concrete positions, so ``manifold_map`` itself
    is not traced: call it eagerly, then differentiate
    :meth:`ManifoldParameterization.with_vertices`: on the ``"paths"`` route it re-solves the
    charts for new positions with every discrete choice held fixed; on the ``"maps"`` route
    the charts (barycentric coordinates) are held fixed and the positions move.  Under
    ``jax.grad``/``jit``/``vmap`` (traced vertices) it raises :class:`MeshError` naming that
    route.

    Example::

        base, param = jp.manifold_map(mesh, base_faces=100)
        semi = param.remesh(3)
        # d(remesh) / d(mesh positions), the combinatorics fixed:
        g = jax.grad(lambda V: loss(param.with_vertices(V).remesh(2).mesh.vertices))(V0)
    """
    mesh = as_mesh(mesh, "manifold_map")
    if _traced(mesh.vertices):
        raise MeshError("manifold_map: the mesh's vertices are traced (under jax.grad, jit or vmap), "
                        "but the base domain, surface paths and charts' connectivity need concrete "
                        "positions. Compute `base, param = jp.manifold_map(mesh, base_faces)` "
                        "eagerly, then differentiate `param.with_vertices(V)` (it re-solves the "
                        "charts for positions V with the discrete choices held fixed).")
    method = choose(method, METHODS, what="method", where="manifold_map")
    check_closed_manifold(mesh)
    refuse_zero_area(mesh, "manifold_map")
    t = mesh.topology
    least = fewest_faces(t.genus)
    if least >= t.n_faces:
        raise MeshError(f"manifold_map: this genus-{t.genus} mesh has {t.n_faces} faces, and a "
                        f"base domain of genus {t.genus} needs at least {least}: there is nothing "
                        f"to decimate. Refine the mesh first (e.g. trimesh's subdivide).")
    if not (isinstance(base_faces, (int, np.integer)) and base_faces % 2 == 0
            and least <= base_faces < t.n_faces):
        hint = ""
        if isinstance(base_faces, (int, np.integer)) and base_faces >= t.n_faces:
            hint = f" Pass a smaller even count (e.g. {max(least, (t.n_faces // 4) * 2)})."
        raise MeshError(f"manifold_map: base_faces must be an even integer in [{least}, "
                        f"{t.n_faces}) for this genus-{t.genus} mesh of {t.n_faces} faces, got "
                        f"{base_faces!r}.{hint}")
    weights = choose(weights, wts.KINDS, what="weights", where="manifold_map")
    if method == "maps":
        return _maps_route(mesh, int(base_faces), verbose)
    kept, F0 = decimate(mesh, int(base_faces))
    base_topo = topo.build(F0, kept.size, where="manifold_map")
    if base_topo.genus != t.genus:                      # the link condition should prevent it
        raise SolverError(f"manifold_map: the base domain has genus {base_topo.genus}, the mesh "
                          f"{t.genus}.", stage="decimate")
    steps: list = []
    W = room_for_paths(mesh, kept, base_topo, int(base_faces), steps)
    # A path can find its corridor walled off by earlier ones where the surface is narrow
    # in vertices: refine everywhere (4x the vertices, the surface unchanged) and retrace.
    for attempt in range(3):
        try:
            paths = trace_paths(W, kept, base_topo)
            region = surface_triangles(W, kept, F0, base_topo, paths)
            _, vface, _, system = charts(W, kept, F0, base_topo, paths, region, weights)
            break
        except SolverError:
            if attempt == 2 or W.n_vertices > 100_000:     # bounded work when it fails
                raise
            W = refine_all(W, steps)
    # The positions and charts returned are those with_vertices computes (the same code),
    # so param.with_vertices(mesh.vertices) reproduces param exactly.
    S = ManifoldStructure(mesh.n_vertices, tuple(steps), W.topology, system)
    W, face_uv, vbary = _solve(S, np.asarray(mesh.vertices), W.name)
    S = replace(S, located_uv=face_uv)
    base = TriMesh(np.asarray(mesh.vertices)[kept], F0, base_topo, validate=False, name="base_domain")
    return base, ManifoldParameterization(W, kept, F0, region, face_uv, vface, vbary, S)


def _maps_route(mesh: TriMesh, base_faces: int, verbose):
    """:func:`manifold_map` with ``method="maps"``: one base domain per area cap (the first
    only above :data:`SELECT_MAX_FACES` faces or :data:`SELECT_MAX_REMESH_FACES` remesh
    faces), the one whose default level :data:`SELECT_LEVEL` remesh is estimated closest to
    the input kept."""
    V = np.asarray(mesh.vertices, np.float64)
    Fm = np.asarray(mesh.faces, np.int64)
    choose = (mesh.n_faces <= SELECT_MAX_FACES
              and base_faces * 4 ** SELECT_LEVEL <= SELECT_MAX_REMESH_FACES)
    caps = (AREA_CAPS if choose else (LARGE_MESH_CAP,) if mesh.n_faces > SELECT_MAX_FACES
            else AREA_CAPS[:1])
    best, sharp = None, None
    # The decimations run together while they make the same collapses (issue 13); each
    # result is the one decimating with its cap alone gives, or the error it raises.
    for decimated in decimate_caps(decision_positions(V, Fm), Fm, base_faces, caps, verbose=verbose):
        if isinstance(decimated, SolverError):
            raise decimated
        out = _maps_param(mesh, V, decimated)
        if len(caps) == 1:
            return out
        if sharp is None:
            sharp = sharpest_vertices(V, Fm)
        samples = out[1]._samples(SELECT_LEVEL, None, snap=False)   # snapped and contracted once chosen
        semi = out[1]._remesh_from(*samples)
        err = estimated_distance(V, Fm, sharp, np.asarray(semi.mesh.vertices), semi.mesh.faces)
        if best is None or err < best[0]:
            best = (err, out, samples)
    # Keep the chosen remesh's samples (issue 13): param.remesh(SELECT_LEVEL), which the CLI
    # and most callers ask for next, then only lifts them (the same arrays, not relaxed again).
    _, (base, param), (H, r, b, pulled) = best
    if SNAP_ROUNDS:
        r, b, pulled = _finish_chosen(param, SELECT_LEVEL, H, r, b, pulled)
    S = replace(param.structure, samples=((SELECT_LEVEL, r, b, pulled),))
    return base, replace(param, structure=S)


def _maps_param(mesh: TriMesh, V: np.ndarray, decimated):
    """``(base, param)`` of a MAPS decimation's result ``decimated``."""
    kept, F0, vface, vbary, history = decimated
    base_topo = topo.build(F0, kept.size, where="manifold_map")
    if base_topo.genus != mesh.topology.genus:          # the link condition prevents it
        raise SolverError(f"manifold_map: the base domain has genus {base_topo.genus}, the mesh "
                          f"{mesh.topology.genus}.", stage="decimate")
    U = unfolding(F0, kept.size, base_charts(V[kept], F0))
    region, face_uv = draw_faces(mesh.faces, vface, vbary, U)
    S = ManifoldStructure(mesh.n_vertices, (), mesh.topology, None, located_uv=face_uv,
                          method="maps", vertex_bary=vbary, history=history, positions=V)
    base = TriMesh(V[kept], F0, base_topo, validate=False, name="base_domain")
    W = TriMesh(V, mesh.faces, mesh.topology, validate=False, name=mesh.name)
    return base, ManifoldParameterization(W, kept, F0, region, face_uv, vface, vbary, S)
