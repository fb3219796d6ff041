"""Step 4 of :mod:`jaxparam.manifold`: the parameterization object, its remesh, and :func:`manifold_map`."""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .. import topology as topo
from .. import weights as wts
from ..errors import MeshError, SolverError, TopologyError
from ..mesh import TriMesh
from ..remesh import Remesh
from ..subdivision import dyadic_hierarchy, split_corner_values
from ..triangles import locate
from .charts import REFERENCE, charts, surface_triangles
from .decimate import decimate
from .paths import refine_all, room_for_paths, trace_paths

__all__ = ["ManifoldParameterization", "manifold_map"]


class _Static(tuple):
    """Arrays as pytree static data: equal when they are the same array objects, so jit's
    cache recognizes a parameterization without comparing (or hashing) array contents."""

    def __hash__(self):
        return hash(tuple(map(id, self)))

    def __eq__(self, other):
        return (isinstance(other, _Static) and len(self) == len(other)
                and all(a is b for a, b in zip(self, other)))


_CHART_FIELDS = ("base_vertices", "base_faces", "region", "face_uv", "vertex_face", "vertex_bary")


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
      reference triangle :data:`~jaxparam.manifold.REFERENCE`);
    - ``vertex_face (n,)``, ``vertex_bary (n, 3)``: a base face of each vertex and its
      barycentric coordinates there (``phi^{-1}`` of the vertex).

    A JAX pytree whose leaf is ``mesh`` (its vertex positions): the chart data are concrete
    numpy, static data, so :meth:`lift` is differentiable in the mesh's positions.
    """

    mesh: TriMesh
    base_vertices: np.ndarray
    base_faces: np.ndarray
    region: np.ndarray
    face_uv: np.ndarray
    vertex_face: np.ndarray
    vertex_bary: np.ndarray

    def tree_flatten(self):
        return (self.mesh,), _Static(getattr(self, f) for f in _CHART_FIELDS)

    @classmethod
    def tree_unflatten(cls, static, children):
        return cls(children[0], *static)

    def remesh(self, levels: int = 3) -> Remesh:
        """The ``levels``-fold dyadic refinement of ``T^0`` mapped onto the surface (§9,
        Fig. 26 (c)), each vertex through its base triangle's chart (eq. (11)).

        **Returns:** a :class:`~jaxparam.remesh.Remesh`: ``.mesh`` a closed :class:`TriMesh`
        with subdivision connectivity whose vertices lie on the surface (no UVs: a closed
        remesh has no plane domain), ``.hierarchy`` for :mod:`jaxparam.wavelets`."""
        if not (isinstance(levels, (int, np.integer)) and 0 <= levels <= 8):
            raise MeshError(f"manifold remesh: levels must be an integer in [0, 8], got {levels!r}.")
        F0 = np.asarray(self.base_faces, np.int64)
        H = dyadic_hierarchy(F0, int(F0.max()) + 1, levels)
        bary = np.broadcast_to(np.eye(3), (F0.shape[0], 3, 3)).copy()   # corner -> bary in base face
        for _ in range(levels):
            bary = split_corner_values(bary)
        F = H.faces[-1]
        base_of_face = np.arange(F.shape[0]) // (4 ** levels)
        # One corner per vertex gives its base face and barycentric coordinates.
        corner = np.full(H.counts[-1], -1, np.int64)
        corner[F.ravel()[::-1]] = np.arange(F.size)[::-1]
        r = base_of_face[corner // 3]
        q = bary.reshape(-1, 3)[corner] @ REFERENCE
        X = self.lift(r, q)
        return Remesh(TriMesh(X, F, validate=False, name="manifold_remesh"), H)

    def lift(self, region: np.ndarray, uv: np.ndarray):
        """Surface points ``(k, 3)`` of chart points ``uv (k, 2)`` in base faces ``region (k,)``.

        Every chart is the reference triangle; the charts are laid out side by side in one
        plane so a single point location serves all of them."""
        m0 = self.base_faces.shape[0]
        cols = int(np.ceil(np.sqrt(m0)))
        offset = 2.0 * np.stack([np.arange(m0) % cols, np.arange(m0) // cols], 1)
        corners = (self.face_uv + offset[self.region][:, None, :]).reshape(-1, 2)
        tri = np.arange(corners.shape[0]).reshape(-1, 3)
        face, b = locate(corners, tri, np.asarray(uv) + offset[np.asarray(region)])
        idx = jnp.asarray(self.mesh.faces[face])
        return jnp.einsum("kc,kcd->kd", jnp.asarray(b), jnp.asarray(self.mesh.vertices)[idx])


def manifold_map(mesh: TriMesh, base_faces: int = 100, *, weights: str = "mean_value"):
    """Parameterize a closed mesh of any genus over a decimated base domain (survey §9).

    **Arguments:** ``mesh`` closed, one component, orientable; ``base_faces`` the size of the
    base domain ``T^0`` (even; at least ``4`` for genus 0 and about ``14 g + 10`` for genus
    ``g``); ``weights`` the convex-combination weights inside the surface triangles.

    **Returns:** ``(base, param)``: ``base`` a :class:`TriMesh` ``T^0`` whose vertices are
    mesh vertices (``param.base_vertices``), and a :class:`ManifoldParameterization`
    (``param.remesh(levels)`` remeshes with subdivision connectivity).

    Example::

        base, param = jp.manifold_map(mesh, base_faces=100)
        semi = param.remesh(3)
    """
    t = mesh.topology
    if not t.is_closed:
        raise TopologyError(f"manifold_map: the mesh has {len(t.boundary_loops)} boundary loops; "
                            "it needs a closed surface (disks: jp.convex_map and jp.remesh).")
    if t.n_components != 1:
        raise TopologyError(f"manifold_map: the mesh has {t.n_components} connected components; "
                            "parameterize each on its own.")
    least = 4 if t.genus == 0 else 14 * t.genus + 10
    if not (isinstance(base_faces, (int, np.integer)) and base_faces % 2 == 0
            and least <= base_faces < t.n_faces):
        raise MeshError(f"manifold_map: base_faces must be an even integer in [{least}, "
                        f"{t.n_faces}) for this genus-{t.genus} mesh of {t.n_faces} faces, got "
                        f"{base_faces!r}.")
    if weights not in wts.KINDS:
        raise MeshError(f"manifold_map: unknown weights {weights!r}; use one of {wts.KINDS}.")
    kept, F0 = decimate(mesh, int(base_faces))
    base_topo = topo.build(F0, kept.size, where="manifold_map")
    if base_topo.genus != t.genus:                      # the link condition should prevent it
        raise SolverError(f"manifold_map: the base domain has genus {base_topo.genus}, the mesh "
                          f"{t.genus}.", stage="decimate")
    W = room_for_paths(mesh, kept, base_topo, int(base_faces))
    # A path can find its corridor walled off by earlier ones where the surface is narrow
    # in vertices: refine everywhere (4x the vertices, the surface unchanged) and retrace.
    for attempt in range(3):
        try:
            paths = trace_paths(W, kept, base_topo)
            region = surface_triangles(W, kept, F0, base_topo, paths)
            face_uv, vface, vbary = charts(W, kept, F0, base_topo, paths, region, weights)
            break
        except SolverError:
            if attempt == 2 or W.n_vertices > 100_000:     # bounded work when it fails
                raise
            W = refine_all(W)
    base = TriMesh(np.asarray(mesh.vertices)[kept], F0, base_topo, validate=False, name="base_domain")
    return base, ManifoldParameterization(W, kept, F0, region, face_uv, vface, vbary)
