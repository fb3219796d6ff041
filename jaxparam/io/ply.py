"""PLY meshes, read and written by jaxparam: vertices ``x y z``, faces ``vertex_indices``,
per-vertex UVs as ``u v`` (``s t`` and ``texture_u texture_v`` are read too) and per-corner
UVs as the face list ``texcoord`` (MeshLab's convention, six numbers a triangle).

Why not ``trimesh``'s PLY exporter: it stores positions and UVs as float32 (a round trip
moves every vertex by up to 6e-8 of its coordinate) and names UVs ``s``/``t`` only; its
reader fails on ASCII face ``texcoord`` lists and, by default, splits vertices at UV seams.
Ours writes ``double`` (exact round trips, which trimesh still reads with its UVs) and
reads ASCII and binary (either byte order) in file order, never merging or splitting.
"""
from __future__ import annotations

import numpy as np

from ..errors import MeshFileError
from .files import existing_file
from .polygons import triangulate

__all__ = ["read_ply", "write_ply", "UV_NAMES"]

#: Vertex property pairs read as per-vertex UVs, first found wins.
UV_NAMES = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"))

_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
          "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
          "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _header(data: bytes, path):
    """``(format, elements, body offset, declared)``; ``elements`` = ``[(name, count, props)]``
    with ``props`` = ``[(name, type)]`` or ``[(name, (count_type, item_type))]`` for lists;
    ``declared`` = ``{name: (line number, text)}`` of each ``element`` header line."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise MeshFileError(f"{path}: not a PLY file (it must start with 'ply' and have an "
                            "'end_header' line).")
    nl = data.find(b"\n", end)
    body = len(data) if nl < 0 else nl + 1
    fmt, elements, declared = None, [], {}
    for line_no, raw in enumerate(data[:end].decode("latin-1").splitlines(), 1):
        tok = raw.split()
        if not tok or tok[0] in ("ply", "comment", "obj_info"):
            continue
        if tok[0] == "format" and len(tok) >= 2:
            fmt = tok[1]
        elif tok[0] == "element" and len(tok) == 3:
            try:
                count = int(tok[2])
            except ValueError:
                count = -1
            if count < 0:
                raise MeshFileError(f"{path}, line {line_no}: cannot read the count of element "
                                    f"{tok[1]!r} from {tok[2]!r}.")
            elements.append((tok[1], count, []))
            declared[tok[1]] = (line_no, raw.strip())
        elif tok[0] == "property" and elements:
            if len(tok) == 5 and tok[1] == "list" and tok[2] in _TYPES and tok[3] in _TYPES:
                elements[-1][2].append((tok[4], (_TYPES[tok[2]], _TYPES[tok[3]])))
            elif len(tok) == 3 and tok[1] in _TYPES:
                elements[-1][2].append((tok[2], _TYPES[tok[1]]))
            else:
                raise MeshFileError(f"{path}, line {line_no}: cannot read the property {raw.strip()!r}.")
        else:
            raise MeshFileError(f"{path}, line {line_no}: unexpected header line {raw.strip()!r}.")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise MeshFileError(f"{path}: cannot read the PLY format {fmt!r} (ascii, "
                            "binary_little_endian or binary_big_endian).")
    return fmt, elements, body, declared


def _truncated(path, name, count):
    return MeshFileError(f"{path}: the file is truncated: the header promises {count} {name} "
                         "elements but the data ends before them (or the counts are wrong).")


def _binary_element(buf, pos, name, count, props, order, path):
    """One element's properties ``{name: (count,) or (count, k)}`` and the next offset."""
    if all(isinstance(t, str) for _, t in props):
        dt = np.dtype([(p, order + t) for p, t in props])
        if pos + dt.itemsize * count > len(buf):
            raise _truncated(path, name, count)
        rec = np.frombuffer(buf, dt, count, pos)
        return {p: rec[p] for p, _ in props}, pos + dt.itemsize * count
    if count == 0:
        return {p: np.zeros(0) for p, _ in props}, pos
    # Lists: assume every row has the first row's counts (all triangles), check, else row by row.
    fields, p0 = [], pos
    for p, t in props:
        if isinstance(t, str):
            fields.append((p, order + t))
            p0 += np.dtype(t).itemsize
        else:
            if p0 + np.dtype(t[0]).itemsize > len(buf):
                raise _truncated(path, name, count)
            k = int(np.frombuffer(buf, order + t[0], 1, p0)[0])
            fields += [(p + "#n", order + t[0]), (p, order + t[1], (k,))]
            p0 += np.dtype(t[0]).itemsize + k * np.dtype(t[1]).itemsize
    dt = np.dtype(fields)
    if pos + dt.itemsize * count <= len(buf):
        rec = np.frombuffer(buf, dt, count, pos)
        ok = all(np.all(rec[p + "#n"] == dt[p].shape[0]) for p, t in props if not isinstance(t, str))
        if ok:
            return ({p: rec[p] for p, _ in props}, pos + dt.itemsize * count)
    out = {p: [] for p, _ in props}
    for _ in range(count):     # mixed polygon sizes: rare, read row by row
        for p, t in props:
            ct, it = (t, None) if isinstance(t, str) else t
            size = np.dtype(ct).itemsize
            if pos + size > len(buf):
                raise _truncated(path, name, count)
            v = np.frombuffer(buf, order + ct, 1, pos)[0]
            pos += size
            if it is not None:
                n = int(v)
                if n < 0 or pos + n * np.dtype(it).itemsize > len(buf):
                    raise _truncated(path, name, count)
                v = np.frombuffer(buf, order + it, n, pos)
                pos += n * np.dtype(it).itemsize
            out[p].append(v)
    return {p: (np.asarray(v) if isinstance(t, str) else v) for (p, t), v in zip(props, out.values())}, pos


