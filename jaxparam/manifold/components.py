"""A closed mesh of several components, parameterized one component at a time (survey §9).

:func:`~jaxparam.manifold.manifold_map` refuses a mesh of several components: one base
domain cannot span surfaces that do not touch.  :func:`manifold_map_each` splits the mesh
into its connected components (:attr:`jaxparam.topology.Topology.components`), checks every
one of them before any work is done, and returns one :class:`ComponentMap` per component,
each with its own base domain and :class:`~jaxparam.manifold.ManifoldParameterization`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..disk import unstitched
from ..errors import MeshError, SolverError
from ..io import as_mesh
from ..mesh import TriMesh
from .parameterization import ManifoldParameterization, fewest_faces, manifold_map
from .report import check_closed_manifold

__all__ = ["ComponentMap", "split_components", "manifold_map_each"]


@dataclass(frozen=True, eq=False)
class ComponentMap:
    """One component's parameterization.

    **Fields:** ``vertices (k,)`` the component's vertices (indices into the input mesh's,
    increasing: vertex ``i`` of ``param.mesh`` is input vertex ``vertices[i]``); ``faces
    (l,)`` its faces (indices into the input's faces, in the order of ``param.mesh.faces``);
    ``base`` the component's base domain ``T^0`` (a :class:`TriMesh`); ``param`` its
    :class:`~jaxparam.manifold.ManifoldParameterization` (``param.remesh(levels)``)."""

    vertices: np.ndarray
    faces: np.ndarray
    base: TriMesh
    param: ManifoldParameterization


def split_components(mesh: TriMesh) -> list[tuple[np.ndarray, np.ndarray, TriMesh]]:
    """The connected components of ``mesh`` as meshes of their own.

    **Returns:** per component, largest first (by faces; ties by the smallest vertex index),
    ``(vertices (k,), faces (l,), TriMesh)``: the input vertices and faces it holds and the
    component as a mesh (vertices renumbered in increasing input order)."""
    mesh = as_mesh(mesh, "split_components")
    t = mesh.topology
    F = np.asarray(mesh.faces, np.int64)
    V = np.asarray(mesh.vertices, np.float64)
    label = t.components[F[:, 0]]
    sizes = np.bincount(label, minlength=t.n_components)
    first = np.full(t.n_components, np.iinfo(np.int64).max)
    np.minimum.at(first, label, F[:, 0])
    out = []
    for c in np.lexsort((first, -sizes)):
        faces = np.flatnonzero(label == c)
        verts = np.unique(F[faces])
        out.append((verts, faces, TriMesh(V[verts], np.searchsorted(verts, F[faces]),
                                          name=f"{mesh.name or 'mesh'}[{len(out)}]")))
    return out


def _counts(base_faces, parts) -> list[int]:
    """Base faces per component: a total split by the components' faces, or one count each."""
    if isinstance(base_faces, (int, np.integer)):
        least = [fewest_faces(p[2].topology.genus) for p in parts]
        if len(parts) > 1 and base_faces < sum(least):
            # (each component's share was raised to its least, silently: 4 asked for two
            # spheres gave 8; session 27)
            raise MeshError(f"manifold_map_each: base_faces = {base_faces} is a total shared by the "
                            f"{len(parts)} components, which need at least {sum(least)} "
                            f"({', '.join(map(str, least))}, largest first, by genus); pass at "
                            f"least {sum(least)}, or one count per component.")
        total = sum(p[2].n_faces for p in parts)
        return [min(max(2 * int(round(base_faces * p[2].n_faces / total / 2)), fewest_faces(p[2].topology.genus)),
                    p[2].n_faces - 2) for p in parts]
    counts = list(base_faces)
    if len(counts) != len(parts):
        raise MeshError(f"manifold_map_each: base_faces gives {len(counts)} counts for a mesh of "
                        f"{len(parts)} components (largest first); give one per component or a total.")
    return counts


def manifold_map_each(mesh: TriMesh, base_faces=100, *, method: str = "maps",
                      verbose: bool | None = None) -> tuple[ComponentMap, ...]:
    """Parameterize every connected component of a closed mesh over a base domain of its own.

    **Arguments:** ``mesh`` closed and oriented, of one or more components (each one a closed
    2-manifold of any genus); ``base_faces`` either the total base faces, shared by the
    components in proportion to their faces (each count rounded to an even number, at least
    :func:`~jaxparam.manifold.fewest_faces` of the component's genus; a total below the sum of
    those is refused), or a sequence of one
    count per component, largest component first (as :func:`split_components` orders them);
    ``method`` and ``verbose`` as in :func:`~jaxparam.manifold.manifold_map`.

    **Returns:** one :class:`ComponentMap` per component, largest first.

    Every component is checked (closed, no unused vertices, a base-face count it allows)
    before any is parameterized, and a bad one raises :class:`~jaxparam.MeshError` naming
    it.  Example::

        for part in jp.manifold.manifold_map_each(mesh, base_faces=200):
            semi = part.param.remesh(3)          # part.vertices: its input vertices
    """
    mesh = as_mesh(mesh, "manifold_map_each")
    t = mesh.topology
    unused = np.flatnonzero(~t.referenced)
    soup = unstitched(mesh) if t.n_components > 1 else None
    if unused.size or soup:
        check_closed_manifold(mesh, where="manifold_map_each")     # raises, naming them
    parts = split_components(mesh)
    counts = _counts(base_faces, parts)
    for k, ((verts, _, sub), nb) in enumerate(zip(parts, counts)):
        check_closed_manifold(sub, where=f"manifold_map_each: component {k} (vertices from "
                                         f"{int(verts[0])}, {sub.n_faces} faces)")
        least = fewest_faces(sub.topology.genus)
        if not (isinstance(nb, (int, np.integer)) and nb % 2 == 0 and least <= nb < sub.n_faces):
            raise MeshError(f"manifold_map_each: component {k} (vertices from {int(verts[0])}, genus "
                            f"{sub.topology.genus}, {sub.n_faces} faces) needs an even base-face count in "
                            f"[{least}, {sub.n_faces}), got {nb!r}; give more faces to it (one count per "
                            "component) or leave it out of the mesh.")
    result = []
    for k, ((verts, faces, sub), nb) in enumerate(zip(parts, counts)):
        try:
            base, param = manifold_map(sub, int(nb), method=method, verbose=verbose)
        except SolverError as exc:
            # The advice of one component's failure ("ask for more than N base faces") is
            # about its own share, which the caller does not give when base_faces is a total.
            raise SolverError(
                f"manifold_map_each: component {k} (vertices from {int(verts[0])}, genus "
                f"{sub.topology.genus}, {sub.n_faces} faces), given {int(nb)} of the base faces "
                f"{list(map(int, counts))} (largest component first): {exc} Pass one count per "
                "component (base_faces=[...]; on the command line, a larger total).",
                stage=exc.stage) from None
        result.append(ComponentMap(verts, faces, base, param))
    return tuple(result)
