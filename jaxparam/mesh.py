"""``TriMesh``: vertices, faces and their topology (files: :mod:`jaxparam.io`).

A ``TriMesh`` is immutable and a JAX pytree whose only array leaves are the
vertex positions (and the UVs, when it carries them): the faces and the
:class:`~jaxparam.topology.Topology` travel as static data, so a ``TriMesh``
passes through ``jax.jit`` and ``jax.grad`` and a new mesh of the same
connectivity reuses compiled code.

UVs come in two kinds.  ``mesh.uv`` is per vertex, ``(n, 2)``: what every map of the
library returns.  A file may also hold per-corner UVs (an OBJ's ``f a/b c/d e/f`` with
several ``vt`` at one vertex, a texture atlas with seams): those are ``mesh.texcoords``,
a ``(t, 2)`` table, with ``mesh.uv_faces``, ``(m, 3)`` rows into it, one per face
corner.  When the per-corner UVs agree at every vertex the loaders give ``mesh.uv``
instead.
"""
from __future__ import annotations

import numpy as np

from .lazy_jax import jax, jnp  # JAX loads on first use (issue 17)
from . import tol
from . import topology as topo
from .errors import DegenerateFaceError, MeshError, first_few

__all__ = ["TriMesh", "grid_faces", "concrete_values", "zero_area_faces", "refuse_zero_area"]


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def concrete_values(a):
    """``a`` as a host array when its value is known now (a constant, or a tracer of
    ``jax.grad`` / ``jax.jvp`` whose primal is concrete), else ``None`` (under ``jax.jit`` or
    ``jax.vmap``)."""
    if not isinstance(a, jax.core.Tracer):
        return np.asarray(a, np.float64)
    try:
        return np.asarray(jax.lax.stop_gradient(a), np.float64)
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return None


