"""glTF 2.0 meshes (``.glb`` binary, ``.gltf`` with embedded buffers) through ``trimesh``:
positions, faces, ``TEXCOORD_0`` and, optionally, a base-colour texture image.

trimesh's glTF exporter is used because it keeps the vertex order and merges nothing
(tested in ``tests/test_io_formats.py``).  glTF stores positions and UVs as float32 (the
format allows nothing else), so a round trip is exact to float32, not float64.  glTF has
one UV per vertex: per-corner UVs are written by splitting vertices at seams
(:func:`jaxparam.io.interop.split_seams`).  trimesh flips ``v`` to glTF's top-left
convention on export and back on import, so UVs read back as they were written.
"""
from __future__ import annotations

import numpy as np

from ..errors import MeshFileError
from .files import existing_file

__all__ = ["gltf_bytes", "read_gltf"]


def gltf_bytes(tm, binary: bool) -> bytes:
    """The ``.glb`` (``binary``) or self-contained ``.gltf`` bytes of a ``trimesh.Trimesh``.

    A mesh farther from the origin than its own size is written about the centre of its
    bounding box, the centre going into its node's transform (JSON numbers, double
    precision): float32 positions of camelhead moved by 1e6 kept 420 distinct positions of
    11,381 (the held-out sweep, session 26); about the centre they keep float32's precision
    relative to the mesh's size, and readers apply the node's transform (ours does)."""
    import trimesh

    V = np.asarray(tm.vertices, np.float64)
    out = tm
    if V.size:
        lo, hi = V.min(0), V.max(0)
        centre = 0.5 * (lo + hi)
        if np.max(np.abs(centre)) > max(float(np.max(hi - lo)), 1e-300):
            moved = tm.copy()
            moved.vertices = V - centre
            out = trimesh.Scene()
            out.add_geometry(moved, transform=trimesh.transformations.translation_matrix(centre))
    if binary:
        return out.export(file_type="glb")
    from trimesh.exchange.gltf import export_gltf

    files = export_gltf(out, embed_buffers=True)
    return files["model.gltf"]


def read_gltf(path):
    """``(vertices (n, 3), faces (m, 3), uv (n, 2) or None)`` of a glTF/GLB file, the scene's
    node transforms applied and its meshes concatenated in scene order (UVs kept when every
    mesh has them)."""
    p = existing_file(path)
    if p.stat().st_size == 0:
        raise MeshFileError(f"{path}: the file is empty.")
    try:
        import trimesh

        scene = trimesh.load(str(p), process=False, force="scene")
        parts = [g for g in scene.dump() if hasattr(g, "faces") and len(g.faces)]
    except Exception as exc:  # trimesh raises many types on malformed input
        raise MeshFileError(f"{path}: cannot read the file as glTF ({type(exc).__name__}: {exc}); "
                            "check that the file is complete.") from None
    if not parts:
        raise MeshFileError(f"{path}: no triangles found in the file.")
    offsets = np.cumsum([0] + [len(g.vertices) for g in parts])
    V = np.concatenate([np.asarray(g.vertices, np.float64) for g in parts])
    F = np.concatenate([np.asarray(g.faces, np.int64) + o for g, o in zip(parts, offsets)])
    uvs = [getattr(g.visual, "uv", None) for g in parts]
    ok = all(u is not None and np.shape(u) == (len(g.vertices), 2) for u, g in zip(uvs, parts))
    uv = np.concatenate([np.asarray(u, np.float64) for u in uvs]) if ok else None
    return V, F, uv
