"""Reading and writing triangle mesh files in the format the extension names.

=========  ======================================  =======================================
format     UVs                                     written by
=========  ======================================  =======================================
``.obj``   per-vertex or per-corner ``vt``         jaxparam (:mod:`.obj`: exact, 17 digits)
``.ply``   ``u v`` per vertex, face ``texcoord``   jaxparam (:mod:`.ply`: binary, doubles)
``.glb``   ``TEXCOORD_0``, optional texture image  trimesh (:mod:`.gltf`: float32)
``.gltf``  as ``.glb``, buffers embedded           trimesh (:mod:`.gltf`)
``.off``   none (a warning says they are dropped)  jaxparam (:mod:`.off`: exact)
=========  ======================================  =======================================

Readers keep the file's vertex order (no merging, no reordering), so a mesh's UVs line up
with its file; ``.stl`` and other formats trimesh knows are read too.  Every file is written
through :func:`jaxparam.io.files.atomic_write`.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..errors import MeshError, MeshFileError, first_few
from ..mesh import TriMesh
from ..triangles import signed_area2
from .files import atomic_write, existing_file, file_path
from .gltf import gltf_bytes, read_gltf
from .interop import as_mesh, split_seams, to_trimesh
from .obj import corner_to_vertex_uv, parse_obj, read_obj, write_obj
from .off import read_off, write_off
from .ply import read_ply, write_ply

__all__ = ["read_obj", "read_off", "read_ply", "load", "read_arrays", "save", "check_output_format",
           "WRITE_FORMATS"]

#: The extensions :func:`save` writes, and what each keeps.
WRITE_FORMATS = {".obj": "OBJ (per-vertex or per-corner vt)", ".ply": "PLY (u, v)",
                 ".glb": "binary glTF (TEXCOORD_0, texture)", ".gltf": "glTF (TEXCOORD_0, texture)",
                 ".off": "OFF (no UVs)"}


def check_output_format(path) -> str:
    """The format :func:`save` would write to ``path``: its lower-case extension (``".obj"``,
    ``".ply"``, ``".glb"``, ``".gltf"``, ``".off"``).

    Raises :class:`MeshFileError` naming the extension and the supported ones for any other;
    call it before long work (the CLI does, right after parsing its options).

    Example::

        jp.io.check_output_format("out.stl")   # MeshFileError: cannot write '.stl' ...
    """
    p = file_path(path, "save", "; the path comes first: jp.save('out.obj', mesh, uv)")
    ext = p.suffix.lower()
    if p.is_dir():
        raise MeshFileError(f"{path}: is a folder; give a file path ending in one of "
                            f"{', '.join(WRITE_FORMATS)}.")
    if ext not in WRITE_FORMATS:
        named = f"the extension {ext!r}" if ext else "a file without an extension"
        raise MeshFileError(f"{path}: cannot write {named}; jaxparam writes "
                            f"{', '.join(WRITE_FORMATS)} (give the output one of those).")
    return ext


#: Extensions of point-set files (:func:`jaxparam.io.points.load_points`), which hold no faces.
POINT_ONLY = (".npy", ".xyz", ".csv", ".pts", ".txt")


def load(path, *, validate: bool = True) -> TriMesh:
    """Read a triangle mesh file, keeping the vertex order, with its UVs.

    OBJ, OFF and PLY are read by jaxparam's own readers, glTF/GLB through trimesh (node
    transforms applied, meshes concatenated), STL and other formats through ``trimesh``
    with ``process=False`` (STL stores triangle soup, so its coincident corners are
    merged, in first-seen order).  UVs: an OBJ's ``vt``, a PLY's ``u``/``v`` (``s``/``t``,
    ``texture_u``/``texture_v``) or face ``texcoord``, a glTF's ``TEXCOORD_0``.  UVs that
    agree at every vertex become ``mesh.uv (n, 2)``; seamed (per-corner) ones
    ``mesh.texcoords (t, 2)`` and ``mesh.uv_faces (m, 3)``.  An OBJ whose faces only
    partly carry ``vt`` loads without UVs and warns.

    Raises :class:`MeshFileError` for a missing or malformed file (with the line) and
    :class:`MeshError` for an invalid mesh.

    Example::

        mesh = jp.load("camelhead.off")
    """
    p, V, F, uv, tex, T = _read(path)
    if tex is not None and uv is None:
        uv = corner_to_vertex_uv(F, tex, T, V.shape[0])
        if uv is not None:
            tex = T = None
    return TriMesh(V, F, uv=uv, validate=validate, name=p.stem, texcoords=tex, uv_faces=T)


def read_arrays(path) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (n, 3) float64, faces (m, 3) int64)`` of a mesh file, read as :func:`load`
    reads it but with no check of the mesh (``jaxparam info`` describes a mesh that fails
    them); raises :class:`MeshFileError` for a file it cannot read."""
    _, V, F, _, _, _ = _read(path)
    return np.asarray(V, np.float64), np.asarray(F, np.int64)