@jax.tree_util.register_pytree_node_class
class TriMesh:
    """A triangle mesh: ``vertices (n, 3) float``, ``faces (m, 3) int``, ``topology``.

    **Arguments:**

    - ``vertices``: ``(n, 3)`` (or ``(n, 2)``, lifted to z = 0) float positions;
      numpy, JAX arrays and tracers are accepted.
    - ``faces``: ``(m, 3)`` integer, counter-clockwise, concrete.
    - ``uv``: optional ``(n, 2)`` per-vertex texture coordinates carried along (from an
      OBJ's ``vt``, a PLY's ``u``/``v``, a glTF's ``TEXCOORD_0``).
    - ``texcoords``, ``uv_faces``: optional per-corner UVs, given together: a ``(t, 2)``
      float table and ``(m, 3)`` integer rows into it (corner ``k`` of face ``f`` has UV
      ``texcoords[uv_faces[f, k]]``), as a seamed OBJ holds them.  ``texcoords`` is a pytree
      leaf, ``uv_faces`` static.
    - ``validate``: check coordinates and face areas (needs concrete vertices; skipped for tracers).

    Raises :class:`MeshError` subclasses naming the offending element: non-finite
    coordinates, indices out of range, repeated vertices, zero-area faces,
    non-manifold edges or vertices, inconsistent orientation.

    Example::

        mesh = TriMesh(np.random.rand(3, 3), [[0, 1, 2]])
        mesh.topology.boundary_loops
    """

    def __init__(self, vertices, faces, topology=None, *, uv=None, validate: bool = True,
                 name: str | None = None, texcoords=None, uv_faces=None):
        if _is_concrete(vertices) and not isinstance(vertices, jax.Array):
            V = np.asarray(vertices)
            if V.dtype == object or not (np.issubdtype(V.dtype, np.number)):
                raise MeshError(f"TriMesh: vertices must be numbers, got dtype {V.dtype}.")
            if np.iscomplexobj(V):
                raise MeshError(f"TriMesh: vertices must be real numbers, got dtype {V.dtype}; "
                                "pass their real part (V.real) if that is what you mean.")
            V = V.astype(np.float64, copy=False)
        else:
            V = vertices
        if V.ndim != 2 or V.shape[1] not in (2, 3):
            raise MeshError(f"TriMesh: vertices must have shape (n, 3), got {tuple(V.shape)}.")
        if V.shape[1] == 2:
            V = (np.concatenate if isinstance(V, np.ndarray) else jnp.concatenate)(
                [V, (np.zeros if isinstance(V, np.ndarray) else jnp.zeros)((V.shape[0], 1))], axis=1)
        if topology is None:
            topology = topo.build(faces, V.shape[0])
        elif topology.n_vertices != V.shape[0]:
            raise MeshError(f"TriMesh: topology has {topology.n_vertices} vertices, vertices has {V.shape[0]}.")
        self.vertices = V
        self.topology = topology
        self.uv = uv
        self.name = name
        self.texcoords, self._uv_faces = _corner_uv(texcoords, uv_faces, topology.n_faces)
        if validate and _is_concrete(V):
            self._validate_geometry(np.asarray(V))

    # -- pytree ---------------------------------------------------------------------------
    def tree_flatten(self):
        return (self.vertices, self.uv, self.texcoords), (self.topology, self.name, self._uv_faces)

    @classmethod
    def tree_unflatten(cls, aux, children):
        obj = object.__new__(cls)
        obj.vertices, obj.uv, obj.texcoords = children
        obj.topology, obj.name, obj._uv_faces = aux
        return obj

    # -- convenience ----------------------------------------------------------------------
    @property
    def faces(self) -> np.ndarray:
        """``(m, 3) int64`` face array."""
        return self.topology.faces

    @property
    def uv_faces(self) -> np.ndarray | None:
        """``(m, 3) int64`` rows of :attr:`texcoords` per face corner, or ``None``."""
        return None if self._uv_faces is None else self._uv_faces.array

    @property
    def n_vertices(self) -> int:
        return self.topology.n_vertices

    @property
    def n_faces(self) -> int:
        return self.topology.n_faces

    def with_vertices(self, vertices) -> "TriMesh":
        """The same connectivity with new positions (no re-validation of topology)."""
        return TriMesh(vertices, None, self.topology, uv=self.uv, validate=False, name=self.name,
                       texcoords=self.texcoords, uv_faces=self._uv_faces)

    def with_uv(self, uv) -> "TriMesh":
        """The same mesh carrying the per-vertex ``uv: (n, 2)`` (per-corner UVs dropped)."""
        return TriMesh(self.vertices, None, self.topology, uv=uv, validate=False, name=self.name)

    def __repr__(self) -> str:
        t = self.topology
        return (f"TriMesh({t.n_vertices} vertices, {t.n_faces} faces, "
                f"{len(t.boundary_loops)} boundary loops, genus {t.genus}, "
                f"{t.n_components} component{'s' if t.n_components != 1 else ''})")

    def _validate_geometry(self, V: np.ndarray) -> None:
        F = self.faces
        bad = np.flatnonzero(~np.all(np.isfinite(V), axis=1))
        if bad.size:
            raise MeshError(f"TriMesh: vertices {first_few(bad)} have non-finite coordinates "
                            f"(vertex {int(bad[0])} is {tuple(float(x) for x in V[bad[0]])}); "
                            "remove or repair them before parameterizing.")
        zero = zero_area_faces(V, F)
        if zero.size:
            used = np.unique(F)
            distinct = np.unique(V[used], axis=0).shape[0]
            hint = ""
            if 2 * zero.size >= F.shape[0] and 2 * distinct <= used.size:
                # most faces flat because the coordinates themselves collapsed: a file's float32
                # values far from the origin keep about 7 digits (session 18: a mesh 1e-4 wide
                # at 5e3, written to PLY as float32, read back as one point)
                hint = (f" The {used.size} vertices have only {distinct} distinct position"
                        f"{'s' if distinct != 1 else ''} (vertex {int(used[0])} at "
                        f"{tuple(float(x) for x in V[used[0]])}): the coordinates lost their "
                        "precision; a float32 file keeps about 7 digits, so a small mesh far "
                        "from the origin collapses. Save it in float64 or near the origin.")
            raise DegenerateFaceError(
                f"TriMesh: faces {first_few(zero)} have zero area (face {int(zero[0])} = "
                f"{tuple(int(v) for v in F[zero[0]])}); collapse or remove them (e.g. with "
                "trimesh: m.update_faces(m.nondegenerate_faces())). TriMesh(..., validate=False) "
                "keeps them, but a map spends no area on them and a remesh may not follow "
                "the surface there."
                + hint)


