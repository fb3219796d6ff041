"""OFF meshes, read and written by jaxparam (OFF holds no UVs).

Why our own writer: trimesh's OFF exporter writes 10 decimal digits (a round trip moves
vertices); ours writes 17 significant digits, exact, in the mesh's vertex order.
"""
from __future__ import annotations

import re
import warnings

import numpy as np

from ..errors import MeshFileError
from .files import read_text, write_rows
from .obj import read_number_fields
from .polygons import polygon_corners, triangulate

__all__ = ["read_off", "write_off", "fast_off"]


def read_off(path):
    """Read an OFF file keeping the vertex order: ``(vertices, faces)``, ``(n, 3) float64`` and
    ``(m, 3) int64``; polygons are split into triangles (fans; ear clipping for concave
    ones; repeated corners merged: :func:`~jaxparam.io.polygons.triangulate`).

    A file of triangles with three numbers a vertex line is read vectorized
    (:func:`fast_off`, 20x faster); any other file, and any file with an error, line by line,
    so that the message names the line.
    """
    text = read_text(path)
    fast = fast_off(text)
    if fast is not None:
        return fast
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
        body = _regrouped(ln, counts, body, nv, nf) or body
    if len(body) < nv + nf:
        raise MeshFileError(f"{path}: the header promises {nv} vertices and {nf} faces but the file has "
                            f"only {len(body)} data lines; the file is truncated or the counts are wrong.")
    if len(body) > nv + nf:
        raise _too_much_data(path, rest[0], body, nv, nf)
    V = np.empty((nv, 3))
    for i in range(nv):
        ln, toks = body[i]
        V[i] = read_number_fields(toks, 3, path, ln, "a coordinate",
                        f"a vertex needs three coordinates, got {len(toks)}.")
    polys, lines = [], []
    for j in range(nf):
        ln, toks = body[nv + j]
        try:
            k = int(toks[0])
            idx = [int(t) for t in toks[1:1 + k]]
        except (ValueError, IndexError):
            raise MeshFileError(f"{path}, line {ln}: cannot read a face from {' '.join(toks)!r}.") from None
        if k < 3:
            raise MeshFileError(f"{path}, line {ln}: a face needs at least 3 vertices, this one "
                                f"has {k}; remove the line (or the file's edges and points).")
        if len(idx) != k:
            raise MeshFileError(f"{path}, line {ln}: a face with {k} vertices but {len(idx)} indices given.")
        bad = [i for i in idx if i < 0 or i >= nv]
        if bad:
            raise MeshFileError(f"{path}, line {ln}: vertex index {bad[0]} is out of range [0, {nv}).")
        polys.append(idx)
        lines.append(ln)
    if not polys:
        raise MeshFileError(f"{path}: the file has no faces.")
    poly, pick = triangulate(V, polys, lambda i: f"{path}, line {lines[i]}")
    flat, start = polygon_corners(polys)
    return V, flat[start[poly][:, None] + pick]


def _regrouped(counts_line: int, counts, body, nv: int, nf: int):
    """The data of an OFF file that breaks its lines elsewhere (the format is whitespace
    separated: a writer may put everything on one line), regrouped into one entry per vertex
    (3 numbers) and per face (``k`` and ``k`` indices), each with the line it starts on; None
    unless the tokens after the counts ``nv nf ne`` (on line ``counts_line``) are exactly that
    many."""
    stream = [(ln, t) for ln, toks in [(counts_line, counts[3:])] + body for t in toks]
    out, i = [], 0
    for j in range(nv + nf):
        if i >= len(stream):
            return None
        if j < nv:
            width = 3
        else:
            try:
                width = 1 + int(stream[i][1])
            except ValueError:
                return None
        out.append((stream[i][0], [t for _, t in stream[i:i + width]]))
        i += width
    return out if i == len(stream) else None


def _looks_like_a_face(toks) -> bool:
    """Whether an OFF data line reads as a face: ``k i1 ... ik`` with ``k >= 3`` integers."""
    try:
        k = int(toks[0])
        return k >= 3 and len(toks) > k and all(int(t) >= 0 for t in toks[1:1 + k])
    except ValueError:
        return False


