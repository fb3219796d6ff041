"""Checks before :func:`~jaxparam.manifold.manifold_map` does any work, and the report of how
faithful its result is.

- :func:`check_closed_manifold` refuses, with the place named, a mesh that is not one closed,
  oriented 2-manifold (boundary loops, several components, unreferenced vertices);
  non-manifold edges and bowties are refused earlier by the mesh's own topology.
- :func:`fidelity` measures a remesh against its input: Hausdorff and RMS distances both
  ways relative to the bounding-box diagonal (:mod:`jaxparam.distance`), the worst area
  distortion of the map, how many pieces of the map turn over in the base domain, how many
  mesh faces turn over in their straight drawing, and how many input vertices miss their
  place in the base domain.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..disk import unstitched
from ..distance import point_triangle_distance, surface_distance
from ..errors import MeshError, TopologyError, first_few
from ..triangles import doubled_areas

__all__ = ["check_closed_manifold", "ManifoldReport", "fidelity", "folded_faces",
           "map_pieces_turned_over", "misplaced_vertices"]


def check_closed_manifold(mesh, where: str = "manifold_map") -> None:
    """Raise :class:`~jaxparam.errors.TopologyError` (a :class:`MeshError`) naming the place
    when ``mesh`` is not one closed, oriented 2-manifold without unused vertices."""
    t = mesh.topology
    soup = unstitched(mesh) if t.n_components > 1 else None
    if soup:
        # a triangle soup (an STL, an unwelded export) reads as open pieces: say why
        raise TopologyError(f"{where}: {soup}.")
    if not t.is_closed:
        loops = t.boundary_loops
        first = loops[0]
        raise TopologyError(
            f"{where}: the mesh has {len(loops)} boundary loop(s) (the longest has {first.size} "
            f"edges, through vertices {first_few(first.tolist())}); it needs a closed surface. "
            "Close the holes first (jp.disk.fill_holes), or use jp.convex_map and jp.remesh for "
            "a disk.")
    if t.n_components != 1:
        labels = t.components[t.referenced]
        sizes = np.bincount(labels)
        reps = [int(np.flatnonzero(t.components == c)[0]) for c in np.argsort(-sizes)[:4]]
        raise TopologyError(
            f"{where}: the mesh has {t.n_components} connected components (of "
            f"{first_few(np.sort(sizes)[::-1].tolist())} vertices; they contain vertices "
            f"{reps}); parameterize each on its own with "
            "jp.manifold.manifold_map_each(mesh, base_faces), one base domain per component.")
    unused = np.flatnonzero(~t.referenced)
    if unused.size:
        raise MeshError(f"{where}: vertices {first_few(unused.tolist())} belong to no face; "
                        "remove them (they have no place on the surface).")


@dataclass(frozen=True)
class ManifoldReport:
    """How faithful a closed remesh is (all distances relative to the input's bounding-box
    diagonal): ``hausdorff`` (both ways), ``hausdorff_in`` (input to remesh),
    ``hausdorff_out`` (remesh to input), ``rms_in``, ``rms_out``; ``area_distortion`` the
    worst, over base triangles, of ``max(x, 1/x)``, ``x`` the surface area mapped onto the
    base triangle over the triangle's own area, relative to the same ratio for the whole
    surface (1 for a map that spreads the area evenly); ``flipped`` the pieces of the map
    (the piecewise-linear map the remesh pulls its samples back through) that are turned over
    or degenerate in the base domain: on the ``"paths"`` route the mesh faces in their charts
    (``param.face_uv``), on the ``"maps"`` route the flattened triangles of every level of
    the decimation, before and after each collapse (each level's map is a bijection of its
    flat rings exactly when all are positive, :func:`map_pieces_turned_over`);
    ``drawn_flipped`` mesh faces whose straight drawing ``param.face_uv`` is turned over or
    missing (on the ``"maps"`` route the straight triangles between the corners' images, which
    the remesh does not use: the map's image of a face is bent, and on strongly distorted
    parts the straight triangle between its corners turns over: 0-86 of 5-12k faces on the
    closed shared meshes at 100 base faces, session 25, where the map has none);
    ``misplaced`` input vertices whose place in the base domain (``param.vertex_face``,
    ``param.vertex_bary``) is outside its base triangle or pulls back more than ``1e-9`` of
    the diagonal away from the vertex;
    ``folded`` remesh faces whose normal points away from the nearest input face's (a fold of
    the straight dyadic triangles, which the distances barely see: found on needle base
    triangles of a marching-cubes double torus, 34-48 of 25,600 faces at level 4, session 22);
    ``levels`` the remesh's level."""

    hausdorff: float
    hausdorff_in: float
    hausdorff_out: float
    rms_in: float
    rms_out: float
    area_distortion: float
    flipped: int
    levels: int
    folded: int = 0
    drawn_flipped: int = 0
    misplaced: int = 0

    @property
    def rms(self) -> float:
        """The larger of the two RMS distances (relative)."""
        return max(self.rms_in, self.rms_out)

    def as_dict(self) -> dict:
        return asdict(self)


