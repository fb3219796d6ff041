"""Disk topology for the disk methods: the check that a mesh is a disk, and hole filling.

:func:`disk_check` refuses meshes that are not one connected genus-0 surface with a boundary,
naming what is wrong and what to do; :func:`fill_holes` closes every boundary loop but the
longest with a fan, so a disk with holes can be mapped with the longest loop as its boundary.
Used by :mod:`jaxparam.linear`, :mod:`jaxparam.optimize`, :mod:`jaxparam.remesh` and the CLI.
"""
from __future__ import annotations

import numpy as np

from .lazy_jax import jax, jnp  # JAX loads on first use (issue 17)
from . import topology as topo
from .errors import MeshError, TopologyError, first_few
from .mesh import TriMesh, refuse_zero_area

__all__ = ["disk_check", "fill_holes", "unstitched", "check_remesh_input"]


def disk_check(mesh: TriMesh, where: str) -> None:
    """Raise :class:`TopologyError` unless the mesh is one connected surface with a boundary."""
    t = mesh.topology
    if t.n_components > 1:
        sizes = np.bincount(t.components[t.components >= 0])
        raise TopologyError(
            f"{where}: the mesh has {t.n_components} connected components (vertex counts "
            f"{first_few(sizes.tolist())}); {_or(unstitched(mesh))}parameterize each on its "
            "own (e.g. trimesh's split) or keep the largest; for texture coordinates of the "
            "whole mesh, make a UV atlas (jp.atlas, jaxparam atlas).")
    if t.is_closed:
        raise TopologyError(
            f"{where}: the mesh is closed (no boundary, genus {t.genus}); a disk method needs a "
            "boundary: cut the mesh open along a path, or parameterize it over a base domain with "
            "jp.manifold_map (closed meshes of any genus), or make a UV atlas of charts with "
            "jp.atlas (jaxparam atlas).")
    if t.genus != 0:
        raise TopologyError(
            f"{where}: the mesh has genus {t.genus} with {len(t.boundary_loops)} boundary loops; a "
            "disk method needs genus 0: cut the handles open first, or make a UV atlas of charts "
            "with jp.atlas (jaxparam atlas).")


def _or(remedy: str | None) -> str:
    return f"{remedy}, or " if remedy else ""


def unstitched(mesh: TriMesh) -> str | None:
    """A sentence naming coincident vertices of different components (faces that meet but are
    not stitched, e.g. a triangle soup), with the remedy; None when there are none or the
    positions are traced."""
    if isinstance(mesh.vertices, jax.core.Tracer):
        return None
    t = mesh.topology
    V = np.asarray(mesh.vertices)[t.referenced]
    ids = np.flatnonzero(t.referenced)
    _, first, inv = np.unique(V, axis=0, return_index=True, return_inverse=True)
    twin = ids[first[inv.reshape(-1)]]                   # each vertex's first equal vertex
    split = np.flatnonzero((twin != ids) & (t.components[twin] != t.components[ids]))
    if not split.size:
        return None
    a, b = int(twin[split[0]]), int(ids[split[0]])
    return (f"vertices {a} and {b} coincide but lie in different components ({split.size} such "
            "copies in all): the faces are not stitched (a triangle soup, as STL exporters write); "
            "merge coincident vertices first (trimesh.Trimesh(V, F) does, with its default "
            "process=True)")


def fill_holes(mesh: TriMesh) -> tuple[TriMesh, int]:
    """Close every boundary loop but the longest with a fan around a new centre vertex.

    **Returns:** ``(filled, n_added)``: the new mesh (its first ``n`` vertices
    are the original ones, in order; the centres, at the loops' centroids, follow).
    """
    t = mesh.topology
    holes = t.boundary_loops[1:]
    if not holes:
        return mesh, 0
    n = t.n_vertices
    centres = []
    faces = [t.faces]
    for h, loop in enumerate(holes):
        c = n + h
        # The hole's boundary edges run a -> b with the surface on their left: the fan uses b -> a.
        faces.append(np.stack([np.roll(loop, -1), loop, np.full(loop.size, c)], axis=1))
        centres.append(loop)
    if isinstance(mesh.vertices, jax.core.Tracer):
        C = jnp.stack([jnp.mean(mesh.vertices[l], axis=0) for l in centres])
        V = jnp.concatenate([mesh.vertices, C], axis=0)
    else:
        V0 = np.asarray(mesh.vertices)
        V = np.concatenate([V0, np.stack([V0[l].mean(0) for l in centres])])
    F = np.concatenate(faces)
    filled = TriMesh(V, F, topo.build(F, n + len(holes), where="fill_holes"), validate=False)
    return filled, len(holes)


def check_remesh_input(mesh: TriMesh, levels, *, base_faces=6, corners=None) -> None:
    """Refuse what :func:`jaxparam.remesh.remesh` cannot remesh, before any work
    (:class:`MeshError` or :class:`TopologyError`): not a disk (closed, several components, several boundary loops),
    zero-area faces, ``levels`` outside ``[0, 10]``, ``base_faces`` not an integer, or both
    ``base_faces`` and ``corners``.  ``jaxparam remesh`` calls it before its map (an annulus
    got "the convex map folds" after the map's work, a levels of -1 took 9 s to refuse;
    session 27)."""
    if corners is not None and base_faces != 6:
        raise MeshError("remesh: pass base_faces or corners, not both (corners is base_faces' "
                        "alias that also takes positions in the boundary loop).")
    if not isinstance(base_faces, (int, np.integer)):
        raise MeshError(f"remesh: base_faces must be an integer (the fan's corner count), got "
                        f"{base_faces!r}; pass positions in the boundary loop as corners=.")
    if not (isinstance(levels, (int, np.integer)) and 0 <= levels <= 10):
        raise MeshError(f"remesh: levels must be an integer in [0, 10], got {levels!r}.")
    disk_check(mesh, "remesh")
    refuse_zero_area(mesh, "remesh")
    loops = len(mesh.topology.boundary_loops)
    if loops != 1:
        raise MeshError(f"remesh: the mesh has {loops} boundary loops; remeshing needs a disk "
                        "(one boundary loop): fill the holes first (e.g. trimesh's fill_holes).")