def _ascii_element(lines, pos, name, count, props, path):
    if pos + count > len(lines):
        raise _truncated(path, name, count)
    rows = lines[pos:pos + count]
    if count == 0:
        return {p: np.zeros(0) for p, _ in props}, pos
    try:
        if all(isinstance(t, str) for _, t in props):
            A = np.asarray(" ".join(rows).split(), np.float64)
            if A.size != count * len(props):
                raise ValueError
            A = A.reshape(count, len(props))
            return {p: A[:, j] for j, (p, _) in enumerate(props)}, pos + count
        fixed = _ascii_fixed(rows, props)
        if fixed is not None:
            return fixed, pos + count
        out = {p: [] for p, _ in props}
        for r in rows:
            tok, j = r.split(), 0
            for p, t in props:
                if isinstance(t, str):
                    out[p].append(float(tok[j]))
                    j += 1
                else:
                    n = int(tok[j])
                    if n < 0 or j + 1 + n > len(tok):
                        raise ValueError
                    out[p].append(np.asarray(tok[j + 1:j + 1 + n], np.float64))
                    j += 1 + n
    except (ValueError, IndexError):
        raise MeshFileError(f"{path}: cannot read the {name} data of this ASCII PLY file; it is "
                            "malformed or does not match its header.") from None
    return {p: (np.asarray(v) if isinstance(t, str) else v) for (p, t), v in
            zip(props, out.values())}, pos + count


def _ascii_fixed(rows, props):
    """The rows read at once when every row has the first row's list counts (all triangles),
    else ``None``."""
    A = np.asarray(" ".join(rows).split(), np.float64)
    if A.size % len(rows):
        return None
    A = A.reshape(len(rows), -1)
    out, j = {}, 0
    for p, t in props:
        if isinstance(t, str):
            if j >= A.shape[1]:
                return None
            out[p], j = A[:, j], j + 1
        else:
            if j >= A.shape[1]:
                return None
            k = A[0, j]
            if (not np.isfinite(k) or not np.all(A[:, j] == k) or k < 0 or k != int(k)
                    or j + 1 + int(k) > A.shape[1]):
                return None
            out[p], j = A[:, j + 1:j + 1 + int(k)], j + 1 + int(k)
    return out if j == A.shape[1] else None


def read_elements(path) -> dict:
    """Every element of a PLY file: ``{element: {property: array}}``, in file order; a list
    property is ``(count, k)`` when all rows have ``k`` items, else a list of arrays."""
    return read_elements_located(path)[0]