def fidelity(param, semi, mesh, *, samples: int = 20_000, seed: int = 0,
             face_grid: int = 0) -> ManifoldReport:
    """The :class:`ManifoldReport` of remesh ``semi`` (a :class:`~jaxparam.remesh.Remesh`)
    of ``mesh`` through ``param`` (a :class:`~jaxparam.manifold.ManifoldParameterization`).
    ``samples``, ``seed`` and ``face_grid`` are
    :func:`~jaxparam.distance.surface_distance`'s (a grid on every face finds a large face's
    farthest point, which random samples can miss)."""
    V = np.asarray(mesh.vertices, np.float64)
    X = np.asarray(semi.mesh.vertices, np.float64)
    d = surface_distance(V, mesh.faces, X, semi.mesh.faces, samples=samples, seed=seed,
                         face_grid=face_grid)
    # Area distortion per base triangle: the surface area of the remesh faces above it.
    F = semi.mesh.faces
    area = 0.5 * np.linalg.norm(np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]]), axis=1)
    per = np.bincount(np.arange(F.shape[0]) // (4 ** semi.levels), weights=area)
    B = np.asarray(param.mesh.vertices, np.float64)[param.base_vertices][param.base_faces]
    base_area = 0.5 * np.linalg.norm(np.cross(B[:, 1] - B[:, 0], B[:, 2] - B[:, 0]), axis=1)
    ratio = (per / np.maximum(base_area, 1e-300)) * (base_area.sum() / max(per.sum(), 1e-300))
    worst = float(np.max(np.maximum(ratio, 1.0 / np.maximum(ratio, 1e-300))))
    drawn = int(np.sum(~(doubled_areas(np.asarray(param.face_uv)) > 0)))
    history = getattr(param.structure, "history", None)
    return ManifoldReport(hausdorff=d.hausdorff, hausdorff_in=d.hausdorff_ab, hausdorff_out=d.hausdorff_ba,
                          rms_in=d.rms_ab, rms_out=d.rms_ba, area_distortion=worst,
                          flipped=drawn if history is None else map_pieces_turned_over(history),
                          levels=int(semi.levels), folded=folded_faces(X, F, V, mesh.faces),
                          drawn_flipped=drawn, misplaced=misplaced_vertices(param))


def map_pieces_turned_over(history) -> int:
    """How many pieces of a MAPS decimation's map (``history`` a
    :class:`~jaxparam.manifold.maps.MapsHistory`) are turned over or degenerate: at every level
    the old faces of each collapsed ring flattened (``before``) and the faces that survive the
    collapse in the same plane (``after``).  A level maps each old flat triangle linearly onto
    the surface and each new one back, so with every triangle positive both tile the same flat
    polygon and the level is a bijection; 0 for the whole map."""
    bad = 0
    for _, _, survive, before, after in history.levels:
        bad += int(np.sum(~(doubled_areas(before) > 0)))
        bad += int(np.sum(~(doubled_areas(after[survive]) > 0)))
    return bad


def misplaced_vertices(param, tol: float = 1e-9) -> int:
    """How many input vertices have a place in the base domain (``param.vertex_face``,
    ``param.vertex_bary``) outside their base triangle (a negative or non-finite barycentric
    coordinate, beyond rounding) or, on the ``"maps"`` route, one that pulls back (the
    remesh's exact inverse) more than ``tol`` of the bounding-box diagonal away from the
    vertex."""
    b = np.asarray(param.vertex_bary, np.float64)
    off = ~np.all(np.isfinite(b) & (b >= -1e-12), axis=1)
    history = getattr(param.structure, "history", None)
    if history is not None:
        V = np.asarray(param.mesh.vertices, np.float64)
        face, bb = history.pull_back(np.asarray(param.vertex_face), np.where(np.isfinite(b), b, 0.0),
                                     verbose=False)
        X = np.einsum("kc,kcd->kd", bb, V[np.asarray(param.mesh.faces)[face]])
        diag = np.linalg.norm(V.max(0) - V.min(0))
        off |= np.linalg.norm(X - V, axis=1) > tol * diag
    return int(np.sum(off))


def folded_faces(X: np.ndarray, F: np.ndarray, V: np.ndarray, F_in: np.ndarray) -> int:
    """How many faces of the remesh ``(X, F)`` have a normal pointing away (negative dot
    product) from the sum of the unit normals of the input faces ``(V, F_in)`` its three
    corners lie on (the input face nearest each corner: a remesh's vertices are on the input
    surface, so on a thin part the face across it is not taken)."""
    n = np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]])
    N = np.cross(V[F_in[:, 1]] - V[F_in[:, 0]], V[F_in[:, 2]] - V[F_in[:, 0]])
    N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-300)
    _, near, _ = point_triangle_distance(X, V, F_in)
    return int(np.sum(np.einsum("ij,ij->i", n, N[near[F]].sum(1)) < 0))