def _read(path):
    """``(path, V, F, uv, texcoords, uv_faces)`` of a mesh file (see :func:`load`)."""
    p = file_path(path, "load", "; a mesh in memory needs no loading (jp.TriMesh(V, F), or "
                  "jp.io.from_trimesh for a trimesh.Trimesh)")
    ext = p.suffix.lower()
    uv = tex = T = None
    if ext == ".obj":
        V, F, tex, T, dropped = parse_obj(p)
        if dropped:
            warnings.warn(f"{path}: {dropped} of the faces have no vt indices, so the file's "
                          "texture coordinates were not loaded (mesh.uv is None).", stacklevel=3)
    elif ext == ".off":
        V, F = read_off(p)
    elif ext == ".ply":
        V, F, uv, tex, T = read_ply(p)
    elif ext in (".glb", ".gltf"):
        V, F, uv = read_gltf(p)
    elif ext in POINT_ONLY:
        existing_file(p)
        raise MeshFileError(f"{p}: a {ext} file holds points, not a mesh; parameterize points with "
                            "jaxparam meshless (jp.meshless_map, jp.load_points), or pass a mesh "
                            "(.obj, .off, .ply, .glb, .gltf, .stl).")
    else:
        V, F = _read_with_trimesh(p, ext)
    return p, V, F, uv, tex, T


def _read_with_trimesh(p: Path, ext: str):
    """``(vertices, faces)`` of an STL, ... file read by ``trimesh``."""
    existing_file(p)
    if p.stat().st_size == 0:
        raise MeshFileError(f"{p}: the file is empty.")
    try:
        import trimesh
        kw = {"process": ext == ".stl", "force": "mesh"}
        m = trimesh.load(str(p), **kw)
    except Exception as exc:  # trimesh raises many types on malformed input
        raise MeshFileError(f"{p}: cannot read the file as {ext or 'a mesh'} ({type(exc).__name__}: "
                            f"{exc}); check the format and that the file is complete.") from None
    V = np.asarray(getattr(m, "vertices", np.empty((0, 3))), np.float64)
    F = np.asarray(getattr(m, "faces", np.empty((0, 3))), np.int64)
    if V.size == 0 or F.size == 0:
        raise MeshFileError(f"{p}: no triangles found in the file.")
    return V, F


def _uvs(mesh: TriMesh, uv, uv_faces):
    """``(uv (n, 2) or None, texcoords (t, 2) or None, uv_faces (m, 3) or None)`` to write."""
    n, m = mesh.n_vertices, mesh.n_faces
    if uv_faces is not None:
        T = np.asarray(uv_faces)
        if uv is None:
            raise MeshError("save: uv_faces needs uv, the (t, 2) table of texture coordinates it "
                            "indexes.")
        tex = np.asarray(uv, np.float64)
        if tex.ndim != 2 or tex.shape[1] != 2:
            raise MeshError(f"save: with uv_faces, uv must be a (t, 2) table, got {tex.shape}.")
        if T.shape != (m, 3) or not np.issubdtype(T.dtype, np.integer):
            raise MeshError(f"save: uv_faces must be ({m}, 3) integers, one row per face, got "
                            f"{T.shape} {T.dtype}.")
        if T.size and (T.min() < 0 or T.max() >= tex.shape[0]):
            raise MeshError(f"save: uv_faces index {int(T.max() if T.max() >= tex.shape[0] else T.min())}"
                            f" is outside the uv table of {tex.shape[0]} rows.")
        return None, tex, T.astype(np.int64)
    if uv is None:
        uv = mesh.uv
        if uv is None and mesh.texcoords is not None:
            return None, np.asarray(mesh.texcoords, np.float64), mesh.uv_faces
    if uv is None:
        return None, None, None
    uv = np.asarray(uv, np.float64)
    if uv.shape != (n, 2):
        raise MeshError(f"save: uv must have shape ({n}, 2), one row per vertex, got {uv.shape} "
                        "(per-corner UVs: pass the (t, 2) table as uv with uv_faces=(m, 3)).")
    # nan is the UV of a vertex in no face (written as 0); at a face's vertex it is a failed map.
    used = np.zeros(n, bool)
    used[np.asarray(mesh.faces).reshape(-1)] = True
    bad = np.flatnonzero(used & ~np.all(np.isfinite(uv), axis=1))
    if bad.size:
        raise MeshError(f"save: uv is not finite at vertices {first_few(bad)} (vertex "
                        f"{int(bad[0])} has {tuple(float(x) for x in uv[bad[0]])}), which belong to "
                        "faces; nothing was written: check the map that made these UVs.")
    return uv, None, None