def read_elements_located(path):
    """``(elements, lines)``: :func:`read_elements`' dictionary and, for an ASCII file,
    ``{element: (count,) file line of each row}`` (``None`` for a binary file).

    Raises :class:`MeshFileError` when an ASCII file has data lines after the last element
    the header declares (its count is too small), naming the line where they start, or a
    binary file has bytes other than white space after it, naming the byte offset; that
    error has ``complete = True`` (:func:`read_ply` passes its message on as it is).
    """
    p = existing_file(path)
    data = p.read_bytes()
    if not data:
        raise MeshFileError(f"{path}: the file is empty.")
    fmt, elements, pos, declared = _header(data, path)
    out = {}
    if fmt == "ascii":
        first = data[:pos].count(b"\n") + 1             # the file line of the body's first line
        numbered = [(first + i, ln) for i, ln in enumerate(data[pos:].decode("latin-1").splitlines())
                    if ln.strip()]
        lines, pos, where = [ln for _, ln in numbered], 0, {}
        for name, count, props in elements:
            where[name] = np.array([n for n, _ in numbered[pos:pos + max(count, 0)]], np.int64)
            out[name], pos = _ascii_element(lines, pos, name, count, props, path)
        if pos < len(lines) and elements:
            name, count, _ = elements[-1]
            extra = len(lines) - pos
            decl_line, decl = declared[name]
            exc = MeshFileError(
                f"{path}, line {numbered[pos][0]}: data goes on after the {count} {name} "
                f"elements the header promises: {extra} more line{'s' if extra != 1 else ''} from "
                f"here ({count + extra} {name} lines in all, if they are all {name}s); fix the "
                f"count in the header (line {decl_line}: {decl!r}) or remove the extra lines.")
            exc.complete = True
            raise exc
        return out, where
    order = "<" if fmt == "binary_little_endian" else ">"
    for name, count, props in elements:
        out[name], pos = _binary_element(data, pos, name, count, props, order, path)
    if data[pos:].strip(b" \t\r\n") and elements:
        name, count, _ = elements[-1]
        decl_line, decl = declared[name]
        extra = len(data) - pos
        exc = MeshFileError(
            f"{path}, byte {pos}: binary data goes on after the {count} {name} elements the "
            f"header promises: {extra} more byte{'s' if extra != 1 else ''} to the end of the "
            f"file; fix the count in the header (line {decl_line}: {decl!r}) or cut the file "
            f"at byte {pos}.")
        exc.complete = True
        raise exc
    return out, None


def read_ply(path):
    """Read a PLY mesh in file order: ``(vertices (n, 3), faces (m, 3), uv (n, 2) or None,
    texcoords (t, 2) or None, uv_faces (m, 3) or None)``; polygons are split into triangles
    (fans; ear clipping for concave ones; repeated corners merged:
    :func:`~jaxparam.io.polygons.triangulate`).

    Per-vertex UVs come from the vertex properties :data:`UV_NAMES`; per-corner UVs from a
    face list ``texcoord`` (2 numbers per corner).  Raises :class:`MeshFileError` for a
    missing or empty file, and ``"{path}: cannot read the file as .ply (what is wrong, with
    the line); check the format ..."`` for one that is not a readable PLY mesh.
    """
    p = existing_file(path)
    if p.stat().st_size == 0:
        raise MeshFileError(f"{path}: the file is empty.")
    try:
        return _read_ply(path)
    except MeshFileError as exc:
        if getattr(exc, "complete", False):
            raise MeshFileError(str(exc)) from None
        detail = str(exc)
        for head in (f"{path}: ", f"{path}, "):
            if detail.startswith(head):
                detail = detail[len(head):]
        raise MeshFileError(f"{path}: cannot read the file as .ply ({detail.rstrip('.')}); check "
                            "the format and that the file is complete.") from None


