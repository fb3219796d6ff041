"""The :class:`Atlas` result and its statistics."""
from __future__ import annotations

from dataclasses import dataclass, field

import jax
import numpy as np

from .. import host
from .pack import Packing

__all__ = ["Atlas", "AtlasStats", "atlas_stats"]


@dataclass(frozen=True)
class AtlasStats:
    """Figures of an :class:`Atlas` (all measured on the packed UVs).

    **Fields:** ``charts``; ``seam_edges`` (mesh edges cut, mesh boundary excluded);
    ``seam_length`` (3D length of the seams) and ``seam_length_rel`` (over sqrt of the 3D
    area); ``sym_dirichlet`` (area-weighted mean of ``s1^2 + s2^2 + s1^-2 + s2^-2`` with the
    UVs scaled to the 3D area: 4 for an isometry, the library's convention; xatlas
    comparisons halve it); ``max_aspect`` (largest ``s1/s2``); ``coverage`` (UV area over
    the unit square's); ``flips`` (faces of non-positive UV area); ``overlaps`` (boundary
    self-crossings of the charts before packing); ``mirrored`` (charts of negative total
    UV area); ``uv_vertices``; ``seconds`` (per stage: charts, start, minimize, pack, total).
    """

    charts: int
    seam_edges: int
    seam_length: float
    seam_length_rel: float
    sym_dirichlet: float
    max_aspect: float
    coverage: float
    flips: int
    overlaps: int
    mirrored: int
    uv_vertices: int
    splits: int
    seconds: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        from dataclasses import asdict
        return asdict(self)


@jax.tree_util.register_pytree_node_class
@dataclass(frozen=True, eq=False)
class Atlas:
    """A UV atlas: per-corner UVs, charts and seams of a mesh whose vertices stay as they were.

    **Fields:**

    - ``uv (n_uv, 2)``: UV vertices in ``[0, 1]^2``; ``uv_faces (m, 3)``: for each face, its
      corners' rows of ``uv`` (so face ``f`` is ``faces[f]`` in 3D and ``uv[uv_faces[f]]``
      in UV; ``jp.save(path, mesh, atlas.uv, uv_faces=atlas.uv_faces)`` writes ``f v/vt``).
    - ``vertex (n_uv,)``: the mesh vertex each UV vertex belongs to
      (``vertex[uv_faces] == faces``); ``uv_chart (n_uv,)``: its chart.
    - ``chart (m,)``: each face's chart, ``0..charts-1``.
    - ``seams (s, 2)``: the cut mesh edges (vertex pairs, ``a < b``).
    - ``chart_uv (n_uv, 2)``: each chart's own map at 3D scale, before packing.
    - ``packing``: the :class:`~jaxparam.atlas.pack.Packing` (rotation, offset, scale).
    - ``energy``: the energy's name; ``stats``: :class:`AtlasStats`.

    A pytree: ``uv`` and ``chart_uv`` are its leaves, the rest static.
    """

    uv: object
    uv_faces: np.ndarray
    vertex: np.ndarray
    uv_chart: np.ndarray
    chart: np.ndarray
    seams: np.ndarray
    chart_uv: object
    packing: Packing
    energy: object
    stats: AtlasStats

    @property
    def n_charts(self) -> int:
        return int(self.stats.charts)

    def tree_flatten(self):
        return (self.uv, self.chart_uv), (self.uv_faces, self.vertex, self.uv_chart, self.chart,
                                          self.seams, self.packing, self.energy, self.stats)

    @classmethod
    def tree_unflatten(cls, aux, children):
        uv, chart_uv = children
        uf, vx, uc, ch, se, pk, en, st = aux
        return cls(uv, uf, vx, uc, ch, se, chart_uv, pk, en, st)


def atlas_stats(V: np.ndarray, faces: np.ndarray, uv: np.ndarray, uv_faces: np.ndarray,
                chart: np.ndarray, seams: np.ndarray, overlaps: int, splits: int,
                seconds: dict) -> AtlasStats:
    """The :class:`AtlasStats` of packed UVs."""
    # NumPy twins (jaxparam.host): no kernel compiled for the atlas's shapes (issue 18).
    V = np.asarray(V, np.float64)
    uv = np.asarray(uv, np.float64)
    a3 = host.face_areas(V, faces)
    auv = host.signed_areas(uv, uv_faces)
    A3, Auv = float(a3.sum()), float(auv.sum())
    k = int(chart.max()) + 1
    per_chart = np.bincount(chart, weights=auv, minlength=k)
    corners = np.arange(3 * faces.shape[0]).reshape(-1, 3)      # faces and UV faces corner by corner
    q = host.face_quantities(V[faces].reshape(-1, 3), corners,
                             (uv * np.sqrt(A3 / Auv))[uv_faces].reshape(-1, 2))
    s1, s2 = q["s1"], q["s2"]
    with np.errstate(divide="ignore", invalid="ignore"):
        sd = s1 ** 2 + s2 ** 2 + s1 ** -2.0 + s2 ** -2.0
        aspect = np.abs(s1) / np.abs(s2)
    seam_len = float(np.linalg.norm(V[seams[:, 0]] - V[seams[:, 1]], axis=1).sum()) if len(seams) else 0.0
    return AtlasStats(
        charts=k, seam_edges=int(len(seams)), seam_length=seam_len,
        seam_length_rel=seam_len / np.sqrt(A3), sym_dirichlet=float(np.sum(sd * a3) / A3),
        max_aspect=float(np.max(aspect)), coverage=Auv, flips=int(np.sum(auv <= 0)),
        overlaps=int(overlaps), mirrored=int(np.sum(per_chart <= 0)), uv_vertices=int(uv.shape[0]),
        splits=int(splits), seconds=dict(seconds))
