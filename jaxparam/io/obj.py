"""OBJ meshes, read and written by jaxparam: ``v``, ``vt`` and ``f`` lines, per-vertex or
per-corner texture coordinates (``f a/b c/d e/f``).

Why our own writer: trimesh's OBJ exporter writes positions and UVs with 8 decimals (a
round trip moves them) and only per-vertex UVs (its ``TextureVisuals`` hold one UV per
vertex, so a seamed atlas cannot be written without splitting vertices); ours keeps the
vertex order, writes 17 significant digits (exact) and per-corner ``vt`` when asked.
"""
from __future__ import annotations

import numpy as np

from ..errors import MeshFileError
from .files import read_text, write_rows
from .polygons import polygon_corners, triangulate

__all__ = ["parse_obj", "read_obj", "write_obj", "corner_to_vertex_uv", "read_number_fields"]


def _number(tok: str, path, line_no: int, what: str) -> float:
    """``tok`` as a float, or a :class:`MeshFileError` naming the file, line and ``what``."""
    try:
        return float(tok)
    except ValueError:
        raise MeshFileError(f"{path}, line {line_no}: cannot read {what} from {tok!r}; "
                            "the file is malformed.") from None


def read_number_fields(tokens, count: int, path, line_no: int, what: str, too_few: str) -> list[float]:
    """The first ``count`` of ``tokens`` as floats; a :class:`MeshFileError` saying
    ``too_few`` when there are fewer, or naming ``what`` could not be read."""
    if len(tokens) < count:
        raise MeshFileError(f"{path}, line {line_no}: {too_few}")
    return [_number(t, path, line_no, what) for t in tokens[:count]]


def logical_lines(text: str):
    """``(line number, line)`` of an OBJ text, a line ending in a backslash joined with the
    next (the format's line continuation, as libigl and trimesh read it); the number is that
    of the first physical line."""
    start, parts = None, []
    for line_no, raw in enumerate(text.splitlines(), 1):
        stripped = raw.rstrip()
        if stripped.endswith("\\") and "#" not in stripped:
            start = line_no if start is None else start
            parts.append(stripped[:-1])
            continue
        yield (line_no if start is None else start), " ".join(parts + [raw])
        start, parts = None, []
    if parts:
        yield start, " ".join(parts)


def parse_obj(path):
    """An OBJ file's data in file order: ``(vertices (n, 3), faces (m, 3), vt (t, 2) or None,
    uv_faces (m, 3) or None, dropped)``; polygons split into triangles
    (:func:`~jaxparam.io.polygons.triangulate`: fans, ear clipping for concave ones, repeated
    corners merged).  ``uv_faces`` are the faces' ``vt`` indices when every face has them;
    ``dropped`` counts faces without ``vt`` in a file that has some (their UVs cannot be
    kept)."""
    verts, tex, polys, ptex, poly_lines = [], [], [], [], []
    text = read_text(path)
    for line_no, raw in logical_lines(text):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        tag = parts[0]
        if tag == "v":
            verts.append(read_number_fields(parts[1:], 3, path, line_no, "a coordinate",
                                  f"a vertex needs three coordinates, got {len(parts) - 1}."))
        elif tag == "vt":
            tex.append(read_number_fields(parts[1:], 2, path, line_no, "a texture coordinate",
                                "a texture coordinate needs two values."))
        elif tag == "f":
            if len(parts) < 4:
                raise MeshFileError(f"{path}, line {line_no}: a face needs at least three vertices, "
                                    f"got {len(parts) - 1}.")
            vi, ti = [], []
            for tok in parts[1:]:
                fields = tok.split("/")
                vi.append(_obj_index(fields[0], len(verts), path, line_no))
                if len(fields) > 1 and fields[1]:
                    ti.append(_obj_index(fields[1], len(tex), path, line_no))
            polys.append(vi)
            ptex.append(ti if len(ti) == len(vi) else None)
            poly_lines.append(line_no)
    if not verts:
        raise MeshFileError(f"{path}: no vertices ('v' lines) found; is this an OBJ mesh file?")
    if not polys:
        raise MeshFileError(f"{path}: no faces ('f' lines) found; jaxparam needs a triangle mesh "
                            "(for bare points use jaxparam meshless).")
    V = np.asarray(verts, np.float64)
    # Positive indices may refer to elements defined further down (as libigl and trimesh read
    # them); only now is it known whether they exist.
    _check_forward(polys, len(verts), poly_lines, path, "vertex")
    poly, pick = triangulate(V, polys, lambda i: f"{path}, line {poly_lines[i]}", base=1)
    flat, start = polygon_corners(polys)
    corner = start[poly][:, None] + pick                    # (m, 3) into ``flat``
    F = flat[corner]
    textured = np.array([t is not None for t in ptex])
    missing = int(np.count_nonzero(~textured[poly]))
    if not tex or missing:
        return V, F, None, None, missing if tex and missing < F.shape[0] else 0
    _check_forward(ptex, len(tex), poly_lines, path, "texture coordinate")
    tflat, _ = polygon_corners(ptex)
    return V, F, np.asarray(tex, np.float64), tflat[corner], 0


