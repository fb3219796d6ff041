"""Reading and writing triangle mesh files: OBJ and OFF by jaxparam's own readers, other
formats through ``trimesh``; OBJ out, with per-vertex texture coordinates.

Readers keep the file's vertex order (no merging, no reordering), so a mesh's UVs
line up with its file.  Every file is written through
:func:`jaxparam.io.files.atomic_write`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MeshError, MeshFileError
from ..mesh import TriMesh
from .files import atomic_write, existing_file, read_text

__all__ = ["read_obj", "read_off", "load", "save"]


def _number(tok: str, path, line_no: int, what: str) -> float:
    """``tok`` as a float, or a :class:`MeshFileError` naming the file, line and ``what``."""
    try:
        return float(tok)
    except ValueError:
        raise MeshFileError(f"{path}, line {line_no}: cannot read {what} from {tok!r}; "
                            "the file is malformed.") from None


def _numbers(tokens, count: int, path, line_no: int, what: str, too_few: str) -> list[float]:
    """The first ``count`` of ``tokens`` as floats; a :class:`MeshFileError` saying
    ``too_few`` when there are fewer, or naming ``what`` could not be read."""
    if len(tokens) < count:
        raise MeshFileError(f"{path}, line {line_no}: {too_few}")
    return [_number(t, path, line_no, what) for t in tokens[:count]]


def read_obj(path):
    """Read an OBJ file keeping the vertex order: ``(vertices, faces, uv_or_None)``,
    ``(n, 3) float64``, ``(m, 3) int64`` (0-based) and ``(n, 2) float64`` or None.

    Polygons are split into triangle fans; negative (relative) indices are
    honoured; ``vt`` coordinates become per-vertex UVs when every face corner
    of a vertex uses the same one.
    """
    verts, tex, faces, ftex = [], [], [], []
    text = read_text(path)
    for line_no, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        tag = parts[0]
        if tag == "v":
            verts.append(_numbers(parts[1:], 3, path, line_no, "a coordinate",
                                  f"a vertex needs three coordinates, got {len(parts) - 1}."))
        elif tag == "vt":
            tex.append(_numbers(parts[1:], 2, path, line_no, "a texture coordinate",
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
            for k in range(1, len(vi) - 1):
                faces.append([vi[0], vi[k], vi[k + 1]])
                ftex.append([ti[0], ti[k], ti[k + 1]] if len(ti) == len(vi) else None)
    if not verts:
        raise MeshFileError(f"{path}: no vertices ('v' lines) found; is this an OBJ mesh file?")
    if not faces:
        raise MeshFileError(f"{path}: no faces ('f' lines) found; jaxparam needs a triangle mesh "
                            "(for bare points use jaxparam meshless).")
    V = np.asarray(verts, np.float64)
    F = np.asarray(faces, np.int64)
    uv = None
    if tex and all(t is not None for t in ftex):
        T = np.asarray(ftex, np.int64)
        uv_all = np.asarray(tex, np.float64)
        uv = np.full((V.shape[0], 2), np.nan)
        uv[F.reshape(-1)] = uv_all[T.reshape(-1)]
        # Only a true per-vertex parameterization is kept (no seams).
        consistent = np.all(uv_all[T.reshape(-1)] == uv[F.reshape(-1)])
        if not consistent:
            uv = None
    return V, F, uv


def _obj_index(tok: str, count: int, path, line_no: int) -> int:
    """The 0-based index of an OBJ (1-based, or negative: relative) index among ``count``."""
    try:
        i = int(tok)
    except ValueError:
        raise MeshFileError(f"{path}, line {line_no}: bad index {tok!r}; the file is malformed.") from None
    if i < 0:
        i = count + i + 1
    if i < 1 or i > count:
        raise MeshFileError(f"{path}, line {line_no}: index {tok} refers to element {i} but only "
                            f"{count} are defined before this line.")
    return i - 1


def read_off(path):
    """Read an OFF file keeping the vertex order: ``(vertices, faces)``, ``(n, 3) float64`` and
    ``(m, 3) int64``; polygons are split into triangle fans."""
    text = read_text(path)
    tokens_by_line = []
    for line_no, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if line:
            tokens_by_line.append((line_no, line.split()))
    if not tokens_by_line:
        raise MeshFileError(f"{path}: the file is empty.")
    line_no, first = tokens_by_line[0]
    if not first[0].upper().endswith("OFF"):
        raise MeshFileError(f"{path}, line {line_no}: expected the header 'OFF', got {first[0]!r}.")
    rest = [(ln, toks) for ln, toks in ([(line_no, first[1:])] if len(first) > 1 else []) + tokens_by_line[1:]]
    if not rest:
        raise MeshFileError(f"{path}: missing the counts line 'nv nf ne' after the header.")
    ln, counts = rest[0]
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (ValueError, IndexError):
        raise MeshFileError(f"{path}, line {ln}: expected the counts 'nv nf ne', got {' '.join(counts)!r}.") from None
    if nv < 0 or nf < 0:
        raise MeshFileError(f"{path}, line {ln}: negative counts {nv} {nf}.")
    body = rest[1:]
    if len(body) < nv + nf:
        raise MeshFileError(f"{path}: the header promises {nv} vertices and {nf} faces but the file has "
                            f"only {len(body)} data lines; the file is truncated or the counts are wrong.")
    V = np.empty((nv, 3))
    for i in range(nv):
        ln, toks = body[i]
        V[i] = _numbers(toks, 3, path, ln, "a coordinate",
                        f"a vertex needs three coordinates, got {len(toks)}.")
    faces = []
    for j in range(nf):
        ln, toks = body[nv + j]
        try:
            k = int(toks[0])
            idx = [int(t) for t in toks[1:1 + k]]
        except (ValueError, IndexError):
            raise MeshFileError(f"{path}, line {ln}: cannot read a face from {' '.join(toks)!r}.") from None
        if k < 3 or len(idx) != k:
            raise MeshFileError(f"{path}, line {ln}: a face with {k} vertices but {len(idx)} indices given.")
        bad = [i for i in idx if i < 0 or i >= nv]
        if bad:
            raise MeshFileError(f"{path}, line {ln}: vertex index {bad[0]} is out of range [0, {nv}).")
        faces.extend([idx[0], idx[t], idx[t + 1]] for t in range(1, k - 1))
    if not faces:
        raise MeshFileError(f"{path}: the file has no faces.")
    return V, np.asarray(faces, np.int64)


def load(path, *, validate: bool = True) -> TriMesh:
    """Read a triangle mesh file, keeping the vertex order.

    OBJ and OFF are read by jaxparam's own readers (no merging or reordering;
    an OBJ's per-vertex ``vt`` becomes ``mesh.uv``); PLY, STL, GLB and other
    formats go through ``trimesh`` with ``process=False`` (STL stores
    triangle soup, so its coincident corners are merged, in first-seen order).

    Raises :class:`MeshFileError` for a missing or malformed file (with the
    line) and :class:`MeshError` for an invalid mesh.

    Example::

        mesh = jp.load("camelhead.off")
    """
    p = Path(path)
    ext = p.suffix.lower()
    uv = None
    if ext == ".obj":
        V, F, uv = read_obj(p)
    elif ext == ".off":
        V, F = read_off(p)
    else:
        V, F = _read_with_trimesh(p, ext)
    return TriMesh(V, F, uv=uv, validate=validate, name=p.stem)


def _read_with_trimesh(p: Path, ext: str):
    """``(vertices, faces)`` of a PLY, STL, GLB, ... file read by ``trimesh``."""
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


def save(path, mesh: TriMesh, uv=None) -> None:
    """Write ``mesh`` (and ``uv: (n, 2)``) as OBJ: ``v``, per-vertex ``vt``, faces ``f a/a b/b c/c``.

    Vertices keep the mesh's order.  The file is written to a temporary name
    and renamed, so it never exists half-written.

    Example::

        jp.save("out.obj", mesh, uv)
    """
    V = np.asarray(mesh.vertices, np.float64)
    F = mesh.faces + 1
    if uv is None:
        uv = mesh.uv
    if uv is not None:
        uv = np.asarray(uv, np.float64)
        if uv.shape != (V.shape[0], 2):
            raise MeshError(f"save: uv must have shape ({V.shape[0]}, 2), got {uv.shape}.")

    def write(f):
        f.write("# written by jaxparam\n")
        np.savetxt(f, V, fmt="v %.17g %.17g %.17g")
        if uv is not None:
            np.savetxt(f, np.nan_to_num(uv), fmt="vt %.17g %.17g")
            np.savetxt(f, np.repeat(F, 2, axis=1), fmt="f %d/%d %d/%d %d/%d")
        else:
            np.savetxt(f, F, fmt="f %d %d %d")

    atomic_write(path, write)