def _read_ply(path):
    el, lines = read_elements_located(path)
    vert = el.get("vertex", {})
    if not all(c in vert for c in "xyz"):
        raise MeshFileError(f"{path}: the PLY file has no vertex x, y, z properties.")
    V = np.stack([np.asarray(vert[c], np.float64) for c in "xyz"], 1)
    face = el.get("face", {})
    key = next((k for k in ("vertex_indices", "vertex_index") if k in face), None)
    if key is None:
        raise MeshFileError(f"{path}: no faces (a 'face' element with 'vertex_indices') in the "
                            "PLY file; for bare points use jaxparam meshless.")
    rows = face[key]
    if isinstance(rows, list):
        short = [i for i, r in enumerate(rows) if len(r) < 3]
        if short:
            raise MeshFileError(f"{path}: face {short[0]} has fewer than three vertices.")
    elif rows.ndim != 2 or rows.shape[1] < 3:
        raise MeshFileError(f"{path}: the faces have fewer than three vertices.")
    if len(rows) == 0:
        raise MeshFileError(f"{path}: the PLY file has no faces.")
    if isinstance(rows, list):
        sizes = np.array([len(r) for r in rows], np.int64)
        flat = np.concatenate([np.asarray(r, np.float64) for r in rows])
    else:
        sizes = np.full(rows.shape[0], rows.shape[1], np.int64)
        flat = np.asarray(rows, np.float64).reshape(-1)
    start = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    wrong = (flat != np.round(flat)) | (flat < 0) | (flat >= V.shape[0])
    if np.any(wrong):
        bad = int(np.searchsorted(start, np.flatnonzero(wrong)[0], side="right") - 1)
        raise MeshFileError(f"{path}: face {bad} has a vertex index out of range "
                            f"[0, {V.shape[0]}).")
    flat = flat.astype(np.int64)
    polys = (flat.reshape(rows.shape) if not isinstance(rows, list)
             else [flat[s:s + n] for s, n in zip(start, sizes)])
    face_lines = None if lines is None else lines.get("face")
    if face_lines is not None and face_lines.size == len(rows):
        def where(i):
            return f"{path}, line {int(face_lines[i])} (face {i})"
    else:
        def where(i):
            return f"{path}, face {i}"
    poly, pick = triangulate(V, polys, where)
    corner = start[poly][:, None] + pick                              # (m, 3) into ``flat``
    F = flat[corner]
    uv = next((np.stack([np.asarray(vert[a], np.float64), np.asarray(vert[b], np.float64)], 1)
               for a, b in UV_NAMES if a in vert and b in vert), None)
    tex = T = None
    if "texcoord" in face:
        tc = face["texcoord"]
        sizes = (np.array([len(r) for r in tc]) if isinstance(tc, list) else
                 np.full(tc.shape[0], tc.shape[1]))
        nverts = np.diff(np.append(start, flat.size))
        if len(tc) != len(rows) or np.any(sizes != 2 * nverts):
            raise MeshFileError(f"{path}: the face texcoord lists must hold two numbers per face "
                                "corner.")
        tflat = (np.concatenate([np.asarray(r) for r in tc]) if isinstance(tc, list)
                 else tc.reshape(-1)).astype(np.float64).reshape(-1, 2)
        tex, T = tflat, corner
    return V, F, uv, tex, T


def write_ply(f, V, F, uv=None, texcoords=None, uv_faces=None) -> None:
    """Write a binary little-endian PLY to the open binary file ``f``: ``double`` ``x y z``
    (and ``u v`` for a per-vertex ``uv (n, 2)``), faces as ``uchar int`` lists (and a
    ``texcoord`` list of six ``double`` per face for per-corner UVs)."""
    n, m = V.shape[0], F.shape[0]
    vfields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")] + ([("u", "<f8"), ("v", "<f8")] if uv is not None else [])
    vert = np.empty(n, np.dtype(vfields))
    vert["x"], vert["y"], vert["z"] = V[:, 0], V[:, 1], V[:, 2]
    if uv is not None:
        vert["u"], vert["v"] = uv[:, 0], uv[:, 1]
    ffields = [("n", "u1"), ("vertex_indices", "<i4", (3,))]
    if texcoords is not None:
        ffields += [("k", "u1"), ("texcoord", "<f8", (6,))]
    face = np.empty(m, np.dtype(ffields))
    face["n"], face["vertex_indices"] = 3, F
    if texcoords is not None:
        face["k"], face["texcoord"] = 6, texcoords[uv_faces].reshape(m, 6)
    head = ["ply", "format binary_little_endian 1.0", "comment written by jaxparam",
            f"element vertex {n}"] + [f"property double {c}" for c, _ in vfields]
    head += [f"element face {m}", "property list uchar int vertex_indices"]
    if texcoords is not None:
        head.append("property list uchar double texcoord")
    f.write(("\n".join(head + ["end_header"]) + "\n").encode("ascii"))
    f.write(vert.tobytes())
    f.write(face.tobytes())