def _too_much_data(path, counts_line, body, nv: int, nf: int) -> MeshFileError:
    """The error for an OFF file with more data lines than its header's counts promise,
    naming the line where the data departs from the counts and the counts found."""
    ln_counts, counts = counts_line
    header = f"line {ln_counts}: {' '.join(counts)!r}"
    first_face = next((i for i, (_, toks) in enumerate(body) if _looks_like_a_face(toks)), len(body))
    found_f = len(body) - first_face
    if first_face != nv and first_face < len(body):
        ln = body[min(nv, first_face)][0]
        return MeshFileError(
            f"{path}, line {ln}: the header promises {nv} vertices and {nf} faces, but the file "
            f"holds {first_face} vertex lines and then {found_f} face lines; fix the counts in "
            f"the header ({header}) or remove the extra lines.")
    ln = body[nv + nf][0]
    extra = len(body) - nv - nf
    return MeshFileError(
        f"{path}, line {ln}: data goes on after the {nf} faces the header promises: {extra} more "
        f"line{'s' if extra != 1 else ''} from here ({nf + extra} face lines in all after the "
        f"{nv} vertices); fix the face count in the header ({header}) or remove the extra "
        "lines.")


def fast_off(text: str):
    """``(vertices (n, 3) float64, faces (m, 3) int64)`` of OFF ``text`` read with whole-array
    NumPy conversions, or None when the file is not the plain case: ASCII, a header line
    ``OFF``, the counts, then exactly ``n`` lines of three numbers and ``m`` lines ``3 a b c``
    with indices in range (comments and blank lines allowed).  :func:`read_off` reads every
    other file, and reports the errors, line by line; both give the same arrays
    (``tests/test_io_formats.py``)."""
    if "#" in text:
        text = re.sub("#[^\n]*", "", text)
    data = text.encode("ascii", "replace")
    b = np.frombuffer(data, np.uint8)
    if np.any((b >= 0x7F) | ((b >= 0x1C) & (b <= 0x1F)) | (b == 0x3F)):
        return None                             # non-ASCII, '?' (replaced), odd separators
    newline = b == 10
    space = newline | (b == 32) | (b == 9) | (b == 11) | (b == 12) | (b == 13)
    start = ~space
    start[1:] &= space[:-1]
    line_of = np.cumsum(newline)                # line number of every byte
    line_start = np.concatenate([[0], np.flatnonzero(newline) + 1])
    tokens = np.bincount(line_of[start], minlength=line_start.size)
    lines = np.flatnonzero(tokens)              # the non-blank lines
    if lines.size < 3 or text[line_start[lines[0]]:line_start[lines[1]]].split() != ["OFF"]:
        return None
    counts = text[line_start[lines[1]]:line_start[lines[2]]].split()
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (ValueError, IndexError):
        return None
    if nv <= 0 or nf <= 0 or lines.size != 2 + nv + nf or np.any(tokens[lines[2:2 + nv]] != 3) \
            or np.any(tokens[lines[2 + nv:]] != 4):
        return None
    split = line_start[lines[2 + nv]]
    V = _numbers(text[line_start[lines[2]]:split], 3 * nv, np.float64)
    F4 = _numbers(text[split:], 4 * nf, np.int64)
    if V is None or F4 is None:
        return None
    V, F4 = V.reshape(nv, 3), F4.reshape(nf, 4)
    if np.any(F4[:, 0] != 3) or F4[:, 1:].min() < 0 or F4[:, 1:].max() >= nv:
        return None
    return V, np.ascontiguousarray(F4[:, 1:])


def _numbers(block: str, count: int, dtype):
    """The ``count`` whitespace-separated numbers of ``block``, or None when one is malformed."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")              # a malformed number stops np.fromstring
        try:
            x = np.fromstring(block, dtype=dtype, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    return x if x.size == count else None


def write_off(f, V, F) -> None:
    """Write OFF text to the open file ``f``: header, counts, ``V (n, 3)`` with 17 significant
    digits and ``F (m, 3)`` as ``3 a b c`` lines (0-based)."""
    f.write(f"OFF\n# written by jaxparam\n{V.shape[0]} {F.shape[0]} 0\n")
    write_rows(f, "%.17g %.17g %.17g\n", np.asarray(V, np.float64))
    write_rows(f, "3 %d %d %d\n", np.asarray(F, np.int64))
