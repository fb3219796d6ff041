"""Meshes from and to ``trimesh``, and :func:`as_mesh`, which every mesh-taking function
calls on its argument so a ``TriMesh``, a ``trimesh.Trimesh`` and a ``(vertices, faces)``
pair are all accepted.

``trimesh`` is imported only when a conversion needs it.  Conversions keep the vertex order
and merge nothing (``process=False``); note that ``trimesh.Trimesh(V, F)`` itself merges
duplicate vertices unless built with ``process=False``, before jaxparam sees it.
"""
from __future__ import annotations

import sys

import numpy as np

from ..errors import ArgumentTypeError, MeshError
from ..mesh import TriMesh

__all__ = ["to_trimesh", "from_trimesh", "as_mesh", "split_seams"]


def _is_trimesh(obj) -> bool:
    """Whether ``obj`` is a ``trimesh.Trimesh`` (without importing trimesh: an object can be
    one only when trimesh is already imported)."""
    mod = sys.modules.get("trimesh")
    return mod is not None and isinstance(obj, mod.Trimesh)


def split_seams(F, texcoords, uv_faces):
    """Split vertices where per-corner UVs differ, for formats with one UV per vertex.

    **Arguments:** ``F: (m, 3)`` faces, ``texcoords: (t, 2)``, ``uv_faces: (m, 3)``.
    **Returns:** ``(source (n', ) int64, faces (m, 3), uv (n', 2))``: new vertex ``i`` is a
    copy of old vertex ``source[i]``; one new vertex per distinct (vertex, UV index) pair,
    ordered by old vertex (so ``source`` is non-decreasing and a mesh without seams keeps
    its order; vertices in no face are left out).
    """
    F = np.asarray(F, np.int64)
    T = np.asarray(uv_faces, np.int64)
    key = F.reshape(-1) * np.int64(max(int(T.max(initial=0)) + 1, 1)) + T.reshape(-1)
    uniq, first, inv = np.unique(key, return_index=True, return_inverse=True)
    source = F.reshape(-1)[first]
    uv = np.asarray(texcoords, np.float64)[T.reshape(-1)[first]]
    return source, inv.reshape(F.shape).astype(np.int64), uv


def to_trimesh(mesh, uv=None, *, texture=None):
    """A ``trimesh.Trimesh`` with the mesh's vertices and faces in its order (``process=False``,
    nothing merged) and its UVs as ``TextureVisuals``.

    **Arguments:** ``mesh`` (anything :func:`as_mesh` takes); ``uv: (n, 2)`` per-vertex UVs
    (default ``mesh.uv``; with neither, per-corner ``mesh.texcoords`` are used, splitting
    vertices at seams as :func:`split_seams` says); ``texture``: an ``(H, W, 3)`` uint8 image
    for the material's base colour (e.g. :func:`jaxparam.io.checker_texture`).  ``nan`` UVs
    (vertices in no face) become 0.

    Example::

        t = jp.to_trimesh(mesh, uv); t.export("flat.glb")
    """
    import trimesh

    mesh = as_mesh(mesh, "to_trimesh")
    V = np.asarray(mesh.vertices, np.float64)
    F = np.asarray(mesh.faces, np.int64)
    uv = mesh.uv if uv is None else uv
    if uv is None and mesh.texcoords is not None:
        source, F, uv = split_seams(F, np.asarray(mesh.texcoords), mesh.uv_faces)
        V = V[source]
    visual = None
    if uv is not None:
        uv = np.asarray(uv, np.float64)
        if uv.shape != (V.shape[0], 2):
            raise MeshError(f"to_trimesh: uv must have shape ({V.shape[0]}, 2), got {uv.shape}.")
        material = None
        if texture is not None:
            from PIL import Image

            material = trimesh.visual.material.PBRMaterial(
                baseColorTexture=Image.fromarray(np.asarray(texture, np.uint8)))
        visual = trimesh.visual.TextureVisuals(uv=np.nan_to_num(uv), material=material)
    t = trimesh.Trimesh(V, F, visual=visual, process=False, validate=False)
    if mesh.name:
        t.metadata["name"] = mesh.name
    return t


def from_trimesh(t, *, validate: bool = True) -> TriMesh:
    """A :class:`TriMesh` from a ``trimesh.Trimesh``, vertex order kept, nothing merged; its
    ``TextureVisuals`` UVs (one per vertex) become ``mesh.uv``.

    Raises :class:`~jaxparam.errors.ArgumentTypeError` (a ``TypeError``) for anything but
    a ``trimesh.Trimesh`` (a ``Scene``: take
    ``scene.to_geometry()`` first) and :class:`MeshError` for an invalid mesh.

    Example::

        mesh = jp.from_trimesh(trimesh.load("bunny.ply", process=False))
    """
    if not _is_trimesh(t):
        raise ArgumentTypeError(f"from_trimesh: expected a trimesh.Trimesh, got {type(t).__module__}."
                        f"{type(t).__qualname__}" + ("; for a Scene take scene.to_geometry() first."
                                                     if type(t).__name__ == "Scene" else "."))
    V = np.asarray(t.vertices, np.float64)
    uv = getattr(t.visual, "uv", None)
    uv = None if uv is None or np.shape(uv) != (V.shape[0], 2) else np.array(uv, np.float64)
    name = t.metadata.get("name") if isinstance(getattr(t, "metadata", None), dict) else None
    return TriMesh(V, np.asarray(t.faces, np.int64), uv=uv, validate=validate,
                   name=None if name is None else str(name))


def as_mesh(obj, what: str = "mesh") -> TriMesh:
    """``obj`` as a :class:`TriMesh`: a ``TriMesh`` as it is, a ``trimesh.Trimesh`` through
    :func:`from_trimesh`, a ``(vertices (n, 3), faces (m, 3))`` pair through ``TriMesh``.

    Raises :class:`~jaxparam.errors.ArgumentTypeError` (a ``TypeError``) naming the type it
    got for anything else (``what`` names the
    argument in the message, e.g. ``"convex_map"``).

    Example::

        uv = jp.convex_map((V, F))
    """
    if isinstance(obj, TriMesh):
        return obj
    if _is_trimesh(obj):
        return from_trimesh(obj)
    if isinstance(obj, (tuple, list)) and len(obj) == 2:
        return TriMesh(obj[0], obj[1])
    kind = type(obj)
    got = kind.__qualname__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__qualname__}"
    extra = f" of length {len(obj)}" if isinstance(obj, (tuple, list)) else ""
    raise ArgumentTypeError(f"{what}: expected a jaxparam TriMesh, a trimesh.Trimesh or a (vertices, faces) "
                    f"pair, got {got}{extra}; e.g. jp.TriMesh(V, F) or jp.load('mesh.obj').")
