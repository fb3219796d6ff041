"""OFF meshes, read and written by jaxparam (OFF holds no UVs).

Why our own writer: trimesh's OFF exporter writes 10 decimal digits (a round trip moves
vertices); ours writes 17 significant digits, exact, in the mesh's vertex order.
"""
from __future__ import annotations

import numpy as np

from ..errors import MeshFileError
from .files import read_text
from .obj import read_number_fields

__all__ = ["read_off", "write_off"]


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
        V[i] = read_number_fields(toks, 3, path, ln, "a coordinate",
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


def write_off(f, V, F) -> None:
    """Write OFF text to the open file ``f``: header, counts, ``V (n, 3)`` with 17 significant
    digits and ``F (m, 3)`` as ``3 a b c`` lines (0-based)."""
    f.write(f"OFF\n# written by jaxparam\n{V.shape[0]} {F.shape[0]} 0\n")
    np.savetxt(f, V, fmt="%.17g %.17g %.17g")
    np.savetxt(f, np.column_stack([np.full(F.shape[0], 3), F]), fmt="%d %d %d %d")