def _warn_float32_flips(path, uv: np.ndarray, F: np.ndarray) -> None:
    """Warn when UV triangles that are positive in float64 turn over or collapse once their
    UVs are rounded to float32, which glTF stores (a meshless map's slivers, s1/s2 about 1e5,
    came out of a .glb with 2 triangles of area -1e-12 that the .ply kept positive;
    session 27)."""
    uv = np.asarray(uv, np.float64)           # (nan UVs of unused vertices compare False)
    before = signed_area2(uv, F)
    after = signed_area2(uv.astype(np.float32).astype(np.float64), F)
    bad = np.flatnonzero((before > 0) & ~(after > 0))
    if bad.size:
        warnings.warn(f"save: {path}: the UV triangles of faces {first_few(bad)} turn over or "
                      "collapse when their UVs are rounded to float32, which glTF stores (they are "
                      "slivers of the map); write .obj or .ply to keep the UVs in float64.",
                      stacklevel=3)


def save(path, mesh, uv=None, *, uv_faces=None, texture=None) -> None:
    """Write ``mesh`` with its UVs in the format ``path``'s extension names (table above).

    **Arguments:**

    - ``mesh``: a :class:`TriMesh` (or what :func:`~jaxparam.io.interop.as_mesh` takes).
    - ``uv``: ``(n, 2)`` per-vertex UVs (default ``mesh.uv``, else the mesh's per-corner
      UVs); with ``uv_faces``, the ``(t, 2)`` table of per-corner UVs.
    - ``uv_faces``: ``(m, 3)`` rows of ``uv`` per face corner (OBJ ``f v/vt``; PLY face
      ``texcoord``; glTF splits vertices at seams, since it has one UV per vertex).
    - ``texture``: an ``(H, W, 3)`` uint8 image embedded as the base colour of a
      ``.glb``/``.gltf`` (e.g. :func:`jaxparam.io.checker_texture`).

    Vertices keep the mesh's order in every format (glTF with seams aside).  ``.off`` holds
    no UVs: given some, it warns that they are not written.  The file is written to a
    temporary name and renamed, so it never exists half-written.  Raises
    :class:`MeshFileError` for an extension jaxparam cannot write (before anything else)
    and :class:`MeshError` for UVs of the wrong shape.

    Example::

        jp.save("out.obj", mesh, uv)
        jp.save("out.glb", mesh, uv, texture=jp.io.checker_texture())
    """
    ext = check_output_format(path)
    mesh = as_mesh(mesh, "save")
    V = np.asarray(mesh.vertices, np.float64)
    F = np.asarray(mesh.faces, np.int64)
    uv, tex, T = _uvs(mesh, uv, uv_faces)
    if texture is not None:
        if ext not in (".glb", ".gltf"):
            raise MeshFileError(f"{path}: a texture image is embedded only in .glb or .gltf; "
                                f"save the image next to the {ext} yourself, or write a .glb.")
        img = np.asarray(texture)
        if img.ndim != 3 or img.shape[2] not in (3, 4) or img.dtype != np.uint8:
            raise MeshError(f"save: texture must be an (H, W, 3) uint8 image, got shape "
                            f"{img.shape} of dtype {img.dtype}.")
        if uv is None and tex is None:
            raise MeshError("save: a texture needs UVs to be drawn through; pass uv.")
    if ext == ".obj":
        atomic_write(path, lambda f: write_obj(f, V, F, uv, tex, T))
    elif ext == ".ply":
        atomic_write(path, lambda f: write_ply(f, V, F, uv, tex, T), mode="wb")
    elif ext == ".off":
        if uv is not None or tex is not None:
            warnings.warn(f"save: {path}: OFF holds no texture coordinates, so the UVs were not "
                          "written; use .obj, .ply or .glb to keep them.", stacklevel=2)
        atomic_write(path, lambda f: write_off(f, V, F))
    else:
        if tex is not None:
            source, F, uv = split_seams(F, tex, T)
            V = V[source]
        if uv is not None:
            _warn_float32_flips(path, uv, F)
        tm = to_trimesh(TriMesh(V, F, validate=False, name=mesh.name), uv, texture=texture)
        data = gltf_bytes(tm, binary=ext == ".glb")
        atomic_write(path, lambda f: f.write(data), mode="wb")