def zero_area_faces(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """The faces of ``F (m, 3)`` over ``V (n, 3)`` whose area is zero relative to the mean edge
    length squared (:data:`jaxparam.tol.DEGENERATE_AREA_REL`), ascending."""
    e1 = V[F[:, 1]] - V[F[:, 0]]
    e2 = V[F[:, 2]] - V[F[:, 0]]
    area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
    scale = np.mean(np.concatenate([np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)])) ** 2
    return np.flatnonzero(area2 <= tol.DEGENERATE_AREA_REL * max(scale, np.finfo(float).tiny))


def refuse_zero_area(mesh: "TriMesh", where: str) -> None:
    """Raise :class:`DegenerateFaceError` when ``mesh`` (concrete vertices; one made with
    ``validate=False``) has faces of zero area: ``where``'s result would be silently wrong (a
    sphere with one flat face remeshed 27 % of its diagonal off, against 1.5 % without it)."""
    V = concrete_values(mesh.vertices)
    if V is None or mesh.n_faces == 0:
        return
    zero = zero_area_faces(np.asarray(V, np.float64), np.asarray(mesh.faces))
    if zero.size:
        raise DegenerateFaceError(
            f"{where}: faces {first_few(zero)} have zero area (face {int(zero[0])} = "
            f"{tuple(int(v) for v in mesh.faces[zero[0]])}; the mesh was made with "
            "validate=False); a map gives them no room and the result does not follow the "
            "surface around them: collapse or remove them first (e.g. with trimesh: "
            "m.update_faces(m.nondegenerate_faces())).")


class _StaticIndex:
    """An integer array held as static pytree data: hashed and compared by identity (as a
    ``Topology`` is), so a ``TriMesh`` with per-corner UVs passes through ``jax.jit``."""

    __slots__ = ("array",)

    def __init__(self, array: np.ndarray):
        self.array = array


def _corner_uv(texcoords, uv_faces, m: int):
    """Check and hold per-corner UVs: ``(texcoords (t, 2), _StaticIndex((m, 3)))`` or ``(None, None)``."""
    if texcoords is None and uv_faces is None:
        return None, None
    if texcoords is None or uv_faces is None:
        raise MeshError("TriMesh: per-corner UVs need both texcoords (t, 2) and uv_faces (m, 3); "
                        f"got only {'uv_faces' if texcoords is None else 'texcoords'}.")
    if isinstance(uv_faces, _StaticIndex):
        return texcoords, uv_faces
    T = np.asarray(uv_faces)
    if T.shape != (m, 3) or not np.issubdtype(T.dtype, np.integer):
        raise MeshError(f"TriMesh: uv_faces must be an (m, 3) = ({m}, 3) integer array, one row "
                        f"per face, got shape {T.shape} of dtype {T.dtype}.")
    if _is_concrete(texcoords) and not isinstance(texcoords, jax.Array):
        texcoords = np.asarray(texcoords, np.float64)
    if texcoords.ndim != 2 or texcoords.shape[1] != 2:
        raise MeshError(f"TriMesh: texcoords must have shape (t, 2), got {tuple(texcoords.shape)}.")
    bad = np.flatnonzero((T < 0).any(1) | (T >= texcoords.shape[0]).any(1))
    if bad.size:
        raise MeshError(f"TriMesh: uv_faces rows {first_few(bad)} point outside texcoords "
                        f"(row {int(bad[0])} = {tuple(int(v) for v in T[bad[0]])}, "
                        f"{texcoords.shape[0]} texcoords).")
    T = T.astype(np.int64)
    T.setflags(write=False)
    return texcoords, _StaticIndex(T)


def grid_faces(nu: int, nv: int) -> np.ndarray:
    """Faces of a ``nu x nv`` vertex grid (vertex ``i * nv + j``), two triangles a cell,
    diagonals alternating so the grid has no preferred direction."""
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    a = (i * nv + j).ravel()
    b, c, d = a + nv, a + nv + 1, a + 1
    flip = ((i + j) % 2 == 1).ravel()
    t1 = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
    t2 = np.where(flip[:, None], np.stack([b, c, d], 1), np.stack([a, c, d], 1))
    return np.concatenate([t1, t2]).astype(np.int64)