def _check_forward(polys, count: int, poly_lines, path, what: str) -> None:
    """A :class:`MeshFileError` naming the first face line whose index in ``polys`` (lists
    of 0-based indices) is at or past ``count``, the number of elements in the whole file."""
    top = np.fromiter((max(p) for p in polys), np.int64, len(polys))
    bad = np.flatnonzero(top >= count)
    if bad.size:
        i = int(bad[0])
        raise MeshFileError(f"{path}, line {poly_lines[i]}: index {int(top[i]) + 1} is out "
                            f"of range: the file defines only {count} ({what} lines); the file "
                            "is truncated or malformed.")


def corner_to_vertex_uv(F, texcoords, uv_faces, n: int):
    """Per-corner UVs as per-vertex ``uv: (n, 2)`` when every corner of each vertex has the
    same UV (``nan`` for vertices in no face), else ``None`` (the UVs have seams)."""
    per_corner = texcoords[uv_faces.reshape(-1)]
    uv = np.full((n, 2), np.nan)
    uv[F.reshape(-1)] = per_corner
    return uv if np.array_equal(uv[F.reshape(-1)], per_corner) else None


def read_obj(path):
    """Read an OBJ file keeping the vertex order: ``(vertices, faces, uv_or_None)``,
    ``(n, 3) float64``, ``(m, 3) int64`` (0-based) and ``(n, 2) float64`` or None.

    Polygons are split into triangles (fans; ear clipping for concave ones); negative
    (relative) indices are honoured; ``vt`` coordinates become per-vertex UVs when every face corner
    of a vertex uses the same one (per-corner UVs: :func:`parse_obj`, or ``jp.load``,
    which keeps them as ``mesh.texcoords`` and ``mesh.uv_faces``).
    """
    V, F, tex, T, _ = parse_obj(path)
    uv = None if tex is None else corner_to_vertex_uv(F, tex, T, V.shape[0])
    return V, F, uv


def write_obj(f, V, F, uv=None, texcoords=None, uv_faces=None) -> None:
    """Write OBJ text to the open file ``f``: ``v`` lines (17 significant digits, exact),
    then per-vertex ``vt`` with faces ``f a/a b/b c/c`` for ``uv (n, 2)``, or the ``vt``
    table ``texcoords (t, 2)`` with faces ``f a/x b/y c/z`` for per-corner UVs, or bare
    ``f a b c``.  ``nan`` UVs (vertices in no face) are written as 0."""
    f.write("# written by jaxparam\n")
    write_rows(f, "v %.17g %.17g %.17g\n", np.asarray(V, np.float64))
    F1 = np.asarray(F, np.int64) + 1
    if uv is not None:
        write_rows(f, "vt %.17g %.17g\n", np.nan_to_num(np.asarray(uv, np.float64)))
        write_rows(f, "f %d/%d %d/%d %d/%d\n", np.repeat(F1, 2, axis=1))
    elif texcoords is not None:
        write_rows(f, "vt %.17g %.17g\n", np.nan_to_num(np.asarray(texcoords, np.float64)))
        pairs = np.stack([F1, np.asarray(uv_faces, np.int64) + 1], axis=2).reshape(-1, 6)
        write_rows(f, "f %d/%d %d/%d %d/%d\n", pairs)
    else:
        write_rows(f, "f %d %d %d\n", F1)


def _obj_index(tok: str, count: int, path, line_no: int) -> int:
    """The 0-based index of an OBJ (1-based, or negative: relative) index among ``count``."""
    try:
        i = int(tok)
    except ValueError:
        raise MeshFileError(f"{path}, line {line_no}: bad index {tok!r}; the file is malformed.") from None
    if i < 0:
        i = count + i + 1
        if i < 1:
            raise MeshFileError(f"{path}, line {line_no}: relative index {tok} refers to element "
                                f"{i} but only {count} are defined before this line.")
    if i == 0:
        raise MeshFileError(f"{path}, line {line_no}: index 0 is not valid (OBJ indices start "
                            "at 1; negative ones count back from the last element defined).")
    return i - 1
